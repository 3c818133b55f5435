"""``lensopt tolerance`` (CLI layer: parse, call ``lensopt.tolerance``, render): sensitivity, Monte Carlo,
yields; plots and the worst trials written with ``--output-dir``."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.table import Table

from lensopt.cli.common import JsonOpt, LensArg, check_seed, console, handle_errors, load_model, print_json
from lensopt.cli.tables import compact_table, show
from lensopt.errors import LensoptError

__all__ = ["commands", "parse_fields", "tolerance_report"]

_METRIC_UNITS = {"esr": "µm", "rms": "µm", "mtf": "", "distortion": "%", "psnr": "dB"}

commands = typer.Typer()  # its commands, put in order by lensopt.cli.app


@commands.command("tolerance")
@handle_errors
def tolerance_cmd(
    lens: LensArg,
    tolerances: Annotated[Path | None, typer.Option("--tolerances", help="TOML file with a [tolerance] "
                                                    "table (default: the spec's [tolerance]).")] = None,
    profile: Annotated[str | None, typer.Option("--profile", help="Named tolerance set: s6.2.")] = None,
    trials: Annotated[int | None, typer.Option("--trials", min=0, help="Monte-Carlo trials (0: none).")] = None,
    seed: Annotated[int | None, typer.Option("--seed", callback=check_seed,
                                                 help="Seed of the draws and the pupil jitter.")] = None,
    metric: Annotated[str | None, typer.Option("--metric", help="esr | rms | mtf | distortion | psnr.")] = None,
    irm: Annotated[Path | None, typer.Option("--irm", help="Restoration network checkpoint (train-irm or "
                                             "joint): the psnr metric after restoration (implies "
                                             "--metric psnr).")] = None,
    mtf_frequency: Annotated[float | None, typer.Option("--mtf-frequency", help="cycles/mm of the MTF "
                                                        "metric.")] = None,
    sampling: Annotated[str | None, typer.Option("--sampling", help="Pupil sampling per trial.")] = None,
    fields: Annotated[str | None, typer.Option("--fields", help="y (the +y fields), xy (±x and ±y) or "
                                               "relative points x,y;x,y;… (decentered lenses).")] = None,
    aim: Annotated[str | None, typer.Option("--aim", help="none | chief: aim each trial's chief rays at "
                                            "its own (decentered) stop centre.")] = None,
    compensator: Annotated[str | None, typer.Option("--compensator", help="focus | lm | none (lm: "
                                                    "the spec's variables by a few LM steps).")] = None,
    scheduler: Annotated[str, typer.Option("--scheduler", help="auto (serial unless the trials left after "
                                           "the first chunk are estimated at 30 s or more and 2+ cores are "
                                           "free: then a LocalCluster), local (a Dask LocalCluster of "
                                           "--workers), serial, or a Dask scheduler address.")] = "auto",
    workers: Annotated[int, typer.Option("--workers", min=1, max=64, help="LocalCluster workers.")] = 2,
    output_dir: Annotated[Path | None, typer.Option("--output-dir", "-o", help="Folder for plots (CDF, "
                                                    "histogram, sensitivity) and the worst trials.")] = None,
    worst: Annotated[int, typer.Option("--worst", min=0, max=100, help="Worst trials saved as lens JSON.")] = 3,
    inverse_delta: Annotated[float | None, typer.Option("--inverse-delta", help="Metric change of the "
                                                        "inverse sensitivity (default 10 % of nominal).")] = None,
    no_sensitivity: Annotated[bool, typer.Option("--no-sensitivity", help="Skip the sensitivity table.")] = False,
    compile_: Annotated[bool, typer.Option("--compile", help="torch.compile the Monte-Carlo evaluation "
                                           "(minutes to compile; for long runs).")] = False,
    as_json: JsonOpt = False,
) -> None:
    """Tolerancing: sensitivity table, inverse sensitivity, RSS prediction, Monte Carlo with yields,
    back-focus compensator; plots and worst trials with --output-dir."""
    from lensopt.spec.io import load_tolerances
    from lensopt.spec.tolerance import ToleranceSpec

    model = load_model(lens)
    base = load_tolerances(tolerances) if tolerances is not None else model.spec.tolerance
    if base is None:
        if profile is None:
            raise LensoptError("the lens has no [tolerance] section; give --tolerances FILE or --profile s6.2",
                               path="--tolerances")
        base = ToleranceSpec(profile="s6.2")
    if irm is not None and metric is None:
        metric = "psnr"
    changes = {k: v for k, v in {"profile": profile, "trials": trials, "seed": seed, "metric": metric,
                                 "mtf_frequency": mtf_frequency, "sampling": sampling,
                                 "compensator": compensator, "aim": aim,
                                 "fields": None if fields is None else parse_fields(fields)}.items()
               if v is not None}
    try:
        settings = ToleranceSpec.model_validate({**base.model_dump(), **changes})
    except Exception as err:  # pydantic ValidationError → one line naming the option
        first = err.errors()[0] if hasattr(err, "errors") else {"loc": (), "msg": str(err)}
        where = "--" + str(first["loc"][0]).replace("_", "-") if first["loc"] else "--tolerances"
        raise LensoptError(first["msg"], path=where) from None
    sched = None if scheduler == "serial" else scheduler
    hook = None
    if irm is not None:
        if settings.metric != "psnr":
            raise LensoptError("--irm scores PSNR after restoration: use it with --metric psnr", path="--irm",
                               got=settings.metric)
        from lensopt.optim.irm_run import restoration_hook

        hook = restoration_hook(model, irm)
    report = tolerance_report(model, settings, scheduler=sched, workers=workers, out_dir=output_dir,
                              worst=worst, inverse_delta=inverse_delta, sensitivity=not no_sensitivity,
                              compiled=compile_, restore=hook)
    if as_json:
        print_json(report)
    else:
        _render(report)


def parse_fields(text: str) -> Any:
    """``--fields``: ``y``, ``xy`` or relative field points ``x,y;x,y;…``."""
    if text.strip() in ("y", "xy"):
        return text.strip()
    try:
        pts = [tuple(float(v) for v in part.split(",")) for part in text.split(";") if part.strip()]
    except ValueError:
        pts = []
    if not pts or any(len(p) != 2 or not all(map(math.isfinite, p)) for p in pts):
        raise LensoptError("expected y, xy or relative field points x,y;x,y;…", path="--fields", got=text)
    return pts


def tolerance_report(model: Any, settings: Any, *, scheduler: str | None, workers: int, out_dir: Path | None,
                     worst: int, inverse_delta: float | None, sensitivity: bool = True,
                     compiled: bool = False, restore: Any = None) -> dict[str, Any]:
    """Run sensitivity and Monte Carlo; write plots and worst trials under ``out_dir``; plain data.
    ``restore``: the restoration hook of the psnr metric (``--irm``)."""
    import numpy as np
    import torch

    from lensopt.spec.io import save_json
    from lensopt.spec.tolerance_build import make_job, trial_spec
    from lensopt.tolerance.run import (
        HIGHER_IS_BETTER,
        monte_carlo,
        nominal_metrics,
        rss_prediction,
        scalar_metric,
    )
    from lensopt.tolerance.run import sensitivity as run_sensitivity

    job = make_job(model, settings, restore=restore)
    if compiled:
        import dataclasses

        job = dataclasses.replace(job, compiled=True)
    unit = _METRIC_UNITS[job.metric]
    nominal = nominal_metrics(job)
    m0 = float(scalar_metric(nominal, job.metric)[0])
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
    rows: list[Any] = []
    if sensitivity:
        rows, target = run_sensitivity(job, nominal, target=inverse_delta, scheduler=None)
        report["sensitivity"] = [{"name": r.name, "kind": r.kind, "limit": r.limit, "minus": r.minus, "plus": r.plus,
                                  "focus_minus_mm": r.focus_minus, "focus_plus_mm": r.focus_plus,
                                  "inverse": r.inverse, "failed_rays": r.failed_rays} for r in rows]
        report["inverse_target"] = target
        report["rss"] = rss_prediction(rows, job.tols, m0, higher_is_better=HIGHER_IS_BETTER[job.metric])
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
            saved = []
            for rank, k in enumerate(mc.worst(worst)):
                params = job.params(torch.from_numpy(mc.values[k:k + 1]))
                offsets = mc.metrics["lm_offsets"][k] if "lm_offsets" in mc.metrics else None
                dz = float(mc.metrics["focus_shift"][k])
                if job.psnr is not None:  # imaged with the compensators relative to the nominal's
                    dz -= job.psnr.focus_reference
                    if offsets is not None and job.psnr.lm_reference is not None:
                        offsets = offsets - np.asarray(job.psnr.lm_reference)
                spec = trial_spec(model, params, dz,
                                  name=f"{model.spec.name} — tolerance trial {k} (rank {rank + 1} worst)",
                                  lm_vars=job.setup.lm_vars, lm_offsets=offsets)
                path = out_dir / f"worst_{rank + 1}_trial_{k}.json"
                save_json(spec, path)
                saved.append({"trial": k, "value": float(mc.scalar[k]), "path": str(path)})
            report["worst"] = saved
            _plots(out_dir, report, mc, rows, job.metric, unit, model.spec.name)
    elif out_dir is not None and rows:
        out_dir.mkdir(parents=True, exist_ok=True)
        _plots(out_dir, report, None, rows, job.metric, unit, model.spec.name)
    return report


def _describe(v: Any) -> dict[str, float]:
    import numpy as np

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


def _render(r: dict[str, Any]) -> None:
    """The report as tables: every sensitivity row (most harmful first), RSS, Monte Carlo, yields."""
    unit = r["unit"]
    console.print(f"[bold]{r['lens']}[/] — metric {r['metric']} {unit}, compensator {r['compensator']}, "
                  f"sampling {r['sampling']}, {len(r['fields'])} fields, aim {r['aim']}; "
                  f"nominal {r['nominal']['value']:.4f} "
                  f"(focus shift {r['nominal']['focus_shift_mm'] * 1e3:+.1f} µm), {len(r['tolerances'])} tolerances")
    if "sensitivity" in r:
        rows = r["sensitivity"]
        t = compact_table(f"Sensitivity of {r['metric']} at ∓limit, all {len(rows)} tolerances, most harmful first; "
                          f"inverse: the ± that changes it by {r['inverse_target']:.4g}",
                          [("tolerance", "left"), ("limit", "right"), ("Δ at −", "right"), ("Δ at +", "right"),
                           ("inverse ±", "right"), ("focus ± (µm)", "right")])
        for s in rows:
            t.add_row(s["name"], f"{s['limit']:g}", f"{s['minus']:+.4f}", f"{s['plus']:+.4f}",
                      "∞" if math.isinf(s["inverse"]) else f"{s['inverse']:.4g}",
                      f"{s['focus_minus_mm'] * 1e3:+.1f}/{s['focus_plus_mm'] * 1e3:+.1f}")
        show(console, t)
        rss = r["rss"]
        at = "≥" if r["higher_is_better"] else "≤"
        console.print(f"RSS prediction: mean {rss['mean']:.4f}, std {rss['std']:.4f}, 90 % {at} {rss['p90']:.4f}; "
                      f"classical RSS {rss['rss_worst']:.4f}")
    if "monte_carlo" in r:
        mc = r["monte_carlo"]
        st = mc["stats"]
        console.print(f"Monte Carlo: {mc['trials']} trials, {mc['scheduler']}; {mc['seconds_per_trial']:.4f} s/trial "
                      f"(wall time, a cluster's start included); "
                      f"mean {st['mean']:.4f}, std {st['std']:.4f}, min {st['min']:.4f}, max {st['max']:.4f}; "
                      f"trials with failed rays {st['trials_with_failed_rays']}, "
                      f"compensator failures {st['compensator_failures']}")
        t = Table(title="Yield: this fraction of lenses is at least as good as")
        for col in ("yield", f"{r['metric']} {unit}", "95 % CI"):
            t.add_column(col, justify="right")
        for y in mc["yields"]:
            t.add_row(f"{100 * y['level']:.0f} %", f"{y['value']:.4f}", f"{y['ci_low']:.4f} – {y['ci_high']:.4f}")
        console.print(t)
    for w in r.get("worst", []):
        console.print(f"worst trial {w['trial']}: {w['value']:.4f} → {w['path']}")
