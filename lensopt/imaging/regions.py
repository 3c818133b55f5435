"""Sensor regions for training batches and evaluation (seed S3.3.1, Figure S8; S4.3.1).

The sensor is divided into non-overlapping tiles of the patch size (Figure S8: 8192×6144 px in 32×24
tiles of 256 px); when the resolution is not a multiple of the patch, the grid of whole tiles is centred
on the sensor. Tiles are sorted by the distance of their centre from the sensor centre (ties broken by
row, then column), and sampled pseudo-randomly so that every batch covers the field evenly: a batch of B
draws splits the sorted list into B contiguous strata (centre → corner) and takes one random tile from
each, then shuffles the order; B larger than the tile count takes every tile ⌊B/N⌋ times and stratifies
the rest. Evaluation pairs image k with draw k of one such batch (S4.3.1: "paired with a sensor region
of the same size, following the pseudo-random strategy ... to ensure equal sensor representation").

Sensor coordinates follow ``imaging.scene``: pixels from the top-left corner, x right, y down; mm on the
image surface with Y up and the optical axis at the sensor centre.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from lensopt.errors import LensoptError
from lensopt.imaging.scene import Region, Sensor

__all__ = ["TileGrid", "tile_grid", "stratified_draw", "RegionSampler", "ring_of"]


@dataclass(frozen=True)
class TileGrid:
    """Non-overlapping ``patch``-sized tiles of a sensor, sorted by distance from the centre.

    Attributes (N tiles, index = rank by distance, 0 = most central):
        sensor: the sensor.
        patch: tile size in sensor pixels (height, width).
        cols, rows: the grid (columns × rows of whole tiles).
        col, row: ``[N]`` int64 grid position of each tile.
        origin_px: ``[N, 2]`` float64 top-left corner (x, y) in sensor pixels.
        center_px: ``[N, 2]`` float64 centre (x, y) in sensor pixels.
        center_mm: ``[N, 2]`` float64 centre (X, Y) in mm on the image surface.
        radius_mm: ``[N]`` float64 distance of the centre from the optical axis.
        radius_rel: ``[N]`` radius / largest tile-centre radius, in [0, 1].
    """

    sensor: Sensor
    patch: tuple[int, int]
    cols: int
    rows: int
    col: torch.Tensor
    row: torch.Tensor
    origin_px: torch.Tensor
    center_px: torch.Tensor
    center_mm: torch.Tensor
    radius_mm: torch.Tensor
    radius_rel: torch.Tensor

    def __len__(self) -> int:
        return int(self.col.numel())

    def region(self, index: int, image_w: int | None = None, image_h: int | None = None) -> Region:
        """Tile ``index`` as an ``imaging.scene.Region`` for ``lensopt simulate``'s path (1:1 pixels by
        default: an image of the patch size covers the tile pixel for pixel)."""
        ph, pw = self.patch
        x0, y0 = (float(v) for v in self.origin_px[index])
        return Region(x0, y0, float(pw), float(ph), image_w or pw, image_h or ph,
                      f"tile:{int(self.col[index])},{int(self.row[index])}/{self.cols}x{self.rows}")


def tile_grid(sensor: Sensor, patch: int | tuple[int, int], *, option: str = "patch") -> TileGrid:
    """The sensor's tiles of ``patch`` pixels (int or (H, W)), sorted centre → corner."""
    ph, pw = (patch, patch) if isinstance(patch, int) else patch
    if ph < 1 or pw < 1:
        raise LensoptError("patch size must be positive", path=option, got=patch)
    cols, rows = sensor.width // pw, sensor.height // ph
    if cols < 1 or rows < 1:
        raise LensoptError(f"the {pw}×{ph} patch is larger than the {sensor.width}×{sensor.height} sensor",
                           path=option, got=patch)
    mx, my = (sensor.width - cols * pw) / 2, (sensor.height - rows * ph) / 2
    cc, rr = np.meshgrid(np.arange(cols), np.arange(rows))
    cc, rr = cc.ravel(), rr.ravel()
    x0, y0 = mx + cc * pw, my + rr * ph
    cx, cy = x0 + pw / 2, y0 + ph / 2
    xm, ym = (cx - sensor.width / 2) * sensor.pitch_mm, (sensor.height / 2 - cy) * sensor.pitch_mm
    # Squared distance in sensor pixels is exact (half-integer offsets), so symmetric tiles tie exactly;
    # ties broken by row, then column.
    d2 = (cx - sensor.width / 2) ** 2 + (cy - sensor.height / 2) ** 2
    rad = np.sqrt(d2) * sensor.pitch_mm
    order = np.lexsort((cc, rr, d2))
    rmax = float(rad.max())
    f64 = torch.float64
    return TileGrid(
        sensor=sensor, patch=(ph, pw), cols=cols, rows=rows,
        col=torch.as_tensor(cc[order], dtype=torch.int64), row=torch.as_tensor(rr[order], dtype=torch.int64),
        origin_px=torch.as_tensor(np.stack([x0, y0], -1)[order], dtype=f64),
        center_px=torch.as_tensor(np.stack([cx, cy], -1)[order], dtype=f64),
        center_mm=torch.as_tensor(np.stack([xm, ym], -1)[order], dtype=f64),
        radius_mm=torch.as_tensor(rad[order], dtype=f64),
        radius_rel=torch.as_tensor(rad[order] / rmax if rmax > 0 else rad[order] * 0, dtype=f64),
    )


def stratified_draw(n_tiles: int, count: int, generator: torch.Generator) -> torch.Tensor:
    """``count`` tile indices (ranks by distance) covering the field evenly, in shuffled order.

    Every tile ⌊count/N⌋ times, plus one random tile from each of ``count mod N`` contiguous strata of
    the distance-sorted list; the result is shuffled so that position carries no field information.
    """
    if n_tiles < 1 or count < 0:
        raise LensoptError("need at least one tile and a non-negative count", path="regions",
                           got=(n_tiles, count))
    full, rest = divmod(count, n_tiles)
    parts = [torch.arange(n_tiles).repeat(full)]
    if rest:
        bounds = torch.linspace(0, n_tiles, rest + 1).round().long()  # strata [b_k, b_{k+1})
        lo, hi = bounds[:-1], bounds[1:]
        pick = lo + (torch.rand(rest, generator=generator, dtype=torch.float64) * (hi - lo)).floor().long()
        parts.append(torch.minimum(pick, hi - 1))
    draw = torch.cat(parts)
    return draw[torch.randperm(draw.numel(), generator=generator)]


class RegionSampler:
    """Seeded pseudo-random sensor regions for training batches (S3.3.1).

    ``sample(B)`` returns B tile indices into ``grid`` (see ``stratified_draw``); successive calls
    continue the same seeded stream.
    """

    def __init__(self, grid: TileGrid, *, seed: int = 0) -> None:
        self.grid = grid
        self.generator = torch.Generator().manual_seed(int(seed))

    def sample(self, batch: int) -> torch.Tensor:
        if batch < 1:
            raise LensoptError("batch size must be positive", path="batch", got=batch)
        return stratified_draw(len(self.grid), batch, self.generator)


def ring_of(radius_rel: torch.Tensor | np.ndarray | float, rings: int = 4) -> np.ndarray:
    """Ring index 0 … rings−1 of relative tile radii in [0, 1] (equal steps of the relative radius)."""
    r = np.clip(np.asarray(radius_rel, dtype=np.float64), 0.0, 1.0)
    return np.minimum((r * rings).astype(np.int64), rings - 1) if rings > 0 else np.zeros_like(r, np.int64)
