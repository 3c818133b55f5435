"""Ray bending at an interface: vector Snell (S12–S13) and the generalized law of refraction for
diffractive phase surfaces (S15–S18), in one tangential-momentum form.

With ``N`` the unit normal on the incidence side, the tangential part of ``n d`` is conserved, plus
the phase gradient for a diffractive surface:

    n' d'_t = (n d + m λ/(2π) ∇φ)_t ,   d' = d'_t + sqrt(1 − |d'_t|²) N

For a plain refraction this is exactly S12 with cos²θ' from S13; for a flat diffractive surface in
air it is S16–S18. ``∇φ = 2 (dφ/du) (x, y, 0)`` is finite at r = 0.
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["bend", "bend_xyz", "refract_ratio_xyz"]


def bend(
    dir: Tensor,
    normal: Tensor,
    n1: Tensor,
    n2: Tensor,
    grating: Tensor | None = None,
) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Direction after an interface.

    Args:
        dir: (*, 3) unit incident directions.
        normal: (*, 3) unit surface normals (either orientation).
        n1, n2: (*) refractive indices before and after (broadcastable).
        grating: (*, 3) ``m λ/(2π) ∇φ`` in the same length unit as λ/φ (dimensionless), or None.

    Returns:
        dir_out: (*, 3) unit refracted/diffracted directions (finite placeholder on failures).
        cos2_in: (*) cos² of the angle of incidence (ζ_I in S43).
        cos2_out: (*) cos² of the angle of refraction (ζ_R in S44); negative means TIR or an
            evanescent diffracted order.
        fail: (*) bool, True where cos2_out < 0 (total internal reflection).
    """
    g = None if grating is None else (grating[..., 0], grating[..., 1])
    d, cos2_in, cos2_out, fail = bend_xyz(dir.unbind(-1), normal.unbind(-1), n1, 1.0 / n2, g)
    return torch.stack(d, -1), cos2_in, cos2_out, fail


def bend_xyz(
    d: tuple[Tensor, Tensor, Tensor],
    normal: tuple[Tensor, Tensor, Tensor],
    n1: Tensor,
    inv_n2: Tensor,
    grating: tuple[Tensor, Tensor] | None = None,
) -> tuple[tuple[Tensor, Tensor, Tensor], Tensor, Tensor, Tensor]:
    """``bend`` on components: directions and normals as (x, y, z) tensors of shape (*), the index
    after the interface as its reciprocal ``1/n'`` (precomputed per medium), the grating vector as its
    (x, y) components (its z component is 0)."""
    dx, dy, dz = d
    nx, ny, nz = normal
    cos_i = dx * nx + dy * ny + dz * nz
    vx, vy, vz = n1 * dx, n1 * dy, n1 * dz
    if grating is not None:
        vx, vy = vx + grating[0], vy + grating[1]
    # The tangential part (v·n) n does not depend on the orientation of n (negation is exact, so
    # the values are bit for bit those with n oriented along the ray); only the normal part does.
    vn = vx * nx + vy * ny + vz * nz
    tx, ty, tz = (vx - vn * nx) * inv_n2, (vy - vn * ny) * inv_n2, (vz - vn * nz) * inv_n2
    cos2_out = 1.0 - (tx * tx + ty * ty + tz * tz)
    fail = cos2_out < 0
    floor = torch.finfo(cos2_out.dtype).eps
    cos_out = torch.sqrt(torch.where(cos2_out > floor, cos2_out, floor))
    # Orient the normal along the ray by the sign of cos_out: one select instead of three on n.
    cos_out = torch.where(cos_i < 0, -cos_out, cos_out)
    return (tx + cos_out * nx, ty + cos_out * ny, tz + cos_out * nz), cos_i * cos_i, cos2_out, fail


def refract_ratio_xyz(
    d: tuple[Tensor, Tensor, Tensor],
    normal: tuple[Tensor, Tensor, Tensor],
    mu: Tensor,
) -> tuple[tuple[Tensor, Tensor, Tensor], Tensor, Tensor, Tensor]:
    """``bend_xyz`` for a plain refraction, given the index ratio ``mu = n/n'`` per ray.

    The same law with fewer operations, for the compiled trace's fast kernel: S12–S13 written as
    ``d' = mu d + (±sqrt(ζ_R) − mu cos_i) N`` with ``cos_i = d·N`` and ``ζ_R = 1 − mu² (1 − cos_i²)``
    (for unit ``d`` and ``N``, which the trace's directions and normals are), one per-ray ratio
    instead of two indices. Equal to ``bend_xyz`` to rounding, not bit for bit; the eager trace
    keeps ``bend_xyz``.
    """
    dx, dy, dz = d
    nx, ny, nz = normal
    cos_i = dx * nx + dy * ny + dz * nz
    cos2_in = cos_i * cos_i
    cos2_out = 1.0 - mu * mu * (1.0 - cos2_in)
    fail = cos2_out < 0
    floor = torch.finfo(cos2_out.dtype).eps
    cos_out = torch.sqrt(torch.where(cos2_out > floor, cos2_out, floor))
    g = torch.where(cos_i < 0, -cos_out, cos_out) - mu * cos_i
    return (mu * dx + g * nx, mu * dy + g * ny, mu * dz + g * nz), cos2_in, cos2_out, fail
