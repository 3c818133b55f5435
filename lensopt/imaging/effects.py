"""Optional effects beyond the seed's blur: distortion warp, relative illumination, sensor noise."""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from lensopt.imaging.pilot import Pilot
from lensopt.imaging.scene import Region, Sensor

__all__ = ["add_noise", "warp_distortion", "apply_relative_illumination"]


def add_noise(image: Tensor, sigma: float, *, seed: int) -> Tensor:
    """Additive white Gaussian noise with σ = ``sigma`` × the image maximum (S3.3.1), seeded. The noise is
    drawn on the CPU and moved to the image's device, so a seed gives the same noise on every device."""
    gen = torch.Generator().manual_seed(seed)
    scale = sigma * float(image.detach().max().clamp_min(0.0))
    noise = torch.randn(image.shape, generator=gen, dtype=image.dtype).to(image.device)
    return noise.mul_(scale).add_(image)  # = image + scale · noise, without two more image-sized temporaries


#: Rows per band: the effects' float64 coordinate grids are made a band at a time (a dozen whole-image
#: float64 grids were ~1 GB for a 12-Mpixel image); every value is per pixel, so the bands change nothing.
BAND_ROWS = 256


def _radius_grid(w: int, rows: range, region: Region, sensor: Sensor) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sensor x, y and radius (mm) of the pixel centres of image ``rows`` (all ``w`` columns)."""
    cols = np.arange(w) + 0.5
    x, y = region.to_mm(sensor, cols[None, :], np.arange(rows.start, rows.stop)[:, None] + 0.5)
    return x, y, np.hypot(x, y)


def _bands(h: int) -> list[range]:
    return [range(a, min(a + BAND_ROWS, h)) for a in range(0, h, BAND_ROWS)]


def apply_relative_illumination(image: Tensor, pilot: Pilot, region: Region, sensor: Sensor) -> Tensor:
    """Multiply each pixel by the relative illumination (S52) of the field that lands there."""
    h, w = image.shape[-2:]
    out = torch.empty_like(image)
    for rows in _bands(h):
        _, _, r = _radius_grid(w, rows, region, sensor)
        ri = pilot.at("ri", pilot.u_of_radius(r))
        band = slice(rows.start, rows.stop)
        out[..., band, :] = image[..., band, :] * torch.from_numpy(ri.astype(np.float32)).to(image.device,
                                                                                              image.dtype)
    return out


def warp_distortion(image: Tensor, pilot: Pilot, region: Region, sensor: Sensor) -> Tensor:
    """Move scene content from its paraxial (ideal) image position to the real one.

    A pixel at real radius r shows the scene point whose paraxial height is y'(u(r)), with u(r) the
    field whose centroid lands at r (bilinear resampling, border values repeated). ``image``: (C, H, W).
    """
    h, w = image.shape[-2:]
    out = torch.empty_like(image)
    for rows in _bands(h):
        x, y, r = _radius_grid(w, rows, region, sensor)
        u = pilot.u_of_radius(r)
        ideal = np.abs(pilot.at("paraxial", u))
        scale = np.where(r > 0, ideal / np.where(r > 0, r, 1.0), 1.0)
        xs, ys = x * scale, y * scale
        # sensor mm → image pixel coordinates → grid_sample's [−1, 1] (align_corners=False).
        col = (xs / sensor.pitch_mm + sensor.width / 2 - region.x0) * region.image_w / region.w
        row = (sensor.height / 2 - ys / sensor.pitch_mm - region.y0) * region.image_h / region.h
        gx = 2.0 * col / w - 1.0
        gy = 2.0 * row / h - 1.0
        grid = torch.from_numpy(np.stack([gx, gy], -1).astype(np.float32))[None].to(image.device, image.dtype)
        out[:, rows.start:rows.stop] = torch.nn.functional.grid_sample(
            image[None], grid, mode="bilinear", padding_mode="border", align_corners=False)[0]
    return out
