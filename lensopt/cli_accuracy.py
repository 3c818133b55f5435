"""``lensopt accuracy``: what accuracy costs in time on one lens (library: ``lensopt.qa.accuracy``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.table import Table


def register(app: typer.Typer) -> None:
    from lensopt.cli import console, err_console, handle_errors, load_model, print_json

    @app.command()
    @handle_errors
    def accuracy(
        lens: Annotated[Path, typer.Argument(help="Lens spec (.toml) or resolved lens (.json).")],
        target: Annotated[str, typer.Option("--target", help="Error target: 1% or 0.01 (relative for ESR/RMS, "
                                            "NRMSE for PSFs, RMSE for images).")] = "1%",
        budget: Annotated[float | None, typer.Option("--budget", help="Seconds: also say what this buys.")] = None,
        knobs: Annotated[str | None, typer.Option("--knobs", help="Comma-separated knobs (default: all): rings, "
                                                  "rings_fixed, grid, float32, compiled, aim_steps, psf_rings, "
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

        from lensopt.errors import LensoptError
        from lensopt.qa.accuracy import parse_knobs, parse_target, run_accuracy

        tgt = parse_target(target)
        names = parse_knobs(knobs)
        if budget is not None and not budget > 0:
            raise LensoptError("must be > 0 seconds", path="--budget", got=budget)
        if output is not None and output.suffix.lower() not in (".png", ".pdf", ".svg"):
            raise LensoptError("the plot is written as .png, .pdf or .svg", path="--output", got=str(output))
        model = load_model(lens)
        with Progress(console=err_console, transient=True, disable=as_json) as bar:
            task = bar.add_task("measuring", total=1.0)
            result = run_accuracy(model, knobs=names, repeats=repeats,
                                  progress=lambda f, s: bar.update(task, completed=f, description=s))
        data = result.as_json(tgt, budget)
        if output is not None:
            from lensopt.plot.accuracy import accuracy_figure
            from lensopt.plot.style import save_figure

            save_figure(accuracy_figure(data, title=model.spec.name), output, dpi=150)
        if as_json:
            print_json(data)
        else:
            render(console, data)
        if output is not None:
            err_console.print(f"wrote {output}", highlight=False)


def render(console: Any, d: dict[str, Any]) -> None:
    ref = d["reference"]["spot"]
    console.print(f"[bold]{d['lens']}[/]: spot reference ESR {ref['esr_um']:.9f} µm by {ref['nodes']}, "
                  f"last doubling changed it by {ref['agreement']:.1e} (relative)"
                  + ("" if ref["converged"] else " [red](not converged to 1e-9)[/]"))
    if "psf" in d["reference"]:
        p = d["reference"]["psf"]
        console.print(f"PSF reference: FFT diffraction PSF, {p['size']}×{p['size']} bins of {p['pitch_um']:g} µm, "
                      f"{p['time_s']:.2f} s; with half the pupil samples it moves by NRMSE {p['self_check_nrmse']:.1e}")
    if "sim" in d["reference"]:
        s = d["reference"]["sim"]
        console.print(f"simulation reference: {s['image']}, grid {s['grid']}, {s['fields']} fields, {s['sampling']}")
    if d.get("compile_s") is not None:
        console.print(f"compiled trace: first call (compilation) {d['compile_s']:.1f} s, excluded from the times")
    t = Table(title="error vs time per knob (others at their defaults)", title_justify="left")
    for col in ("knob", "setting", "ESR err", "RMS err", "aim err", "PSF NRMSE", "image RMSE", "time s", "note"):
        t.add_column(col, justify="left" if col in ("knob", "setting", "note") else "right")
    for p in d["points"]:
        e = p["errors"]
        cells = [f"{e[m]:.2e}" if m in e else "" for m in ("esr", "rms", "aim", "psf", "sim")]
        t.add_row(p["knob"], p["setting"], *cells, f"{p['time_s']:.4f}", p["note"])
    console.print(t)
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
