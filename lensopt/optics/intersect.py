"""Ray–surface intersection (seed S1.2.1): closed form for planes, spheres and conics, Newton (S10)
with implicit differentiation for even aspheres.

Coordinates are local to the surface vertex (vertex at the origin, axis along +z), in mm.
Every function returns finite values for every ray; rays without a solution are masked, never NaN.
"""

from __future__ import annotations

import torch
from torch import Tensor

from lensopt.optics.surfaces import sag

__all__ = ["intersect_quadric", "intersect_asphere", "NEWTON_ITERATIONS"]

NEWTON_ITERATIONS = 12
"""Fixed iteration cap: Newton from the conic start converges in 3–5 steps in float64."""


def _safe_div(num: Tensor, den: Tensor) -> Tensor:
    """``num / den``, and 0 on rows where ``|den|`` is below machine epsilon (no inf, no NaN)."""
    ok = den.abs() > torch.finfo(den.dtype).eps
    return torch.where(ok, num / torch.where(ok, den, torch.ones_like(den)), torch.zeros_like(num))


def intersect_quadric(pos: Tensor, dir: Tensor, c: Tensor, k: Tensor) -> tuple[Tensor, Tensor]:
    """Distance along the ray to the conic ``c(x² + y²) + c(1 + κ) z² − 2z = 0`` (plane when c = 0).

    The ray is first carried to the vertex plane z = 0 (as in Spencer & Murty's procedure), then the
    root that tends to the plane intersection as c → 0 (the vertex side of the surface) is taken, in
    the cancellation-free form ``t = C / (B + sign(B) sqrt(B² − aC))``. Without the transfer, the
    sign of B depends on where the ray starts: from more than |R| before the vertex (a ball lens, a
    thick plano-convex lens) it picks the far root and the ray is wrongly reported as missed.

    Args:
        pos: (*, 3) ray positions relative to the surface vertex, mm.
        dir: (*, 3) unit directions.
        c: curvature 1/mm (broadcastable scalar tensor).
        k: conic constant (broadcastable scalar tensor).

    Returns:
        t: (*) signed distance to the intersection, mm (0 where there is none).
        hit: (*) bool, False where the ray misses or meets the other branch of the conic.
    """
    rho = 1.0 + k
    # Transfer to the vertex plane (skipped for rays parallel to it, which keep their start point).
    t0 = _safe_div(-pos[..., 2], dir[..., 2])
    px, py, pz = (pos + t0.unsqueeze(-1) * dir).unbind(-1)
    pz = torch.where(t0 == 0, pz, torch.zeros_like(pz))  # exactly on the plane after a transfer
    dx, dy, dz = dir.unbind(-1)
    a = c * (dx * dx + dy * dy + rho * dz * dz)
    b = dz - c * (px * dx + py * dy + rho * pz * dz)
    cc = c * (px * px + py * py + rho * pz * pz) - 2.0 * pz
    disc = b * b - a * cc
    hit = disc >= 0
    root = torch.sqrt(torch.where(hit, disc, torch.zeros_like(disc)).clamp_min(torch.finfo(disc.dtype).tiny))
    sign = torch.where(b >= 0, torch.ones_like(b), -torch.ones_like(b))
    q = b + sign * root
    t = _safe_div(cc, q)
    hit = hit & (q.abs() > torch.finfo(q.dtype).eps)
    # The sag formula's branch satisfies (1 + κ) c z ≤ 1; the far side of a sphere/ellipsoid and the
    # second sheet of a hyperboloid do not.
    on_sheet = rho * c * (pz + t * dz) <= 1.0
    # The other root, q / a: still needed after the transfer when the ray crosses the vertex plane
    # beyond the centre of curvature (b < 0 going forward); then C / q is the far side of the
    # sphere and the sag-branch crossing is q / a.
    t_other = _safe_div(q, a)
    other_ok = (a.abs() > torch.finfo(a.dtype).eps) & (rho * c * (pz + t_other * dz) <= 1.0)
    t = torch.where(hit & ~on_sheet & other_ok, t_other, t)
    hit = hit & (on_sheet | other_ok)
    return torch.where(hit, t0 + t, torch.zeros_like(t)), hit


def intersect_asphere(
    pos: Tensor,
    dir: Tensor,
    c: Tensor,
    k: Tensor,
    asphere: Tensor,
    *,
    iterations: int = NEWTON_ITERATIONS,
) -> tuple[Tensor, Tensor, Tensor]:
    """Newton solve of ``z(r(t)) − z_ray(t) = 0`` (S9–S10) for an even asphere.

    The iterations run on detached values (no graph, flat memory); one final Newton step is taken
    on the attached values, so that first derivatives (reverse and forward mode) equal the implicit
    derivative ``dt = −(∂f/∂p) dp / f'(t)`` at the converged point.

    Args:
        pos: (*, 3) positions relative to the vertex, mm.
        dir: (*, 3) unit directions.
        c, k: curvature (1/mm) and conic constant, scalar tensors.
        asphere: (A,) coefficients a4, a6, … (mm^(1−2i)).
        iterations: fixed number of Newton iterations.

    Returns:
        t: (*) distance to the intersection, mm (0 where Newton did not converge).
        defined: (*) bool, False where the sag is undefined at the last iterate (ray misses).
        converged: (*) bool, False where Newton did not reach the tolerance.
    """
    p0, d0 = pos.detach(), dir.detach()
    c0, k0, a0 = c.detach(), k.detach(), asphere.detach()
    # Start from the conic (a good start: asphere terms are small near the vertex), else the plane.
    t_conic, hit = intersect_quadric(p0, d0, c0, k0)
    t_plane = _safe_div(-p0[..., 2], d0[..., 2])
    t = torch.where(hit, t_conic, t_plane)
    for _ in range(iterations):
        f, fp, _ = _residual(p0, d0, t, c0, k0, a0)
        t_next = t - _safe_div(f, fp)
        # A step that overflows (iterates running away on a pathological sag, float32) is not taken.
        t = torch.where(torch.isfinite(t_next), t_next, t)
    f, _, defined = _residual(p0, d0, t, c0, k0, a0)
    scale = 1.0 + p0[..., :2].abs().amax(-1) + t.abs()
    tol = 64.0 * torch.finfo(t.dtype).eps * scale
    converged = f.abs() <= tol  # False where f is not finite
    # Differentiable final step from the converged point. Rows that did not converge take it from
    # t = 0 (the ray's own, finite start) and return 0: no far-away iterate feeds inf or NaN into
    # values or gradients (0 · inf in a masked backward pass is NaN).
    t = torch.where(converged, t, torch.zeros_like(t))
    f, fp, _ = _residual(pos, dir, t, c, k, asphere)
    t_final = t - _safe_div(f, fp)
    return torch.where(converged, t_final, torch.zeros_like(t_final)), defined, converged


def _residual(pos: Tensor, dir: Tensor, t: Tensor, c: Tensor, k: Tensor, asphere: Tensor):
    """``f(t) = sag(r(t)) − z(t)``, ``f'(t)`` and whether the sag is defined at r(t)."""
    x = pos + t.unsqueeze(-1) * dir
    u = x[..., 0] ** 2 + x[..., 1] ** 2
    z, dz_du, defined = sag(u, c, k, asphere)
    f = z - x[..., 2]
    fp = 2.0 * dz_du * (x[..., 0] * dir[..., 0] + x[..., 1] * dir[..., 1]) - dir[..., 2]
    return f, fp, defined
