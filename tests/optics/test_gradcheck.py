"""Exactness of the derivatives of the trace building blocks.

* ``torch.autograd.gradcheck`` (float64, reverse and forward mode) on the pure functions of
  ``surfaces``, ``interact`` and ``intersect`` and on a whole trace of a few rays.
* The Newton intersection of an asphere differentiates through one final Newton step taken from the
  detached, converged solution (implicit differentiation). Its derivative must equal the implicit
  function theorem ``dt/dp = −(∂f/∂p) / (∂f/∂t)`` for ``f(t, p) = z_sag(r(t)) − z(t)``, written out
  here by hand from the sag formula (S31, S33), and central finite differences at tight tolerance.
"""

from __future__ import annotations

import math

import pytest
import torch
from torch import Tensor

from lensopt.optics.interact import bend
from lensopt.optics.intersect import intersect_asphere, intersect_quadric
from lensopt.optics.lens import Lens, SurfaceShape
from lensopt.optics.surfaces import normal_from_slope, phase_slope, sag
from lensopt.optics.trace import Rays, trace

D = torch.float64


def _rays(n: int, *, seed: int, start_z: float = -2.0, max_angle_deg: float = 15.0) -> tuple[Tensor, Tensor]:
    """Tilted rays starting on the plane z = start_z within a 4 mm radius (local coordinates)."""
    gen = torch.Generator().manual_seed(seed)
    xy = (torch.rand(n, 2, generator=gen, dtype=D) - 0.5) * 8.0
    ang = torch.deg2rad((torch.rand(n, 2, generator=gen, dtype=D) - 0.5) * 2 * max_angle_deg)
    d = torch.stack([torch.tan(ang[:, 0]), torch.tan(ang[:, 1]), torch.ones(n, dtype=D)], -1)
    d = d / torch.linalg.vector_norm(d, dim=-1, keepdim=True)
    pos = torch.cat([xy, torch.full((n, 1), start_z, dtype=D)], -1)
    return pos, d


C, K = 1.0 / 20.0, -0.8
ASPH = [1.0e-4, -2.0e-6, 3.0e-8]


def test_newton_gradient_equals_implicit_function_theorem_and_fd() -> None:
    pos, d = _rays(64, seed=0)
    c = torch.tensor(C, dtype=D)
    k = torch.tensor(K, dtype=D)
    a = torch.tensor(ASPH, dtype=D)

    def t_of(c_: Tensor, k_: Tensor, a_: Tensor) -> Tensor:
        t, defined, converged = intersect_asphere(pos, d, c_, k_, a_)
        assert bool(defined.all()) and bool(converged.all())
        return t

    t = t_of(c, k, a)
    # Hand-derived partials at the solution: with u = x² + y², ρ = 1 + κ, q = sqrt(1 − ρ c² u),
    # z = c u/(1 + q) + Σ a_j u^(j+2):  ∂z/∂c = u / (q (1 + q)),  ∂z/∂κ = c³ u² / (2 q (1 + q)²),
    # ∂z/∂a_j = u^(j+2);  ∂f/∂t = 2 (dz/du)(x dx + y dy) − dz with dz/du = c/(2q) + Σ (j+2) a_j u^(j+1).
    x = pos + t.unsqueeze(-1) * d
    u = x[:, 0] ** 2 + x[:, 1] ** 2
    q = torch.sqrt(1 - (1 + K) * C * C * u)
    dz_du = C / (2 * q) + sum((j + 2) * ASPH[j] * u ** (j + 1) for j in range(3))
    df_dt = 2 * dz_du * (x[:, 0] * d[:, 0] + x[:, 1] * d[:, 1]) - d[:, 2]
    partials = torch.stack([u / (q * (1 + q)), C**3 * u**2 / (2 * q * (1 + q) ** 2)]
                           + [u ** (j + 2) for j in range(3)], -1)
    implicit = -partials / df_dt.unsqueeze(-1)  # (N, 5): dt/dc, dt/dκ, dt/da4, dt/da6, dt/da8

    params = torch.cat([c.view(1), k.view(1), a])

    def t_flat(p: Tensor) -> Tensor:
        return t_of(p[0], p[1], p[2:])

    jac_rev = torch.func.jacrev(t_flat)(params)
    jac_fwd = torch.func.jacfwd(t_flat)(params)
    torch.testing.assert_close(jac_rev, implicit, rtol=1e-11, atol=0)
    torch.testing.assert_close(jac_fwd, implicit, rtol=1e-11, atol=0)
    # Fourth-order central differences, step 1e-3 of each parameter: truncation ≈ 1e-12, measured ≤ 1e-11.
    for i in range(5):
        h = 1e-3 * abs(float(params[i]))
        e = torch.zeros_like(params)
        e[i] = h
        fd = (t_flat(params - 2 * e) - 8 * t_flat(params - e) + 8 * t_flat(params + e)
              - t_flat(params + 2 * e)) / (12 * h)
        torch.testing.assert_close(fd, implicit[:, i], rtol=1e-9, atol=1e-9 * float(implicit[:, i].abs().max()))


def test_newton_iterations_carry_no_graph() -> None:
    # Only the final step is on the graph: the derivative must not depend on the iteration count
    # once converged, and must not be what differentiating the detached start would give (zero).
    pos, d = _rays(16, seed=1)
    a = torch.tensor(ASPH, dtype=D, requires_grad=True)
    grads = []
    for iterations in (6, 12, 30):
        t, _, converged = intersect_asphere(pos, d, torch.tensor(C, dtype=D), torch.tensor(K, dtype=D), a,
                                            iterations=iterations)
        assert bool(converged.all())
        (g,) = torch.autograd.grad(t.sum(), a)
        grads.append(g)
    assert float(grads[0].abs().min()) > 0
    torch.testing.assert_close(grads[0], grads[1], rtol=1e-13, atol=0)
    torch.testing.assert_close(grads[1], grads[2], rtol=1e-13, atol=0)


def _check(fn, inputs: tuple[Tensor, ...]) -> None:
    leaves = tuple(x.detach().clone().requires_grad_(True) for x in inputs)
    assert torch.autograd.gradcheck(fn, leaves, eps=1e-6, atol=1e-7, rtol=1e-5, check_forward_ad=True)


def test_gradcheck_sag_phase_normal() -> None:
    gen = torch.Generator().manual_seed(2)
    u = torch.rand(7, generator=gen, dtype=D) * 16.0  # r up to 4 mm (inside the domain r < 1/(c sqrt(1+κ)))
    u = torch.cat([u, torch.zeros(1, dtype=D)])  # and the vertex, r = 0
    c, k = torch.tensor(0.06, dtype=D), torch.tensor(0.5, dtype=D)
    a = torch.tensor(ASPH, dtype=D)
    _check(lambda u_, c_, k_, a_: sag(u_, c_, k_, a_)[:2], (u, c, k, a))
    _check(lambda u_, p_: phase_slope(u_, p_), (u, torch.tensor([-30.0, 0.05, -1e-3], dtype=D)))
    xy = torch.randn(8, 2, generator=gen, dtype=D)
    _check(lambda xy_, s_: normal_from_slope(xy_, s_), (xy, torch.randn(8, generator=gen, dtype=D)))


@pytest.mark.parametrize("grating", [False, True])
def test_gradcheck_bend(grating: bool) -> None:
    gen = torch.Generator().manual_seed(3)
    d = torch.randn(6, 3, generator=gen, dtype=D) * 0.2 + torch.tensor([0.0, 0.0, 1.0], dtype=D)
    d = d / torch.linalg.vector_norm(d, dim=-1, keepdim=True)
    nrm = torch.randn(6, 3, generator=gen, dtype=D) * 0.3 + torch.tensor([0.0, 0.0, 1.0], dtype=D)
    nrm = nrm / torch.linalg.vector_norm(nrm, dim=-1, keepdim=True)
    n1 = torch.full((6,), 1.0, dtype=D)
    n2 = torch.full((6,), 1.6, dtype=D)
    g = torch.randn(6, 3, generator=gen, dtype=D) * 0.05 if grating else None
    if g is None:
        _check(lambda d_, n_, a_, b_: bend(d_, n_, a_, b_)[:3], (d, nrm, n1, n2))
    else:
        _check(lambda d_, n_, a_, b_, g_: bend(d_, n_, a_, b_, g_)[:3], (d, nrm, n1, n2, g))


def test_gradcheck_intersections() -> None:
    pos, d = _rays(6, seed=4)
    c, k = torch.tensor(C, dtype=D), torch.tensor(K, dtype=D)
    _check(lambda p_, d_, c_, k_: intersect_quadric(p_, d_, c_, k_)[0], (pos, d, c, k))
    # gradcheck steps are absolute (1e-6): give it asphere coefficients in units of their size.
    unit = torch.tensor(ASPH, dtype=D).abs()
    _check(lambda p_, d_, c_, k_, a_: intersect_asphere(p_, d_, c_, k_, a_ * unit)[0],
           (pos, d, c, k, torch.tensor(ASPH, dtype=D) / unit))


def test_gradcheck_whole_trace() -> None:
    # Asphere (Newton) in glass, then a diffractive surface on a sphere, to a flat image: a few rays.
    shapes = (SurfaceShape(kind="asphere"), SurfaceShape(kind="sphere", diffractive=True))
    wl = torch.tensor([0.55], dtype=D)

    unit = torch.tensor([[1e-5, 1e-7], [1.0, 1.0]], dtype=D)  # asphere inputs in units of 1e-5, 1e-7

    def image(curv: Tensor, thick: Tensor, asph: Tensor, phase: Tensor, n_glass: Tensor) -> Tensor:
        one = torch.ones(1, dtype=D)
        lens = Lens(shapes=shapes, curvature=curv, conic=torch.tensor([-0.5, 0.0], dtype=D), asphere=asph * unit,
                    phase=phase, thickness=thick, index=torch.stack([one, n_glass, one]), wavelength_um=wl,
                    semi_diameter=torch.zeros(2, dtype=D), stop=0)
        pos, d = _rays(5, seed=5, start_z=-1.0, max_angle_deg=8.0)
        result = trace(lens, Rays(pos, d, torch.zeros((), dtype=torch.long)))
        assert bool(result.valid.all())
        return result.pos[..., :2]

    inputs = (torch.tensor([1 / 25.0, -1 / 60.0], dtype=D), torch.tensor([4.0, 30.0], dtype=D),
              torch.tensor([[2.0, -1.0], [0.0, 0.0]], dtype=D), torch.tensor([[0.0, 0.0], [-20.0, 0.02]], dtype=D),
              torch.tensor([1.58], dtype=D))
    _check(image, inputs)
    assert math.isfinite(float(image(*inputs).sum()))
