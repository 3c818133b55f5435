"""Monte Carlo of a tolerance study (S6.2): random lenses drawn from the tolerances with a seed, their
metrics, the yield table with distribution-free confidence intervals, the worst trials."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from lensopt.tolerance.job import HIGHER_IS_BETTER, Job, run_trials, scalar_metric
from lensopt.tolerance.model import draw

__all__ = ["LEVELS", "MonteCarlo", "monte_carlo", "yield_table", "normal_quantile"]

LEVELS = (0.5, 0.8, 0.9, 0.95, 0.99)


def normal_quantile(p: float) -> float:
    """The standard normal quantile of ``p`` (float64)."""
    return float(torch.special.ndtri(torch.tensor(p, dtype=torch.float64)))


@dataclass
class MonteCarlo:
    """A Monte-Carlo run.

    Attributes:
        values: (K, T) drawn values.
        metrics: per-trial metrics (``evaluate``'s keys, numpy).
        metric: the scalar metric name; ``scalar``: (K,) its values.
        yields: rows of the yield table (``yield_table``).
        stats: mean, std, min, max of the scalar metric.
    """

    values: np.ndarray
    metrics: dict[str, np.ndarray]
    metric: str
    scalar: np.ndarray
    yields: list[dict[str, float]] = field(default_factory=list)
    stats: dict[str, float] = field(default_factory=dict)

    @property
    def num_trials(self) -> int:
        return int(self.scalar.shape[0])

    def worst(self, n: int) -> list[int]:
        """Indices of the n worst trials (worst first)."""
        order = np.argsort(self.scalar)
        if not HIGHER_IS_BETTER[self.metric]:
            order = order[::-1]
        return [int(i) for i in order[:n]]


def yield_table(scalar: np.ndarray, *, higher_is_better: bool, levels: tuple[float, ...] = LEVELS,
                confidence: float = 0.95) -> list[dict[str, float]]:
    """For each level p: the metric value that a fraction p of the trials meets (a quantile), with a
    distribution-free confidence interval from order statistics (binomial ranks, normal approximation).
    """
    v = np.sort(scalar)
    if higher_is_better:
        v = v[::-1]
    n = v.shape[0]
    z = normal_quantile(0.5 + confidence / 2)
    rows = []
    for p in levels:
        k = p * n
        half = z * math.sqrt(n * p * (1 - p))
        lo = int(min(max(math.floor(k - half) - 1, 0), n - 1))
        hi = int(min(max(math.ceil(k + half) - 1, 0), n - 1))
        at = int(min(max(math.ceil(k) - 1, 0), n - 1))
        a, b = float(v[lo]), float(v[hi])
        rows.append({"level": p, "value": float(v[at]), "ci_low": min(a, b), "ci_high": max(a, b)})
    return rows


def monte_carlo(job: Job, num_trials: int, seed: int, *, scheduler: str | None = None,
                workers: int = 2, on_plan: Callable[[str], None] | None = None) -> MonteCarlo:
    """``num_trials`` random lenses drawn from the tolerances with ``seed``, evaluated in chunks
    (``run_trials``)."""
    values = draw(list(job.tols), num_trials, seed)
    out = run_trials(job, values, scheduler=scheduler, workers=workers, on_plan=on_plan)
    s = scalar_metric(out, job.metric)
    finite = s[np.isfinite(s)]
    stats = {"mean": float(finite.mean()) if finite.size else math.inf,
             "std": float(finite.std(ddof=1)) if finite.size > 1 else 0.0,
             "min": float(s.min()), "max": float(s.max()),
             "trials_with_failed_rays": int((out["failed_rays"] > 0).sum()),
             "compensator_failures": int((~out["compensator_ok"]).sum())}
    return MonteCarlo(values.numpy(), out, job.metric, s,
                      yield_table(s, higher_is_better=HIGHER_IS_BETTER[job.metric]), stats)
