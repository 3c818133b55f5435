"""The compiled trace's formulation (``trace.trace_kernel`` with ``KernelOptions``), run eagerly:
same statuses as the reference ``trace`` and the same numbers to rounding, on rays chosen to hit the
hard cases (every failure reason, far starts, rays parallel to a vertex plane, backward rays, both
sheets of a hyperboloid), without needing a compiler.

Oracles: the reference eager ``trace`` (validated against optiland and closed forms elsewhere), and
for the near-root fast path the full quadric solve ``intersect.quadric_flag_xyz`` plus the hand
derivation in ``intersect.quadric_near_xyz``'s docstring (both roots on one side of the vertex plane,
the far one farther, for 1 + κ ≥ 0).
"""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from lensopt.accel.compiled import near_only_surfaces
from lensopt.optics.intersect import quadric_flag_xyz, quadric_near_xyz
from lensopt.optics.trace import KernelOptions, Rays, Status, trace, trace_kernel
from lensopt.spec import build, parse_spec
from tests.hard_cases.hard_tools import make_lens
from tests.helpers import MIXED
from tests.helpers import mixed_rays as _rays

D = torch.float64


def _wild_rays(n: int, seed: int, *, spread: float = 30.0) -> tuple[tuple, tuple]:
    """Rays from anywhere in a ±spread mm box, in any direction (a quarter of them backward, a tenth
    exactly parallel to the vertex plane), as components (x, y, z), (dx, dy, dz)."""
    g = torch.Generator().manual_seed(seed)
    p = (torch.rand(3, n, generator=g, dtype=D) * 2 - 1) * spread
    d = torch.randn(3, n, generator=g, dtype=D)
    d[2, : n // 10] = 0.0
    d = d / torch.linalg.vector_norm(d, dim=0)
    return tuple(p), tuple(d)


@pytest.mark.parametrize("k", [0.0, 0.8, -0.5, -1.0])
@pytest.mark.parametrize("c", [0.1, -0.1, 0.02])
def test_near_root_alone_is_the_full_solve_when_one_plus_kappa_is_not_negative(c: float, k: float) -> None:
    p, d = _wild_rays(20_000, seed=3)
    ct, kt = torch.tensor(c, dtype=D), torch.tensor(k, dtype=D)
    t_full, hit_full = quadric_flag_xyz(p, d, ct, kt)
    t_near, hit_near = quadric_near_xyz(p, d, ct, kt)
    assert torch.equal(hit_near, hit_full)
    assert torch.equal(t_near, t_full)
    # The case has teeth: rays hit, rays miss, and (except on the paraboloid, where every point is on
    # the sag branch) rays meet the quadric first on its far side, which both report as a miss.
    assert 500 < int(hit_full.sum()) < 19_000
    if k > -1.0 and abs(c) > 0.05:  # R = ±10 mm inside the ±30 mm box of start points
        x0, y0, z0 = p
        # The first crossing of the full quadric along the ray's line, by the textbook quadratic from
        # the start point (independent of the trace's formulation): rays whose nearest crossing lies
        # beyond the sag branch (1 + κ) c z > 1 exist, and are misses.
        rho = 1.0 + k
        a = c * (d[0] ** 2 + d[1] ** 2 + rho * d[2] ** 2)
        b = c * (x0 * d[0] + y0 * d[1] + rho * z0 * d[2]) - d[2]
        cc = c * (x0**2 + y0**2 + rho * z0**2) - 2 * z0
        disc = b * b - a * cc
        roots = torch.stack([(-b - disc.clamp_min(0).sqrt()) / a, (-b + disc.clamp_min(0).sqrt()) / a])
        z = z0 + roots * d[2]
        both_far = (disc > 0) & (rho * c * z > 1 + 1e-9).all(0)
        assert int(both_far.sum()) > 200
        assert not bool(hit_full[both_far].any())


def test_hyperboloid_needs_the_far_root() -> None:
    # κ = −3 (c = 0.1: second sheet with vertex at z = 2/(c(1 + κ)) = −10 mm): the two roots can lie on
    # both sides of the vertex plane, and for many rays the nearer crossing is the second sheet while
    # the far root is the sag branch. The full solve takes it; the near root alone would report a
    # miss. So the compiled trace must not take the fast path on this surface (decided from κ).
    c, k = torch.tensor(0.1, dtype=D), torch.tensor(-3.0, dtype=D)
    p, d = _wild_rays(20_000, seed=3)
    t_full, hit_full = quadric_flag_xyz(p, d, c, k)
    _, hit_near = quadric_near_xyz(p, d, c, k)
    rescued = (hit_full == 1) & (hit_near == 0)
    assert int(rescued.sum()) > 500
    assert not bool(((hit_near == 1) & (hit_full == 0)).any())
    # The full solve's points are right (invariants): on the quadric c r² + c(1 + κ) z² − 2z = 0 and
    # on its sag branch (1 + κ) c z ≤ 1.
    x, y, z = (p[i][rescued] + t_full[rescued] * d[i][rescued] for i in range(3))
    scale = 1.0 + c * (x * x + y * y) + 2 * z.abs()  # points reach thousands of mm: relative residual
    assert float(((c * (x * x + y * y) + c * (1 + k) * z * z - 2 * z).abs() / scale).max()) < 1e-13
    assert bool(((1 + k) * c * z <= 1).all())
    lens = make_lens([{"kind": "conic", "c": 0.1, "k": -3.0, "t": 60.0},
                      {"kind": "sphere", "c": -0.02, "k": 0.0, "t": 5.0},
                      {"kind": "conic", "c": 0.05, "k": -1.0, "t": 5.0}], index=[1.0, 1.5, 1.0, 1.5])
    assert near_only_surfaces(lens) == (False, True, True)


def _lenses() -> dict[str, object]:
    """Small lenses for the hard cases (each surface: kind, curvature c, conic k, gap t)."""
    return {
        "ball": make_lens([{"kind": "sphere", "c": 0.2, "t": 10.0}, {"kind": "sphere", "c": -0.2, "t": 2.5}],
                          index=[1.0, 1.5, 1.0]),
        # κ = −3 then a plane: rays that reach the hyperboloid's sag branch only by its far root go on.
        "hyperboloid": make_lens([{"kind": "conic", "c": 0.1, "k": -3.0, "t": 8.0}, {"kind": "plane", "t": 20.0}],
                                 index=[1.0, 1.6, 1.0]),
        "tir": make_lens([{"kind": "plane", "t": 2.0}, {"kind": "sphere", "c": -0.15, "t": 3.0},
                          {"kind": "conic", "c": 0.08, "k": -1.0, "t": 10.0}], index=[1.0, 1.9, 1.0, 1.0]),
        "mixed": build(parse_spec(MIXED)).lens,
    }


@pytest.mark.parametrize("name", ["ball", "hyperboloid", "tir", "mixed"])
@pytest.mark.parametrize("record", [False, True])
def test_kernel_formulation_matches_the_reference_trace(name: str, record: bool) -> None:
    lens = _lenses()[name]
    if name == "mixed":
        rays = _rays(2000)
    else:
        p, d = _wild_rays(4000, seed=5, spread=12.0)
        rays = Rays(torch.stack(p, -1), torch.stack(d, -1), torch.zeros((), dtype=torch.long))
    ref = trace(lens, rays, record=record)
    options = KernelOptions(near_only=near_only_surfaces(lens))
    out = trace_kernel(lens, rays, options, record=record)
    if name == "hyperboloid":  # the fast path must not be taken there, and the case shows why
        assert options.near_only == (False, True)
        wrong = trace_kernel(lens, rays, KernelOptions(near_only=(True, True)))
        assert int((wrong.status != ref.status).sum()) > 100
    assert torch.equal(out.status, ref.status)
    assert torch.equal(out.backtrack, ref.backtrack)
    # Every outcome occurs (the wild rays fail in many ways) and many rays get through.
    assert int((ref.status == Status.OK).sum()) > 50 and int((ref.status == Status.MISSED).sum()) > 50
    # Numbers: to rounding on every row (placeholders of failed rays included), except rows whose
    # trace is ill-conditioned, where rounding is amplified and either formulation is off by more
    # than 1e-12 from the exact ray: grazing refraction (cos² of refraction < 1e-2 at a surface the
    # ray leaves: rounding × 1/cos), a normal off unit length by > 1e-13 (the hit point off the
    # surface by rounding after a far transfer to the vertex plane; the two refraction formulas are
    # equal only for unit normals), or an image-plane crossing at a grazing angle (|dz| < 0.1).
    full = trace(lens, rays, record=True)
    cond = ref.dir[..., 2].abs() > 0.1
    for s, h in enumerate(full.hits):
        live = (full.failed_at < 0) | (full.failed_at > s)
        bad = (h.cos2_out < 1e-2) | ((torch.linalg.vector_norm(h.normal, dim=-1) - 1.0).abs() > 1e-13)
        cond &= ~(live & bad)
    assert int(cond.sum()) > 0.8 * cond.numel()
    # Wild rays travel hundreds of mm: agreement relative to the size of the coordinates.
    scale = 1.0 + ref.pos.abs().amax(-1)
    assert bool(((out.pos - ref.pos).abs().amax(-1) <= 1e-13 * scale)[cond].all())
    assert (out.dir - ref.dir)[cond].abs().max() <= 1e-12
    assert out.pos.movedim(-1, 0).is_contiguous()  # written component-major
    if record:
        assert torch.equal(out.failed_at, ref.failed_at)
        for s, (h_o, h_r) in enumerate(zip(out.hits, ref.hits, strict=True)):
            # Rays still live after surface s: every field. At the surface where a ray fails, what the
            # optimizer's failure margin reads (position, incoming direction, cos² of refraction of a
            # totally reflected ray); the rest there is a placeholder (e.g. a missed ray's "normal" at
            # a point off the surface) from different formulas in the two.
            live = (ref.failed_at < 0) | (ref.failed_at > s)
            here = ref.failed_at == s
            for f in dataclasses.fields(h_r):
                a, b = getattr(h_o, f.name), getattr(h_r, f.name)
                rows = live | here if f.name in ("pos", "dir_in", "t", "cos2_in") else live
                if f.name == "cos2_out":
                    rows = live | (here & (ref.status == Status.TIR))
                rows = rows & cond
                assert (a[rows] - b[rows]).abs().max() <= 1e-13 * (1.0 + b[rows].abs().max()), f.name


def test_kernel_formulation_has_the_reference_gradients() -> None:
    # Reverse mode through the kernel's formulation (what AOTAutograd compiles for the backward of
    # compiled_trace) equals the reference trace's gradients, lens tensors and rays alike.
    lens = _lenses()["mixed"]
    rays = _rays(300)
    names = ("curvature", "conic", "asphere", "phase", "thickness", "index")

    def grads(fn) -> list[torch.Tensor]:
        leaves = {n: getattr(lens, n).detach().clone().requires_grad_(True) for n in names}
        pos = rays.pos.detach().clone().requires_grad_(True)
        r = fn(dataclasses.replace(lens, **leaves), Rays(pos, rays.dir, rays.wavelength))
        loss = torch.where(r.valid.unsqueeze(-1), r.pos[..., :2], 0.0).pow(2).sum() + r.dir.sum()
        return list(torch.autograd.grad(loss, [*leaves.values(), pos]))

    ref = grads(lambda ln, r: trace(ln, r))
    out = grads(lambda ln, r: trace_kernel(ln, r, KernelOptions(near_only=near_only_surfaces(ln))))
    # Not the conic of a sphere or plane: their normal formula assumes κ = 0, so d/dκ there is not a
    # derivative of the traced surface in either formulation (a spec cannot vary it: conic and
    # asphere surfaces only).
    sphere = torch.tensor([s.kind in ("sphere", "plane") for s in lens.shapes])
    out[1], ref[1] = out[1][~sphere], ref[1][~sphere]
    for g_o, g_r in zip(out, ref, strict=True):
        assert bool(torch.isfinite(g_o).all())
        torch.testing.assert_close(g_o, g_r, rtol=1e-9, atol=1e-9 * (1.0 + float(g_r.abs().max())))


def test_refraction_by_index_ratio_obeys_snell() -> None:
    # Snell's law by hand: a ray at 30° onto a flat interface n = 1 → 1.5 leaves at asin(sin 30°/1.5),
    # and from glass at 60° (beyond the critical angle asin(1/1.5) = 41.8°) it is totally reflected.
    from lensopt.optics.interact import refract_ratio_xyz

    a = torch.tensor([math.radians(30.0), math.radians(60.0)], dtype=D)
    d = (torch.zeros_like(a), torch.sin(a), torch.cos(a))
    n = (torch.zeros_like(a), torch.zeros_like(a), -torch.ones_like(a))  # normal against the ray
    mu = torch.tensor([1 / 1.5, 1.5], dtype=D)
    (ox, oy, oz), cos2_in, cos2_out, fail = refract_ratio_xyz(d, n, mu)
    assert fail.tolist() == [False, True]
    assert float(oy[0]) == pytest.approx(math.sin(math.radians(30.0)) / 1.5, abs=1e-15)
    assert float(oz[0]) == pytest.approx(math.sqrt(1 - (0.5 / 1.5) ** 2), abs=1e-15)
    assert float(cos2_in[0]) == pytest.approx(0.75, abs=1e-15)
    assert float(cos2_out[1]) == pytest.approx(1 - 1.5**2 * 0.75, abs=1e-15)
