"""Front aperture (S1.3.2, S4.1.5) on the plastic telephoto: vignetting factors against brute force.

Brute force, independent of the factor geometry: the same lens with a real clipping plane (a dummy
surface of diameter D at z = d, traced first; the lens follows it at −d) is traced for a dense grid
over the whole entrance pupil; the rays that pass that plane are kept and the extents of the kept
pupil points are compared with the factors lensopt launches with (≤ 1 % of the pupil radius, the
issue's criterion; the grid cell is 0.67 % of it).
"""

import copy
import tomllib
from functools import cache
from pathlib import Path

import pytest
import torch

from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import field_tangents, first_order
from lensopt.optics.sampling import launch, pupil_grid
from lensopt.optics.trace import Status, trace
from lensopt.optics.vignetting import clip_ellipse_to_disc, front_aperture_disc
from lensopt.spec import Model, build, parse_spec
from tests.helpers import cooke_data

SPEC = Path(__file__).resolve().parents[2] / "specs" / "telephoto_plastic.toml"
F64 = torch.float64
GRID = 301  # cell 2/301 = 0.0066 relative pupil units (0.0086 over the ±1.3 grid used with aiming)
TOL = 0.01  # 1 % of the pupil radius


@cache
def _data(lateral: str, aim: str) -> dict:
    data = tomllib.loads(SPEC.read_text())
    data["spectrum"] = {"wavelengths_nm": [550.0]}  # the aperture's geometry does not depend on λ
    data["system"]["aim"] = aim
    data["system"]["aim_steps"] = 1  # the seed's single step: misses ~2 µm here, 0.05 % of the pupil
    data["system"]["front_aperture"]["lateral"] = lateral
    return data


@cache
def _model(lateral: str, aim: str) -> Model:
    return build(parse_spec(_data(lateral, aim)))


@cache
def _dummy_model(aim: str, stop_radius: float | None) -> Model:
    """The lens behind a real clipping plane at the front aperture (and a clipping stop if given)."""
    data = copy.deepcopy(_data("inscribed", aim))
    fa = data["system"].pop("front_aperture")
    data["system"]["aim"] = "none"
    # 1e-9 relative slack: with D = EPD the axial rim rays graze the edge exactly (rounding decides).
    plane = {"type": "plane", "thickness": -fa["distance"], "semi_diameter": fa["diameter"] / 2 * (1 + 1e-9),
             "clip": True, "label": "front aperture"}
    if stop_radius is not None:
        stop = next(s for s in data["surfaces"] if s.get("stop"))
        stop.update(semi_diameter=stop_radius, clip=True)
    data["surfaces"].insert(0, plane)
    return build(parse_spec(data))


def _kept_extents(aim: str, half: float, centre: torch.Tensor, stop_radius: float | None,
                  fields: list[int] | None = None) -> torch.Tensor:
    """(F, 3): lowest y, highest y, widest |x| of the pupil points (paraxial pupil units) whose rays pass
    the clipping plane (and the clipping stop, if given): traced up to the last aperture, no further."""
    m = _dummy_model(aim, stop_radius)
    g = pupil_grid(GRID, dtype=F64) * half  # cell-centred points in the disc of radius ``half``
    pts = g.unsqueeze(0).unsqueeze(0) + torch.stack([torch.zeros_like(centre), centre], -1)[:, None, None, :]
    fo = first_order(m.lens, m.system)
    rel = torch.tensor(m.system.rel_field, dtype=F64)
    if fields is not None:
        rel, pts = rel[fields], pts[fields]
    tan = field_tangents(m.lens, m.system, rel)
    rays = launch(m.lens, m.system, pts, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
    keep = trace(m.lens, rays, upto=m.lens.stop if stop_radius is not None else 0).valid
    out = []
    for h in range(pts.shape[0]):
        k = keep[h, 0]
        p = pts[h, 0][k]
        out.append(torch.stack([p[:, 1].min(), p[:, 1].max(), p[:, 0].abs().max()]))
    return torch.stack(out)


def test_dummy_lens_launches_the_same_rays() -> None:
    # The brute-force lens starts at the aperture plane: same entrance pupil (shifted by d), same EPD.
    a, b = _model("extent", "none"), _dummy_model("none", None)
    fa = _data("extent", "none")["system"]["front_aperture"]
    fo_a, fo_b = first_order(a.lens, a.system), first_order(b.lens, b.system)
    assert float(fo_b.entrance_pupil_z) == pytest.approx(float(fo_a.entrance_pupil_z) - fa["distance"], abs=1e-12)
    assert float(fo_b.efl) == pytest.approx(float(fo_a.efl), rel=1e-14)


@pytest.mark.parametrize("lateral", ["extent", "inscribed"])
def test_factors_match_brute_force_without_aiming(lateral: str) -> None:
    m = _model(lateral, "none")
    with torch.no_grad():
        v = trace_bundle(m.lens, m.system, torch.zeros(1, 2, dtype=F64)).vignetting[:, 0]
        kept = _kept_extents("none", 1.0, torch.zeros(v.shape[0], dtype=F64), None)
    assert float((v[:, 0] - (1.0 + kept[:, 0])).abs().max()) <= TOL  # V_i: lowest passing pupil point
    assert float((v[:, 1] - (1.0 - kept[:, 1])).abs().max()) <= TOL  # V_s: highest
    if lateral == "extent":
        assert float(((1.0 - v[:, 2]) - kept[:, 2]).abs().max()) <= TOL  # V_l: widest
    else:
        assert bool((1.0 - v[:, 2] <= kept[:, 2] + 2.0 / GRID).all())  # inscribed: never wider than the kept set
    assert float(v[-1, 0]) > 0.05  # the full field is really vignetted (V_i ≈ 0.08)


def test_inscribed_bundle_passes_the_aperture_entirely() -> None:
    # Every ray of the inscribed ellipse passes the real clipping plane and lies in the entrance pupil;
    # 1 % wider, some would not (outside the pupil or clipped).
    m = _model("inscribed", "none")
    d = _dummy_model("none", None)
    with torch.no_grad():
        t = torch.linspace(0.0, 2.0 * torch.pi, 721, dtype=F64)[:-1]
        rim = torch.stack([torch.cos(t), torch.sin(t)], -1)
        b = trace_bundle(m.lens, m.system, torch.cat([pupil_grid(41, dtype=F64), rim]))
        assert not bool((b.result.status == Status.BLOCKED).any())
        pts = b.pupil  # the launched (vignetted) pupil points, paraxial pupil units
        assert bool((trace_bundle(d.lens, d.system, pts).result.status != Status.CLIPPED).all())
        assert float(torch.linalg.vector_norm(pts, dim=-1).max()) <= 1.0 + 1e-12
        wider = pts * torch.tensor([1.01, 1.0], dtype=F64)
        out = (trace_bundle(d.lens, d.system, wider).result.status == Status.CLIPPED)
        out = out | (torch.linalg.vector_norm(wider, dim=-1) > 1.0 + 1e-12)
        assert bool(out[-1].any())


def test_factors_match_brute_force_with_full_aiming() -> None:
    # With full aiming the kept set is cut by the stop (radius of the axial beam) and the aperture:
    # y limits exact (aimed marginal ray / aperture edge), x the extent of the aimed ellipse ∩ disc.
    # The full field only (the most vignetted); benchmarks/trace/pupils_vignetting.py does every field.
    m = _model("extent", "full")
    with torch.no_grad():
        b = trace_bundle(m.lens, m.system, torch.zeros(1, 2, dtype=F64))
        v = b.vignetting[:, 0]
        r = float(b.pupil_aim.stop_radius_mm)
        v = v[-1:]
        centre = 0.5 * (v[:, 0] - v[:, 1])
        kept = _kept_extents("full", 1.3, centre, r, fields=[-1])
    assert float((v[:, 0] - (1.0 + kept[:, 0])).abs().max()) <= TOL
    assert float((v[:, 1] - (1.0 - kept[:, 1])).abs().max()) <= TOL
    assert float(((1.0 - v[:, 2]) - kept[:, 2]).abs().max()) <= TOL


def test_factors_are_differentiable_in_the_lens() -> None:
    # V_i of the full field against the thickness of element 1 (it moves the entrance pupil):
    # forward-mode autodiff against central differences of the same closed-form pipeline.
    m = _model("inscribed", "none")
    lens, system = m.lens, m.system
    rel = torch.tensor([1.0], dtype=F64)
    fa = system.front_aperture

    def factors(t0: torch.Tensor) -> torch.Tensor:
        ln = lens.__class__(**{**lens.__dict__, "thickness": torch.cat([t0.reshape(1), lens.thickness[1:]])})
        fo = first_order(ln, system)
        c, rho = front_aperture_disc(fa.distance, fa.diameter, field_tangents(ln, system, rel), epd=fo.epd,
                                     entrance_pupil_z=fo.entrance_pupil_z)
        one = torch.ones_like(c[:, None])
        (y, a, bb), _ = clip_ellipse_to_disc((0 * one, one, one), c[:, None], rho)
        return torch.stack([y, a, bb], -1)

    t0 = lens.thickness[0].clone()
    jac = torch.func.jacfwd(factors)(t0)
    h = 1e-6
    fd = (factors(t0 + h) - factors(t0 - h)) / (2 * h)
    assert torch.allclose(jac, fd, rtol=1e-6, atol=1e-9)
    assert float(jac.abs().max()) > 1e-3  # the factors do move with the lens


def test_bundle_statistics_are_differentiable_through_aiming_and_the_aperture() -> None:
    # End to end, as an optimizer sees it: spot radii, S52 illumination, S48 distortion and the launched
    # factors of a Cooke triplet with a front aperture (10 mm before it, 12 mm wide: V_i up to 1.3) and
    # converged full aiming, forward-mode derivative in one curvature against central differences.
    import dataclasses

    from lensopt.analysis.distortion import distortion
    from lensopt.analysis.illumination import relative_illumination_std
    from lensopt.analysis.spot import spot_stats
    from lensopt.optics.sampling import PupilSampling

    data = cooke_data()
    data["system"].update(aim="full", aim_steps=4, front_aperture={"distance": -10.0, "diameter": 12.0})
    m = build(parse_spec(data))
    lens, system = m.lens, m.system
    pts = PupilSampling.parse("rings:3").points(dtype=F64)

    def f(c: torch.Tensor) -> torch.Tensor:
        ln = dataclasses.replace(lens, curvature=torch.cat([lens.curvature[:2], c.reshape(1), lens.curvature[3:]]))
        b = trace_bundle(ln, system, pts, half_pupil=True)
        st = spot_stats(b, system.wavelength_weights)
        return torch.cat([st.rms_radius, relative_illumination_std(b, system.wavelength_weights),
                          distortion(ln, system, b, st), b.vignetting.flatten()])

    c = lens.curvature[2].clone()
    y, dy = torch.func.jvp(f, (c,), (torch.ones_like(c),))
    h = 1e-7
    fd = (f(c + h) - f(c - h)) / (2 * h)
    assert float(y[-3]) > 1.0  # the full field is cut above its centre by the aperture
    assert bool(torch.isfinite(dy).all())
    assert torch.allclose(dy, fd, rtol=1e-5, atol=1e-7)
