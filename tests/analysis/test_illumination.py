"""Relative illumination (S51, S52) and the flux-counting reference, against closed forms on a
monocentric lens: one refracting sphere (radius R, glass n behind it) with the stop at its centre of
curvature. The centre images onto itself, so the paraxial entrance pupil is there too and every chief
ray passes the centre undeviated; a ray at perpendicular distance d from its chief ray is bent towards
it by u'(d) = asin(d/R) − asin(d/(nR)) in the plane through the centre (exact, any field)."""

import math

import numpy as np
import pytest
import torch

from lensopt.analysis.illumination import (
    THREE_RAY_PUPIL,
    relative_illumination_std,
    relative_illumination_three_ray,
)
from lensopt.analysis.irradiance import relative_illumination_flux
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build, parse_spec

R_MM, N_GLASS, HFOV = 10.0, 1.5, 30.0
REL = [0.0, 0.5, 1.0]


def _monocentric(epd: float) -> dict:
    back = R_MM / (N_GLASS - 1.0)  # paraxial focus behind the centre
    glass = {"nd": N_GLASS, "vd": 60.0}
    return {
        "name": "monocentric",
        "system": {"aperture": {"epd": epd}, "field": {"hfov_deg": HFOV, "relative": REL}},
        "spectrum": {"wavelengths_nm": [587.6]},
        "surfaces": [{"type": "sphere", "radius": R_MM, "thickness": R_MM, "material": glass},
                     {"type": "plane", "thickness": back, "material": glass, "stop": True}],
    }


def _u(d: np.ndarray, n: float) -> np.ndarray:
    return np.arcsin(d / R_MM) - np.arcsin(d / (n * R_MM))


def _directions(points: np.ndarray, theta: float, h: float, n: float) -> np.ndarray:
    """Image-space directions (P, 3) of rays launched through relative pupil points at field θ."""
    e1 = np.array([0.0, math.sin(theta), math.cos(theta)])
    p = np.stack([points[:, 0] * h, points[:, 1] * h, np.zeros(len(points))], -1)  # from the centre
    v = p - (p @ e1)[:, None] * e1
    d = np.linalg.norm(v, axis=-1)
    u = _u(d, n)
    unit = np.divide(v, d[:, None], out=np.zeros_like(v), where=d[:, None] > 0)
    return np.cos(u)[:, None] * e1 - np.sin(u)[:, None] * unit


def test_three_ray_estimate_closed_form() -> None:
    # S51 with α_l = −sin u'(h), β_{i,s} = sin(θ ± u'(h cos θ)) gives R = cos θ sin u'(h cos θ) / sin u'(h).
    epd = 4.0
    m = build(parse_spec(_monocentric(epd)))
    b = trace_bundle(m.lens, m.system, torch.tensor(THREE_RAY_PUPIL, dtype=torch.float64))
    ours = relative_illumination_three_ray(b, 0)
    n, h = float(m.lens.index[1, 0]), epd / 2
    expected = [math.cos(t) * math.sin(_u(np.array(h * math.cos(t)), n)) / math.sin(_u(np.array(h), n))
                for t in (math.radians(u * HFOV) for u in REL)]
    assert ours.tolist() == pytest.approx(expected, abs=1e-12)


def test_std_estimate_matches_analytic_directions() -> None:
    # S52 from analytic image-space directions of the same pupil points (numpy), half pupil: ᾱ = 0.
    epd = 4.0
    m = build(parse_spec(_monocentric(epd)))
    scheme = PupilSampling.parse("rings:10:nojitter")
    pts = scheme.points(dtype=torch.float64)
    b = trace_bundle(m.lens, m.system, pts, half_pupil=True)
    ours = relative_illumination_std(b, m.system.wavelength_weights)
    n = float(m.lens.index[1, 0])
    prods = []
    for u in REL:
        d = _directions(pts.numpy(), math.radians(u * HFOV), epd / 2, n)
        a_std = math.sqrt(float((d[:, 0] ** 2).mean()))
        prods.append(a_std * float(d[:, 1].std()))
    assert ours.tolist() == pytest.approx([p / prods[0] for p in prods], abs=1e-12)


def test_flux_reference_gives_cos4_on_a_flat_image() -> None:
    # Flux counting sees the flat stop at the centre from the image plane: E ∝ cos⁴θ (the exit pupil is
    # the stop; with a small aperture the spot centroid is the chief ray L tan θ up to O(h²)).
    m = build(parse_spec(_monocentric(0.2)))
    ri = relative_illumination_flux(m.lens, m.system, REL, grid=61)
    assert int(ri.edge_hits.sum()) == 0
    expected = [math.cos(math.radians(u * HFOV)) ** 4 for u in REL]
    assert ri.relative_illumination.tolist() == pytest.approx(expected, abs=2e-3)


def test_flux_reference_is_the_same_in_tiles() -> None:
    # Tracing the pupil grid in tiles (bounded memory) sums the same passing rays and centroids.
    m = build(parse_spec(_monocentric(0.2)))
    whole = relative_illumination_flux(m.lens, m.system, REL, grid=61)
    tiled = relative_illumination_flux(m.lens, m.system, REL, grid=61, max_rays=2000)
    assert torch.equal(tiled.pass_area, whole.pass_area)
    assert torch.equal(tiled.edge_hits, whole.edge_hits)
    torch.testing.assert_close(tiled.relative_illumination, whole.relative_illumination, rtol=1e-12, atol=0.0)
