"""Wiener deconvolution (S3.2) with a learnable signal-to-noise ratio stored as its logarithm.

Closed form, per channel, in the Fourier domain (circular convolution of the padded image):

    X̂ = conj(K̂) Ŷ / (|K̂|² + 1/SNR)

with K̂ the transform of the PSF zero-padded to the image size and centred at the origin.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn
from torch.nn import functional as tnf

__all__ = ["psf_otf", "wiener_deconvolve", "Wiener"]


def psf_otf(psf: Tensor, height: int, width: int) -> Tensor:
    """Optical transfer function (*, H, W//2+1) of a centred PSF (*, k, k) (k odd) on an H×W grid.

    The PSF is zero-padded to H×W and rolled so that its centre pixel sits at (0, 0): the circular
    convolution with it does not shift the image.
    """
    k_h, k_w = psf.shape[-2:]
    if k_h > height or k_w > width:
        raise ValueError(f"PSF {k_h}×{k_w} larger than the image {height}×{width}")
    padded = tnf.pad(psf, (0, width - k_w, 0, height - k_h))
    padded = torch.roll(padded, shifts=(-(k_h // 2), -(k_w // 2)), dims=(-2, -1))
    return torch.fft.rfft2(padded)


def wiener_deconvolve(image: Tensor, psf: Tensor, snr: Tensor | float, *, pad: int | None = None) -> Tensor:
    """Wiener deconvolution of ``image`` (B, C, H, W) by ``psf`` (B, C, k, k) or (B, 1, k, k).

    Args:
        snr: signal-to-noise ratio (a tensor keeps it differentiable), scalar or broadcastable to (B, C).
        pad: reflect padding on each side before the transform (limits wrap-around at the borders);
            default k // 2; 0 gives the plain circular closed form.

    Returns:
        (B, C, H, W), same dtype and device as ``image``.
    """
    if image.ndim != 4 or psf.ndim != 4:
        raise ValueError(f"expected image (B, C, H, W) and psf (B, C, k, k), got {tuple(image.shape)}, "
                         f"{tuple(psf.shape)}")
    h, w = image.shape[-2:]
    p = psf.shape[-1] // 2 if pad is None else pad
    x = tnf.pad(image, (p, p, p, p), mode="reflect") if p > 0 else image
    hh, ww = x.shape[-2:]
    otf = psf_otf(psf.to(image.dtype), hh, ww)
    snr_t = torch.as_tensor(snr, dtype=image.dtype, device=image.device)
    inv = 1.0 / snr_t.reshape(snr_t.shape + (1,) * (4 - snr_t.ndim)) if snr_t.ndim else 1.0 / snr_t
    filt = otf.conj() / (otf.real**2 + otf.imag**2 + inv)
    out = torch.fft.irfft2(torch.fft.rfft2(x) * filt, s=(hh, ww))
    return out[..., p:p + h, p:p + w] if p > 0 else out


class Wiener(nn.Module):
    """Wiener deconvolution with a learnable ``log_snr`` (one scalar, initial value log(snr))."""

    def __init__(self, snr: float = 1000.0) -> None:
        super().__init__()
        self.log_snr = nn.Parameter(torch.tensor(math.log(snr)))

    def forward(self, image: Tensor, psf: Tensor) -> Tensor:
        return wiener_deconvolve(image, psf, self.log_snr.to(image.dtype).exp())
