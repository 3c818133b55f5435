"""Ray-fan plots (S1.3.4, Figure S3): one row per field (largest on top), tangential fan on the left
(ε_y against py), sagittal fan on the right (ε_x against px), one colour per wavelength, one common
vertical scale, as CODE V and Zemax draw them."""

from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from lensopt.analysis.fans import RayFans
from lensopt.plot.style import RC, new_figure, wavelength_color

__all__ = ["plot_fans"]


def plot_fans(fans: RayFans, *, title: str | None = None, subtitle: str | None = None) -> Figure:
    """Draw ``fans`` (from :func:`lensopt.analysis.fans.ray_fans`); failed rays leave gaps in the curves."""
    tan_um = np.where(fans.tangential_valid.numpy(), 1e3 * fans.tangential.numpy(), np.nan)  # (F, W, T)
    sag_um = np.where(fans.sagittal_valid.numpy(), 1e3 * fans.sagittal.numpy(), np.nan)
    py, px = fans.py.numpy(), fans.px.numpy()
    wl_nm = 1e3 * fans.wavelength_um.numpy()
    num_f, num_w = tan_um.shape[:2]
    finite = np.concatenate([tan_um[np.isfinite(tan_um)], sag_um[np.isfinite(sag_um)]])
    scale = float(np.abs(finite).max()) if finite.size else 1.0
    scale = _round_up(max(scale, 1e-3))
    order = np.argsort(-fans.rel_field.numpy(), kind="stable")  # largest field on top

    with matplotlib.rc_context(RC):
        fig = new_figure(8.0, 1.0 + 1.75 * num_f)
        axes = fig.subplots(num_f, 2, sharey=True, squeeze=False)
        for row, f in enumerate(order):
            for col, (u, eps) in enumerate(((py, tan_um[f]), (px, sag_um[f]))):
                ax = axes[row, col]
                ax.axhline(0.0, color="0.55", lw=0.7, zorder=1)
                if col == 0:
                    ax.axvline(0.0, color="0.55", lw=0.7, zorder=1)
                for w in range(num_w):
                    lw = 1.5 if w == fans.reference else 1.1
                    ax.plot(u, eps[w], color=wavelength_color(wl_nm[w]), lw=lw, zorder=3)
                ax.set_ylim(-1.08 * scale, 1.08 * scale)
                ax.set_xlim(-1.04, 1.04) if col == 0 else ax.set_xlim(-0.02, 1.04)
                ax.grid(True, color="0.93", lw=0.5, zorder=0)
                for side in ("top", "right"):
                    ax.spines[side].set_visible(False)
                if row == num_f - 1:
                    ax.set_xlabel("relative pupil py" if col == 0 else "relative pupil px")
            field = float(fans.field_deg[f])
            axes[row, 0].set_ylabel(f"{field:.2f}°\n(rel. {float(fans.rel_field[f]):.2f})\nµm")
        axes[0, 0].set_title("tangential   ε_y = y − y_chief", loc="center")
        axes[0, 1].set_title("sagittal   ε_x = x − x_chief", loc="center")
        handles = [Line2D([], [], color=wavelength_color(w), lw=1.5,
                          label=f"{w:g} nm" + (" (ref)" if i == fans.reference else ""))
                   for i, w in enumerate(wl_nm)]
        fig.legend(handles=handles, loc="outside lower center", ncol=min(num_w, 6), frameon=False)
        head = title or "Ray fans"
        note = f"scale ±{scale:g} µm · relative to the {wl_nm[fans.reference]:g} nm chief ray"
        fig.suptitle("\n".join(x for x in (head, subtitle, note) if x), fontsize=10)
    return fig


def _round_up(x: float) -> float:
    """The smallest 1, 1.5, 2, 2.5, 3, 4, 5, 6 or 8 × 10^k at or above ``x`` (a readable axis limit)."""
    k = np.floor(np.log10(x))
    for m in (1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0):
        if m * 10**k >= x * (1 - 1e-12):
            return float(m * 10**k)
    return float(10 ** (k + 1))
