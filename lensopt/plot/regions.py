"""Sensor tiles and one sampled batch (the picture of seed Figure S8): tiles coloured by their
distance from the centre (relative radius 0 → 1), the batch's tiles outlined in red.

Takes the tile grid as data (any object with the fields of ``imaging.regions.TileGrid``); plot does not
import imaging (they are one layer, side by side)."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from lensopt.plot.style import RC, new_figure

__all__ = ["plot_regions"]


def plot_regions(grid: Any, batch: torch.Tensor, *, title: str = "") -> Figure:
    """``grid``'s tiles in sensor pixels (x right, y down, as on the sensor) and the tiles ``batch`` drew.

    Args:
        grid: a ``TileGrid``: ``sensor`` (width, height), ``patch``, ``cols``, ``rows`` and per-tile ``col``,
            ``row``, ``origin_px`` ``[N, 2]``, ``radius_rel`` ``[N]``.
        batch: ``[B]`` tile indices into ``grid``.
    """
    import matplotlib

    with matplotlib.rc_context(RC):
        w, h = grid.sensor.width, grid.sensor.height
        fig = new_figure(6.0, 6.0 * h / w + 0.6)
        ax = fig.add_subplot()
        img = np.full((grid.rows, grid.cols), np.nan)
        img[grid.row.numpy(), grid.col.numpy()] = grid.radius_rel.numpy()
        ph, pw = grid.patch
        x0, y0 = float(grid.origin_px[:, 0].min()), float(grid.origin_px[:, 1].min())
        im = ax.imshow(img, cmap="viridis", vmin=0, vmax=1, origin="upper",
                       extent=(x0, x0 + grid.cols * pw, y0 + grid.rows * ph, y0))
        for k in torch.unique(batch).tolist():
            ox, oy = (float(v) for v in grid.origin_px[k])
            ax.add_patch(Rectangle((ox, oy), pw, ph, fill=False, edgecolor="red", linewidth=1.5))
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        ax.set_aspect("equal")
        ax.set_xlabel("sensor x (px)")
        ax.set_ylabel("sensor y (px)")
        ax.set_title(title or f"{grid.cols}×{grid.rows} tiles of {pw}×{ph} px; {batch.numel()} sampled (red)")
        fig.colorbar(im, ax=ax, label="relative distance from the centre", shrink=0.8)
    return fig
