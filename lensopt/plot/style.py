"""Shared look of lensopt figures: wavelength and field colours, scale bars, atomic saving.

Figures are built as ``matplotlib.figure.Figure`` objects (no pyplot, so no global figure state and
no GUI backend); ``savefig`` renders them with Agg or the vector backend the file suffix asks for.
"""

from __future__ import annotations

import math
import os

from matplotlib.axes import Axes
from matplotlib.figure import Figure

from lensopt.files import atomic_path

__all__ = ["contrast_on_white", "relative_luminance", "wavelength_color", "field_color", "nice_length", "add_scale_bar",
           "save_figure", "new_figure"]

#: Field colours of layouts (colour-blind-safe Okabe–Ito palette: blue, bluish green, vermillion, ...).
FIELD_COLORS = ("#0072B2", "#009E73", "#D55E00", "#CC79A7", "#E69F00", "#56B4E9", "#000000", "#F0E442")

RC = {
    "font.size": 9,
    "axes.titlesize": 9,
    "axes.labelsize": 9,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "legend.fontsize": 8,
    "axes.linewidth": 0.8,
}


def new_figure(width_in: float, height_in: float) -> Figure:
    """A figure with lensopt's font sizes, independent of the user's matplotlibrc."""
    fig = Figure(figsize=(width_in, height_in), dpi=100, layout="constrained")
    return fig


#: Least WCAG contrast ratio of a wavelength colour against the white figure background (3:1 is WCAG's
#: minimum for graphics; a small margin above it).
MIN_CONTRAST = 3.2


def relative_luminance(rgb: tuple[float, float, float]) -> float:
    """WCAG 2 relative luminance of an sRGB colour (components 0…1)."""
    lin = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in rgb]
    return 0.2126 * lin[0] + 0.7152 * lin[1] + 0.0722 * lin[2]


def contrast_on_white(rgb: tuple[float, float, float]) -> float:
    """WCAG 2 contrast ratio of ``rgb`` against white: (1 + 0.05) / (L + 0.05), 1 … 21."""
    return 1.05 / (relative_luminance(rgb) + 0.05)


def wavelength_color(nm: float) -> tuple[float, float, float]:
    """An RGB colour for a wavelength in nm: the visible spectrum (after D. Bruton's approximation),
    darkened (same hue) until its contrast against white is at least ``MIN_CONTRAST`` (the yellows and
    greens of 540–600 nm are otherwise nearly invisible on white); below 380 nm violet, above 700 nm dark red."""
    w = min(max(nm, 380.0), 700.0)
    if w < 440:
        r, g, b = (440 - w) / 60, 0.0, 1.0
    elif w < 490:
        r, g, b = 0.0, (w - 440) / 50, 1.0
    elif w < 510:
        r, g, b = 0.0, 1.0, (510 - w) / 20
    elif w < 580:
        r, g, b = (w - 510) / 70, 1.0, 0.0
    elif w < 645:
        r, g, b = 1.0, (645 - w) / 65, 0.0
    else:
        r, g, b = 1.0, 0.0, 0.0
    if nm > 700:  # infrared: darker with distance
        fade = max(0.45, 1.0 - (nm - 700) / 600)
        r, g, b = r * fade, g * fade, b * fade
    r, g, b = r * 0.92, g * 0.92, b * 0.92
    if contrast_on_white((r, g, b)) >= MIN_CONTRAST:
        return (r, g, b)
    lo, hi = 0.0, 1.0  # scale factor: contrast falls as the factor grows; bisect for the largest that passes
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if contrast_on_white((r * mid, g * mid, b * mid)) >= MIN_CONTRAST:
            lo = mid
        else:
            hi = mid
    return (r * lo, g * lo, b * lo)


def field_color(i: int) -> str:
    return FIELD_COLORS[i % len(FIELD_COLORS)]


def nice_length(target: float) -> float:
    """The largest 1, 2 or 5 × 10^k not above ``target`` (> 0)."""
    if not target > 0 or not math.isfinite(target):
        return 1.0
    k = math.floor(math.log10(target))
    for m in (5.0, 2.0, 1.0):
        if m * 10**k <= target:
            return m * 10**k
    return 10.0**k


def format_length_um(value_um: float) -> str:
    """``20 µm``, ``0.5 µm``, ``1.5 mm``: a scale-bar label."""
    if value_um >= 1000:
        return f"{value_um / 1000:g} mm"
    return f"{value_um:g} µm"


def add_scale_bar(ax: Axes, length: float, label: str, *, x0: float, y0: float, color: str = "black") -> None:
    """A horizontal bar of ``length`` data units starting at (x0, y0), label centred above it."""
    ax.plot([x0, x0 + length], [y0, y0], color=color, lw=2.0, solid_capstyle="butt", zorder=5)
    ax.text(x0 + length / 2, y0, label, ha="center", va="bottom", fontsize=8, color=color, zorder=5)


def save_figure(fig: Figure, path: str | os.PathLike[str], *, dpi: int = 150) -> None:
    """Write ``fig`` to ``path`` atomically (temp file + rename); the suffix picks the format."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, facecolor="white", bbox_inches="tight", pad_inches=0.12)
