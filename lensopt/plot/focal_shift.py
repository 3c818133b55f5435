"""Chromatic focal shift: the paraxial focus against wavelength (wavelength on the vertical axis, shift in
µm on the horizontal one, as Zemax draws it), the spec's wavelengths marked, the diffraction depth of
focus ±2 λ N_w² shaded for scale."""

from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib.figure import Figure

from lensopt.analysis.field_curves import FocalShift
from lensopt.plot.style import RC, new_figure, wavelength_color

__all__ = ["focal_shift_figure"]


def focal_shift_figure(fs: FocalShift, *, working_fnumber: float | None = None, title: str = "",
                       subtitle: str = "") -> Figure:
    """Draw ``fs`` (from :func:`lensopt.analysis.field_curves.chromatic_focal_shift`)."""
    lam = 1e3 * fs.wavelength_um.cpu().numpy()
    shift = 1e3 * fs.shift_mm.detach().cpu().numpy()
    spec = 1e3 * fs.spec_wavelength_um.cpu().numpy()
    with matplotlib.rc_context(RC):
        fig = new_figure(5.5, 4.4)
        ax = fig.add_subplot()
        if working_fnumber is not None:
            dof = 2.0 * fs.reference_um * working_fnumber**2  # µm
            ax.axvspan(-dof, dof, color="0.92", zorder=0, label=f"±2λN² = ±{dof:.3g} µm")
        ax.plot(shift, lam, color="black", lw=1.4, zorder=3)
        on = np.interp(spec, lam, shift)
        ax.scatter(on, spec, c=[wavelength_color(w) for w in spec], s=28, zorder=4, edgecolors="black",
                   linewidths=0.5)
        ax.axvline(0.0, color="0.55", lw=0.7)
        span = max(float(np.abs(shift).max()), 1e-3) * 1.15
        if working_fnumber is not None:
            span = max(span, 1.15 * dof)
        ax.set_xlim(-span, span)
        pad = 0.03 * float(lam.max() - lam.min()) or 1.0
        ax.set_ylim(float(lam.min()) - pad, float(lam.max()) + pad)
        ax.set_xlabel("paraxial focus shift (µm)")
        ax.set_ylabel("wavelength (nm)")
        ax.grid(True, color="0.93", lw=0.5)
        for side in ("top", "right"):
            ax.spines[side].set_visible(False)
        if working_fnumber is not None:
            ax.legend(loc="upper left", frameon=False)
        ref = f"relative to {1e3 * fs.reference_um:g} nm · max − min {float(shift.max() - shift.min()):.3g} µm"
        fig.suptitle("\n".join(x for x in (title or "Chromatic focal shift", subtitle, ref) if x), fontsize=10)
    return fig
