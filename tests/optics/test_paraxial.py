"""First-order optics against closed forms derived by hand, and exact invariants of the real-ray trace.

Every expected number below comes from a textbook formula written out in the test (lensmaker's
equation with thickness, Gullstrand's combination, Newton/Gauss imaging of the stop for pupils, the
thin-lens conjugate equation, the paraxial power of a phase φ = d2 r²), never from lensopt itself.
Lenses are built directly as tensors so that thin elements (zero thickness) can be expressed.
"""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path

import pytest
import torch

from lensopt.optics.bundle import Bundle, trace_bundle
from lensopt.optics.lens import Lens, SurfaceShape, System
from lensopt.optics.paraxial import chief_image_height, first_order, trace_paraxial
from lensopt.optics.sampling import pupil_grid
from lensopt.optics.trace import Rays, trace
from lensopt.spec import build, load_spec
from lensopt.spec.build import Model

F64 = torch.float64
LAM_UM = 0.5875618


def make_lens(curvature: list[float], thickness: list[float], index: list[float], *, stop: int = 0,
              phase: list[float] | None = None, order: int = 1) -> Lens:
    """Lens of spheres/planes at one wavelength; ``index`` has S + 1 entries (object space first);
    ``phase`` gives d2 (rad/mm²) per surface, making those with a non-zero value diffractive."""
    s = len(curvature)
    phase = phase or [0.0] * s
    shapes = tuple(SurfaceShape(kind="sphere" if c else "plane", diffractive=bool(p), order=order)
                   for c, p in zip(curvature, phase, strict=True))
    t = lambda v: torch.tensor(v, dtype=F64)  # noqa: E731
    return Lens(shapes=shapes, curvature=t(curvature), conic=t([0.0] * s), asphere=torch.zeros(s, 0, dtype=F64),
                phase=t(phase).reshape(s, 1), thickness=t(thickness), index=t(index).reshape(-1, 1),
                wavelength_um=t([LAM_UM]), semi_diameter=t([0.0] * s), stop=stop)


def make_system(*, epd: float = 10.0, hfov_deg: float = 5.0, object_distance: float | None = None) -> System:
    return System(epd=epd, fnumber=None, field_type="angle", field_max=hfov_deg, rel_field=(0.0, 1.0),
                  object_distance=object_distance, wavelength_weights=torch.ones(1, dtype=F64), reference=0)


def thick_lens(n: float, r1: float, r2: float, t: float) -> tuple[float, float, float, float, float]:
    """Lensmaker's equation with thickness (lens in air): EFL, BFL, FFL and the principal planes
    P1 (from vertex 1) and P2 (from vertex 2)."""
    c1, c2 = 1 / r1, 1 / r2
    power = (n - 1) * (c1 - c2) + (n - 1) ** 2 * t * c1 * c2 / n
    f = 1 / power
    d1 = -f * (n - 1) * t * c2 / n  # vertex 1 → P1
    d2 = -f * (n - 1) * t * c1 / n  # vertex 2 → P2
    return f, f + d2, d1 - f, d1, d2


@pytest.mark.parametrize(("n", "r1", "r2", "t"), [(1.5168, 50.0, -50.0, 5.0), (1.7847, 30.0, 120.0, 8.0),
                                                   (1.62, -40.0, -15.0, 6.0), (1.5, 25.0, math.inf, 4.0)])
def test_thick_lens_lensmaker(n: float, r1: float, r2: float, t: float) -> None:
    f, bfl, ffl, p1, p2 = thick_lens(n, r1, r2, t)
    lens = make_lens([1 / r1, 0.0 if math.isinf(r2) else 1 / r2], [t, 80.0], [1.0, n, 1.0])
    fo = first_order(lens, make_system())
    assert float(fo.efl) == pytest.approx(f, rel=1e-13)
    assert float(fo.bfl) == pytest.approx(bfl, rel=1e-13)
    assert float(fo.ffl) == pytest.approx(ffl, rel=1e-13)
    # Principal planes from lensopt's data: P1 = F + f (from vertex 1), P2 = F' − f (from vertex 2).
    assert float(fo.ffl + fo.efl) == pytest.approx(p1, abs=1e-12)
    assert float(fo.bfl - fo.efl) == pytest.approx(p2, abs=1e-12)


def test_thin_lens_limit() -> None:
    # Zero thickness: 1/f = (n − 1)(c1 − c2), both focal points at distance f from the lens.
    n, c1, c2 = 1.6, 1 / 40.0, -1 / 60.0
    f = 1 / ((n - 1) * (c1 - c2))
    fo = first_order(make_lens([c1, c2], [0.0, 50.0], [1.0, n, 1.0]), make_system())
    assert (float(fo.efl), float(fo.bfl), float(fo.ffl)) == pytest.approx((f, f, -f), rel=1e-14)


def test_gullstrand_two_thick_lenses() -> None:
    # Gullstrand: Φ = Φa + Φb − e Φa Φb with e the air gap from P2 of lens a to P1 of lens b; the
    # rear focal point lies f(1 − e Φa) past P2 of b, the front one f(1 − e Φb) before P1 of a.
    fa, _, _, p1a, p2a = thick_lens(1.5168, 40.0, -60.0, 5.0)
    fb, _, _, p1b, p2b = thick_lens(1.6727, -30.0, -80.0, 3.0)
    gap = 12.0
    e = gap - p2a + p1b
    pa, pb = 1 / fa, 1 / fb
    power = pa + pb - e * pa * pb
    f = 1 / power
    bfl = p2b + f * (1 - e * pa)
    ffl = p1a - f * (1 - e * pb)
    lens = make_lens([1 / 40.0, -1 / 60.0, -1 / 30.0, -1 / 80.0], [5.0, gap, 3.0, 40.0],
                     [1.0, 1.5168, 1.0, 1.6727, 1.0])
    fo = first_order(lens, make_system())
    assert float(fo.efl) == pytest.approx(f, rel=1e-13)
    assert float(fo.bfl) == pytest.approx(bfl, rel=1e-12)
    assert float(fo.ffl) == pytest.approx(ffl, rel=1e-12)


def _thin(f: float, n: float = 1.5) -> tuple[float, float]:
    """Curvatures of an equi-convex thin lens of focal length f in glass n."""
    c = 1 / (2 * f * (n - 1))
    return c, -c


@pytest.mark.parametrize("s_over_f", [0.25, 0.5, 0.9, 1.5])
def test_entrance_pupil_of_rear_stop(s_over_f: float) -> None:
    # Thin lens f, stop a distance s behind it: the entrance pupil is the image of the stop through
    # the lens seen from object space: z_EP = s f / (f − s), magnified by f / (f − s).
    f, n = 50.0, 1.5
    s = s_over_f * f
    c1, c2 = _thin(f, n)
    lens = make_lens([c1, c2, 0.0], [0.0, s, 60.0], [1.0, n, 1.0, 1.0], stop=2)
    epd = 8.0
    fo = first_order(lens, make_system(epd=epd))
    assert float(fo.entrance_pupil_z) == pytest.approx(s * f / (f - s), rel=1e-13)
    assert float(fo.stop_semi_diameter) == pytest.approx(epd / 2 * abs(f - s) / f, rel=1e-13)


@pytest.mark.parametrize("s_over_f", [0.5, 0.9, 1.1, 2.0])
def test_exit_pupil_of_front_stop(s_over_f: float) -> None:
    # Stop (surface 1, a plane) a distance s before a thin lens f: exit pupil = image of the stop,
    # at v = s f / (s − f) after the lens (Gauss), diameter EPD · |f / (f − s)|.
    f, n, epd = 40.0, 1.6, 6.0
    s = s_over_f * f
    c1, c2 = _thin(f, n)
    lens = make_lens([0.0, c1, c2], [s, 0.0, 45.0], [1.0, 1.0, n, 1.0], stop=0)
    fo = first_order(lens, make_system(epd=epd))
    assert float(fo.entrance_pupil_z) == 0.0
    assert float(fo.exit_pupil_z) == pytest.approx(s + s * f / (s - f), rel=1e-12)
    assert float(fo.exit_pupil_diameter) == pytest.approx(epd * abs(f / (f - s)), rel=1e-12)


def test_image_space_telecentric() -> None:
    # Stop at the front focal plane (s = f): every chief ray leaves parallel to the axis and the exit
    # pupil is at infinity; the paraxial image height is f tan θ (chief ray through the focal point).
    f, n = 40.0, 1.6
    c1, c2 = _thin(f, n)
    lens = make_lens([0.0, c1, c2], [f, 0.0, f], [1.0, 1.0, n, 1.0], stop=0)
    system = make_system(hfov_deg=10.0)
    tan = torch.tensor(math.tan(math.radians(10.0)), dtype=F64)
    _, omega = trace_paraxial(lens, 0, torch.zeros((), dtype=F64), tan)
    assert abs(float(omega[-1])) < 1e-15
    fo = first_order(lens, system)
    assert abs(float(fo.exit_pupil_z)) > 1e12
    assert float(chief_image_height(lens, system, tan)) == pytest.approx(f * float(tan), rel=1e-13)


def test_object_space_telecentric_limit() -> None:
    # Stop at the rear focal plane: the entrance pupil recedes to infinity as s → f; the exact
    # formula z_EP = s f / (f − s) holds on both sides arbitrarily close to it.
    f, n = 50.0, 1.5
    c1, c2 = _thin(f, n)
    for s in (f * (1 - 1e-6), f * (1 + 1e-6)):
        lens = make_lens([c1, c2, 0.0], [0.0, s, 60.0], [1.0, n, 1.0, 1.0], stop=2)
        z = float(first_order(lens, make_system()).entrance_pupil_z)
        assert z == pytest.approx(s * f / (f - s), rel=1e-8)
        assert abs(z) > 1e6


@pytest.mark.parametrize("distance", [100.0, 250.0, 1000.0])
def test_finite_conjugates(distance: float) -> None:
    # Thin lens with the stop on it, object at distance d: image at v = 1/(1/f − 1/d); the marginal
    # ray converges with slope h / v, so the working f-number is v / EPD; the chief ray through the
    # lens centre is undeviated, so the image height is v tan θ.
    f, n, epd, theta = 50.0, 1.5, 10.0, 4.0
    v = 1 / (1 / f - 1 / distance)
    c1, c2 = _thin(f, n)
    lens = make_lens([c1, c2], [0.0, v], [1.0, n, 1.0], stop=0)
    system = make_system(epd=epd, hfov_deg=theta, object_distance=distance)
    fo = first_order(lens, system)
    assert float(fo.working_fnumber) == pytest.approx(v / epd, rel=1e-13)
    assert float(fo.fnumber) == pytest.approx(f / epd, rel=1e-13)
    assert float(fo.paraxial_image_height) == pytest.approx(v * math.tan(math.radians(theta)), rel=1e-13)
    # The axial object point images onto the image plane: marginal ray height there is 0.
    y, _ = trace_paraxial(lens, 0, torch.tensor(epd / 2, dtype=F64), torch.tensor(epd / 2 / distance, dtype=F64))
    assert abs(float(y[-1])) < 1e-12


@pytest.mark.parametrize("order", [1, 2, -1])
def test_diffractive_paraxial_power(order: int) -> None:
    # A phase φ = d2 r² deflects a ray at height y by m λ/(2π) dφ/dy = m λ d2 y / π (generalized law,
    # S15), so a thin DOE in air has power K = −m λ d2 / π and EFL = −π / (m λ d2).
    d2 = -6.0  # rad/mm²
    lam_mm = LAM_UM * 1e-3
    lens = make_lens([0.0], [100.0], [1.0, 1.0], phase=[d2], order=order)
    fo = first_order(lens, make_system())
    assert float(fo.efl) == pytest.approx(-math.pi / (order * lam_mm * d2), rel=1e-14)


# ----------------------------------------------------------------------------- real-ray invariants

SPECS = Path(__file__).resolve().parents[2] / "specs"
INVARIANT_SPECS = ["cooke_triplet", "double_gauss", "asphere_singlet", "hybrid_asphere", "hybrid_achromat"]


@cache
def _bundle(name: str) -> tuple[Model, Bundle]:
    model = build(load_spec(SPECS / f"{name}.toml"))
    # Full-pupil grid at every field: off-axis rays are skew rays.
    return model, trace_bundle(model.lens, model.system, pupil_grid(9, dtype=F64), record=True)


def _tangential(v: torch.Tensor, normal: torch.Tensor) -> torch.Tensor:
    return v - (v * normal).sum(-1, keepdim=True) * normal


@pytest.mark.parametrize("name", INVARIANT_SPECS)
def test_snell_tangential_invariant(name: str) -> None:
    # Vector Snell: the component of n·d tangential to the surface is conserved across a refracting
    # interface; across a phase surface it changes by exactly the tangential part of m λ/(2π) ∇φ with
    # ∇φ = (∂φ/∂x, ∂φ/∂y, 0), φ = Σ d_2i r^2i (generalized law S15).
    model, bundle = _bundle(name)
    lens = model.lens
    assert bool(bundle.result.valid.all())
    lam_mm = (lens.wavelength_um * 1e-3)[None, :, None, None]
    for s, hit in enumerate(bundle.result.hits):
        n1 = lens.index[s][None, :, None, None]
        n2 = lens.index[s + 1][None, :, None, None]
        change = _tangential(n2 * hit.dir_out - n1 * hit.dir_in, hit.normal)
        expected = torch.zeros_like(change)
        shape = lens.shapes[s]
        if shape.diffractive:
            x, y = hit.pos[..., 0], hit.pos[..., 1]
            r2 = x * x + y * y
            dphi_dr2 = sum((i + 1) * d * r2**i for i, d in enumerate(lens.phase[s].tolist()))
            grad = torch.stack([2 * dphi_dr2 * x, 2 * dphi_dr2 * y, torch.zeros_like(x)], -1)
            expected = _tangential(shape.order * lam_mm / (2 * math.pi) * grad, hit.normal)
            assert float(expected.abs().max()) > 1e-4  # the DOE does bend these rays
        assert float((change - expected).abs().max()) < 1e-14
        assert float((hit.dir_out.norm(dim=-1) - 1).abs().max()) < 1e-14


def reversed_lens(lens: Lens, z_end: float) -> Lens:
    """The same lens traversed backwards, in the mirrored frame z' = z_last − z: surfaces in reverse
    order with negated sag (curvature, asphere terms), media reversed, ending on the plane z = ``z_end``
    of the original frame. The phase keeps its sign: reversing n2 d2_t = n1 d1_t + g_t for the ray −d2
    needs the same transverse grating vector g, and the mirror leaves (x, y) unchanged."""
    thickness = torch.cat([lens.thickness[:-1].flip(0), torch.tensor([-z_end], dtype=lens.dtype)])
    return Lens(shapes=lens.shapes[::-1], curvature=-lens.curvature.flip(0), conic=lens.conic.flip(0),
                asphere=-lens.asphere.flip(0), phase=lens.phase.flip(0), thickness=thickness,
                index=lens.index.flip(0), wavelength_um=lens.wavelength_um,
                semi_diameter=lens.semi_diameter.flip(0), stop=lens.num_surfaces - 1 - lens.stop)


@pytest.mark.parametrize("name", INVARIANT_SPECS)
def test_reversibility(name: str) -> None:
    # Reversing every exit ray and tracing it back through the mirrored lens returns the input ray.
    model, bundle = _bundle(name)
    lens = model.lens
    start, d0 = bundle.rays.pos.expand_as(bundle.result.pos), bundle.rays.dir.expand_as(bundle.result.pos)
    z_last = float(lens.vertex_z()[-2])
    z0 = float(start[..., 2].flatten()[0])
    assert bool((start[..., 2] == z0).all())
    mirror = torch.tensor([1.0, 1.0, -1.0], dtype=F64)
    out_pos, out_dir = bundle.result.pos, bundle.result.dir
    back_pos = torch.stack([out_pos[..., 0], out_pos[..., 1], z_last - out_pos[..., 2]], -1)
    back = trace(reversed_lens(lens, z0), Rays(pos=back_pos, dir=-out_dir * mirror, wavelength=bundle.rays.wavelength))
    assert bool(back.valid.all())
    assert float((back.pos[..., :2] - start[..., :2]).abs().max()) < 1e-12
    assert float((back.pos[..., 2] - (z_last - z0)).abs().max()) < 1e-12
    assert float((back.dir - (-d0 * mirror)).abs().max()) < 1e-14
