"""2D layout: the lens in meridional section with its elements, stop, image plane and traced rays."""

from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Polygon

from lensopt.analysis.layout import Layout
from lensopt.plot.style import RC, field_color, new_figure

__all__ = ["plot_layout"]

GLASS_FACE = "#cfe3f3"
GLASS_EDGE = "#27415c"


def plot_layout(data: Layout, *, title: str | None = None, subtitle: str | None = None) -> Figure:
    """Draw ``data`` (from :func:`lensopt.analysis.layout.layout`) to scale, z to the right, y up.

    Elements are filled between their two faces (each drawn to its own semi-diameter, joined by flat
    flanges at the larger one); the aperture stop is marked by two bars at its semi-diameter (STO), a
    front aperture likewise (FA, below the axis); rays are coloured per field.
    """
    vz = data.vertex_z.numpy()
    sd = data.semi_diameter.numpy()
    py, pz, ok = data.profile_y.numpy(), data.profile_z.numpy(), data.profile_defined.numpy()
    rays, reached = data.rays.numpy(), data.reached.numpy()
    num_s = len(sd)
    img_h = float(data.image_half_height)

    fa = data.front_aperture
    z_lo = float(min(rays[..., 0].min(), pz.min(), fa[0] if fa else np.inf))
    z_hi = float(vz[-1])
    y_hi = float(max(sd.max() * 1.3, img_h, 1.3 * fa[1] if fa else 0.0))
    span_z = z_hi - z_lo
    width = 10.0
    aspect = (2.24 * y_hi) / (1.08 * span_z)  # data height / width of the axes box
    height = float(np.clip((width - 2.0) * aspect, 1.2, 9.0)) + 1.4
    with matplotlib.rc_context(RC):
        fig = new_figure(width, height)
        ax = fig.add_subplot()

        # Rays over the glass fill, under the outlines.
        handles = []
        for f in range(rays.shape[0]):
            color = field_color(f)
            for r in range(rays.shape[1]):
                keep = reached[f, r]
                ax.plot(rays[f, r, keep, 0], rays[f, r, keep, 1], color=color, lw=0.75, alpha=0.9, zorder=2)
            handles.append(Line2D([], [], color=color, lw=1.5, label=f"{float(data.field_deg[f]):.2f}°"))

        # Elements: surface s and s + 1 enclose glass.
        for s in range(num_s - 1):
            if data.glass_after[s]:
                outline = _element_outline(py[s], pz[s], ok[s], py[s + 1], pz[s + 1], ok[s + 1])
                ax.add_patch(Polygon(outline, closed=True, facecolor=GLASS_FACE, edgecolor=GLASS_EDGE,
                                     lw=1.0, zorder=1.5))
        # Every face as a crisp line, except flat dummy surfaces in air (a stop plane, say).
        for s in range(num_s):
            in_air = not data.glass_after[s] and (s == 0 or not data.glass_after[s - 1])
            if in_air and np.ptp(pz[s][ok[s]]) == 0.0:
                continue
            ax.plot(pz[s][ok[s]], py[s][ok[s]], color=GLASS_EDGE, lw=1.0, zorder=4)

        # Aperture stop: bars from the stop's semi-diameter outwards.
        s = data.stop
        h = float(sd[s])
        z_edge = float(pz[s][-1] if ok[s][-1] else vz[s])
        bar = 0.22 * h + 0.04 * y_hi
        for sign in (1.0, -1.0):
            ax.plot([z_edge, z_edge], [sign * h, sign * (h + bar)], color="black", lw=2.4,
                    solid_capstyle="butt", zorder=5)
        ax.text(z_edge, h + bar, "STO", ha="center", va="bottom", fontsize=7, zorder=5)

        # Front aperture (object space): bars from its opening outwards.
        if fa:
            fa_bar = 0.22 * fa[1] + 0.04 * y_hi
            for sign in (1.0, -1.0):
                ax.plot([fa[0], fa[0]], [sign * fa[1], sign * (fa[1] + fa_bar)], color="0.25", lw=2.0,
                        solid_capstyle="butt", zorder=5)
            ax.text(fa[0], -(fa[1] + fa_bar), "FA", ha="center", va="top", fontsize=7, zorder=5)

        # Image surface and optical axis.
        ax.plot([vz[-1], vz[-1]], [-img_h, img_h], color="black", lw=1.4, zorder=5)
        ax.text(vz[-1], img_h, "IMG", ha="center", va="bottom", fontsize=7)
        ax.axhline(0.0, color="0.45", lw=0.6, ls=(0, (8, 3, 2, 3)), zorder=1)

        ax.set_aspect("equal")
        ax.set_xlim(z_lo - 0.04 * span_z, z_hi + 0.04 * span_z)
        ax.set_ylim(-1.12 * y_hi, 1.12 * y_hi)
        ax.set_xlabel("z (mm, from surface 1)")
        ax.set_ylabel("y (mm)")
        ax.grid(True, color="0.92", lw=0.5, zorder=0)
        ax.legend(handles=handles, title="field", loc="upper left", frameon=True, framealpha=0.9,
                  bbox_to_anchor=(1.005, 1.0), borderaxespad=0.0)
        if title:
            fig.suptitle(title if not subtitle else f"{title}\n{subtitle}", fontsize=10)
    return fig


def _element_outline(y1: np.ndarray, z1: np.ndarray, ok1: np.ndarray,
                     y2: np.ndarray, z2: np.ndarray, ok2: np.ndarray) -> np.ndarray:
    """Closed (z, y) outline of an element: front face bottom → top, flange, back face top → bottom."""
    y1, z1 = y1[ok1], z1[ok1]
    y2, z2 = y2[ok2], z2[ok2]
    h = max(abs(y1).max(), abs(y2).max())
    pts: list[tuple[float, float]] = []
    pts.append((z1[0], -h))
    pts.extend(zip(z1, y1, strict=True))
    pts.append((z1[-1], h))
    pts.append((z2[-1], h))
    pts.extend(zip(z2[::-1], y2[::-1], strict=True))
    pts.append((z2[0], -h))
    return np.asarray(pts, dtype=float)
