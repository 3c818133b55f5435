"""A tolerance study of a built spec as plain data (``lensopt tolerance``): the nominal metrics, the
sensitivity table with its inverse and RSS prediction, the Monte Carlo with yields, and with an output
folder the worst trials written as lens specs and the figures (CDF, histogram, sensitivity)."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lensopt.design.tolerance import tolerance_job, trial_spec
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.spec.build import Model
from lensopt.spec.io import save_json
from lensopt.tolerance.job import HIGHER_IS_BETTER, Job, nominal_metrics, scalar_metric
from lensopt.tolerance.monte_carlo import MonteCarlo, monte_carlo
from lensopt.tolerance.sensitivity import SensitivityRow, rss_prediction, sensitivity

__all__ = ["METRIC_UNITS", "tolerance_report", "write_worst"]

METRIC_UNITS = {"esr": "µm", "rms": "µm", "mtf": "", "distortion": "%", "psnr": "dB"}


def tolerance_report(model: Model, settings: Any, *, scheduler: str | None, workers: int, out_dir: Path | None,
                     worst: int, inverse_delta: float | None, sensitivity: bool = True,
                     compiled: bool = False, restore: Any = None, engine: Engine | None = None) -> dict[str, Any]:
    """Run sensitivity and Monte Carlo; write plots and worst trials under ``out_dir``; plain data.
    ``restore``: the restoration hook of the psnr metric (``--irm``)."""
    job = tolerance_job(model, settings, restore=restore, engine=engine)
    if compiled:
        import dataclasses

        job = dataclasses.replace(job, compiled=True)
    unit = METRIC_UNITS[job.metric]
    nominal = nominal_metrics(job)
    m0 = float(scalar_metric(nominal, job.metric)[0])
    if not math.isfinite(m0):
        raise LensoptError(f"the nominal {job.metric} cannot be computed: {_why_not_finite(job, m0)}",
                           path="tolerance.metric", got=m0)
    report: dict[str, Any] = {
        "lens": model.spec.name, "metric": job.metric, "unit": unit, "higher_is_better": HIGHER_IS_BETTER[job.metric],
        "sampling": settings.sampling, "compensator": settings.compensator, "seed": settings.seed,
        "aim": settings.aim,
        "fields": (model.system.rel_field if job.setup.field_xy is None else job.setup.field_xy.tolist()),
        "nominal": {"value": m0, "focus_shift_mm": float(nominal["focus_shift"][0]),
                    "esr_um": float(nominal["esr"][0] * 1e3),
                    **{f"{k}_db": float(nominal[k][0]) for k in ("psnr_pre", "psnr_post") if k in nominal}},
        "tolerances": [{"name": t.name, "kind": t.kind, "target": t.target, "limit": t.limit,
                        "distribution": t.distribution} for t in job.tols],
    }
    rows: list[SensitivityRow] = []
    if sensitivity:
        rows = _sensitivity(job, nominal, m0, inverse_delta, report)
    if settings.trials > 0:
        start = time.perf_counter()
        plan: list[str] = []
        mc = monte_carlo(job, settings.trials, settings.seed, scheduler=scheduler, workers=workers,
                         on_plan=plan.append)
        elapsed = time.perf_counter() - start
        per = {k: _describe(v) for k, v in mc.metrics.items() if v.ndim == 1 and k != "compensator_ok"}
        report["monte_carlo"] = {"trials": mc.num_trials, "seconds": elapsed,
                                 "seconds_per_trial": elapsed / mc.num_trials,
                                 "scheduler": plan[-1] if plan else scheduler or "serial", "stats": mc.stats,
                                 "yields": mc.yields,
                                 "metrics": per}
        if out_dir is not None:
            out_dir.mkdir(parents=True, exist_ok=True)
            report["worst"] = write_worst(model, job, mc, worst, out_dir)
            _plots(out_dir, report, mc, rows, job.metric, unit, model.spec.name)
    elif out_dir is not None and rows:
        out_dir.mkdir(parents=True, exist_ok=True)
        _plots(out_dir, report, None, rows, job.metric, unit, model.spec.name)
    return report


def _why_not_finite(job: Job, m0: float) -> str:
    """Why the nominal metric ``m0`` is not a finite number (one line)."""
    if job.metric == "psnr" and job.psnr is not None:
        if m0 == math.inf:
            return ("the nominal captures equal their scenes (PSNR ∞): the lens blurs less than a pixel at "
                    "tolerance.psnr_patch; add noise (tolerance.psnr_noise) or score another metric")
        from lensopt.tolerance.psnr import psnr_failure

        return psnr_failure(job.psnr, job.lens) or "the nominal lens could not be imaged"
    return "the nominal lens's rays fail (trace it with lensopt trace)"


def _sensitivity(job: Job, nominal: dict[str, np.ndarray], m0: float, inverse_delta: float | None,
                 report: dict[str, Any]) -> list[SensitivityRow]:
    """The sensitivity rows (worst first); their table, inverse target and RSS prediction go into ``report``."""
    rows, target = sensitivity(job, nominal, target=inverse_delta, scheduler=None)
    report["sensitivity"] = [{"name": r.name, "kind": r.kind, "limit": r.limit, "minus": r.minus, "plus": r.plus,
                              "focus_minus_mm": r.focus_minus, "focus_plus_mm": r.focus_plus,
                              "inverse": r.inverse, "failed_rays": r.failed_rays} for r in rows]
    report["inverse_target"] = target
    report["rss"] = rss_prediction(rows, job.tols, m0, higher_is_better=HIGHER_IS_BETTER[job.metric])
    return rows


def write_worst(model: Model, job: Job, mc: MonteCarlo, worst: int, out_dir: Path) -> list[dict[str, Any]]:
    """The ``worst`` worst trials of ``mc`` written as lens specs under ``out_dir`` (compensators applied);
    returns (trial, value, path) records, worst first."""
    saved = []
    for rank, k in enumerate(mc.worst(worst)):
        params = job.params(torch.from_numpy(mc.values[k:k + 1]))
        offsets = mc.metrics["lm_offsets"][k] if "lm_offsets" in mc.metrics else None
        dz = float(mc.metrics["focus_shift"][k])
        if job.psnr is not None:  # imaged with the compensators relative to the nominal's
            dz -= job.psnr.focus_reference
            if offsets is not None and job.psnr.lm_reference is not None:
                offsets = offsets - np.asarray(job.psnr.lm_reference)
        spec = trial_spec(model, params, dz, name=f"{model.spec.name} — tolerance trial {k} (rank {rank + 1} worst)",
                          lm_vars=job.setup.lm_vars, lm_offsets=offsets)
        path = out_dir / f"worst_{rank + 1}_trial_{k}.json"
        save_json(spec, path)
        saved.append({"trial": k, "value": float(mc.scalar[k]), "path": str(path)})
    return saved


def _describe(v: Any) -> dict[str, float]:
    v = np.asarray(v, dtype=float)
    f = v[np.isfinite(v)]
    if f.size == 0:
        return {"mean": math.inf, "std": 0.0, "min": math.inf, "max": math.inf}
    return {"mean": float(f.mean()), "std": float(f.std(ddof=1)) if f.size > 1 else 0.0, "min": float(v.min()),
            "max": float(v.max())}


def _plots(out_dir: Path, report: dict[str, Any], mc: Any, rows: list[Any], metric: str, unit: str,
           name: str) -> None:
    higher = bool(report["higher_is_better"])
    from lensopt.plot.style import save_figure
    from lensopt.plot.tolerance import cdf_figure, histogram_figure, sensitivity_figure

    label = f"{metric} ({unit})" if unit else metric
    files = []
    if mc is not None:
        rss = report.get("rss")
        pred = (rss["mean"], rss["std"]) if rss else None
        m0 = report["nominal"]["value"]
        save_figure(cdf_figure(mc.scalar, metric=label, nominal=m0, title=name, predicted=pred,
                                       higher_is_better=higher), out_dir / "cdf.png")
        save_figure(histogram_figure(mc.scalar, metric=label, nominal=m0, title=name), out_dir / "histogram.png")
        files += ["cdf.png", "histogram.png"]
    if rows:
        save_figure(sensitivity_figure([r.name for r in rows], [r.minus for r in rows], [r.plus for r in rows],
                                       metric=label, title=name), out_dir / "sensitivity.png")
        files.append("sensitivity.png")
    report["plots"] = [str(out_dir / f) for f in files]
