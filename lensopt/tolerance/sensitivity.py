"""Sensitivity of a tolerance study (S6.2): each tolerance alone at ±limit, the inverse sensitivity (the
error that costs a target change of the metric), and the RSS prediction of the Monte-Carlo distribution
from the sensitivities."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from lensopt.tolerance.job import Job, run_trials, scalar_metric
from lensopt.tolerance.model import Tolerance
from lensopt.tolerance.monte_carlo import LEVELS, normal_quantile

__all__ = ["SensitivityRow", "sensitivity", "moments", "rss_prediction"]


@dataclass(frozen=True)
class SensitivityRow:
    """One tolerance at ±limit: the change of the metric (compensated), and the inverse sensitivity.

    Attributes:
        name, kind, limit, unit: the tolerance.
        minus, plus: metric change at −limit and +limit.
        focus_minus, focus_plus: compensator shifts, mm.
        linear, quadratic: b and q of the fit Δ(x) = b x + q x² through both points.
        inverse: the |x| that costs ``target`` (inf: never within the fit).
        failed_rays: rays lost at ±limit.
    """

    name: str
    kind: str
    limit: float
    minus: float
    plus: float
    focus_minus: float
    focus_plus: float
    linear: float
    quadratic: float
    inverse: float
    failed_rays: int

    @property
    def worst(self) -> float:
        return max(abs(self.minus), abs(self.plus))


def _inverse(b: float, q: float, target: float) -> float:
    """Smallest |x| with |b x + q x²| = |target| (either sign of x)."""
    best = math.inf
    for sign in (1.0, -1.0):
        for tgt in (target, -target):
            # q x² + b x − tgt = 0 for x of the given sign.
            if abs(q) < 1e-300:
                roots = [tgt / b] if abs(b) > 1e-300 else []
            else:
                disc = b * b + 4 * q * tgt
                roots = [] if disc < 0 else [(-b + r) / (2 * q) for r in (math.sqrt(disc), -math.sqrt(disc))]
            for x in roots:
                if x * sign > 0:
                    best = min(best, abs(x))
    return best


def sensitivity(job: Job, nominal: dict[str, np.ndarray], *, target: float | None = None,
                scheduler: str | None = None, workers: int = 2) -> tuple[list[SensitivityRow], float]:
    """Each tolerance alone at −limit and +limit (2T trials, batched), sorted by the larger change.

    Args:
        nominal: the compensated nominal metrics (``run_trials`` on a zero row).
        target: metric change for the inverse sensitivity; default 10 % of the nominal metric.

    Returns:
        rows (worst first) and the target used.
    """
    num = len(job.tols)
    limits = torch.tensor([t.limit for t in job.tols], dtype=torch.float64)
    values = torch.zeros(2 * num, num, dtype=torch.float64)
    idx = torch.arange(num)
    values[2 * idx, idx] = -limits
    values[2 * idx + 1, idx] = limits
    out = run_trials(job, values, scheduler=scheduler, workers=workers)
    m = scalar_metric(out, job.metric)
    m0 = float(scalar_metric(nominal, job.metric)[0])
    target = abs(0.1 * m0) if target is None else abs(target)
    rows = []
    for t, tol in enumerate(job.tols):
        dm, dp = float(m[2 * t] - m0), float(m[2 * t + 1] - m0)
        b = (dp - dm) / (2 * tol.limit)
        q = (dp + dm) / (2 * tol.limit**2)
        inv = _inverse(b, q, target) if math.isfinite(dm) and math.isfinite(dp) else 0.0
        rows.append(SensitivityRow(tol.name, tol.kind, tol.limit, dm, dp, float(out["focus_shift"][2 * t]),
                                   float(out["focus_shift"][2 * t + 1]), b, q, inv,
                                   int(out["failed_rays"][2 * t] + out["failed_rays"][2 * t + 1])))
    rows.sort(key=lambda r: -r.worst if math.isfinite(r.worst) else -math.inf)
    return rows, target


def moments(distribution: str, limit: float) -> tuple[float, float]:
    """(E[x²], E[x⁴]) of a tolerance's distribution (see ``tolerance.model``)."""
    if distribution == "uniform":
        return limit**2 / 3.0, limit**4 / 5.0
    sigma = limit / 2.0
    if distribution == "normal":
        return sigma**2, 3.0 * sigma**4
    c = 2.0  # truncated at ±2σ
    phi = math.exp(-c * c / 2) / math.sqrt(2 * math.pi)
    z = math.erf(c / math.sqrt(2))
    return sigma**2 * (1 - 2 * c * phi / z), sigma**4 * (3 - 2 * (c**3 + 3 * c) * phi / z)


def rss_prediction(rows: list[SensitivityRow], tols: tuple[Tolerance, ...], m0: float, *,
                   higher_is_better: bool = False) -> dict[str, float]:
    """Predicted distribution of the metric from the sensitivities (independent errors).

    Statistical: with Δ_i(x) = b_i x + q_i x², mean = m0 + Σ q_i E[x²], variance =
    Σ b_i² E[x²] + q_i² (E[x⁴] − E[x²]²). Classical RSS: m0 + sqrt(Σ max(|Δ−|, |Δ+|)²) (m0 − … when
    higher is better). ``p50`` … ``p99``: the value that that fraction of lenses meets under a normal
    law (at most it; at least it when higher is better, as the yield table).
    """
    by_name = {t.name: t for t in tols}
    mean, var, rss = m0, 0.0, 0.0
    for r in rows:
        e2, e4 = moments(by_name[r.name].distribution, r.limit)
        mean += r.quadratic * e2
        var += r.linear**2 * e2 + r.quadratic**2 * (e4 - e2 * e2)
        rss += r.worst**2
    std = math.sqrt(max(var, 0.0))
    sign = -1.0 if higher_is_better else 1.0
    return {"nominal": m0, "mean": mean, "std": std, "rss_worst": m0 + sign * math.sqrt(rss),
            **{f"p{int(p * 100)}": mean + sign * normal_quantile(p) * std for p in LEVELS}}
