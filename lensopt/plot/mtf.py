"""MTF figure: sagittal (dashed) and tangential (solid) MTF against spatial frequency, one colour per
field, with the diffraction limit of the reference wavelength for comparison."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from lensopt.analysis.mtf import MtfResult
from lensopt.plot.style import FIELD_COLORS, new_figure

__all__ = ["mtf_figure"]


def mtf_figure(result: MtfResult, *, title: str, subtitle: str = "", field_deg: list[float] | None = None,
               limit: np.ndarray | None = None) -> Figure:
    """MTF curves of ``result`` (frequencies along the x axis, cycles/mm)."""
    fig = new_figure(6.0, 4.0)
    ax = fig.add_subplot()
    nu = result.frequency.detach().cpu().numpy()
    sag = result.sagittal.detach().cpu().numpy()
    tan = result.tangential.detach().cpu().numpy()
    for f in range(sag.shape[0]):
        color = FIELD_COLORS[f % len(FIELD_COLORS)]
        label = f"{field_deg[f]:.2f}°" if field_deg is not None else f"field {float(result.rel_field[f]):.2f}"
        ax.plot(nu, tan[f], color=color, lw=1.2, label=f"{label} T")
        ax.plot(nu, sag[f], color=color, lw=1.2, ls="--", label=f"{label} S")
    if limit is not None:
        ax.plot(nu, limit, color="0.4", lw=0.8, ls=":", label="diffraction limit")
    ax.set_xlim(0, float(nu.max()))
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("spatial frequency (cycles/mm)")
    ax.set_ylabel("modulation")
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.legend(ncol=2, fontsize=7, loc="upper right")
    ax.set_title(f"{title}\n{subtitle} — MTF ({result.method})" if subtitle else f"{title} — MTF ({result.method})")
    return fig
