"""MTF against field: the tangential (solid) and sagittal (dashed) MTF at a few spatial frequencies
(one colour each) over the field angle."""

from __future__ import annotations

import matplotlib
from matplotlib.figure import Figure

from lensopt.analysis.mtf_field import MtfField
from lensopt.plot.style import RC, field_color, new_figure

__all__ = ["mtf_field_figure"]


def mtf_field_figure(res: MtfField, *, title: str = "", subtitle: str = "") -> Figure:
    """Draw ``res`` (from :func:`lensopt.analysis.mtf_field.mtf_vs_field`)."""
    ang = res.field_deg.detach().cpu().numpy()
    sag = res.sagittal.detach().cpu().numpy()
    tan = res.tangential.detach().cpu().numpy()
    with matplotlib.rc_context(RC):
        fig = new_figure(6.0, 4.4)
        ax = fig.add_subplot()
        for k, nu in enumerate(res.frequency.tolist()):
            c = field_color(k)
            ax.plot(ang, tan[:, k], color=c, lw=1.4, label=f"{nu:g} c/mm T")
            ax.plot(ang, sag[:, k], color=c, lw=1.4, ls="--", label=f"{nu:g} c/mm S")
        ax.set_xlim(0.0, max(float(ang.max()), 1e-9))
        ax.set_ylim(0.0, 1.02)
        ax.set_xlabel("field angle (°)")
        ax.set_ylabel("modulation")
        ax.grid(True, color="0.93", lw=0.5)
        for side in ("top", "right"):
            ax.spines[side].set_visible(False)
        fig.legend(*ax.get_legend_handles_labels(), ncol=min(2 * len(res.frequency), 6), loc="outside lower center",
                   frameon=False)  # outside: no curve hides behind it
        note = f"{res.method} MTF · polychromatic · cutoff {res.cutoff:.4g} c/mm"
        fig.suptitle("\n".join(x for x in (title or "MTF vs field", subtitle, note) if x), fontsize=10)
    return fig
