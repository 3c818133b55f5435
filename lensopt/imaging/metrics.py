"""Image quality metrics: PSNR and SSIM (scikit-image's implementations, Wang et al. 2004 SSIM with
its Gaussian-weighted variant as in the seed's comparisons), on images in [0, 1]; and the PSNR of a mean
squared error (image objectives) and of a batch of tensors (the restoration network's validation).

Both run in bands of rows, so that a 12-Mpixel RGB image costs a few float64 bands instead of a dozen
float64 copies of the whole image (2.9 GB): SSIM's Gaussian window reaches ``SSIM_HALO`` rows, and
scikit-image averages the SSIM map without ``SSIM_HALO`` pixels at every border, so each band computed
with that many rows of context on both sides gives exactly the rows it owns; the means of the bands,
weighted by their rows, are the mean of the whole map (to float64 rounding).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import torch
from torch import Tensor

__all__ = ["psnr", "psnr_batch", "psnr_of_mse", "ssim"]

#: Side of skimage's Gaussian SSIM window for σ = 1.5 (2·⌊3.5σ + 0.5⌋ + 1).
SSIM_MIN_SIDE = 11
#: Rows of the window on each side of its centre, and the border skimage leaves out of the mean.
SSIM_HALO = (SSIM_MIN_SIDE - 1) // 2
#: Rows per band (before the halo).
BAND_ROWS = 256


Transform = Callable[[np.ndarray], np.ndarray]


def _identity(x: np.ndarray) -> np.ndarray:
    return x


def psnr(reference: np.ndarray, test: np.ndarray, *, data_range: float = 1.0,
         transform: Transform | None = None) -> float:
    """Peak signal-to-noise ratio in dB of ``test`` against ``reference`` (same shape): 10 log10(L² / MSE),
    the mean squared error in float64 (as scikit-image), summed band by band. ``transform`` (elementwise,
    e.g. ``linear_to_srgb``) is applied to each band of both images first: no transformed copies."""
    ref, tst = np.asarray(reference), np.asarray(test)
    f = transform or _identity
    if ref.shape != tst.shape:
        raise ValueError(f"shapes differ: {ref.shape} vs {tst.shape}")
    if np.array_equal(ref, tst):
        return float("inf")  # identical images (scikit-image would divide by zero with a warning)
    total = 0.0
    for y in range(0, ref.shape[0], BAND_ROWS):
        d = f(ref[y:y + BAND_ROWS]).astype(np.float64) - f(tst[y:y + BAND_ROWS])
        total += float(np.dot(d.ravel(), d.ravel()))
    if total == 0.0:  # equal after the transform (e.g. both clipped)
        return float("inf")
    return float(10.0 * math.log10(data_range**2 / (total / ref.size)))


def psnr_of_mse(mse: float, peak: float = 1.0) -> float:
    """PSNR in dB of a mean squared error for signals of peak ``peak``: 10 log10(peak² / MSE), ∞ for 0."""
    return 10.0 * math.log10(peak**2 / mse) if mse > 0 else math.inf


def psnr_batch(reference: Tensor, test: Tensor) -> Tensor:
    """(B,) PSNR in dB of each image of ``test`` (B, ...), clamped to [0, 1], against ``reference`` (data
    range 1), in the tensors' dtype (the MSE clamped at 1e-20)."""
    mse = ((test.clamp(0, 1) - reference) ** 2).flatten(1).mean(1)
    return 10 * torch.log10(1.0 / mse.clamp_min(1e-20))


def ssim(reference: np.ndarray, test: np.ndarray, *, data_range: float = 1.0,
         transform: Transform | None = None) -> float:
    """Structural similarity (H, W) or (H, W, C): Gaussian window σ = 1.5, as in Wang et al. 2004; NaN for
    images smaller than the window (11 pixels). Scikit-image's value, computed in bands of rows;
    ``transform`` as for ``psnr``."""
    from skimage.metrics import structural_similarity

    ref, tst = np.asarray(reference), np.asarray(test)
    f = transform or _identity
    if min(ref.shape[0], ref.shape[1]) < SSIM_MIN_SIDE:  # smaller than the Gaussian window: not measurable
        return math.nan
    if ref.ndim == 2:
        ref, tst = ref[..., None], tst[..., None]
    h, halo = ref.shape[0], SSIM_HALO
    owned = h - 2 * halo  # rows of the SSIM map that enter the mean
    total = np.zeros(ref.shape[-1])
    for a in range(halo, h - halo, BAND_ROWS):
        b = min(a + BAND_ROWS, h - halo)
        for c in range(ref.shape[-1]):  # skimage: the mean over channels of each channel's mean
            band_ref = f(ref[a - halo:b + halo, :, c]).astype(np.float64)
            band_tst = f(tst[a - halo:b + halo, :, c]).astype(np.float64)
            total[c] += (b - a) * structural_similarity(band_ref, band_tst, data_range=data_range,
                                                        gaussian_weights=True, sigma=1.5,
                                                        use_sample_covariance=False)
    return float(np.mean(total / owned))
