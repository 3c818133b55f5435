"""Newton intersection (S10) that cannot or does not converge, on pathological aspheres.

* z = r⁴ (c = 0, a4 = 1/mm³) and a ray from (0, 0, −1) tilted by θ: f(t) = sag − z = s⁴t⁴ − γt + 1
  (s = sin θ, γ = cos θ) has its minimum at t* = (γ/(4 s⁴))^(1/3), where f = 1 − ¾ γ t*. For θ above
  the angle where that reaches 0 (≈ 29.68°, solved below) there is no intersection at all; the sag is
  defined everywhere (c = 0), so Newton cannot converge and the ray is counted as ``Newton not
  converged``. Below it, the first root is found and lies on z = r⁴.
* An iteration cap of 1: rays parallel to the axis keep r fixed, so f(t) is linear in t and one Newton
  step is exact; tilted rays on a strong asphere are not converged after one step.
* A wildly oscillating polynomial sag in float32, where Newton iterates run off to infinity: every
  value and gradient must stay finite anyway.
"""

from __future__ import annotations

import math

import pytest
import torch

from lensopt.optics.trace import Rays
from tests.hard_cases.hard_tools import collimated, counts, make_lens, make_rays, trace_checked

D = torch.float64


def _critical_angle() -> float:
    def f_min(theta: float) -> float:
        s, g = math.sin(theta), math.cos(theta)
        t_star = (g / (4 * s**4)) ** (1 / 3)
        return 1 - 0.75 * g * t_star

    lo, hi = math.radians(5.0), math.radians(80.0)  # f_min < 0 at 5°, > 0 at 80°
    for _ in range(200):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if f_min(mid) < 0 else (lo, mid)
    return lo


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_quartic_sag_without_intersection(dtype: torch.dtype) -> None:
    theta_c = math.degrees(_critical_angle())
    assert abs(theta_c - 29.68) < 0.01
    angles = [a for a in range(2, 86, 2) if abs(a - theta_c) > 1.0]
    lens = make_lens([{"kind": "asphere", "c": 0.0, "a": [1.0], "t": 2.0}], index=[1.0, 1.5], dtype=dtype)
    rad = torch.deg2rad(torch.tensor(angles, dtype=dtype))
    d = torch.stack([torch.zeros_like(rad), torch.sin(rad), torch.cos(rad)], -1)
    pos = torch.tensor([0.0, 0.0, -1.0], dtype=dtype).expand_as(d)
    result, _ = trace_checked(lens, make_rays(pos, d))
    no_root = torch.tensor([a > theta_c for a in angles])
    assert counts(result) == {"Newton not converged": int(no_root.sum())}
    assert bool((result.valid == ~no_root).all())
    hit = result.hits[0].pos[~no_root]
    r = hit[:, 1]
    tol = 64 * torch.finfo(dtype).eps
    torch.testing.assert_close(hit[:, 2], r**4, rtol=tol, atol=tol)


def test_iteration_cap_leaves_tilted_rays_unconverged() -> None:
    lens = make_lens([{"kind": "asphere", "c": 1 / 15, "k": -1.0, "a": [2e-3, -4e-5], "t": 20.0}], index=[1.0, 1.5])
    heights = torch.linspace(-4.0, 4.0, 9, dtype=D)
    flat, _ = trace_checked(lens, collimated(heights), newton_iterations=1)
    assert counts(flat) == {}
    tilted, _ = trace_checked(lens, collimated(heights, angle_deg=15.0), newton_iterations=1)
    assert counts(tilted) == {"Newton not converged": 9}
    converged, _ = trace_checked(lens, collimated(heights, angle_deg=15.0))
    assert counts(converged) == {}


# Rays (angle °, y0, z0) for which a seeded random search over 2e5 rays found float32 Newton
# iterates overflowing to inf/NaN on the two surfaces below (before intersect_asphere kept them
# finite); the values are float32 numbers, printed exactly.
WITNESSES = [
    [(26.92056394374891, -0.5116013288497925, -4.347803115844727)],
    [(0.06436157291022435, -1.9881056547164917, -6.910490036010742),
     (-17.83184807371909, 1.990657091140747, -0.9162932634353638)],
]
SURFACES = [{"kind": "asphere", "c": 0.0, "a": [1.0, -1.0, 0.5], "t": 3.0},
            {"kind": "asphere", "c": 0.5, "k": 1.0, "a": [-10.0, 10.0, -10.0], "t": 3.0}]


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("which", [0, 1])
def test_oscillating_polynomial_sag_stays_finite(dtype: torch.dtype, which: int) -> None:
    # z = r⁴ − r⁶ + r⁸/2 (flat base) and z = −10 r⁴ + 10 r⁶ − 10 r⁸ on a curved base: Newton iterates
    # can jump far away, and in float32 the r⁸ term overflows at |t| ~ 1e5.
    surf = SURFACES[which]
    angles = torch.linspace(-70.0, 70.0, 57, dtype=torch.float64)
    heights = torch.linspace(-3.0, 3.0, 13, dtype=torch.float64)
    a, y = torch.meshgrid(angles, heights, indexing="ij")
    rays = [(float(ai), float(yi), -1.0) for ai, yi in zip(a.flatten(), y.flatten(), strict=True)]
    rays += WITNESSES[which]
    ang = torch.deg2rad(torch.tensor([r[0] for r in rays], dtype=torch.float64)).to(dtype)
    # Directions are built exactly as in the search (sin, cos in the working dtype, not renormalized).
    d = torch.stack([torch.zeros_like(ang), torch.sin(ang), torch.cos(ang)], -1)
    pos = torch.tensor([[0.0, r[1], r[2]] for r in rays], dtype=dtype)
    lens = make_lens([surf, {"kind": "plane", "t": 5.0}], index=[1.0, 1.5, 1.0], dtype=dtype)
    result, _ = trace_checked(lens, Rays(pos=pos, dir=d, wavelength=torch.zeros((), dtype=torch.long)))
    assert 0 < int(result.valid.sum()) < len(pos)
    failures = counts(result)
    assert set(failures) <= {"missed surface", "Newton not converged", "total internal reflection",
                             "backtracking (flagged)"}
    # Every ray reported as traced really lies on the sag where it met surface 1.
    hit = result.hits[0].pos[result.valid]
    u = hit[:, 0] ** 2 + hit[:, 1] ** 2
    c, k, coef = surf["c"], surf.get("k", 0.0), surf["a"]
    z = c * u / (1 + torch.sqrt(1 - (1 + k) * c * c * u)) + sum(coef[j] * u ** (j + 2) for j in range(3))
    tol = 1e3 * torch.finfo(dtype).eps
    assert float(((hit[:, 2] - z).abs() / (1 + z.abs())).max()) <= tol
