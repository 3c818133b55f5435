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
plot_app = typer.Typer(no_args_is_help=True, help="Figures: layout, ray fans, spot diagrams, PSFs.")
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


# -------------------------------------------------------------------------------------- simulate


@app.command()
@handle_errors
def simulate(
    lens: LensArg,
    image: Annotated[Path, typer.Argument(help="Scene image (PNG/JPEG/TIFF/EXR; 8/16-bit files are sRGB).")],
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Simulated image (format from suffix).")] = None,
    region: Annotated[str | None, typer.Option("--region", help="Where the image lies on the sensor: "
                                               "x0,y0,w,h | full | center | corner | tile:C,R/NCxNR.")] = None,
    effects: Annotated[str | None, typer.Option("--effects", help="Force effects: +name / -name / noise=σ; names: "
                                                "convolution, diffraction, distortion, ri, noise.")] = None,
    reference: Annotated[Path | None, typer.Option("--reference", help="Image to score the result against "
                                                   "(PSNR/SSIM); default: the input scene.")] = None,
    plan_only: Annotated[bool, typer.Option("--plan", help="Print the plan and stop (nothing simulated).")] = False,
    rays: Annotated[str, typer.Option("--rays", help="Pupil sampling per PSF (rings:N = 2N² rays).")] = "rings:32",
    kernel: Annotated[str, typer.Option("--kernel", help="count | triangular | cosine (S1.4).")] = "triangular",
    grid: Annotated[str | None, typer.Option("--grid", help="Force the PSF grid, e.g. 5x4.")] = None,
    overlap: Annotated[float, typer.Option("--overlap", help="Overlap of patches (S1.5.2).")] = 0.25,
    seed: SeedOpt = 0,
    as_json: JsonOpt = False,
) -> None:
    """Simulate a scene through the lens, computing only the effects the scene calls for."""
    from lensopt.imaging.commands import parse_grid, run_simulate

    if not plan_only and output is None:
        raise LensoptError("needed unless --plan", path="--output")
    if not 0.0 <= overlap < 1.0:
        raise LensoptError("must lie in [0, 1)", path="--overlap", got=overlap)
    result = run_simulate(load_model(lens), image, output, region=region, effects=effects, reference=reference,
                          plan_only=plan_only, sampling=rays, kernel=kernel, grid=parse_grid(grid), overlap=overlap,
                          seed=seed, on_plan=None if as_json else _render_plan)
    if as_json:
        print_json(result)
    elif not plan_only:
        _render_run(result)


def _render_plan(p: dict[str, Any]) -> None:
    t = Table(title=f"plan — {p['lens']}: {p['image']['width']}×{p['image']['height']} "
                    f"{'/'.join(p['channels'])} ({p['image']['encoding']}) on region {p['region']['name']} "
                    f"({p['region']['w']:.0f}×{p['region']['h']:.0f} sensor px, image pixel {p['pixel_um']:.2f} µm)",
              show_header=False)
    t.add_row("wavelengths", ", ".join(f"{w:g}" for w in p["wavelengths_nm"]) + " nm")
    t.add_row("fields traced", ", ".join(f"{f:.2f}°" for f in p["fields_deg"]) or "none")
    grid = p["psf_grid"]
    t.add_row("PSF grid", f"{grid[0]}×{grid[1]}, overlap {p['overlap']:.0%}" if grid else "none")
    ps = p["psf"]
    t.add_row("PSFs", f"{ps['sampling']}, {ps['kernel']} kernel, bins {ps['pitch_um']:.2f} µm"
                      + (", resized to the image pixel" if ps["resize_to_pixel"] else ""))
    for name, e in p["effects"].items():
        t.add_row(name, f"[{'green' if e['on'] else 'dim'}]{'on' if e['on'] else 'off'}[/] — {e['reason']}")
    for note in p["notes"]:
        t.add_row("note", note)
    console.print(t)


def _render_run(r: dict[str, Any]) -> None:
    t = Table(title="stages")
    t.add_column("stage")
    t.add_column("s", justify="right")
    for k, v in r["timings"].items():
        t.add_row(k, f"{v:.3f}")
    console.print(t)
    m = r.get("metrics")
    if m:
        console.print(f"vs {m['against']}: PSNR {m['psnr_db']:.2f} dB, SSIM {m['ssim']:.4f} ({m['space']})")
    console.print(f"wrote {r['output']} ({r['output_encoding']}; input {r['input_encoding']})")


# ------------------------------------------------------------------------------------- plot psf


@plot_app.command("psf")
@handle_errors
def plot_psf(
    lens: LensArg,
    output: Annotated[Path, typer.Option("--output", "-o", help="Figure file (png, pdf, svg).")],
    rays: Annotated[str, typer.Option("--rays", help="Pupil sampling per PSF.")] = "rings:32",
    kernel: Annotated[str, typer.Option("--kernel", help="count | triangular | cosine.")] = "triangular",
    diffraction: Annotated[str, typer.Option("--diffraction", help="heuristic | none | incoherent.")] = "heuristic",
    pitch_um: Annotated[float | None, typer.Option("--pitch-um", help="Bin size (default: sensor pitch, "
                                                   "else 1 µm).")] = None,
    sqrt: Annotated[bool, typer.Option("--sqrt", help="Square-root intensity scale (shows the tails).")] = False,
    seed: SeedOpt = 0,
) -> None:
    """RGB PSFs across the field (the spec's fields)."""
    from lensopt.imaging.commands import plot_psfs

    plot_psfs(load_model(lens), output, sampling=rays, kernel=kernel, diffraction=diffraction, pitch_um=pitch_um,
              sqrt=sqrt, seed=seed)
    console.print(f"wrote {output}")


if __name__ == "__main__":  # pragma: no cover
    app()
