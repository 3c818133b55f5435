"""The ``lensopt`` command line: parse arguments, call the library, render with rich. No physics here.

Every ``LensoptError`` becomes one line on stderr and exit code 2 (DESIGN.md rule 6).
"""

from __future__ import annotations

import functools
import json
import logging
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.logging import RichHandler
from rich.table import Table

from lensopt.errors import LensoptError
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import Model, build, load_spec

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Differentiable lens design: trace, plot, optimize, simulate, export.")
plot_app = typer.Typer(no_args_is_help=True, help="Figures: layout, ray fans, spot diagrams.")
app.add_typer(plot_app, name="plot")

# Wide enough for the tables when stdout is a pipe or a file (rich would assume 80 columns).
console = Console(width=None if sys.stdout.isatty() else 160)
err_console = Console(stderr=True, width=None if sys.stderr.isatty() else 1000)
F = TypeVar("F", bound=Callable[..., Any])

LensArg = Annotated[Path, typer.Argument(help="Lens spec (.toml) or resolved lens (.json).")]
SamplingOpt = Annotated[str, typer.Option("--sampling", help="Pupil sampling: rings:N[:nojitter] or grid:N.")]
AimOpt = Annotated[str | None, typer.Option("--aim", help="Ray aiming: none | chief (default: the spec's).")]
SeedOpt = Annotated[int, typer.Option("--seed", help="Seed of every random draw (pupil jitter).")]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print one JSON object instead of tables.")]


def handle_errors(fn: F) -> F:
    """Turn lensopt errors into one line and exit code 2; Ctrl-C into exit code 130."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except LensoptError as err:
            err_console.print(f"[bold red]error:[/] {err}", markup=True, highlight=False, soft_wrap=True)
            raise typer.Exit(2) from None
        except KeyboardInterrupt:
            err_console.print("interrupted")
            raise typer.Exit(130) from None

    return wrapper  # type: ignore[return-value]


@app.callback()
def main(verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Debug logging.")] = False) -> None:
    logging.basicConfig(level=logging.DEBUG if verbose else logging.WARNING, format="%(message)s",
                        handlers=[RichHandler(console=err_console, show_path=False)])


def load_model(path: Path) -> Model:
    return build(load_spec(path))


def check_aim(aim: str | None) -> str | None:
    if aim is not None and aim not in ("none", "chief"):
        raise LensoptError("must be none or chief", path="--aim", got=aim)
    return aim


def print_json(obj: Any) -> None:
    sys.stdout.write(json.dumps(obj, indent=2, allow_nan=True) + "\n")


# ----------------------------------------------------------------------------------------- trace


@app.command()
@handle_errors
def trace(lens: LensArg, sampling: SamplingOpt = "rings:24", aim: AimOpt = None, seed: SeedOpt = 0,
          as_json: JsonOpt = False) -> None:
    """First-order data, RMS spot radius per field and wavelength, ray failures."""
    from lensopt.analysis.report import trace_report

    model = load_model(lens)
    report = trace_report(model, PupilSampling.parse(sampling, seed=seed, path="--sampling"),
                          aim=check_aim(aim))
    if as_json:
        print_json(report)
        return
    _render_trace(report)


def _render_trace(r: dict[str, Any]) -> None:
    fo = r["first_order"]
    t = Table(title=f"{r['name']} — first-order data (reference {r['reference_nm']:g} nm)", show_header=False)
    labels = {"efl": "EFL", "bfl": "BFL", "ffl": "FFL (front focus from S1)", "epd": "EPD",
              "entrance_pupil_z": "entrance pupil z (from S1)", "exit_pupil_z": "exit pupil z (from S1)",
              "exit_pupil_diameter": "exit pupil diameter", "fnumber": "f-number (EFL/EPD)",
              "working_fnumber": "working f-number", "paraxial_image_height": "paraxial image height",
              "total_track": "total track"}
    for key, label in labels.items():
        unit = "" if "fnumber" in key else " mm"
        t.add_row(label, f"{fo[key]:.6f}{unit}")
    console.print(t)
    wl = r["wavelengths_nm"]
    s = Table(title=f"RMS spot radius (µm), sampling {r['sampling']}, aim {r['aim']}")
    s.add_column("field °", justify="right")
    for w in wl:
        s.add_column(f"{w:g} nm", justify="right")
    s.add_column("weighted", justify="right", style="bold")
    s.add_column("centroid y mm", justify="right")
    s.add_column("chief y mm", justify="right")
    s.add_column("failed", justify="right")
    for f in r["fields"]:
        s.add_row(f"{f['angle_deg']:.3f}", *[f"{v:.4f}" for v in f["rms_spot_radius_um"]],
                  f"{f['rms_spot_radius_weighted_um']:.4f}", f"{f['centroid_y_mm']:.6f}",
                  f"{f['chief_ray_y_mm']:.6f}", f"{f['failed_rays']}/{f['rays']}")
    console.print(s)
    console.print(f"effective spot radius: [bold]{r['effective_spot_radius_um']:.4f} µm[/]")
    failures: dict[str, int] = {}
    for f in r["fields"]:
        for reason, n in f["failures"].items():
            failures[reason] = failures.get(reason, 0) + n
        if f["backtracking_rays"]:
            failures["backtracking (flagged, still traced)"] = (
                failures.get("backtracking (flagged, still traced)", 0) + f["backtracking_rays"])
    if failures:
        console.print("ray failures: " + ", ".join(f"{k}: {v}" for k, v in failures.items()))
    else:
        console.print("ray failures: none")


# ------------------------------------------------------------------------------------------- ray


@app.command()
@handle_errors
def ray(
    lens: LensArg,
    field: Annotated[float, typer.Option("--field", help="Field angle in degrees.")] = 0.0,
    pupil: Annotated[tuple[float, float], typer.Option("--pupil", help="Relative pupil PX PY.")] = (0.0, 1.0),
    wavelength: Annotated[float | None, typer.Option("--wavelength", help="nm (default: reference).")] = None,
    aim: AimOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """One real ray, surface by surface: position, direction cosines, angles (like CODE V's RSI)."""
    from lensopt.analysis.report import ray_report

    model = load_model(lens)
    if wavelength is None:
        wavelength = model.spec.spectrum.wavelengths_nm[model.system.reference]
    if not wavelength > 0:
        raise LensoptError("must be a positive wavelength in nm", path="--wavelength", got=wavelength)
    r = ray_report(model, field_deg=field, px=pupil[0], py=pupil[1], wavelength_nm=wavelength,
                   aim=check_aim(aim) or model.system.aim)
    if as_json:
        print_json(r)
        return
    t = Table(title=f"real ray: field {field:g}°, pupil ({r['pupil'][0]:g}, {r['pupil'][1]:.6g}), "
                    f"{wavelength:g} nm, aim {r['aim']}")
    for col in ("surf", "x", "y", "z", "L", "M", "N", "AOI °", "AOR °"):
        t.add_column(col, justify="right")
    for s in r["surfaces"]:
        aor = "TIR" if s["aor_deg"] is None else f"{s['aor_deg']:.4f}"
        t.add_row(str(s["surface"]), *[f"{s[k]:.6f}" for k in ("x", "y", "z", "L", "M", "N")],
                  f"{s['aoi_deg']:.4f}", aor)
    im = r["image"]
    t.add_row("image", *[f"{im[k]:.6f}" for k in ("x", "y", "z", "L", "M", "N")], "", "")
    console.print(t)
    console.print(f"status: {r['status']}" + (" (backtracking flagged)" if r["backtracking"] else ""))


# -------------------------------------------------------------------------------------- optimize


@app.command()
@handle_errors
def optimize(
    spec: Annotated[Path, typer.Argument(help="Lens spec (.toml or .json) with vary lists and [optimize].")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Where to write the optimized lens (.json).")],
    optimizer: Annotated[str | None, typer.Option("--optimizer", help="lm | adam (default: the spec's).")] = None,
    steps: Annotated[int | None, typer.Option("--steps", min=1, help="Steps (default: the spec's).")] = None,
    seed: SeedOpt = 0,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No live display.")] = False,
    as_json: JsonOpt = False,
) -> None:
    """Levenberg–Marquardt (or Adam) for spot size with solves and constraints; Ctrl-C keeps the best lens."""
    from lensopt.analysis.report import trace_report
    from lensopt.cli_optimize import LiveProgress, render_summary, summary
    from lensopt.optim import Problem
    from lensopt.optim import optimize as run_optimize
    from lensopt.optim.report import constraint_report
    from lensopt.spec import save_json

    if output.suffix.lower() != ".json":
        raise LensoptError("the optimized lens is written as .json", path="--output", got=str(output))
    start_spec = load_spec(spec)
    with LiveProgress(err_console, enabled=not quiet) as live:
        result = run_optimize(start_spec, optimizer=optimizer, steps=steps, seed=seed, callback=live)
    save_json(result.spec, output)  # atomic
    sampling = PupilSampling.parse("rings:24", seed=seed)
    final_problem = Problem(result.spec, seed=seed)
    s = summary(result, trace_report(build(start_spec), sampling), trace_report(build(result.spec), sampling),
                constraint_report(final_problem, final_problem.theta0), str(output))
    if as_json:
        print_json(s)
    else:
        render_summary(console, s)
    if result.interrupted:
        raise typer.Exit(130)


if __name__ == "__main__":  # pragma: no cover
    app()
