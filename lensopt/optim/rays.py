"""The optimization rays: the spot-size sample plus probe rays on the pupil rim and at its centre,
where the geometric constraints bind (edge thicknesses and the steepest angles at the beam's rim,
centre thicknesses on its axis), and the part of a bundle that makes the spot."""

from __future__ import annotations

import math
from dataclasses import replace

import torch
from torch import Tensor

from lensopt.optics.bundle import Bundle
from lensopt.optics.trace import RayTrace

__all__ = ["rim_points", "with_rim", "head"]


def rim_points(n: int, *, half: bool, dtype: torch.dtype) -> Tensor:
    """(n, 2) points on the unit pupil rim: from the top (0, 1) to the bottom (0, −1) through the
    lateral point (1, 0) for a half pupil, all around for a full pupil (top, lateral and bottom
    points always included when n allows)."""
    if n == 0:
        return torch.zeros(0, 2, dtype=dtype)
    if half:
        psi = torch.linspace(0.0, math.pi, n, dtype=torch.float64) if n > 1 else torch.zeros(1, dtype=torch.float64)
    else:
        psi = torch.arange(n, dtype=torch.float64) * (2 * math.pi / n)
    return torch.stack([torch.sin(psi), torch.cos(psi)], -1).to(dtype)


def with_rim(points: Tensor, n: int, *, half: bool) -> Tensor:
    """(P + n + 1, 2): the sample, ``n`` rim points and the pupil centre (nothing added for n = 0)."""
    if n == 0:
        return points
    centre = torch.zeros(1, 2, dtype=points.dtype)
    return torch.cat([points, rim_points(n, half=half, dtype=points.dtype), centre])


def head(bundle: Bundle, n: int) -> Bundle:
    """The first ``n`` pupil samples of a (F, W, P) bundle, as a bundle (for spot statistics)."""
    if bundle.pupil.shape[-2] == n:
        return bundle
    res = bundle.result

    def cut(t: Tensor) -> Tensor:
        return t[..., :n, :] if t.dim() == len(res.status.shape) + 1 else t[..., :n]

    hits = tuple(replace(h, **{k: cut(getattr(h, k)) for k in ("pos", "dir_in", "dir_out", "normal", "t",
                                                              "cos2_in", "cos2_out")}) for h in res.hits)
    result = RayTrace(pos=cut(res.pos), dir=cut(res.dir), status=cut(res.status), backtrack=cut(res.backtrack),
                      hits=hits, failed_at=None if res.failed_at is None else cut(res.failed_at))
    rays = replace(bundle.rays, pos=bundle.rays.pos[..., :n, :] if bundle.rays.pos.shape[-2] > 1 else bundle.rays.pos,
                   dir=bundle.rays.dir[..., :n, :] if bundle.rays.dir.shape[-2] > 1 else bundle.rays.dir)
    weights = None if bundle.pupil_weights is None else bundle.pupil_weights[:n]
    return replace(bundle, pupil=bundle.pupil[..., :n, :], rays=rays, result=result, pupil_weights=weights)
