"""Encircled energy: the polychromatic fraction of energy within a radius, one colour per field, with
the diffraction limit (the Airy pattern, 1 − J0² − J1²) for comparison and the radius of 80 % marked."""

from __future__ import annotations

import math

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from scipy.special import j0, j1

from lensopt.analysis.encircled import EnergyCurves
from lensopt.plot.style import RC, field_color, new_figure

__all__ = ["encircled_figure"]


def encircled_figure(curves: EnergyCurves, *, ensquared: bool = False, title: str = "", subtitle: str = "",
                     level: float = 0.8) -> Figure:
    """Draw ``curves`` (geometric or diffraction; ``ensquared`` draws the square half-width instead)."""
    r_um = 1e3 * curves.radius_mm.detach().cpu().numpy()
    ee = (curves.ensquared if ensquared else curves.encircled).detach().cpu().numpy()
    with matplotlib.rc_context(RC):
        fig = new_figure(6.0, 4.4)
        ax = fig.add_subplot()
        if curves.airy_radius_mm > 0 and not ensquared:
            dense = np.linspace(0.0, float(r_um.max()), 1001)
            v = 3.8317 * dense / (1e3 * curves.airy_radius_mm)  # first zero of J1 at the Airy radius
            ax.plot(dense, 1 - j0(v) ** 2 - j1(v) ** 2, color="0.45", lw=0.9, ls=":",
                    label="diffraction limit (reference λ)")
        order = np.argsort(curves.rel_field.cpu().numpy(), kind="stable")
        for i, f in enumerate(order):
            at = float(np.interp(level, ee[f], r_um)) if ee[f].max() >= level else math.nan
            label = f"{float(curves.field_deg[f]):.2f}°  ({100 * level:g} %: {at:.3g} µm)"
            ax.plot(r_um, ee[f], color=field_color(i), lw=1.4, label=label)
        ax.axhline(level, color="0.75", lw=0.6, ls="--")
        full = [float(np.interp(0.995, e, r_um)) for e in ee if e.max() >= 0.995]
        right = max(full) * 1.15 if len(full) == ee.shape[0] else float(r_um.max())
        ax.set_xlim(0.0, min(right, float(r_um.max())))
        ax.set_ylim(0.0, 1.02)
        ax.set_xlabel(("half-width of the square" if ensquared else "radius") + " (µm)")
        ax.set_ylabel(("ensquared" if ensquared else "encircled") + " energy")
        ax.grid(True, color="0.93", lw=0.5)
        for side in ("top", "right"):
            ax.spines[side].set_visible(False)
        ax.legend(loc="lower right", frameon=False)
        kind = "Ensquared" if ensquared else "Encircled"
        note = f"{curves.method} · polychromatic · Airy radius {1e3 * curves.airy_radius_mm:.3g} µm (reference λ)"
        fig.suptitle("\n".join(x for x in (title or f"{kind} energy", subtitle, note) if x), fontsize=10)
    return fig
