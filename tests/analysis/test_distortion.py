"""Distortion per field (S48) against closed forms."""

import math

import pytest
import torch

from lensopt.analysis.distortion import distortion, paraxial_heights
from lensopt.analysis.spot import spot_stats
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build, parse_spec

N_GLASS = 1.6
L_MM = 20.0
HFOV = 30.0
REL = [0.0, 0.5, 0.8, 1.0]


def _plate_spec() -> dict:
    """A single flat refracting surface (the stop) into glass, image plane L behind it in the glass."""
    return {
        "name": "flat interface",
        "system": {"aperture": {"epd": 4.0}, "field": {"hfov_deg": HFOV, "relative": REL}},
        "spectrum": {"wavelengths_nm": [587.6]},
        "surfaces": [{"type": "plane", "thickness": L_MM, "stop": True,
                      "material": {"nd": N_GLASS, "vd": 60.0}}],
    }


@pytest.mark.parametrize("sampling", ["grid:31", "rings:12:nojitter"])
def test_flat_interface_closed_form(sampling: str) -> None:
    # A collimated beam stays collimated through a flat interface, so the spot is a translated copy of
    # the (symmetric) pupil and its centroid is the chief ray: ȳ = L tan(asin(sin θ / n)), while the
    # paraxial height is y' = L tan θ / n. S48: D = (ȳ − y') / y'(HFOV).
    m = build(parse_spec(_plate_spec()))
    scheme = PupilSampling.parse(sampling)
    b = trace_bundle(m.lens, m.system, scheme.points(dtype=torch.float64), half_pupil=scheme.half)
    stats = spot_stats(b, m.system.wavelength_weights)
    ours = distortion(m.lens, m.system, b, stats)
    n = float(m.lens.index[1, 0])
    theta = [math.radians(u * HFOV) for u in REL]
    real = [L_MM * math.tan(math.asin(math.sin(t) / n)) for t in theta]
    par = [L_MM * math.tan(t) / n for t in theta]
    expected = [(r - p) / par[-1] for r, p in zip(real, par, strict=True)]
    assert ours.tolist() == pytest.approx(expected, abs=1e-13)
    assert paraxial_heights(m.lens, m.system, b).tolist() == pytest.approx(par, abs=1e-12)


def test_distortion_is_differentiable() -> None:
    # dD/dn of the flat interface: autograd against the derivative of the closed form.
    m = build(parse_spec(_plate_spec()))
    scheme = PupilSampling.parse("grid:9")
    n = torch.tensor(float(m.lens.index[1, 0]), dtype=torch.float64, requires_grad=True)
    index = torch.stack([m.lens.index[0], n.reshape(1)])
    lens = m.lens.__class__(**{**m.lens.__dict__, "index": index})
    b = trace_bundle(lens, m.system, scheme.points(dtype=torch.float64))
    d = distortion(lens, m.system, b, spot_stats(b, m.system.wavelength_weights))[-1]
    (g,) = torch.autograd.grad(d, n)
    t = math.radians(HFOV)

    def closed(nv: float) -> float:
        return (math.tan(math.asin(math.sin(t) / nv)) - math.tan(t) / nv) / (math.tan(t) / nv)

    h = 1e-6
    n0 = n.item()
    assert g.item() == pytest.approx((closed(n0 + h) - closed(n0 - h)) / (2 * h), rel=1e-7)
