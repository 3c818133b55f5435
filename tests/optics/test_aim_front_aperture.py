"""Full aiming behind a front aperture (issue 15, "aiming behind a front aperture"; seed S1.3.2, last
paragraph): the vignetting the aperture causes comes first, then the top and sagittal rays of the
vignetted pupil are aimed at the stop edge while the bottom stays on the aperture's edge.

Test lens: tests/data/telephoto_vignetted.toml, the plastic telephoto with its front aperture 6 mm in
front of the first vertex (V_i ≈ 0.4 at the edge of the field) and a first element clipped to the
vignetted beam, so that the inferior marginal ray of the *unvignetted* pupil misses it.

Brute force, independent of the aiming: the lens behind a real clipping plane at the aperture and with
a clipping stop of the axial beam's radius, traced for a dense grid over the pupil; the extents of the
pupil points whose rays reach the stop are the factors aiming must find (≤ 1 % of the pupil radius).
"""

import copy
import tomllib
from functools import cache
from pathlib import Path

import pytest
import torch

from lensopt.analysis.field import field_summary
from lensopt.optics.aiming import aim_full
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import field_tangents, first_order
from lensopt.optics.sampling import PupilSampling, launch, pupil_grid
from lensopt.optics.trace import Status, trace
from lensopt.spec import Model, build, parse_spec

SPEC = Path(__file__).resolve().parents[1] / "data" / "telephoto_vignetted.toml"
F64 = torch.float64
GRID = 301  # cell 2.6/301 = 0.0086 relative pupil units over the ±1.3 grid
TOL = 0.01  # 1 % of the pupil radius


@cache
def _data(wavelengths: tuple[float, ...] | None = None, lateral: str = "inscribed") -> dict:
    data = tomllib.loads(SPEC.read_text())
    data["system"]["front_aperture"]["lateral"] = lateral
    if wavelengths is not None:
        data["spectrum"] = {"wavelengths_nm": list(wavelengths)}
    return data


@cache
def _model(wavelengths: tuple[float, ...] | None = None, lateral: str = "inscribed") -> Model:
    return build(parse_spec(_data(wavelengths, lateral)))


@cache
def _bundle(wavelengths: tuple[float, ...] | None = None, lateral: str = "inscribed"):
    m = _model(wavelengths, lateral)
    with torch.no_grad():
        return trace_bundle(m.lens, m.system, torch.zeros(1, 2, dtype=F64))


def test_test_lens_vignettes_strongly_and_defeats_aiming_the_unvignetted_pupil() -> None:
    # The hard case is real: V_i of 0.3–0.6 at the edge of the field, and aiming the unvignetted pupil
    # (no aperture passed to aim_full, the old order) loses the inferior ray at the outer fields.
    b = _bundle()
    assert 0.3 <= float(b.vignetting[-1, :, 0].min()) and float(b.vignetting[-1, :, 0].max()) <= 0.6
    m = _model()
    fo = first_order(m.lens, m.system)
    tan = field_tangents(m.lens, m.system, torch.tensor(m.system.rel_field, dtype=F64))
    with torch.no_grad():
        old = aim_full(m.lens, m.system, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z,
                       steps=m.system.aim_steps)
    assert not bool(old.traced[-1, :, 0].any())  # inferior ray lost at the full field, every wavelength


def test_aiming_converges_in_every_bundle_with_no_fallback() -> None:
    # Every field × wavelength (5 × 11): every marginal ray and the chief ray reach the stop, every
    # residual below the tolerance, the bottom held on the aperture's edge off axis, and the field
    # summary carries no "full aiming not converged" note (the fallback's message).
    b = _bundle()
    pa = b.pupil_aim
    assert pa.converged.shape == (5, 11)
    assert bool(pa.traced.all())
    assert bool(pa.converged.all())
    assert bool(pa.held[1:, :, 0].all()) and not bool(pa.held[1:, :, 1].any())
    assert not bool((b.result.status == Status.BLOCKED).any())
    m = _model()
    with torch.no_grad():
        s = field_summary(m.lens, m.system, PupilSampling.parse("rings:3"))
    assert not [n for n in s.notes if "aiming" in n], s.notes


@cache
def _dummy_model(stop_radius: float) -> Model:
    """The lens behind a real clipping plane at the front aperture, with a clipping stop."""
    data = copy.deepcopy(_data((550.0,)))
    fa = data["system"].pop("front_aperture")
    data["system"]["aim"] = "none"
    plane = {"type": "plane", "thickness": -fa["distance"], "semi_diameter": fa["diameter"] / 2 * (1 + 1e-9),
             "clip": True, "label": "front aperture"}
    stop = next(s for s in data["surfaces"] if s.get("stop"))
    stop.update(semi_diameter=stop_radius * (1 + 1e-9), clip=True)  # rays aimed at the edge graze it
    data["surfaces"].insert(0, plane)
    return build(parse_spec(data))


@pytest.mark.parametrize("field", [2, 3, 4])
def test_factors_match_brute_force_with_aiming_behind_the_aperture(field: int) -> None:
    b = _bundle((550.0,))
    ext = _bundle((550.0,), "extent").vignetting[field, 0]  # x: the aimed sagittal ray, no inscribing
    v = b.vignetting[field, 0]
    r = float(b.pupil_aim.stop_radius_mm)
    m = _dummy_model(r)
    centre = 0.5 * float(v[0] - v[1])
    g = pupil_grid(GRID, dtype=F64) * 1.3 + torch.tensor([0.0, centre], dtype=F64)
    fo = first_order(m.lens, m.system)
    tan = field_tangents(m.lens, m.system, torch.tensor([m.system.rel_field[field]], dtype=F64))
    with torch.no_grad():
        rays = launch(m.lens, m.system, g.expand(1, 1, *g.shape), tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
        keep = trace(m.lens, rays, upto=m.lens.stop).valid[0, 0]
    p = g[keep]
    assert float(v[0]) > 0.15  # really vignetted
    assert abs(float(v[0]) - (1.0 + float(p[:, 1].min()))) <= TOL  # V_i: the lowest point that passes
    assert abs(float(v[1]) - (1.0 - float(p[:, 1].max()))) <= TOL  # V_s: the highest
    assert abs(float(ext[2]) - (1.0 - float(p[:, 0].abs().max()))) <= TOL  # V_l (extent): the widest
    # Inscribed lateral factor: never wider than the kept set. Every launched ray passes the aperture
    # (none BLOCKED) and the clipped first element, and meets the stop inside its edge up to the
    # ellipse's own approximation (S19–S20: the launched ellipse is not the exact image of the stop
    # circle; measured 6e-5 of r at the full field).
    assert 1.0 - float(v[2]) <= float(p[:, 0].abs().max()) + 2.6 / GRID
    t = torch.linspace(0.0, 2.0 * torch.pi, 361, dtype=F64)[:-1]
    rim = torch.cat([pupil_grid(21, dtype=F64), torch.stack([torch.cos(t), torch.sin(t)], -1)])
    lm = _model((550.0,))
    with torch.no_grad():
        launched = trace_bundle(lm.lens, lm.system, rim)
        hit = trace(lm.lens, launched.rays, upto=lm.lens.stop)
    assert not bool((launched.result.status[field, 0] == Status.BLOCKED).any())
    assert bool(hit.valid[field, 0].all())
    assert float(hit.pos[field, 0, :, :2].norm(dim=-1).max()) <= r * (1.0 + 1e-4)


def test_held_and_aimed_factors_are_differentiable_in_the_lens() -> None:
    # The held bottom (the aperture's edge, moving with the entrance pupil) and the aimed top and
    # sagittal rays: forward-mode derivative in the thickness of element 1 against central differences
    # (converged aiming, so the last attached step gives the exact derivative).
    import dataclasses

    m = _model((550.0,))
    lens, system = m.lens, m.system
    zero = torch.zeros(1, 2, dtype=F64)

    def f(t0: torch.Tensor) -> torch.Tensor:
        ln = dataclasses.replace(lens, thickness=torch.cat([t0.reshape(1), lens.thickness[1:]]))
        b = trace_bundle(ln, system, zero)
        return torch.cat([b.vignetting[2:, 0].flatten(), b.pupil_aim.factors[2:, 0].flatten()])

    t0 = lens.thickness[0].clone()
    y, dy = torch.func.jvp(f, (t0,), (torch.ones_like(t0),))
    h = 1e-6
    fd = (f(t0 + h) - f(t0 - h)) / (2 * h)
    assert bool(torch.isfinite(dy).all())
    assert torch.allclose(dy, fd, rtol=1e-5, atol=1e-8)
    assert float(dy.abs().max()) > 1e-3  # the factors do move with the lens


def test_stop_radius_and_chief_offsets_are_differentiable_in_the_lens() -> None:
    # The stop radius (real axial marginal ray) and the converged chief-ray offsets: forward-mode
    # derivatives in a thickness and a curvature of element 1 (their attached final steps, with the
    # trace to the stop differentiated by its explicit partials) against central differences.
    import dataclasses

    from lensopt.optics.aiming import aim_chief, stop_radius

    m = _model()
    lens, system = m.lens, m.system
    rel = torch.tensor(system.rel_field, dtype=F64)

    def f(v: torch.Tensor) -> torch.Tensor:
        ln = dataclasses.replace(lens, thickness=torch.cat([v[:1], lens.thickness[1:]]),
                                 curvature=torch.cat([lens.curvature[:1], v[1:], lens.curvature[2:]]))
        fo = first_order(ln, system)
        opts = {"epd": fo.epd, "entrance_pupil_z": fo.entrance_pupil_z}
        chief = aim_chief(ln, system, field_tangents(ln, system, rel), **opts)
        assert bool(chief.converged.all())
        return torch.cat([stop_radius(ln, system, **opts).reshape(1), chief.offset.flatten()])

    v0 = torch.stack([lens.thickness[0], lens.curvature[1]])
    jac = torch.func.jacfwd(f)(v0)
    for k in range(2):
        h = 1e-6 * float(v0[k].abs())
        e = torch.zeros(2, dtype=F64)
        e[k] = h
        fd = (f(v0 + e) - f(v0 - e)) / (2 * h)
        assert bool(torch.isfinite(jac[:, k]).all())
        assert torch.allclose(jac[:, k], fd, rtol=1e-5, atol=1e-7 * float(fd.abs().max()))
        assert float(fd[1:].abs().max()) > 1e-4  # the offsets do move with the lens
    assert float(jac[0].abs().max()) > 1e-3
