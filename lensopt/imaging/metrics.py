"""Image quality metrics: PSNR and SSIM (scikit-image's implementations, Wang et al. 2004 SSIM with
its Gaussian-weighted variant as in the seed's comparisons), on images in [0, 1]."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["psnr", "ssim"]

#: Side of skimage's Gaussian SSIM window for σ = 1.5 (2·⌊3.5σ + 0.5⌋ + 1).
SSIM_MIN_SIDE = 11


def psnr(reference: np.ndarray, test: np.ndarray, *, data_range: float = 1.0) -> float:
    """Peak signal-to-noise ratio in dB of ``test`` against ``reference`` (same shape)."""
    from skimage.metrics import peak_signal_noise_ratio

    if np.array_equal(reference, test):
        return float("inf")  # identical images (scikit-image would divide by zero with a warning)
    return float(peak_signal_noise_ratio(np.asarray(reference, np.float64), np.asarray(test, np.float64),
                                         data_range=data_range))


def ssim(reference: np.ndarray, test: np.ndarray, *, data_range: float = 1.0) -> float:
    """Structural similarity (H, W) or (H, W, C): Gaussian window σ = 1.5, as in Wang et al. 2004; NaN for
    images smaller than the window (11 pixels)."""
    from skimage.metrics import structural_similarity

    ref = np.asarray(reference, np.float64)
    tst = np.asarray(test, np.float64)
    if min(ref.shape[0], ref.shape[1]) < SSIM_MIN_SIDE:  # smaller than the Gaussian window: not measurable
        return math.nan
    channel_axis = -1 if ref.ndim == 3 else None
    if ref.ndim == 3 and ref.shape[-1] == 1:
        ref, tst, channel_axis = ref[..., 0], tst[..., 0], None
    return float(structural_similarity(ref, tst, data_range=data_range, channel_axis=channel_axis,
                                       gaussian_weights=True, sigma=1.5, use_sample_covariance=False))
