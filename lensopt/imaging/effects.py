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
    return image + scale * torch.randn(image.shape, generator=gen, dtype=image.dtype).to(image.device)


def _radius_grid(image: Tensor, region: Region, sensor: Sensor) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    h, w = image.shape[-2:]
    cols = np.arange(w) + 0.5
    rows = np.arange(h) + 0.5
    x, y = region.to_mm(sensor, cols[None, :], rows[:, None])
    return x, y, np.hypot(x, y)


def apply_relative_illumination(image: Tensor, pilot: Pilot, region: Region, sensor: Sensor) -> Tensor:
    """Multiply each pixel by the relative illumination (S52) of the field that lands there."""
    _, _, r = _radius_grid(image, region, sensor)
    ri = pilot.at("ri", pilot.u_of_radius(r))
    return image * torch.from_numpy(ri.astype(np.float32)).to(image.device, image.dtype)


def warp_distortion(image: Tensor, pilot: Pilot, region: Region, sensor: Sensor) -> Tensor:
    """Move scene content from its paraxial (ideal) image position to the real one.

    A pixel at real radius r shows the scene point whose paraxial height is y'(u(r)), with u(r) the
    field whose centroid lands at r (bilinear resampling, border values repeated).
    """
    h, w = image.shape[-2:]
    x, y, r = _radius_grid(image, region, sensor)
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
    out = torch.nn.functional.grid_sample(image[None], grid, mode="bilinear", padding_mode="border",
                                          align_corners=False)
    return out[0]
