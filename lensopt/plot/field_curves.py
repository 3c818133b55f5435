"""Field curves: astigmatic field curves (tangential solid, sagittal dashed, one colour per wavelength),
real chief-ray distortion, and lateral colour, each against the field angle on the vertical axis, as
Zemax's "field curvature / distortion" window draws them."""

from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from lensopt.analysis.field_curves import FieldCurves
from lensopt.plot.style import RC, new_figure, wavelength_color

__all__ = ["field_curves_figure"]


def _symmetric(ax, values: np.ndarray, floor: float) -> None:
    v = values[np.isfinite(values)]
    top = max(float(np.abs(v).max()) if v.size else 0.0, floor) * 1.1
    ax.set_xlim(-top, top)


def field_curves_figure(fc: FieldCurves, *, title: str = "", subtitle: str = "", airy_um: float | None = None
                        ) -> Figure:
    """Three panels of ``fc`` (from :func:`lensopt.analysis.field_curves.field_curves`): field curvature
    (mm from the image surface), distortion (%) and lateral colour (µm, each wavelength's chief ray minus
    the reference wavelength's; the Airy radius ``airy_um`` is shaded for scale)."""
    ang = fc.field_deg.detach().cpu().numpy()
    valid = fc.valid.cpu().numpy()
    tan = np.where(valid, fc.tangential_mm.detach().cpu().numpy(), np.nan)
    sag = np.where(valid, fc.sagittal_mm.detach().cpu().numpy(), np.nan)
    lat = 1e3 * np.where(valid, fc.lateral_color_mm.detach().cpu().numpy(), np.nan)
    dist = 100.0 * fc.distortion.detach().cpu().numpy()
    wl = 1e3 * fc.wavelength_um.cpu().numpy()
    num_w = wl.shape[0]
    top = max(float(ang.max()), 1e-9)
    with matplotlib.rc_context(RC):
        fig = new_figure(11.0, 4.4)
        ax_f, ax_d, ax_l = fig.subplots(1, 3, sharey=True)
        for w in range(num_w):
            c = wavelength_color(wl[w])
            lw = 1.5 if w == fc.reference else 1.0
            ax_f.plot(tan[:, w], ang, color=c, lw=lw)
            ax_f.plot(sag[:, w], ang, color=c, lw=lw, ls="--")
            if w != fc.reference:
                ax_l.plot(lat[:, w], ang, color=c, lw=lw)
        ax_l.axvline(0.0, color=wavelength_color(wl[fc.reference]), lw=1.5)
        _symmetric(ax_f, np.concatenate([tan.ravel(), sag.ravel()]), 1e-3)
        ax_f.set_xlabel("focus from the image surface (mm)")
        ax_f.set_ylabel("field angle (°)")
        ax_f.set_title("Field curvature   T solid · S dashed")
        ax_d.plot(dist, ang, color="black", lw=1.3)
        _symmetric(ax_d, dist, 0.01)
        ax_d.set_xlabel("distortion (%)")
        ax_d.set_title("Distortion (real chief ray vs paraxial)")
        if airy_um is not None:
            ax_l.axvspan(-airy_um, airy_um, color="0.96", zorder=0)
            ax_l.text(airy_um, 0.01 * top, "Airy\nradius ", fontsize=7, color="0.45", va="bottom", ha="right")
        _symmetric(ax_l, np.concatenate([lat.ravel(), [airy_um or 0.0]]), 0.1)
        ax_l.set_xlabel("lateral colour (µm)")
        ax_l.set_title(f"Lateral colour (vs {wl[fc.reference]:g} nm)")
        for ax in (ax_f, ax_d, ax_l):
            ax.axvline(0.0, color="0.6", lw=0.7, zorder=1)
            ax.set_ylim(0.0, top)
            ax.grid(True, color="0.93", lw=0.5)
            for side in ("top", "right"):
                ax.spines[side].set_visible(False)
        handles = [Line2D([], [], color=wavelength_color(w), lw=1.5,
                          label=f"{w:g} nm" + (" (ref)" if i == fc.reference else "")) for i, w in enumerate(wl)]
        fig.legend(handles=handles, loc="outside lower center", ncol=min(num_w, 8), frameon=False)
        fig.suptitle("\n".join(x for x in (title or "Field curves", subtitle) if x), fontsize=10)
    return fig
