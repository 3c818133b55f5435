"""``lensopt check`` (regression checks of lenses against a baseline, for CI; library ``lensopt.qa.check``)
and ``lensopt accuracy`` (what accuracy costs in time on one lens; library ``lensopt.qa.accuracy``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.table import Table

from lensopt.cli.common import console, err_console, handle_errors, load_model, make_engine, print_json
from lensopt.cli.tables import compact_table, show
from lensopt.errors import LensoptError

__all__ = ["commands"]

DEFAULT_BASELINE = Path("lenses/check_baseline.json")

commands = typer.Typer()  # its commands, put in order by lensopt.cli.app


@commands.command("check")
@handle_errors
def check(
    lenses: Annotated[list[Path], typer.Argument(help="Lenses (.json or .toml) to check.")],
    baseline: Annotated[Path, typer.Option("--baseline", help="Baseline JSON (lenses keyed by file name).")]
    = DEFAULT_BASELINE,
    update: Annotated[bool, typer.Option("--update", help="Rewrite these lenses' baseline entries "
                                         "(atomically) instead of comparing.")] = False,
    junit: Annotated[Path | None, typer.Option("--junit", help="Also write JUnit XML here (one test case "
                                               "per lens and metric).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of tables.")] = False,
) -> None:
    """Recompute each lens's metrics with the baseline's recorded settings and compare them with the
    baseline: exit 0 when every metric is within its tolerance, 1 on a regression, 2 on bad input."""
    from lensopt.files import write_text_atomic
    from lensopt.qa import check as qc

    # ``lensopt check lenses/*.json`` also matches the baseline itself when it lives there.
    lenses = [p for p in lenses if p.resolve() != baseline.resolve()]
    engine = make_engine("eager", report_compiles=False)  # the memory budget; the backend is the baseline's
    if update:
        data = qc.update_baseline(lenses, baseline, engine=engine)
        err_console.print(f"wrote {baseline} ({len(lenses)} lens(es) measured, {len(data['lenses'])} in all)",
                          highlight=False)
        return
    results = qc.check_lenses(lenses, qc.load_baseline(baseline), engine=engine)
    if junit is not None:
        write_text_atomic(junit, qc.junit_xml(results))
    if as_json:
        print_json(qc.as_json(results))
    else:
        for r in results:
            n_bad = sum(not m.passed for m in r.metrics)
            if n_bad == 0:
                console.print(f"[green]ok[/] {r.key}: {len(r.metrics)} metrics within tolerance")
                console.print(_esr_note(r), highlight=False)
                continue
            t = Table(title=f"{r.key} ({r.name}): {n_bad} of {len(r.metrics)} metrics moved",
                      title_justify="left")
            for col in ("metric", "baseline", "now", "Δ", "tolerance"):
                t.add_column(col, justify="left" if col == "metric" else "right")
            for m in r.metrics:
                if m.passed:
                    continue
                t.add_row(m.metric, _fmt(m.baseline), _fmt(m.value),
                          "" if m.delta is None else f"{m.delta:+.3g}", f"{m.tolerance:.3g}")
            console.print(t)
            console.print(_esr_note(r), highlight=False)
    if not all(r.passed for r in results):
        raise typer.Exit(1)


def _fmt(v: float | None) -> str:
    return "—" if v is None else f"{v:.9g}"


def _esr_note(r: Any) -> str:
    """``   ESR 13.711 µm; seed's measure (11 fields, grid:61) 13.438 µm``: the lens's values now ("—" where
    not measured), under its line."""
    from lensopt.analysis.spot import SEED_MEASURE

    now = {m.metric: m.value for m in r.metrics}

    def um(v: float | None) -> str:
        return "—" if v is None or v != v else f"{v:.3f} µm"

    return f"   ESR {um(now.get('esr_um'))}; seed's measure ({SEED_MEASURE}) {um(now.get('seed_esr_um'))}"


@commands.command("accuracy")
@handle_errors
def accuracy(
    lens: Annotated[Path, typer.Argument(help="Lens spec (.toml) or resolved lens (.json).")],
    target: Annotated[str, typer.Option("--target", help="Error target: 1% or 0.01 (relative for ESR/RMS, "
                                        "NRMSE for PSFs, RMSE for images).")] = "1%",
    budget: Annotated[float | None, typer.Option("--budget", help="Seconds: also say what this buys.")] = None,
    knobs: Annotated[str | None, typer.Option("--knobs", help="Comma-separated knobs (default: all): rings, "
                                              "rings_fixed, grid, gauss, float32, compiled, aim_steps, psf_rings, "
                                              "psf_kernel, psf_bins, diffraction, sim_grid, sim_overlap.")]
    = None,
    repeats: Annotated[int, typer.Option("--repeats", min=1, max=20, help="Timing repeats (median).")] = 3,
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Plot: error vs time (png, pdf, svg).")]
    = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of tables.")] = False,
) -> None:
    """Error against a converged reference and wall time of every accuracy knob, measured on this lens;
    the Pareto front and the cheapest settings that meet --target."""
    from rich.progress import Progress

    from lensopt.qa.accuracy import parse_knobs, parse_target, run_accuracy

    tgt = parse_target(target)
    names = parse_knobs(knobs)
    if budget is not None and not budget > 0:
        raise LensoptError("must be > 0 seconds", path="--budget", got=budget)
    if output is not None and output.suffix.lower() not in (".png", ".pdf", ".svg"):
        raise LensoptError("the plot is written as .png, .pdf or .svg", path="--output", got=str(output))
    engine = make_engine()
    model = load_model(lens)
    with Progress(console=err_console, transient=True, disable=as_json) as bar:
        task = bar.add_task("measuring", total=1.0)
        result = run_accuracy(model, knobs=names, repeats=repeats,
                              progress=lambda f, s: bar.update(task, completed=f, description=s), engine=engine)
    data = result.as_json(tgt, budget)
    if output is not None:
        from lensopt.plot.accuracy import accuracy_figure
        from lensopt.plot.style import save_figure

        save_figure(accuracy_figure(data, title=model.spec.name), output, dpi=150)
    if as_json:
        print_json(data)
    else:
        _render_accuracy(data)
    if output is not None:
        err_console.print(f"wrote {output}", highlight=False)


def _render_accuracy(d: dict[str, Any]) -> None:
    ref = d["reference"]["spot"]
    console.print(f"[bold]{d['lens']}[/]: spot reference ESR {ref['esr_um']:.9f} µm by {ref['nodes']}, "
                  f"last doubling changed it by {ref['agreement']:.1e} (relative)"
                  + ("" if ref["converged"] else " [red](not converged to 1e-9)[/]"))
    if "psf" in d["reference"]:
        p = d["reference"]["psf"]
        console.print(f"PSF reference: FFT diffraction PSF, {p['size']}×{p['size']} bins of {p['pitch_um']:g} µm, "
                      f"{p['time_s']:.2f} s; with half the pupil samples it moves by NRMSE {p['self_check_nrmse']:.1e}")
    if "sim" in d["reference"] and "skipped" in d["reference"]["sim"]:
        console.print(f"simulation knobs skipped: {d['reference']['sim']['skipped']}", markup=False)
    elif "sim" in d["reference"]:
        s = d["reference"]["sim"]
        console.print(f"simulation reference: {s['image']}, grid {s['grid']}, {s['fields']} fields, {s['sampling']}")
    if d.get("compile_s") is not None:
        console.print(f"compiled trace: first call (compilation) {d['compile_s']:.1f} s, excluded from the times")
    from lensopt.qa.accuracy_analyses import ANALYSIS_KNOBS

    core = [p for p in d["points"] if p["knob"] not in ANALYSIS_KNOBS]
    if core:
        # Only the error columns some point has (``--knobs rings,gauss``: ESR and RMS), notes only if any.
        metrics = [(m, name) for m, name in (("esr", "ESR err"), ("rms", "RMS err"), ("aim", "aim err"),
                                             ("psf", "PSF NRMSE"), ("sim", "image RMSE"))
                   if any(m in p["errors"] for p in core)]
        notes = any(p["note"] for p in core)
        t = compact_table("error vs time per knob (others at their defaults)",
                          [("knob", "left"), ("setting", "left"), *((name, "right") for _, name in metrics),
                           ("time s", "right"), *([("note", "left")] if notes else [])])
        for p in core:
            e = p["errors"]
            cells = [f"{e[m]:.2e}" if m in e else "" for m, _ in metrics]
            t.add_row(p["knob"], p["setting"], *cells, f"{p['time_s']:.4f}", *([p["note"]] if notes else []))
        show(console, t)
    analyses = [p for p in d["points"] if p["knob"] in ANALYSIS_KNOBS]
    if analyses:
        _render_analyses(analyses, d["reference"].get("analyses", {}))
    for m, front in d["pareto"].items():
        console.print(f"Pareto front ({m}): " + " → ".join(f"{p['setting']} ({p['errors'][m]:.1e}, {p['time_s']:.3g} s)"
                                                           for p in front))
    for m, r in d["recommendation"].items():
        c = r["cheapest"]
        line = (f"[bold]{m}[/] ≤ {r['target']:g}: " + (f"{c['setting']} ({c['errors'][m]:.2e} in {c['time_s']:.3g} s)"
                                                      if c else r.get("why_not", "none")))
        if "budget_buys" in r:
            b = r["budget_buys"]
            bought = f"{b['setting']} ({b['errors'][m]:.2e})" if b else "nothing measured"
            line += f"; {d['budget_s']:g} s buys {bought}"
        console.print(line)


def _render_analyses(points: list[dict[str, Any]], refs: dict[str, Any]) -> None:
    """The designer's analyses (``qa.accuracy_analyses``): each setting's error against the same analysis at
    its converged reference setting, and its time; the reference's own time on the knob's last row."""
    from lensopt.qa.accuracy_analyses import ANALYSIS_ERRORS

    t = Table(title="analyses: error vs time per knob (against the same analysis at the reference setting)",
              title_justify="left")
    for col in ("knob", "setting", "error", "time s", "error of"):
        t.add_column(col, justify="right" if col in ("error", "time s") else "left")
    for i, p in enumerate(points):
        knob = p["knob"]
        (err,) = p["errors"].values()
        t.add_row(knob, p["setting"], f"{err:.2e}", f"{p['time_s']:.4f}", ANALYSIS_ERRORS[knob])
        last = i + 1 == len(points) or points[i + 1]["knob"] != knob
        if last and knob in refs and knob != "seidel":
            t.add_row(knob, f"reference: {refs[knob]['reference']}", "—", f"{refs[knob]['time_s']:.4f}",
                      "(one run)", style="dim")
    console.print(t)
