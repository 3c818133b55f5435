"""Spot diagrams: one panel per field, one colour per wavelength, centred on the field's weighted
centroid, on a common scale shown by a µm scale bar, with the Airy disc (1.22 λ N_w) for scale."""

from __future__ import annotations

import math

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle

from lensopt.analysis.spot_diagram import SpotDiagram
from lensopt.plot.style import RC, add_scale_bar, format_length_um, new_figure, nice_length, wavelength_color

__all__ = ["marker_area", "plot_spots"]


def marker_area(points: int) -> float:
    """Dot area (pt²) for a panel of ``points`` rays per wavelength: 100 / √points, between 2 and 25 pt²
    (≈ 1.6 pt dots at rings:24, twice the old 0.6 pt² floor in diameter; larger on sparse samplings), so dots
    stay visible on dense samplings without merging into one blot."""
    return float(np.clip(100.0 / math.sqrt(max(points, 1)), 2.0, 25.0))


def plot_spots(spots: SpotDiagram, *, title: str | None = None, subtitle: str | None = None) -> Figure:
    """Draw ``spots`` (from :func:`lensopt.analysis.spot_diagram.spot_diagram`).

    A half-pupil sampling (``rings``) is drawn with its mirror image x → −x (the lens is symmetric
    about the meridional plane, so the mirrored rays are the ones not traced). Failed rays are left out.
    """
    xy = spots.xy.numpy()  # (F, W, P, 2) mm
    valid = spots.valid.numpy()
    centroid = spots.stats.centroid.numpy()  # (F, 2)
    rms_um = 1e3 * spots.stats.rms_radius.numpy()
    wl_nm = 1e3 * spots.wavelength_um.numpy()
    airy_um = 1e3 * float(spots.airy_radius[spots.reference])
    num_f, num_w = xy.shape[:2]

    rel = 1e3 * (xy - centroid[:, None, None, :])  # µm about the weighted centroid
    if spots.half_pupil:
        mirrored = rel * np.array([-1.0, 1.0])
        rel = np.concatenate([rel, mirrored], axis=2)
        valid = np.concatenate([valid, valid], axis=2)
    radii = np.linalg.norm(rel, axis=-1)
    extent = float(radii[valid].max()) if valid.any() else 1.0
    half = 1.12 * max(extent, 1.3 * airy_um)
    marker = marker_area(int(valid[0].sum()) // max(num_w, 1))

    ncols = min(num_f, 4)
    nrows = math.ceil(num_f / ncols)
    order = np.argsort(spots.rel_field.numpy(), kind="stable")
    with matplotlib.rc_context(RC):
        fig = new_figure(2.9 * ncols + 0.4, 3.05 * nrows + 1.0)
        axes = fig.subplots(nrows, ncols, squeeze=False)
        for k, ax in enumerate(axes.flat):
            if k >= num_f:
                ax.set_axis_off()
                continue
            f = order[k]
            # Interleave the wavelengths (pupil sample by pupil sample) so no colour hides the others.
            pts = rel[f].transpose(1, 0, 2).reshape(-1, 2)
            keep = valid[f].T.reshape(-1)
            colors = np.tile(np.array([wavelength_color(w) for w in wl_nm]), (rel.shape[2], 1))
            ax.scatter(pts[keep, 0], pts[keep, 1], s=marker, c=colors[keep], lw=0, alpha=0.85, zorder=3,
                       rasterized=True)
            ax.add_patch(Circle((0.0, 0.0), airy_um, fill=False, color="black", lw=0.8, ls="--", zorder=4))
            ax.plot([0], [0], marker="+", color="black", ms=6, mew=0.8, zorder=5)
            ax.set_xlim(-half, half)
            ax.set_ylim(-half, half)
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            bar = nice_length(0.4 * half)
            add_scale_bar(ax, bar, format_length_um(bar), x0=-0.92 * half, y0=-0.9 * half)
            failed, total = int((~spots.valid[f]).sum()), spots.valid[f].numel()
            lost = f"\n{failed} of {total} rays failed" if failed else ""
            ybar = f"{centroid[f, 1]:.4f}".replace("-0.0000", "0.0000")
            ax.set_title(f"{float(spots.field_deg[f]):.2f}°   ȳ = {ybar} mm\n"
                         f"RMS radius {rms_um[f]:.3f} µm{lost}")
        handles = [Line2D([], [], ls="", marker="o", ms=5, color=wavelength_color(w), label=f"{w:g} nm")
                   for w in wl_nm]
        handles.append(Line2D([], [], ls="--", color="black", lw=0.8,
                              label=f"Airy radius {airy_um:.2f} µm ({wl_nm[spots.reference]:g} nm)"))
        fig.legend(handles=handles, loc="outside lower center", ncol=min(num_w + 1, 6), frameon=False)
        head = title or "Spot diagrams"
        note = (f"sampling {spots.sampling} · working f/{float(spots.working_fnumber):.2f} · "
                "centred on the weighted centroid (+)")
        fig.suptitle("\n".join(x for x in (head, subtitle, note) if x), fontsize=10)
    return fig
