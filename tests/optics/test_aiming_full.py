"""Full ray aiming (S1.3.2, S21–S22) on a lens with strong pupil aberration: Laikin's 100° retrofocus
(specs/wide_angle_laikin.toml), whose real entrance pupil at 50° sits ~3.7 paraxial pupil radii
above the paraxial one and is 20 % taller."""

from functools import cache
from pathlib import Path

import pytest
import torch

from lensopt.optics.aiming import aim_full, stop_radius
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import field_tangents, first_order
from lensopt.optics.sampling import launch
from lensopt.optics.trace import trace
from lensopt.spec import Model, build, load_spec

SPEC = Path(__file__).resolve().parents[2] / "specs" / "wide_angle_laikin.toml"
F64 = torch.float64
MARGINAL = torch.tensor([[0.0, -1.0], [0.0, 1.0], [1.0, 0.0]], dtype=F64)


@cache
def _model() -> Model:
    return build(load_spec(SPEC))


def _stop_misses(steps: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Where the launched bundle's marginal rays (pupil (0, ∓1), (1, 0)) and the aimed chief ray meet
    the stop, as misses from (∓r, r, 0), mm: (F, W, 3) and (F, W)."""
    m = _model()
    with torch.no_grad():
        b = trace_bundle(m.lens, m.system, MARGINAL, aim="full", aim_steps=steps, record=True)
        r = b.pupil_aim.stop_radius_mm
        hit = b.result.hits[m.lens.stop].pos
        miss = torch.stack([hit[..., 0, 1] + r, hit[..., 1, 1] - r,
                            torch.linalg.vector_norm(hit[..., 2, :2], dim=-1) - r], -1)
        chief = torch.stack([torch.zeros_like(b.aim.offset), b.aim.offset], -1).unsqueeze(-2)
        rays = launch(m.lens, m.system, chief, b.tan_field, epd=b.first_order.epd,
                      entrance_pupil_z=b.first_order.entrance_pupil_z)
        c = trace(m.lens, rays, upto=m.lens.stop)
        assert bool(b.result.valid.all()) and bool(c.valid.all())
    return miss, c.pos[..., 0, 1]


def test_marginal_rays_meet_the_stop_edge_after_three_steps() -> None:
    # Measured (benchmarks/README.md, trace): 1 step leaves 3.6e-3 mm at 50°, 2 steps 6e-8 mm, 3 steps 1e-13 mm.
    miss, chief = _stop_misses(3)
    assert float(miss.abs().max()) <= 1e-9
    assert float(chief.abs().max()) <= 1e-9
    one, _ = _stop_misses(1)
    assert float(one.abs().max()) > 1e-6  # one step is not enough on this lens


def test_reported_residuals_are_the_traced_misses() -> None:
    m = _model()
    miss, chief = _stop_misses(2)
    with torch.no_grad():
        b = trace_bundle(m.lens, m.system, MARGINAL, aim="full", aim_steps=2)
    res = b.pupil_aim.residual_mm
    assert torch.allclose(res[..., :3], miss, atol=1e-12)
    assert torch.allclose(res[..., 3], chief, atol=1e-12)
    assert not bool(b.pupil_aim.converged[1:].all())  # 2 steps: not converged off axis, and says so


def test_axis_factors_vanish_at_the_reference_wavelength() -> None:
    # On axis the stop radius is, by definition, the height of the pupil-edge ray (S1.3.2).
    m = _model()
    with torch.no_grad():
        b = trace_bundle(m.lens, m.system, MARGINAL, aim="full", aim_steps=3)
    assert float(b.vignetting[0, m.system.reference].abs().max()) <= 1e-12


def test_aimed_rays_match_optiland_iterative_aiming() -> None:
    """Oracle: optiland 0.6.3's iterative ray aiming (real on-axis marginal ray sets the stop radius, as
    here), same lens built with ``IdealMaterial`` at lensopt's indices, reference wavelength. Its aimed
    rays Py = ∓1, 0 at full field are compared on the image with ours (inferior, superior, chief)."""
    pytest.importorskip("optiland")
    import math
    import warnings

    from optiland import optic as ol_optic
    from optiland.materials import IdealMaterial

    m = _model()
    lens, w = m.lens, m.system.reference
    idx = lens.index[:, w].tolist()
    o = ol_optic.Optic()
    o.surfaces.add(index=0, radius=math.inf, thickness=math.inf, material=IdealMaterial(n=idx[0]))
    for i in range(lens.num_surfaces):
        c = float(lens.curvature[i])
        o.surfaces.add(index=i + 1, radius=math.inf if c == 0 else 1 / c, thickness=float(lens.thickness[i]),
                       is_stop=i == lens.stop, material=IdealMaterial(n=idx[i + 1]))
    o.surfaces.add(index=lens.num_surfaces + 1)
    fo = first_order(lens, m.system)
    o.set_aperture("EPD", float(fo.epd))
    o.fields.set_type("angle")
    o.fields.add(y=0.0)
    o.fields.add(y=m.system.field_max)
    wl = float(lens.wavelength_um[w])
    o.wavelengths.add(value=wl, is_primary=True)
    o.ray_tracer.set_aiming("iterative", max_iter=50, tol=1e-13)
    theirs = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for py in (-1.0, 1.0, 0.0):
            o.trace_generic(Hx=0.0, Hy=1.0, Px=0.0, Py=py, wavelength=wl)
            theirs.append(float(o.surfaces.y[-1, 0]))
    with torch.no_grad():
        b = trace_bundle(lens, m.system, MARGINAL[:2], aim="full", aim_steps=4)
        c = trace_bundle(lens, m.system, torch.zeros(1, 2, dtype=F64), aim="chief")
    ours = [float(b.result.pos[-1, w, 0, 1]), float(b.result.pos[-1, w, 1, 1]), float(c.result.pos[-1, w, 0, 1])]
    assert ours == pytest.approx(theirs, abs=1e-8)


def test_factors_are_differentiable_in_the_lens() -> None:
    # d(factors)/d(c_2) by forward-mode autodiff through the attached final step, against central
    # differences of converged factors (implicit function theorem).
    m = _model()
    lens, system = m.lens, m.system
    rel = torch.tensor([1.0], dtype=F64)

    def factors(c2: torch.Tensor) -> torch.Tensor:
        curv = torch.cat([lens.curvature[:1], c2.reshape(1), lens.curvature[2:]])
        ln = lens.__class__(**{**lens.__dict__, "curvature": curv})
        fo = first_order(ln, system)
        return aim_full(ln, system, field_tangents(ln, system, rel), epd=fo.epd,
                        entrance_pupil_z=fo.entrance_pupil_z, steps=5).factors

    c2 = lens.curvature[1].clone()
    jac = torch.func.jacfwd(factors)(c2)
    h = 1e-7 * float(c2.abs())
    fd = (factors(c2 + h) - factors(c2 - h)) / (2 * h)
    assert torch.isfinite(jac).all()
    assert torch.allclose(jac, fd, rtol=1e-5, atol=1e-6 * float(fd.abs().max()))


def test_stop_radius_is_the_real_axial_marginal_height() -> None:
    m = _model()
    fo = first_order(m.lens, m.system)
    r = stop_radius(m.lens, m.system, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
    # The paraxial marginal height differs (spherical aberration of the front group), so this is a check
    # of which one is used: the real ray's (optiland's RealReferenceStrategy, the seed's S1.3.2).
    assert abs(float(r) - float(fo.stop_semi_diameter)) > 1e-6
    pupil = torch.tensor([[[[0.0, 1.0]]]], dtype=F64)
    hit = trace(m.lens, launch(m.lens, m.system, pupil, torch.zeros(1, dtype=F64), epd=fo.epd,
                               entrance_pupil_z=fo.entrance_pupil_z), upto=m.lens.stop)
    assert float(r) == pytest.approx(abs(float(hit.pos[0, m.system.reference, 0, 1])), abs=1e-15)
