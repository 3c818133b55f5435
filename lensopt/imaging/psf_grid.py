"""The PSF grid of S1.5.1: field PSFs K1 (F, W, S, S) → RGB (W_w) → sensor regions (W_f) → rotated to
each region's azimuth → resized to the image pixel → image orientation.

Orientation: field PSFs are computed for fields along +Y (``lensopt.analysis.psf`` convention, rows
growing with +Y). A region centred at sensor (X, Y) sees the PSF rotated by φ = atan2(−X, Y), which
takes +Y to the region's direction. Image rows grow downwards (−Y), so the last step flips rows.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from lensopt.imaging.convolve import patch_bounds
from lensopt.imaging.rotate import resample_psf, rotate_psf
from lensopt.imaging.scene import Region, Sensor

__all__ = ["field_weights", "cell_centers_mm", "build_psf_grid"]


def field_weights(field_radius_mm: np.ndarray, region: Region, sensor: Sensor, grid: tuple[int, int], *,
                  samples: int = 16) -> np.ndarray:
    """W_f (F, H_g·W_g): for each grid cell, the fraction of its area closest (in radius) to each field.

    Args:
        field_radius_mm: (F,) image radius of each traced field (centroid heights).
        grid: (W_g, H_g).
    """
    gw, gh = grid
    fr = np.asarray(field_radius_mm, dtype=np.float64)
    out = np.zeros((fr.size, gh * gw))
    rows, cols = patch_bounds(region.image_h, gh), patch_bounds(region.image_w, gw)
    for i, (r0, r1) in enumerate(rows):
        for j, (c0, c1) in enumerate(cols):
            cc = c0 + (np.arange(samples) + 0.5) * (c1 - c0) / samples
            rr = r0 + (np.arange(samples) + 0.5) * (r1 - r0) / samples
            x, y = region.to_mm(sensor, cc[None, :], rr[:, None])
            rad = np.hypot(x, y).reshape(-1)
            nearest = np.argmin(np.abs(rad[:, None] - fr[None, :]), axis=1)
            out[:, i * gw + j] = np.bincount(nearest, minlength=fr.size) / rad.size
    return out


def cell_centers_mm(region: Region, sensor: Sensor, grid: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(H_g, W_g) sensor coordinates X, Y (mm) of the centre of each grid cell."""
    gw, gh = grid
    rows, cols = patch_bounds(region.image_h, gh), patch_bounds(region.image_w, gw)
    cc = np.array([(a + b) / 2 for a, b in cols])
    rr = np.array([(a + b) / 2 for a, b in rows])
    x, y = region.to_mm(sensor, cc[None, :], rr[:, None])
    x, y = np.broadcast_arrays(x, y)
    return np.ascontiguousarray(x), np.ascontiguousarray(y)


def build_psf_grid(
    psf: Tensor,
    channel_weights: Tensor,
    field_w: Tensor,
    centers_xy: tuple[np.ndarray, np.ndarray],
    *,
    pitch_mm: float,
    pixel_mm: float,
) -> Tensor:
    """K_grid (H_g, W_g, C, K, K) in image orientation, each PSF summing to 1.

    Args:
        psf: (F, W, S, S) field PSFs K1.
        channel_weights: (W, C) W_w, columns summing to 1.
        field_w: (F, H_g·W_g) W_f, columns summing to 1.
        centers_xy: (H_g, W_g) sensor X and Y of the cell centres, mm.
        pitch_mm: PSF bin size; pixel_mm: image pixel size (resized when they differ).
    """
    k2 = torch.einsum("fwij,wc->fcij", psf, channel_weights.to(psf.dtype))  # S1.5.1 step 2
    k3 = torch.einsum("fcij,fg->gcij", k2, field_w.to(psf.dtype))  # step 3
    x, y = centers_xy
    gh, gw = x.shape
    phi = torch.as_tensor(np.arctan2(-x, y).reshape(-1), dtype=psf.dtype, device=psf.device)
    phi = torch.where(torch.as_tensor(np.hypot(x, y).reshape(-1) > 0, device=psf.device), phi, torch.zeros_like(phi))
    k4 = rotate_psf(k3, phi[:, None])  # step 4
    if abs(pitch_mm - pixel_mm) > 1e-9 * pixel_mm:  # step 5
        k4 = resample_psf(k4, pitch_mm, pixel_mm)
    k4 = k4 / k4.sum((-1, -2), keepdim=True)
    k4 = torch.flip(k4, (-2,))  # rows grow downwards in images
    return k4.reshape(gh, gw, *k4.shape[1:])
