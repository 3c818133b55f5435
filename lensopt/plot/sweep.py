"""Design-sweep figure (seed Figure S13's form): the best ESR of every grid point against the swept
value, one line per combination of the other keys, every finished start as a faint dot (a start above twice
the best curve's maximum as a marker on the top edge, so that a stalled start does not flatten the curve)."""

from __future__ import annotations

import math

from matplotlib.figure import Figure

from lensopt.plot.style import FIELD_COLORS, new_figure

__all__ = ["sweep_figure"]


def sweep_figure(series: dict[str, list[tuple[float, float]]], starts: list[tuple[float, float]], *, xlabel: str,
                 title: str = "", ylabel: str = "ESR (µm)") -> Figure:
    """Best ESR against the swept value.

    Args:
        series: label → [(value, best ESR µm)] per point (label "" when one key is swept).
        starts: (value, ESR µm) of every finished start.
    """
    fig = new_figure(5.5, 3.8)
    ax = fig.add_subplot()
    best = [y for pts in series.values() for _, y in pts]
    top = 2.0 * max(best) if best else math.inf  # starts far above the best curve (stalled ones) would flatten it
    inside = [(x, y) for x, y in starts if y <= top]
    above = [(x, y) for x, y in starts if y > top]
    if inside:
        xs, ys = zip(*inside, strict=True)
        ax.scatter(xs, ys, s=12, color="0.55", alpha=0.35, lw=0, label="every start", zorder=1)
    if above:
        ax.scatter([x for x, _ in above], [0.97 * top] * len(above), s=18, marker="^", color="0.45", lw=0,
                   label=f"{len(above)} start(s) above {top:.3g}, up to {max(y for _, y in above):.3g}", zorder=1)
    if best:
        ax.set_ylim(0.0, top)
    for j, (label, pts) in enumerate(sorted(series.items())):
        pts = sorted(pts)
        x, y = zip(*pts, strict=True)
        ax.plot(x, y, "o-", color=FIELD_COLORS[j % len(FIELD_COLORS)], lw=1.4, ms=4,
                label=f"best of starts{': ' + label if label else ''}", zorder=2)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.legend(fontsize=7)
    if title:
        ax.set_title(title)
    return fig
