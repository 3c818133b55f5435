"""Field curves: distortion (S48) and relative illumination (S51, S52) against field angle.

Takes a ``FieldSummary`` (analysis results); traces nothing. Save with ``plot.style.save_figure``.
"""

from __future__ import annotations

from matplotlib.figure import Figure

from lensopt.analysis.field import FieldSummary
from lensopt.plot.style import new_figure

__all__ = ["field_figure"]


def field_figure(s: FieldSummary, *, title: str = "", subtitle: str = "") -> Figure:
    """Two panels: distortion in % and relative illumination (S51, S52) against the field angle.

    Fields none of whose rays reached the image are left out of the distortion curve (nothing to
    measure); both illumination estimates are 0 there.
    """
    valid = (s.valid_fraction > 0).cpu().numpy()
    angle = s.angle_deg.cpu().numpy()
    fig = new_figure(10.0, 4.4)
    ax_d, ax_r = fig.subplots(1, 2)
    ax_d.plot(100.0 * s.distortion.cpu().numpy()[valid], angle[valid], color="tab:blue")
    ax_d.axvline(0.0, color="0.6", lw=0.8)
    ax_d.set_xlabel("distortion (%): spot centroid vs paraxial height")
    ax_d.set_ylabel("field angle (°)")
    ax_d.set_ylim(0.0, max(float(angle.max()), 1e-9))
    ax_d.set_title("Distortion")
    ax_r.plot(angle, s.ri_three_ray.cpu().numpy(), label="three rays (chief and rim rays)", color="tab:orange")
    ax_r.plot(angle, s.ri_std.cpu().numpy(), label="all rays (spread of ray directions)", color="tab:green", ls="--")
    ax_r.set_xlabel("field angle (°)")
    ax_r.set_ylabel("relative illumination")
    ax_r.set_xlim(0.0, max(float(angle.max()), 1e-9))
    top = max(s.ri_three_ray.nan_to_num(0.0).max(), s.ri_std.nan_to_num(0.0).max())
    ax_r.set_ylim(0.0, max(1.05, float(top) * 1.05))
    ax_r.grid(alpha=0.3)
    ax_r.legend(loc="lower left")
    ax_r.set_title("Relative illumination")
    if title or subtitle:
        fig.suptitle(title + (f"\n{subtitle}" if subtitle else ""), fontsize=10)
    return fig
