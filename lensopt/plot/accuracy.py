"""Accuracy vs time (``lensopt accuracy``): error against wall time on log axes, one curve per knob,
one panel per error metric, the Pareto front dashed. Takes the plain result of
``lensopt.qa.accuracy.AccuracyResult.as_json``; measures nothing."""

from __future__ import annotations

from typing import Any

from matplotlib.figure import Figure

from lensopt.plot.style import field_color, new_figure

__all__ = ["accuracy_figure"]

LABELS = {"esr": "ESR relative error", "rms": "worst-field RMS relative error",
          "aim": "ESR error of full aiming (vs 12 steps)", "psf": "PSF NRMSE vs FFT",
          "sim": "simulated-image RMSE", "wfe": "RMS wavefront error, relative",
          "zernike": "Zernike coefficients (max |Δc|/max |c|)", "strehl": "Strehl ratio, absolute",
          "seidel": "Seidel sums (closed form)", "field": "field curvature, relative",
          "focal": "focal shift curve, relative", "ee": "encircled energy error", "mtf": "MTF, absolute"}


def accuracy_figure(result: dict[str, Any], *, title: str = "") -> Figure:
    metrics = [m for m in LABELS if any(m in p["errors"] for p in result["points"])]
    cols = min(3, max(1, len(metrics)))
    rows = -(-max(1, len(metrics)) // cols)
    fig = new_figure(4.4 * cols, 3.6 * rows)
    axes = list(fig.subplots(rows, cols, squeeze=False).flat)
    for ax in axes[len(metrics):]:
        ax.set_visible(False)
    target = result.get("target")
    for ax, m in zip(axes, metrics, strict=False):
        knobs = list(dict.fromkeys(p["knob"] for p in result["points"] if m in p["errors"]))
        for i, k in enumerate(knobs):
            # In sweep order (rays, grid size ...): timings of cheap settings are noisy, the order is not.
            pts = [p for p in result["points"] if p["knob"] == k and m in p["errors"]]
            ax.plot([p["time_s"] for p in pts], [max(p["errors"][m], 1e-16) for p in pts], "o-", ms=3, lw=1,
                    color=field_color(i), label=k)
        front = result.get("pareto", {}).get(m, [])
        if front:
            ax.plot([p["time_s"] for p in front], [max(p["errors"][m], 1e-16) for p in front], "k--", lw=0.8,
                    label="Pareto front")
        if target is not None and m in ("esr", "rms"):
            ax.axhline(target, color="0.5", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel(LABELS[m])
        ax.grid(True, which="both", lw=0.3, color="0.85")
        ax.legend(loc="best")
    if title:
        fig.suptitle(title)
    return fig
