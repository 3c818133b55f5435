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

__all__ = ["bend"]


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
    cos_i = (dir * normal).sum(-1)
    orient = torch.where(cos_i < 0, -torch.ones_like(cos_i), torch.ones_like(cos_i))
    nrm = normal * orient.unsqueeze(-1)
    cos_i = cos_i * orient
    v = n1.unsqueeze(-1) * dir
    if grating is not None:
        v = v + grating
    v_t = v - (v * nrm).sum(-1, keepdim=True) * nrm
    d_t = v_t / n2.unsqueeze(-1)
    cos2_out = 1.0 - (d_t * d_t).sum(-1)
    fail = cos2_out < 0
    floor = torch.finfo(dir.dtype).eps
    cos_out = torch.sqrt(torch.where(cos2_out > floor, cos2_out, torch.full_like(cos2_out, floor)))
    dir_out = d_t + cos_out.unsqueeze(-1) * nrm
    return dir_out, cos_i * cos_i, cos2_out, fail
