"""Tolerancing figures: cumulative probability of the metric (Monte Carlo, with the RSS prediction),
its histogram, and the sensitivity bars (metric change at −/+ limit per tolerance)."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from lensopt.plot.style import new_figure

__all__ = ["cdf_figure", "histogram_figure", "sensitivity_figure"]


def cdf_figure(values: np.ndarray, *, metric: str, nominal: float, title: str,
               predicted: tuple[float, float] | None = None, higher_is_better: bool = False) -> Figure:
    """Empirical cumulative probability of ``values`` (finite ones), nominal marked; ``predicted``
    (mean, std) draws the normal CDF of the RSS prediction. ``higher_is_better`` (MTF, PSNR): the
    probability of at least the value (the yield), P(metric ≥ x), instead of P(metric ≤ x)."""
    fig = new_figure(5.5, 3.8)
    ax = fig.add_subplot()
    v = np.sort(values[np.isfinite(values)])
    p = np.arange(1, v.size + 1) / max(v.size, 1)
    if higher_is_better:  # P(metric ≥ v_i) = (n − i) / n for the sorted v_i (i from 0)
        p = (v.size - np.arange(v.size)) / max(v.size, 1)
    ax.step(v, 100 * p, where="pre" if higher_is_better else "post", color="#0072B2", lw=1.4,
            label=f"Monte Carlo ({values.size} trials)")
    ax.axvline(nominal, color="0.3", ls="--", lw=0.8, label="nominal (compensated)")
    if predicted is not None and predicted[1] > 0:
        from math import erf, sqrt

        x = np.linspace(v.min() if v.size else nominal, v.max() if v.size else nominal + 1, 200)
        cdf = [50 * (1 + erf((xi - predicted[0]) / (predicted[1] * sqrt(2)))) for xi in x]
        if higher_is_better:
            cdf = [100 - c for c in cdf]
        ax.plot(x, cdf, color="#D55E00", lw=1.0, ls=":", label="RSS prediction (normal)")
    ax.set_xlabel(metric)
    ax.set_ylabel("probability of at least (%)" if higher_is_better else "cumulative probability (%)")
    ax.set_ylim(0, 100)
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title(title)
    return fig


def histogram_figure(values: np.ndarray, *, metric: str, nominal: float, title: str) -> Figure:
    fig = new_figure(5.5, 3.8)
    ax = fig.add_subplot()
    v = values[np.isfinite(values)]
    ax.hist(v, bins=max(10, min(60, int(np.sqrt(max(v.size, 1))) * 2)), color="#009E73", alpha=0.85)
    ax.axvline(nominal, color="0.3", ls="--", lw=0.8, label="nominal")
    ax.set_xlabel(metric)
    ax.set_ylabel("trials")
    ax.legend(fontsize=7)
    ax.set_title(title)
    return fig


def sensitivity_figure(names: list[str], minus: list[float], plus: list[float], *, metric: str, title: str,
                       top: int = 20) -> Figure:
    """Horizontal bars of the metric change at −limit and +limit, largest first."""
    n = min(top, len(names))
    fig = new_figure(6.0, 0.9 + 0.22 * n)
    ax = fig.add_subplot()
    y = np.arange(n)[::-1]
    ax.barh(y + 0.2, minus[:n], height=0.4, color="#56B4E9", label="−limit")
    ax.barh(y - 0.2, plus[:n], height=0.4, color="#D55E00", label="+limit")
    ax.set_yticks(y, names[:n])
    ax.axvline(0, color="0.3", lw=0.6)
    ax.set_xlabel(f"Δ {metric}")
    ax.legend(fontsize=7)
    ax.set_title(title)
    return fig
