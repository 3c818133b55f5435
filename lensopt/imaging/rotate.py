"""Energy-preserving PSF rotation by three shears (S1.5.1 step 4; Paeth's decomposition) and
area-weighted PSF resampling (S1.5.1 step 5).

R(φ) = Sx(−tan φ/2) · Sy(sin φ) · Sx(−tan φ/2). Each shear moves every row (or column) by a
fractional offset with linear splatting: a sample's value is split between the two bins it lands
between, so each shear conserves the energy exactly (and stays non-negative and differentiable).
The PSF is padded so that its rotated corners stay on the canvas; what falls outside the final S×S
crop is spread uniformly over the crop (S1.5.1, as for rays missing the grid in S1.4).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

__all__ = ["shear_rows", "rotate_psf", "resample_psf", "resample_matrix"]


def shear_rows(img: Tensor, shift: Tensor) -> Tensor:
    """Shift each row of ``img`` (*B, H, W) along the last axis by ``shift`` (*B, H) bins, mass-conserving
    (linear splatting; mass leaving the canvas is dropped)."""
    w = img.shape[-1]
    n = torch.floor(shift.detach())
    f = (shift - n).unsqueeze(-1)
    n = n.to(torch.int64).unsqueeze(-1)
    j = torch.arange(w, device=img.device)

    def take(offset: Tensor) -> Tensor:
        src = j - offset  # out[j] = in[j − offset]
        ok = (src >= 0) & (src < w)
        vals = torch.gather(img, -1, src.clamp(0, w - 1).expand_as(img))
        return torch.where(ok, vals, torch.zeros_like(vals))

    return (1.0 - f) * take(n) + f * take(n + 1)


def _shear_x(img: Tensor, a: Tensor) -> Tensor:
    """(x, y) → (x + a·y, y) on (*B, H, W) images with y = row − centre; ``a`` (*B,)."""
    h = img.shape[-2]
    y = torch.arange(h, dtype=img.dtype, device=img.device) - (h - 1) / 2
    return shear_rows(img, a.unsqueeze(-1) * y)


def _shear_y(img: Tensor, b: Tensor) -> Tensor:
    """(x, y) → (x, y + b·x)."""
    return _shear_x(img.transpose(-1, -2), b).transpose(-1, -2)


def rotate_psf(psf: Tensor, angle: Tensor) -> Tensor:
    """Rotate PSFs counter-clockwise (x → y) by ``angle`` radians about their centre bin.

    Args:
        psf: (*B, S, S) PSFs (row index grows with +y, column with +x), S odd.
        angle: (*B,) or broadcastable angles, radians.

    Returns:
        (*B, S, S) rotated PSFs with the same total energy as the input.
    """
    s = psf.shape[-1]
    angle = torch.as_tensor(angle, dtype=psf.dtype, device=psf.device).expand(psf.shape[:-2])
    # Shears are accurate for |φ| ≤ π/2: rotate by π exactly (flip both axes) where needed.
    wrapped = torch.remainder(angle + math.pi, 2 * math.pi) - math.pi
    big = wrapped.abs() > math.pi / 2
    flipped = torch.flip(psf, (-1, -2))
    psf = torch.where(big[..., None, None], flipped, psf)
    phi = torch.where(big, wrapped - torch.sign(wrapped) * math.pi, wrapped)
    pad = math.ceil(s * (math.sqrt(2.0) - 1.0) / 2.0) + 2
    canvas = torch.nn.functional.pad(psf, (pad, pad, pad, pad))
    a = -torch.tan(phi / 2)
    b = torch.sin(phi)
    canvas = _shear_x(_shear_y(_shear_x(canvas, a), b), a)
    out = canvas[..., pad:pad + s, pad:pad + s]
    lost = psf.sum((-1, -2), keepdim=True) - out.sum((-1, -2), keepdim=True)
    return out + lost / (s * s)


def resample_matrix(n_in: int, pitch_in: float, n_out: int, pitch_out: float, *,
                    dtype: torch.dtype = torch.float64, device: torch.device | None = None) -> Tensor:
    """(n_out, n_in) matrix of bin overlaps (fraction of each input bin falling in each output bin);
    both grids centred on the same point."""
    ci, co = (n_in - 1) / 2, (n_out - 1) / 2
    i = torch.arange(n_in, dtype=torch.float64, device=device)
    o = torch.arange(n_out, dtype=torch.float64, device=device)
    lo_i, hi_i = (i - ci - 0.5) * pitch_in, (i - ci + 0.5) * pitch_in
    lo_o, hi_o = (o - co - 0.5) * pitch_out, (o - co + 0.5) * pitch_out
    overlap = (torch.minimum(hi_o[:, None], hi_i[None, :]) - torch.maximum(lo_o[:, None], lo_i[None, :])).clamp_min(0)
    return (overlap / pitch_in).to(dtype)


def resample_psf(psf: Tensor, pitch_in: float, pitch_out: float, size_out: int | None = None) -> Tensor:
    """Resize PSFs (*B, S, S) from bin pitch ``pitch_in`` to ``pitch_out`` (S1.5.1 step 5) by exact
    bin-area overlap (no aliasing when shrinking), then renormalize each PSF to its input energy.

    ``size_out`` defaults to the smallest odd size covering the input grid.
    """
    s = psf.shape[-1]
    if size_out is None:
        size_out = max(1, math.ceil(s * pitch_in / pitch_out))
        size_out += 1 - size_out % 2
    m = resample_matrix(s, pitch_in, size_out, pitch_out, dtype=psf.dtype, device=psf.device)
    out = m @ psf @ m.T
    total = psf.sum((-1, -2), keepdim=True)
    return out * total / out.sum((-1, -2), keepdim=True).clamp_min(torch.finfo(psf.dtype).tiny)
