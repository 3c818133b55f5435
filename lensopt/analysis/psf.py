"""Geometric PSFs from spot diagrams (S1.4.1–S1.4.2): ray counting and kernel density estimation.

A PSF is a (…, S, S) grid of bins of side ``pitch`` (mm), S odd, centred on a given point (the
wavelength-averaged centroid of the field, S1.4.1). Array convention: ``psf[..., i, j]`` is the bin
at ``x = (j − c)·pitch``, ``y = (i − c)·pitch`` relative to the centre, c = (S − 1)/2, so row index
grows with +y (mathematical orientation; imaging flips it to image rows).

Every ray carries the same energy 1/P. Energy of rays that failed, or whose deposit falls outside the
grid, is spread uniformly over all bins (simulated scattering, S1.4.1), so every PSF sums to 1.

KDE (S1.4.2) spreads each ray over the bins with a separable kernel of finite support σ = ``support``
bins (an even integer). The triangular and cosine (raised-cosine) kernels are antisymmetric about
±σ/4 on [0, σ/2], so the kernel sampled at the bin centres sums to exactly 1 wherever the ray lands
(a partition of unity): each ray deposits exactly its energy, whatever its sub-bin position.
KDE is differentiable in the ray coordinates; ray counting is not.
"""

from __future__ import annotations

import math
from typing import Literal

import torch
from torch import Tensor

from lensopt.errors import LensoptError

__all__ = ["Kernel", "KERNELS", "kernel_1d", "ray_count", "kde", "deposit", "mirror_half_pupil",
           "bin_down", "grid_size_for"]

Kernel = Literal["count", "triangular", "cosine"]
KERNELS: tuple[str, ...] = ("count", "triangular", "cosine")


def kernel_1d(t: Tensor, kind: str) -> Tensor:
    """Unit-support 1D kernel k(t), t in units of σ/2: zero for |t| ≥ 1, k(t) + k(1 − t) = 1 on [0, 1].

    ``triangular``: 1 − |t|;  ``cosine``: (1 + cos πt)/2.
    """
    a = t.abs()
    if kind == "triangular":
        k = 1.0 - a
    elif kind == "cosine":
        k = 0.5 * (1.0 + torch.cos(math.pi * a.clamp(max=1.0)))
    else:
        raise LensoptError("must be triangular or cosine", path="kernel", got=kind)
    return torch.where(a < 1.0, k, torch.zeros_like(k))


def _check(size: int, support: int, allow_even: bool = False) -> None:
    if size < 1 or (size % 2 == 0 and not allow_even):
        raise LensoptError("PSF grid size must be a positive odd number of bins", path="size", got=size)
    if support < 2 or support % 2:
        raise LensoptError("KDE support must be an even number of bins ≥ 2", path="support", got=support)


def deposit(
    xy: Tensor,
    valid: Tensor,
    center: Tensor,
    *,
    pitch: float,
    size: int,
    kernel: str = "triangular",
    support: int = 2,
    allow_even: bool = False,
) -> Tensor:
    """Deposit rays on PSF grids by ray counting (``kernel="count"``) or KDE, normalized to sum 1.

    Args:
        xy: (*B, P, 2) ray intercepts on the image surface, mm.
        valid: (*B, P) rays that reached the image (others are scattered uniformly).
        center: (*B, 2) grid centres, mm.
        pitch: bin size, mm.
        size: odd number of bins per side S (the centre bin is centred on ``center``).
        kernel: ``count``, ``triangular`` or ``cosine``.
        support: KDE support σ in bins (even); ignored for ``count``.
        allow_even: accept an even S: ``center`` then falls on the corner between the four middle bins.
            For the fine grids of oversampling (``bin_down`` by an even factor restores an odd grid whose
            centre bin is centred on ``center``).

    Returns:
        (*B, S, S) PSFs, each summing to 1.
    """
    if kernel == "count":
        return ray_count(xy, valid, center, pitch=pitch, size=size, allow_even=allow_even)
    return kde(xy, valid, center, pitch=pitch, size=size, kernel=kernel, support=support, allow_even=allow_even)


def _bin_coords(xy: Tensor, center: Tensor, pitch: float, size: int) -> Tensor:
    """(*B, P, 2) positions in bin units, bin centres at integers 0..S−1."""
    c = (size - 1) / 2
    return (xy - center.unsqueeze(-2)) / pitch + c


def _scatter(batch: tuple[int, ...], size: int, idx_x: Tensor, idx_y: Tensor, w: Tensor) -> Tensor:
    """Sum weights ``w`` (*B, P, …) at bins (idx_y, idx_x); out-of-grid entries must have w = 0."""
    nb = math.prod(batch)
    inside = (idx_x >= 0) & (idx_x < size) & (idx_y >= 0) & (idx_y < size)
    w = torch.where(inside, w, torch.zeros_like(w))
    flat = idx_y.clamp(0, size - 1) * size + idx_x.clamp(0, size - 1)
    offset = torch.arange(nb, device=w.device).view(*batch, *([1] * (flat.dim() - len(batch)))) * size * size
    flat = (flat + offset.view(*batch, *([1] * (flat.dim() - len(batch))))).reshape(-1)
    out = torch.zeros(nb * size * size, dtype=w.dtype, device=w.device)
    out = out.scatter_add(0, flat, w.reshape(-1))
    return out.view(*batch, size, size)


def _finish(grid: Tensor, rays: int) -> Tensor:
    """Scale deposits (one unit per ray) to energy 1/P per ray and spread what is missing uniformly."""
    grid = grid / rays
    missing = 1.0 - grid.sum((-1, -2), keepdim=True)
    return grid + missing / (grid.shape[-1] * grid.shape[-2])


def ray_count(xy: Tensor, valid: Tensor, center: Tensor, *, pitch: float, size: int,
              allow_even: bool = False) -> Tensor:
    """Ray counting (S1.4.1): each valid ray adds 1/P to the bin it lands in. See ``deposit``."""
    _check(size, 2, allow_even)
    u = _bin_coords(xy.detach(), center.detach(), pitch, size)
    j = torch.floor(u + 0.5).to(torch.int64)
    w = valid.to(xy.dtype)
    grid = _scatter(tuple(xy.shape[:-2]), size, j[..., 0], j[..., 1], w)
    return _finish(grid, xy.shape[-2])


def kde(
    xy: Tensor,
    valid: Tensor,
    center: Tensor,
    *,
    pitch: float,
    size: int,
    kernel: str = "triangular",
    support: int = 2,
    allow_even: bool = False,
) -> Tensor:
    """Kernel density estimate (S1.4.2) with a separable finite-support kernel; differentiable in
    ``xy`` and ``center`` (failed rays: zero weight, finite zero gradient). See ``deposit``."""
    _check(size, support, allow_even)
    m = support // 2
    u = _bin_coords(xy, center, pitch, size)
    valid = valid & torch.isfinite(u).all(-1)
    u = torch.where(valid.unsqueeze(-1), u, torch.zeros_like(u))
    base = torch.floor(u.detach())
    steps = torch.arange(-m + 1, m + 1, device=xy.device, dtype=xy.dtype)  # (2m,)
    bins = base.unsqueeze(-1) + steps  # (*B, P, 2, 2m)
    k = kernel_1d((bins - u.unsqueeze(-1)) / m, kernel) / m
    k = torch.where(valid[..., None, None], k, torch.zeros_like(k))
    kx, ky = k[..., 0, :], k[..., 1, :]
    w = ky.unsqueeze(-1) * kx.unsqueeze(-2)  # (*B, P, 2m_y, 2m_x)
    bx = bins[..., 0, :].to(torch.int64).unsqueeze(-2).expand_as(w)
    by = bins[..., 1, :].to(torch.int64).unsqueeze(-1).expand_as(w)
    grid = _scatter(tuple(xy.shape[:-2]), size, bx, by, w)
    return _finish(grid, xy.shape[-2])


def mirror_half_pupil(xy: Tensor, valid: Tensor, center_x: Tensor | float = 0.0) -> tuple[Tensor, Tensor]:
    """Complete a half-pupil spot (x ≥ 0 pupil samples) by its mirror image about x = ``center_x``.

    Args:
        xy: (*B, P, 2); valid: (*B, P).

    Returns:
        (*B, 2P, 2) intercepts and (*B, 2P) validity.
    """
    cx = torch.as_tensor(center_x, dtype=xy.dtype, device=xy.device)
    mirrored = torch.stack([2 * cx - xy[..., 0], xy[..., 1]], -1)
    return torch.cat([xy, mirrored], -2), torch.cat([valid, valid], -1)


def bin_down(psf: Tensor, factor: int) -> Tensor:
    """Sum ``factor × factor`` blocks: (*B, S·f, S·f) → (*B, S, S) (energy preserving)."""
    if factor == 1:
        return psf
    *b, h, w = psf.shape
    return psf.reshape(*b, h // factor, factor, w // factor, factor).sum((-1, -3))


def grid_size_for(half_width_mm: float, pitch_mm: float, *, margin_bins: int = 1, max_size: int = 255) -> int:
    """Smallest odd bin count whose half-width covers ``half_width_mm`` plus ``margin_bins``, capped."""
    half = math.ceil(max(half_width_mm, 0.0) / pitch_mm + 0.5) + margin_bins
    size = 2 * half + 1
    cap = max_size if max_size % 2 else max_size - 1
    return max(3, min(size, cap))
