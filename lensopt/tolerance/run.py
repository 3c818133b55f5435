"""Sensitivity, inverse sensitivity, Monte Carlo with yields and an RSS prediction; trials in chunks,
serially or on Dask (S6.2).

Every number of a run follows from the seed: the (K, T) table of drawn values is made once, up front,
from the seed; chunks of it are evaluated in any order and on any worker (a Dask ``LocalCluster`` or an
existing scheduler) and put back in trial order, so serial and distributed runs give the same results.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from torch import Tensor

from lensopt.optics.lens import Lens, System
from lensopt.parallel import run_tasks
from lensopt.tolerance.evaluate import EvalSetup, evaluate
from lensopt.tolerance.model import Tolerance, TrialParams, draw, perturb
from lensopt.tolerance.psnr import PsnrSetup, trial_lens, trial_psnr

__all__ = ["Job", "run_trials", "sensitivity", "monte_carlo", "yield_table", "rss_prediction", "scalar_metric",
           "LEVELS", "HIGHER_IS_BETTER", "MonteCarlo", "SensitivityRow", "moments", "nominal_metrics"]

LEVELS = (0.5, 0.8, 0.9, 0.95, 0.99)
HIGHER_IS_BETTER = {"esr": False, "rms": False, "mtf": True, "distortion": False, "psnr": True}


@dataclass(frozen=True)
class Job:
    """A tolerance study: what every trial shares, the tolerances, and the data ``perturb`` needs.

    Attributes:
        setup: the evaluation setup (lens, system, pupil, compensator, MTF frequency).
        tols: the T tolerances.
        nd: (S+1,) d-line indices of the media (Abbe-number changes).
        semi_aperture: (S,) semi-apertures, mm (fringes).
        metric: the metric of the yield table and the sensitivities: esr, rms, mtf or distortion.
        chunk: trials per vmapped call.
        psnr: imaging of every trial for the ``psnr`` metric (``tolerance.psnr``), or None.
        compiled: run the vmapped evaluation under ``torch.compile`` (one compilation per process and
            chunk size, minutes on a loaded 2-core machine; then ~3× faster per trial at rings:24). The
            last chunk is padded to the chunk size so that it does not compile again.
    """

    setup: EvalSetup
    tols: tuple[Tolerance, ...]
    nd: Tensor
    semi_aperture: Tensor
    metric: str = "esr"
    chunk: int = 25
    compiled: bool = False
    psnr: PsnrSetup | None = None

    @property
    def lens(self) -> Lens:
        return self.setup.lens

    @property
    def system(self) -> System:
        return self.setup.system

    def params(self, values: Tensor) -> TrialParams:
        return perturb(self.lens, list(self.tols), values, nd=self.nd, semi_aperture=self.semi_aperture)


def scalar_metric(out: dict[str, np.ndarray], metric: str) -> np.ndarray:
    """(K,) one number per trial: ESR (µm), worst-field RMS (µm), worst MTF over fields and S/T,
    |distortion| at the full field (%), or PSNR (dB; after restoration when a network is given)."""
    if metric == "esr":
        return out["esr"] * 1e3
    if metric == "rms":
        return out["rms"].max(-1) * 1e3
    if metric == "mtf":
        if "mtf_s" not in out:
            raise ValueError("the mtf metric needs an MTF frequency")
        return np.minimum(out["mtf_s"], out["mtf_t"]).min(-1)
    if metric == "distortion":
        return np.abs(out["distortion"])
    if metric == "psnr":
        if "psnr_pre" not in out:
            raise ValueError("the psnr metric needs the imaging setup (Job.psnr)")
        return out["psnr_post"] if "psnr_post" in out else out["psnr_pre"]
    raise ValueError(f"metric must be one of {tuple(HIGHER_IS_BETTER)}, got {metric!r}")


_COMPILED: dict[int, Any] = {}


def _chunk_eval(job: Job, values: Tensor) -> dict[str, np.ndarray]:
    """Evaluate one chunk (runs on a Dask worker or in-process)."""
    k = values.shape[0]
    with torch.no_grad():
        if job.compiled:
            fn = _COMPILED.get(id(job))
            if fn is None:
                fn = _COMPILED[id(job)] = torch.compile(lambda p: evaluate(job.setup, p))
            if k < job.chunk:  # pad with copies of the last row: same shapes, no recompilation
                values = torch.cat([values, values[-1:].expand(job.chunk - k, -1)])
            out = fn(job.params(values))
        else:
            out = evaluate(job.setup, job.params(values))
    res = {name: v[:k].cpu().numpy() for name, v in out.items()}
    if job.psnr is not None:
        res.update(_chunk_psnr(job, values[:k], res))
    return res


def _chunk_psnr(job: Job, values: Tensor, res: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """PSNR of every trial of a chunk (a loop over trials: image simulation is not batched)."""
    params = job.params(values)
    lenses = [trial_lens(job.lens, job.setup.placement, params.select(slice(i, i + 1)), float(res["focus_shift"][i]),
                         res["lm_offsets"][i] if "lm_offsets" in res else None, job.psnr)
              for i in range(values.shape[0])]
    return trial_psnr(job.psnr, lenses)


def run_trials(job: Job, values: Tensor, *, scheduler: str | None = None, workers: int = 2,
               on_plan: Callable[[str], None] | None = None) -> dict[str, np.ndarray]:
    """Metrics of the trials in ``values`` ((K, T)), chunk by chunk.

    Args:
        scheduler: None (serial, in this process), ``auto`` (serial unless the chunks left after the
            first are worth a cluster, ``lensopt.parallel``), ``local`` (a fresh Dask LocalCluster with
            ``workers`` single-threaded worker processes) or a scheduler address (``tcp://…``).
        on_plan: told in words how the chunks run.
    """
    chunks = [values[i:i + job.chunk] for i in range(0, values.shape[0], job.chunk)]
    parts = run_tasks(_chunk_eval, chunks, shared=job, scheduler=scheduler, workers=workers, on_plan=on_plan)
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


# --------------------------------------------------------------------------------- sensitivity


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
            **{f"p{int(p * 100)}": mean + sign * _z(p) * std for p in LEVELS}}


def _z(p: float) -> float:
    return float(torch.special.ndtri(torch.tensor(p, dtype=torch.float64)))


# --------------------------------------------------------------------------------- Monte Carlo


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
    z = _z(0.5 + confidence / 2)
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


def nominal_metrics(job: Job) -> dict[str, np.ndarray]:
    """The nominal lens's metrics with the compensator (one trial of zeros)."""
    return run_trials(job, torch.zeros(1, len(job.tols), dtype=torch.float64))
