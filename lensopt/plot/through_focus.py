"""Through-focus MTF: the tangential (solid) and sagittal (dashed) MTF at one frequency per panel
against the image-surface shift, one colour per field, the best focus of each curve marked (▼), the legend
under the panels."""

from __future__ import annotations

import matplotlib
from matplotlib.figure import Figure

from lensopt.analysis.mtf_field import ThroughFocus
from lensopt.plot.style import RC, field_color, new_figure

__all__ = ["through_focus_figure"]


def through_focus_figure(tf: ThroughFocus, *, title: str = "", subtitle: str = "") -> Figure:
    """Draw ``tf`` (from :func:`lensopt.analysis.mtf_field.through_focus_mtf`)."""
    z_um = 1e3 * tf.focus_mm.detach().cpu().numpy()
    sag = tf.sagittal.detach().cpu().numpy()  # (Z, F, K)
    tan = tf.tangential.detach().cpu().numpy()
    nus = tf.frequency.tolist()
    with matplotlib.rc_context(RC):
        fig = new_figure(1.0 + 5.0 * len(nus), 4.4)
        axes = fig.subplots(1, len(nus), sharey=True, squeeze=False)[0]
        for k, (ax, nu) in enumerate(zip(axes, nus, strict=True)):
            for f in range(tan.shape[1]):
                c = field_color(f)
                ax.plot(z_um, tan[:, f, k], color=c, lw=1.4, label=f"{float(tf.field_deg[f]):.2f}° T")
                ax.plot(z_um, sag[:, f, k], color=c, lw=1.4, ls="--", label=f"{float(tf.field_deg[f]):.2f}° S")
            best = 1e3 * tf.best_focus_mm[:, k].detach().cpu().numpy()  # (F, 2): sagittal, tangential
            inside = (best > z_um.min()) & (best < z_um.max())  # a maximum at a sweep end is not a best focus
            for f in range(tan.shape[1]):
                pts = [(best[f, 1], tan[:, f, k].max(), inside[f, 1]), (best[f, 0], sag[:, f, k].max(), inside[f, 0])]
                xs, ys = [p[0] for p in pts if p[2]], [p[1] for p in pts if p[2]]
                ax.scatter(xs, ys, color=field_color(f), marker="v", s=22, zorder=4, edgecolors="none")
            ax.axvline(0.0, color="0.55", lw=0.7)
            ax.set_xlim(float(z_um.min()), float(z_um.max()))
            ax.set_ylim(0.0, 1.02)
            ax.set_xlabel("image-surface shift (µm)")
            ax.set_title(f"{nu:g} cycles/mm")
            ax.grid(True, color="0.93", lw=0.5)
            for side in ("top", "right"):
                ax.spines[side].set_visible(False)
        axes[0].set_ylabel("modulation")
        fig.legend(*axes[0].get_legend_handles_labels(), ncol=min(2 * tan.shape[1], 6), loc="outside lower center",
                   frameon=False)  # outside: no curve hides behind it
        note = f"{tf.method} MTF · polychromatic · positive shift: away from the lens · ▼ best focus"
        fig.suptitle("\n".join(x for x in (title or "Through-focus MTF", subtitle, note) if x), fontsize=10)
    return fig
