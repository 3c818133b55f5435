"""OPD fans: one row per field (largest on top), W along the pupil's y axis (tangential) on the left and
along its x axis (sagittal) on the right, one colour per wavelength, one common vertical scale in waves,
as Zemax and CODE V draw them. Failed rays leave gaps."""

from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from lensopt.analysis.wavefront import OpdFans
from lensopt.plot.fans import _round_up
from lensopt.plot.style import RC, new_figure, wavelength_color

__all__ = ["opd_fans_figure"]


def opd_fans_figure(fans: OpdFans, *, title: str = "", subtitle: str = "") -> Figure:
    """Draw ``fans`` (from :func:`lensopt.analysis.wavefront.opd_fans`)."""
    tan = np.where(fans.tangential_valid.cpu().numpy(), fans.tangential.detach().cpu().numpy(), np.nan)
    sag = np.where(fans.sagittal_valid.cpu().numpy(), fans.sagittal.detach().cpu().numpy(), np.nan)
    u = fans.coord.cpu().numpy()
    wl_nm = 1e3 * fans.wavelength_um.cpu().numpy()
    num_f, num_w = tan.shape[:2]
    finite = np.concatenate([tan[np.isfinite(tan)], sag[np.isfinite(sag)]])
    scale = _round_up(max(float(np.abs(finite).max()) if finite.size else 0.0, 0.01))
    order = np.argsort(-fans.rel_field.cpu().numpy(), kind="stable")
    with matplotlib.rc_context(RC):
        fig = new_figure(8.0, 1.0 + 1.75 * num_f)
        axes = fig.subplots(num_f, 2, sharey=True, squeeze=False)
        for row, f in enumerate(order):
            for col, w_curves in enumerate((tan[f], sag[f])):
                ax = axes[row, col]
                ax.axhline(0.0, color="0.55", lw=0.7, zorder=1)
                ax.axvline(0.0, color="0.55", lw=0.7, zorder=1)
                for w in range(num_w):
                    ax.plot(u, w_curves[w], color=wavelength_color(wl_nm[w]), lw=1.5 if w == fans.reference else 1.1,
                            zorder=3)
                ax.set_ylim(-1.08 * scale, 1.08 * scale)
                ax.set_xlim(-1.04, 1.04)
                ax.grid(True, color="0.93", lw=0.5, zorder=0)
                for side in ("top", "right"):
                    ax.spines[side].set_visible(False)
                if row == num_f - 1:
                    ax.set_xlabel("relative pupil py" if col == 0 else "relative pupil px")
            axes[row, 0].set_ylabel(f"{float(fans.field_deg[f]):.2f}°\n(rel. {float(fans.rel_field[f]):.2f})\nwaves")
        axes[0, 0].set_title("tangential   W(0, py)")
        axes[0, 1].set_title("sagittal   W(px, 0)")
        handles = [Line2D([], [], color=wavelength_color(w), lw=1.5,
                          label=f"{w:g} nm" + (" (ref)" if i == fans.reference else "")) for i, w in enumerate(wl_nm)]
        fig.legend(handles=handles, loc="outside lower center", ncol=min(num_w, 6), frameon=False)
        note = f"scale ±{scale:g} waves · W = OPL(chief) − OPL(ray) to the chief ray's reference sphere"
        fig.suptitle("\n".join(x for x in (title or "OPD fans", subtitle, note) if x), fontsize=10)
    return fig
