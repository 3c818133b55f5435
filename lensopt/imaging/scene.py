"""Where a scene lies on the sensor: region parsing and image-pixel ↔ sensor-mm geometry.

Sensor coordinates: pixel (sx, sy) from the top-left corner of the sensor, x to the right, y down;
millimetres on the image surface: X = (sx − W_s/2)·p, Y = (H_s/2 − sy)·p (Y up, optical axis at the
sensor centre). The scene image (W × H pixels) covers the region (x0, y0, w, h) in sensor pixels, so
an image pixel measures p·w/W by p·h/H.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from lensopt.errors import LensoptError

__all__ = ["Region", "Sensor", "parse_region", "REGION_HELP"]

REGION_HELP = ("x0,y0,w,h in sensor pixels; or full | center | corner (1:1 crops of the image's size); "
               "or tile:C,R/NCxNR (tile C,R of an NC×NR grid)")


@dataclass(frozen=True)
class Sensor:
    """Pixel pitch (mm) and resolution (W_s, H_s) in pixels."""

    pitch_mm: float
    width: int
    height: int

    @property
    def half_diagonal_mm(self) -> float:
        return 0.5 * self.pitch_mm * math.hypot(self.width, self.height)


@dataclass(frozen=True)
class Region:
    """A rectangle of the sensor (sensor pixels, may be fractional) covered by a W × H image."""

    x0: float
    y0: float
    w: float
    h: float
    image_w: int
    image_h: int
    name: str

    def pixel_mm(self, sensor: Sensor) -> tuple[float, float]:
        """Image pixel size (x, y) in mm."""
        return sensor.pitch_mm * self.w / self.image_w, sensor.pitch_mm * self.h / self.image_h

    def to_mm(self, sensor: Sensor, col: np.ndarray, row: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Image-pixel coordinates (continuous, pixel centres at k + 0.5) → sensor mm (X, Y)."""
        sx = self.x0 + col * self.w / self.image_w
        sy = self.y0 + row * self.h / self.image_h
        return (sx - sensor.width / 2) * sensor.pitch_mm, (sensor.height / 2 - sy) * sensor.pitch_mm

    def radius_range_mm(self, sensor: Sensor) -> tuple[float, float]:
        """Smallest and largest distance of the region from the optical axis, mm."""
        xs = (np.array([self.x0, self.x0 + self.w]) - sensor.width / 2) * sensor.pitch_mm
        ys = (sensor.height / 2 - np.array([self.y0, self.y0 + self.h])) * sensor.pitch_mm
        far = max(math.hypot(x, y) for x in xs for y in ys)
        nx = 0.0 if xs.min() <= 0 <= xs.max() else float(np.abs(xs).min())
        ny = 0.0 if ys.min() <= 0 <= ys.max() else float(np.abs(ys).min())
        return math.hypot(nx, ny), far

    def as_dict(self) -> dict[str, object]:
        return {"name": self.name, "x0": self.x0, "y0": self.y0, "w": self.w, "h": self.h}


def parse_region(text: str | None, sensor: Sensor, image_w: int, image_h: int, *, option: str = "--region") -> Region:
    """The region a ``image_w × image_h`` image covers on ``sensor``.

    Default (None or ``fit``): the largest centred region with the image's aspect ratio.
    """
    sw, sh = sensor.width, sensor.height
    t = (text or "fit").strip().lower()
    if t == "fit":
        scale = min(sw / image_w, sh / image_h)
        w, h = image_w * scale, image_h * scale
        return Region((sw - w) / 2, (sh - h) / 2, w, h, image_w, image_h, "fit")
    if t == "full":
        return _checked(Region(0.0, 0.0, float(sw), float(sh), image_w, image_h, "full"), sensor, option, text)
    if t == "center":
        return _checked(Region((sw - image_w) / 2, (sh - image_h) / 2, image_w, image_h, image_w, image_h,
                               "center"), sensor, option, text)
    if t == "corner":
        return _checked(Region(float(sw - image_w), 0.0, image_w, image_h, image_w, image_h, "corner"),
                        sensor, option, text)
    m = re.fullmatch(r"tile:(\d+),(\d+)/(\d+)x(\d+)", t)
    if m:
        c, r, nc, nr = (int(g) for g in m.groups())
        if not (0 <= c < nc and 0 <= r < nr):
            raise LensoptError("tile index outside the tile grid", path=option, got=text)
        w, h = sw / nc, sh / nr
        return _checked(Region(c * w, r * h, w, h, image_w, image_h, t), sensor, option, text)
    parts = t.split(",")
    try:
        x0, y0, w, h = (float(p) for p in parts)
    except ValueError:
        raise LensoptError(f"expected {REGION_HELP}", path=option, got=text) from None
    return _checked(Region(x0, y0, w, h, image_w, image_h, "custom"), sensor, option, text)


def _checked(reg: Region, sensor: Sensor, option: str, text: str | None) -> Region:
    if not all(math.isfinite(v) for v in (reg.x0, reg.y0, reg.w, reg.h)):
        raise LensoptError("region numbers must be finite", path=option, got=text)
    if not (reg.w > 0 and reg.h > 0):
        raise LensoptError("region width and height must be positive", path=option, got=text)
    eps = 1e-6
    if reg.x0 < -eps or reg.y0 < -eps or reg.x0 + reg.w > sensor.width + eps or reg.y0 + reg.h > sensor.height + eps:
        raise LensoptError(f"region must lie on the {sensor.width}×{sensor.height} sensor", path=option, got=text)
    sx, sy = reg.w / reg.image_w, reg.h / reg.image_h
    if abs(sx - sy) > 0.01 * max(sx, sy):
        raise LensoptError(f"region aspect w/h must match the image's {reg.image_w}×{reg.image_h} "
                           "(square pixels)", path=option, got=text)
    return reg
