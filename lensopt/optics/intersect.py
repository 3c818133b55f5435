"""Ray–surface intersection (seed S1.2.1): closed form for planes, spheres and conics, Newton (S10)
with implicit differentiation for even aspheres.

Coordinates are local to the surface vertex (vertex at the origin, axis along +z), in mm.
Every function returns finite values for every ray; rays without a solution are masked, never NaN.
"""

from __future__ import annotations

import torch
from torch import Tensor

from lensopt.optics.surfaces import sag
from lensopt.transforms import all_settled

__all__ = ["intersect_quadric", "intersect_asphere", "quadric_xyz", "quadric_flag_xyz", "quadric_near_xyz",
           "asphere_xyz", "Vec3", "NEWTON_ITERATIONS"]

NEWTON_ITERATIONS = 12
"""Fixed iteration cap: Newton from the conic start converges in 3–5 steps in float64."""


def _safe_div(num: Tensor, den: Tensor) -> Tensor:
    """``num / den``, and 0 on rows where ``|den|`` is below machine epsilon (no inf, no NaN)."""
    ok = den.abs() > torch.finfo(den.dtype).eps
    return torch.where(ok, num / torch.where(ok, den, 1.0), 0.0)


Vec3 = tuple[Tensor, Tensor, Tensor]
"""A vector field as its three components: the hot loop works on (x, y, z) tensors of shape (*)
because fused kernels then vectorize over rays (see benchmarks/README.md, trace); the
public functions take and return ``(*, 3)`` tensors."""


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
    return quadric_xyz(pos.unbind(-1), dir.unbind(-1), c, k)


def quadric_xyz(p: Vec3, d: Vec3, c: Tensor, k: Tensor) -> tuple[Tensor, Tensor]:
    """``intersect_quadric`` on components (x, y, z) of shape (*)."""
    t, hit = quadric_flag_xyz(p, d, c, k)
    return t, hit > 0


def quadric_flag_xyz(p: Vec3, d: Vec3, c: Tensor, k: Tensor, *, shortcuts: bool = False) -> tuple[Tensor, Tensor]:
    """``quadric_xyz`` with ``hit`` as a float flag (1.0 hit, 0.0 missed) in the rays' dtype.

    The masks are combined by selects on comparisons, never by boolean algebra: inside a
    ``torch.compile``-d trace, Inductor's C++ backend converts every boolean ``&``/``|``/``~`` lane by
    lane between mask formats, which cost more than the arithmetic (git history of benchmarks/RESULTS.md).
    The values are those of the boolean formulation. ``shortcuts`` (eager only, no transform
    watching): skip the far root when every ray meets the sag branch with the near one (same values).
    """
    t0, pz, dz, rho, a, q, t, hit, on_sheet = _near_root(p, d, c, k)
    if shortcuts and bool(on_sheet.all()):
        return torch.where(hit > 0, t0 + t, 0.0), hit
    # The other root, q / a: where the near root C / q is off the sag branch, the sag-branch crossing
    # can be q / a on a hyperboloid (1 + κ < 0: the roots can lie on both sides of the vertex plane,
    # the near one on the second sheet); for 1 + κ ≥ 0 it never is (``quadric_near_xyz``).
    eps = torch.finfo(q.dtype).eps
    t_other = _safe_div(q, a)
    other_ok = torch.where(a.abs() > eps, torch.where(rho * c * (pz + t_other * dz) <= 1.0, hit.new_ones(()), 0.0),
                           0.0)
    t = torch.where(on_sheet, t, torch.where(hit * other_ok > 0, t_other, t))
    hit = torch.where(on_sheet, hit, hit * other_ok)
    return torch.where(hit > 0, t0 + t, 0.0), hit


def quadric_near_xyz(p: Vec3, d: Vec3, c: Tensor, k: Tensor) -> tuple[Tensor, Tensor]:
    """``quadric_flag_xyz`` without the far root, for a sphere, an ellipsoid or a paraboloid
    (1 + κ ≥ 0; the caller decides from the prescription, e.g. the compiled trace's structure).

    There the far root never yields a hit: after the transfer to the vertex plane both roots lie on
    the same side of it (their product C/a = (x² + y²)/(dx² + dy² + (1 + κ) dz²) ≥ 0) and the far
    one at least as far from it (|q/a| ≥ |C/q| since q² ≥ b² ≥ aC), so where the near root is off the
    sag branch ((1 + κ) c z > 1) the far one is too, and ``quadric_flag_xyz`` reports a miss. This
    function reports the same miss without computing the far root (a division and a dozen selects
    per ray): the same ``t`` and ``hit`` bit for bit, except for a ray tangent to the quadric on the
    boundary of the sag branch, where rounding decides either way. Hyperboloids (1 + κ < 0) need the
    full solve (their roots can lie on both sides of the vertex plane).
    """
    t0, _, _, _, _, _, t, hit, on_sheet = _near_root(p, d, c, k)
    hit = torch.where(on_sheet, hit, 0.0)
    return torch.where(hit > 0, t0 + t, 0.0), hit


def _near_root(p: Vec3, d: Vec3, c: Tensor, k: Tensor):
    """The shared part of the quadric solves: transfer to the vertex plane, the near root C / q,
    whether the ray hits (float flag) and whether the near root lies on the sag branch (mask)."""
    rho = 1.0 + k
    px, py, pz = p
    dx, dy, dz = d
    # Transfer to the vertex plane (skipped for rays parallel to it, which keep their start point).
    t0 = _safe_div(-pz, dz)
    px, py = px + t0 * dx, py + t0 * dy
    pz = torch.where(t0 == 0, pz, 0.0)  # exactly on the plane after a transfer
    a = c * (dx * dx + dy * dy + rho * dz * dz)
    b = dz - c * (px * dx + py * dy + rho * pz * dz)
    cc = c * (px * px + py * py + rho * pz * pz) - 2.0 * pz
    disc = b * b - a * cc
    root = torch.sqrt(torch.where(disc >= 0, disc, 0.0).clamp_min(torch.finfo(disc.dtype).tiny))
    q = b + torch.where(b >= 0, root, -root)
    t = _safe_div(cc, q)
    eps = torch.finfo(q.dtype).eps
    # The flag in the rays' dtype (``torch.where(m, 1.0, 0.0)`` alone would be float32, the default
    # dtype, and a fused float64 kernel would convert masks and flags between the two lane formats).
    hit = torch.where(disc >= 0, torch.where(q.abs() > eps, q.new_ones(()), 0.0), 0.0)
    # The sag formula's branch satisfies (1 + κ) c z ≤ 1; the far side of a sphere/ellipsoid and the
    # second sheet of a hyperboloid do not.
    on_sheet = rho * c * (pz + t * dz) <= 1.0
    return t0, pz, dz, rho, a, q, t, hit, on_sheet


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
    return asphere_xyz(pos.unbind(-1), dir.unbind(-1), c, k, asphere, iterations=iterations)


def asphere_xyz(
    p: Vec3, d: Vec3, c: Tensor, k: Tensor, asphere: Tensor, *, iterations: int = NEWTON_ITERATIONS
) -> tuple[Tensor, Tensor, Tensor]:
    """``intersect_asphere`` on components (x, y, z) of shape (*)."""
    p0 = tuple(v.detach() for v in p)
    d0 = tuple(v.detach() for v in d)
    c0, k0, a0 = c.detach(), k.detach(), asphere.detach()
    # Start from the conic (a good start: asphere terms are small near the vertex), else the plane.
    t_conic, hit = quadric_xyz(p0, d0, c0, k0)
    t = torch.where(hit, t_conic, _safe_div(-p0[2], d0[2]))
    eps64 = 64.0 * torch.finfo(t.dtype).eps
    reach = 1.0 + torch.maximum(p0[0].abs(), p0[1].abs())
    f, fp, defined = _residual(p0, d0, t, c0, k0, a0)
    for _ in range(iterations):
        # Stop once every ray whose sag is defined has converged (``all_settled``: eager only; further
        # steps would move t by rounding only). The flags below are those of the fixed count.
        if all_settled((f.abs() <= eps64 * (reach + t.abs())) | ~defined):
            break
        t_next = t - _safe_div(f, fp)
        # A step that overflows (iterates running away on a pathological sag, float32) is not taken.
        t = torch.where(torch.isfinite(t_next), t_next, t)
        f, fp, defined = _residual(p0, d0, t, c0, k0, a0)
    tol = eps64 * (reach + t.abs())
    converged = f.abs() <= tol  # False where f is not finite
    # Differentiable final step from the converged point. Rows that did not converge take it from
    # t = 0 (the ray's own, finite start) and return 0: no far-away iterate feeds inf or NaN into
    # values or gradients (0 · inf in a masked backward pass is NaN).
    t = torch.where(converged, t, 0.0)
    f, fp, _ = _residual(p, d, t, c, k, asphere)
    t_final = t - _safe_div(f, fp)
    return torch.where(converged, t_final, 0.0), defined, converged


def _residual(p: Vec3, d: Vec3, t: Tensor, c: Tensor, k: Tensor, asphere: Tensor):
    """``f(t) = sag(r(t)) − z(t)``, ``f'(t)`` and whether the sag is defined at r(t)."""
    x, y, z_ray = p[0] + t * d[0], p[1] + t * d[1], p[2] + t * d[2]
    z, dz_du, defined = sag(x * x + y * y, c, k, asphere)
    fp = 2.0 * dz_du * (x * d[0] + y * d[1]) - d[2]
    return z - z_ray, fp, defined
