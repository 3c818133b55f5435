"""``lensopt tolerance`` (CLI layer: parse, call ``lensopt.design.tolerance_study``, render): sensitivity,
Monte Carlo, yields; plots and the worst trials written with ``--output-dir``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.table import Table

from lensopt.cli.common import (
    JsonOpt,
    LensArg,
    SchedulerOpt,
    WorkersOpt,
    check_scheduler,
    check_seed,
    console,
    handle_errors,
    load_model,
    make_engine,
    print_json,
)
from lensopt.cli.tables import compact_table, show
from lensopt.errors import LensoptError

__all__ = ["commands", "parse_fields"]

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
    scheduler: SchedulerOpt = "auto",
    workers: WorkersOpt = 2,
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
    engine = make_engine()
    model = load_model(lens)
    if irm is not None and metric is None:
        metric = "psnr"
    settings = _settings(model, tolerances, profile, {
        "profile": profile, "trials": trials, "seed": seed, "metric": metric, "mtf_frequency": mtf_frequency,
        "sampling": sampling, "compensator": compensator, "aim": aim, "fields": fields})
    sched = check_scheduler(scheduler)
    hook = None
    if irm is not None:
        if settings.metric != "psnr":
            raise LensoptError("--irm scores PSNR after restoration: use it with --metric psnr", path="--irm",
                               got=settings.metric)
        from lensopt.restore.apply import restoration_hook

        hook = restoration_hook(model, irm, engine=engine)
    from lensopt.design.tolerance_study import tolerance_report

    report = tolerance_report(model, settings, scheduler=sched, workers=workers, out_dir=output_dir,
                              worst=worst, inverse_delta=inverse_delta, sensitivity=not no_sensitivity,
                              compiled=compile_, restore=hook, engine=engine)
    if as_json:
        print_json(report)
    else:
        _render(report)


def _settings(model: Any, tolerances: Path | None, profile: str | None, options: dict[str, Any]) -> Any:
    """The study's ``ToleranceSpec``: ``--tolerances`` FILE, else the spec's ``[tolerance]``, else the named
    ``--profile``, with the options given on the command line (None: not given; ``fields`` as text) on top;
    a bad value is one line naming its option."""
    from lensopt.spec.io import load_tolerances
    from lensopt.spec.tolerance import ToleranceSpec

    base = load_tolerances(tolerances) if tolerances is not None else model.spec.tolerance
    if base is None:
        if profile is None:
            raise LensoptError("the lens has no [tolerance] section; give --tolerances FILE or --profile s6.2",
                               path="--tolerances")
        base = ToleranceSpec(profile="s6.2")
    if options.get("fields") is not None:
        options = {**options, "fields": parse_fields(options["fields"])}
    changes = {k: v for k, v in options.items() if v is not None}
    try:
        return ToleranceSpec.model_validate({**base.model_dump(), **changes})
    except Exception as err:  # pydantic ValidationError → one line naming the option
        first = err.errors()[0] if hasattr(err, "errors") else {"loc": (), "msg": str(err)}
        where = "--" + str(first["loc"][0]).replace("_", "-") if first["loc"] else "--tolerances"
        raise LensoptError(first["msg"], path=where) from None


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
