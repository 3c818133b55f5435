"""Field curves: distortion (S48) and relative illumination (S51, S52) against field angle.

Takes a ``FieldSummary`` (analysis results); traces nothing. Written atomically.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from lensopt.analysis.field import FieldSummary  # noqa: E402
from lensopt.io.files import atomic_path  # noqa: E402

__all__ = ["field_figure", "plot_field"]


def field_figure(s: FieldSummary, *, title: str = "") -> Figure:
    """Two panels: distortion in % and relative illumination (S51, S52) against the field angle."""
    angle = s.angle_deg.cpu().numpy()
    fig, (ax_d, ax_r) = plt.subplots(1, 2, figsize=(10, 4.2), layout="constrained")
    ax_d.plot(100.0 * s.distortion.cpu().numpy(), angle, color="tab:blue")
    ax_d.axvline(0.0, color="0.6", lw=0.8)
    ax_d.set_xlabel("distortion (%)  (S48: centroid vs paraxial height)")
    ax_d.set_ylabel("field angle (°)")
    ax_d.set_ylim(0.0, max(float(angle.max()), 1e-9))
    ax_d.set_title("Distortion")
    ax_r.plot(angle, s.ri_three_ray.cpu().numpy(), label="three rays (S51)", color="tab:orange")
    ax_r.plot(angle, s.ri_std.cpu().numpy(), label="all rays, std (S52)", color="tab:green", ls="--")
    ax_r.set_xlabel("field angle (°)")
    ax_r.set_ylabel("relative illumination")
    ax_r.set_xlim(0.0, max(float(angle.max()), 1e-9))
    ax_r.set_ylim(0.0, max(1.05, float(max(s.ri_three_ray.max(), s.ri_std.max())) * 1.05))
    ax_r.grid(alpha=0.3)
    ax_r.legend(loc="lower left")
    ax_r.set_title("Relative illumination")
    if title:
        fig.suptitle(title)
    return fig


def plot_field(s: FieldSummary, path: str | Path, *, title: str = "") -> None:
    """Write ``field_figure`` to ``path`` (format from the suffix), atomically."""
    fig = field_figure(s, title=title)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=130)
    finally:
        plt.close(fig)
