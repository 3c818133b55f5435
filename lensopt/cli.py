"""The ``lensopt`` command line: parse arguments, call the library, render with rich. No physics here.

Every ``LensoptError`` becomes one line on stderr and exit code 2 (DESIGN.md rule 6).
"""

from __future__ import annotations

import logging
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from lensopt import __version__
from lensopt.cli_backend import BackendOpt, with_backend
from lensopt.cli_common import (  # noqa: F401  (re-exported: commands of other modules import them from here)
    AimOpt,
    AimStepsOpt,
    DeviceOpt,
    JsonOpt,
    LensArg,
    LensoptGroup,
    LowerLevelFormatter,
    SamplingOpt,
    SeedOpt,
    check_output,
    console,
    err_console,
    handle_errors,
    print_json,
    report_signal,
    signals_deferred,
    state,
)
from lensopt.errors import LensoptError

if TYPE_CHECKING:
    from rich.table import Table

    from lensopt.spec import Model

app = typer.Typer(cls=LensoptGroup, add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  rich_markup_mode=None,
                  help="Differentiable lens design: trace, plot, optimize, simulate, export.")
plot_app = typer.Typer(cls=LensoptGroup, no_args_is_help=True, help="Figures: layout, fans, spots, PSFs, field curves.")
app.add_typer(plot_app, name="plot")


def _version(value: bool) -> None:
    if value:
        sys.stdout.write(f"lensopt {__version__}\n")
        raise typer.Exit(0)


@app.callback()
def main(verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Debug logging; tracebacks of bugs.")] = False,
         max_memory: Annotated[str | None, typer.Option(
             "--max-memory", help="Memory budget, e.g. 4G (default: half the machine's memory).")] = None,
         version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True,
                                               help="Print the version and exit.")] = False) -> None:
    from lensopt import resources

    state.verbose = verbose
    resources.set_budget(None)
    if max_memory is not None:
        try:
            resources.set_budget(resources.parse_size(max_memory))
        except LensoptError as err:
            raise typer.BadParameter(err.message + f" (got {max_memory!r})", param_hint="'--max-memory'") from None
    handler = logging.StreamHandler(sys.stderr)  # one plain line per message: "warning: ..."
    handler.setFormatter(LowerLevelFormatter("%(levelname)s: %(message)s"))
    logging.basicConfig(level=logging.DEBUG if verbose else logging.WARNING, handlers=[handler], force=True)


def load_model(path: Path, device: Any = None) -> Model:
    """The built lens, its tensors on ``device`` (a torch.device; None: the CPU)."""
    from lensopt.spec import build, load_spec

    return build(load_spec(path), device=device)


def parse_sampling(text: str, seed: int, option: str = "--sampling"):  # noqa: ANN201
    from lensopt.optics.sampling import PupilSampling

    return PupilSampling.parse(text, seed=seed, path=option)


def check_aim(aim: str | None) -> str | None:
    if aim is not None and aim not in ("none", "chief", "full"):
        raise LensoptError("must be none, chief or full", path="--aim", got=aim)
    return aim


def check_aim_steps(steps: int | None) -> int | None:
    if steps is not None and not 1 <= steps <= 100:
        raise LensoptError("must be an integer from 1 to 100", path="--aim-steps", got=steps)
    return steps


def _table(*args: Any, **kwargs: Any) -> Table:
    from rich.table import Table

    return Table(*args, **kwargs)


# ----------------------------------------------------------------------------------------- trace


@app.command(short_help="First-order data, spot sizes, failures, distortion, illumination.")
@handle_errors
@with_backend(err_console)
def trace(lens: LensArg, sampling: SamplingOpt = "rings:24", aim: AimOpt = None, seed: SeedOpt = 0,
          as_json: JsonOpt = False, aim_steps: AimStepsOpt = None,
          mtf: Annotated[str | None, typer.Option("--mtf", help="Also MTF at these cycles/mm (comma-separated; "
                                                  "in --json as mtf).")] = None,
          backend: BackendOpt = "auto") -> None:
    """First-order data, RMS spot radius per field and wavelength, ray failures, distortion and
    relative illumination per field."""
    from lensopt.analysis.report import trace_report

    model = load_model(lens)
    report = trace_report(model, parse_sampling(sampling, seed),
                          aim=check_aim(aim), aim_steps=check_aim_steps(aim_steps))
    if mtf is not None:
        from lensopt.cli_tolerance import mtf_report, parse_frequencies

        report["mtf"] = mtf_report(model, parse_frequencies(mtf, "--mtf"))
    if as_json:
        print_json(report)
        return
    _render_trace(report)
    _render_field(report)


def _render_trace(r: dict[str, Any]) -> None:
    ref = r["wavelengths_nm"].index(r["reference_nm"])
    console.print(f"[bold]{r['name']}[/]")
    console.print(_prescription_table(r["surfaces"], ref, r["reference_nm"]))
    fo = r["first_order"]
    t = _table(title=f"first-order data ({r['reference_nm']:g} nm)", title_justify="left")
    t.add_column("quantity")
    t.add_column("value", justify="right")
    t.add_column("unit")
    labels = {"efl": "EFL", "bfl": "BFL (last surface to focus)", "ffl": "FFL (front focus from S1)",
              "epd": "EPD", "entrance_pupil_z": "entrance pupil z (from S1)",
              "exit_pupil_z": "exit pupil z (from S1)", "exit_pupil_diameter": "exit pupil diameter",
              "fnumber": "f-number (EFL/EPD)", "working_fnumber": "working f-number",
              "paraxial_image_height": "paraxial image height", "total_track": "total track"}
    for key, label in labels.items():
        t.add_row(label, f"{fo[key]:.6f}", "" if "fnumber" in key else "mm")
    console.print(t)
    wl = r["wavelengths_nm"]
    s = _table(title=f"RMS spot radius (µm), sampling {r['sampling']}, aim {r['aim']}", title_justify="left")
    s.add_column("field °", justify="right")
    for w in wl:
        s.add_column(f"{w:g} nm", justify="right")
    s.add_column("weighted", justify="right", style="bold")
    s.add_column("centroid y mm", justify="right")
    s.add_column("chief y mm", justify="right")
    s.add_column("failed", justify="right")
    for f in r["fields"]:
        s.add_row(f"{f['angle_deg']:.3f}", *[_num(v) for v in f["rms_spot_radius_um"]],
                  _num(f["rms_spot_radius_weighted_um"]), _num(f["centroid_y_mm"], ".6f"),
                  _num(f["chief_ray_y_mm"], ".6f"), f"{f['failed_rays']}/{f['rays']}")
    console.print(s)
    esr = r["effective_spot_radius_um"]
    console.print(f"effective spot radius: [bold]{esr:.4f} µm[/]" if esr is not None else
                  "effective spot radius: — (no ray reaches the image at some field or wavelength: see the "
                  "failures below)")
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


def _num(v: float | None, fmt: str = ".4f") -> str:
    return "—" if v is None else format(v, fmt)


def _render_field(r: dict[str, Any]) -> None:
    from lensopt.analysis.field import AIM_NOTE_FRACTION

    full = r["aim"] == "full"
    t = _table(title=f"Distortion, relative illumination, pupil (V factors at {r['reference_nm']:g} nm)"
                    + (f", full aiming {r['aim_steps']} step(s), stop radius {r['stop_radius_mm']:.6f} mm"
                       if full else ""))
    for col in ("field °", "distortion %", "RI S51", "RI S52", "V_i", "V_s", "V_l"):
        t.add_column(col, justify="right")
    if full:
        t.add_column("stop miss µm", justify="right")
        limit = 1e3 * AIM_NOTE_FRACTION * r["stop_radius_mm"]
    for f in r["fields"]:
        v = f["vignetting"]
        ri = f["relative_illumination"]
        row = [f"{f['angle_deg']:.3f}", _num(f["distortion_percent"]), _num(ri["three_ray"]), _num(ri["std"]),
               f"{v['inferior']:.4f}", f"{v['superior']:.4f}", f"{v['lateral']:.4f}"]
        if full:
            miss = 1e3 * max(v["aim_residual_mm"].values())
            row.append(f"{miss:.2e}" + ("" if v["aim_rays_traced"] and miss <= limit else " (!)"))
        t.add_row(*row)
    console.print(t)
    for note in r["notes"]:
        console.print(f"[yellow]note:[/] {note}", highlight=False)


def _prescription_table(surfaces: list[dict[str, Any]], ref: int, ref_nm: float) -> Table:
    """The resolved prescription as traced: one row per surface (the ``surfaces`` of ``trace --json``)."""
    t = _table(title="prescription (lengths in mm)", title_justify="left")
    for col, just in (("surf", "right"), ("type", "left"), ("radius", "right"), ("thickness", "right"),
                      ("material", "left"), (f"n {ref_nm:g} nm", "right"), ("semi-diam.", "right"),
                      ("notes", "left")):
        t.add_column(col, justify=just)  # type: ignore[arg-type]
    for i, sf in enumerate(surfaces, start=1):
        radius = "inf" if math.isinf(sf["radius"]) else f"{sf['radius']:.6f}"
        notes = []
        if sf["stop"]:
            notes.append("stop")
        if sf["conic"]:
            notes.append(f"k={sf['conic']:g}")
        if sf["asphere"]:
            notes.append("asph " + " ".join(f"a{p}={v:.4g}" for p, v in sf["asphere"].items()))
        if "diffractive" in sf:
            d = sf["diffractive"]
            notes.append("DOE " + " ".join(f"d{p}={v:.4g}" for p, v in d.items() if p.isdigit())
                         + f" @{d['design_wavelength_nm']:g} nm m={d['order']}")
        t.add_row(str(i), sf["type"], radius, f"{sf['thickness']:.6f}", sf["material"],
                  f"{sf['index'][ref]:.6f}", f"{sf['semi_diameter']:.4f}", ", ".join(notes))
    return t


# ------------------------------------------------------------------------------------------- ray


@app.command(short_help="One real ray, surface by surface (like CODE V's RSI).")
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

    if not (math.isfinite(field) and abs(field) < 90.0):
        raise LensoptError("must be a field angle in degrees, strictly between -90 and 90", path="--field", got=field)
    if not all(math.isfinite(p) for p in pupil):
        raise LensoptError("must be two finite relative pupil coordinates", path="--pupil", got=pupil)
    model = load_model(lens)
    if wavelength is None:
        wavelength = model.spec.spectrum.wavelengths_nm[model.system.reference]
    if not (math.isfinite(wavelength) and wavelength > 0):
        raise LensoptError("must be a positive wavelength in nm", path="--wavelength", got=wavelength)
    r = ray_report(model, field_deg=field, px=pupil[0], py=pupil[1], wavelength_nm=wavelength,
                   aim=check_aim(aim) or model.system.aim)
    if as_json:
        print_json(r)
        return
    t = _table(title=f"real ray: field {field:g}°, pupil ({r['pupil'][0]:g}, {r['pupil'][1]:.6g}), "
                    f"{wavelength:g} nm, aim {r['aim']}")
    for col in ("surf", "x", "y", "z", "L", "M", "N", "AOI °", "AOR °"):
        t.add_column(col, justify="right")
    for s in r["surfaces"]:
        aor = "TIR" if s["aor_deg"] is None and s["aoi_deg"] is not None else _num(s["aor_deg"])
        t.add_row(str(s["surface"]), *[_num(s[k], ".6f") for k in ("x", "y", "z", "L", "M", "N")],
                  _num(s["aoi_deg"]), aor)
    im = r["image"]
    t.add_row("image", *[_num(im[k], ".6f") for k in ("x", "y", "z", "L", "M", "N")], "", "")
    console.print(t)
    at = f" at surface {r['failed_at_surface']}" if r.get("failed_at_surface") else ""
    console.print(f"status: {r['status']}{at}" + (" (backtracking flagged)" if r["backtracking"] else ""))


# ------------------------------------------------------------------------------------------ plot

OutOpt = Annotated[Path, typer.Option("--output", "-o",
                                      help="Image file (.png, .pdf, .svg, .jpg; the suffix picks the format).")]
DpiOpt = Annotated[int, typer.Option("--dpi", min=30, max=1200, help="Resolution of raster images.")]


def _titles(model: Model) -> tuple[str, str]:
    """Figure title and a one-line first-order summary."""
    from lensopt.optics.paraxial import first_order

    fo = first_order(model.lens, model.system)
    s = model.system
    field = (f"HFOV {s.field_max:g}°" if s.field_type == "angle" else f"image height {s.field_max:g} mm")
    wl = "/".join(f"{w:g}" for w in model.spec.spectrum.wavelengths_nm)
    return model.spec.name, f"EFL {float(fo.efl):.3f} mm · f/{float(fo.fnumber):.2f} · {field} · {wl} nm"


FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg")


def _check_output(path: Path) -> Path:
    return check_output(path, FIGURE_SUFFIXES, what="image file")


@plot_app.command("layout", short_help="2D meridional layout with traced rays.")
@handle_errors
def plot_layout_cmd(lens: LensArg, output: OutOpt, aim: AimOpt = None,
                    rays: Annotated[int, typer.Option("--rays", min=2, max=101,
                                                      help="Meridional rays per field.")] = 7,
                    dpi: DpiOpt = 150) -> None:
    """2D meridional layout: elements, stop, image plane and traced rays per field."""
    from lensopt.analysis.layout import layout
    from lensopt.plot import plot_layout, save_figure

    out = _check_output(output)
    model = load_model(lens)
    data = layout(model, aim=check_aim(aim), rays_per_field=rays)
    title, sub = _titles(model)
    save_figure(plot_layout(data, title=title, subtitle=sub), out, dpi=dpi)
    err_console.print(f"wrote {output}")


@plot_app.command("fans", short_help="Tangential and sagittal ray fans.")
@handle_errors
def plot_fans_cmd(lens: LensArg, output: OutOpt, aim: AimOpt = None,
                  points: Annotated[int, typer.Option("--points", min=3, max=2001,
                                                      help="Rays per fan.")] = 101,
                  dpi: DpiOpt = 150) -> None:
    """Tangential and sagittal ray fans per field, one curve per wavelength (S1.3.4)."""
    import torch

    from lensopt.analysis.fans import ray_fans
    from lensopt.plot import plot_fans, save_figure

    out = _check_output(output)
    model = load_model(lens)
    with torch.no_grad():
        fans = ray_fans(model.lens, model.system, points=points, aim=check_aim(aim))
    title, sub = _titles(model)
    save_figure(plot_fans(fans, title=title, subtitle=sub), out, dpi=dpi)
    err_console.print(f"wrote {output}")


@plot_app.command("spots", short_help="Spot diagrams per field and wavelength.")
@handle_errors
def plot_spots_cmd(lens: LensArg, output: OutOpt, sampling: SamplingOpt = "rings:24", aim: AimOpt = None,
                   seed: SeedOpt = 0, dpi: DpiOpt = 150) -> None:
    """Spot diagram per field, colour per wavelength, RMS radius and Airy disc."""
    import torch

    from lensopt.analysis.spot_diagram import spot_diagram
    from lensopt.plot import plot_spots, save_figure

    out = _check_output(output)
    model = load_model(lens)
    pupil = parse_sampling(sampling, seed)
    with torch.no_grad():
        spots = spot_diagram(model.lens, model.system, pupil, aim=check_aim(aim))
    title, sub = _titles(model)
    save_figure(plot_spots(spots, title=title, subtitle=sub), out, dpi=dpi)
    err_console.print(f"wrote {output}")


# ----------------------------------------------------------------------------------------- codev

OutputOpt = Annotated[Path, typer.Option("--output", "-o", help="Output file.")]


@app.command("export-codev")
@handle_errors
def export_codev(
    lens: LensArg,
    output: OutputOpt,
    private_catalog: Annotated[bool, typer.Option(
        "--private-catalog", help="Write every glass as a private catalog of lensopt's indices.")] = False,
) -> None:
    """Write the lens as a CODE V sequence file (.seq)."""
    from lensopt.io.codev_export import write_codev
    from lensopt.spec import load_spec

    check_output(output, (".seq",), what="CODE V sequence file")
    write_codev(load_spec(lens), output, private_catalog=private_catalog)
    err_console.print(f"wrote {output}", highlight=False)


@app.command("import-codev")
@handle_errors
def import_codev(
    seq: Annotated[Path, typer.Argument(help="CODE V sequence file (.seq).")],
    output: OutputOpt,
) -> None:
    """Read a CODE V sequence file into a lensopt lens (.json)."""
    from lensopt.io.codev_import import read_codev
    from lensopt.spec.io import save_json

    if output.suffix.lower() != ".json":
        raise LensoptError("the imported lens is written as JSON; name it *.json", path="--output",
                           got=str(output))
    check_output(output)
    result = read_codev(seq)
    for warning in result.warnings:
        err_console.print(f"[yellow]warning:[/] {warning}", markup=True, highlight=False, soft_wrap=True)
    save_json(result.spec, output)
    err_console.print(f"wrote {output}", highlight=False)

# -------------------------------------------------------------------------------------- optimize


# (optimize: lensopt/cli_optimize.py)


# -------------------------------------------------------------------------------------- simulate


@app.command(short_help="Simulate a scene image through the lens.")
@handle_errors
@with_backend(err_console)
def simulate(
    lens: LensArg,
    image: Annotated[Path, typer.Argument(help="Scene image (PNG/JPEG/TIFF/EXR; 8/16-bit files are sRGB).")],
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Simulated image (format from suffix).")] = None,
    region: Annotated[str | None, typer.Option("--region", help="Where the image lies on the sensor: "
                                               "x0,y0,w,h | full | center | corner | tile:C,R/NCxNR.")] = None,
    effects: Annotated[str | None, typer.Option("--effects", help="Force effects: +name / -name / noise=σ; names: "
                                                "convolution, diffraction, distortion, ri, noise.")] = None,
    reference: Annotated[Path | None, typer.Option("--reference", help="Image to score the result against "
                                                   "(PSNR/SSIM); implies --score.")] = None,
    score: Annotated[bool, typer.Option("--score", help="Score PSNR/SSIM against the input scene (or "
                                        "--reference); off by default: it costs more than the simulation.")] = False,
    plan_only: Annotated[bool, typer.Option("--plan", help="Print the plan and stop (nothing simulated).")] = False,
    rays: Annotated[str, typer.Option("--rays", help="Pupil sampling per PSF (rings:N = 2N² rays).")] = "rings:32",
    kernel: Annotated[str, typer.Option("--kernel", help="count | triangular | cosine (S1.4).")] = "triangular",
    grid: Annotated[str | None, typer.Option("--grid", help="Force the PSF grid, e.g. 5x4.")] = None,
    overlap: Annotated[float, typer.Option("--overlap", help="Overlap of patches (S1.5.2).")] = 0.25,
    seed: SeedOpt = 0,
    as_json: JsonOpt = False,
    backend: BackendOpt = "auto",
    device: DeviceOpt = "cpu",
) -> None:
    """Simulate a scene through the lens, computing only the effects the scene calls for."""
    from lensopt.cli_imaging import parse_grid, render_plan, render_run, run_simulate
    from lensopt.cli_restore import resolve_device
    from lensopt.resources import require

    dev = resolve_device(device)
    psf_grid = parse_grid(grid)
    if psf_grid is not None:  # each cell holds RGB PSFs of up to 161×161 float32 bins, a few copies
        require(psf_grid[0] * psf_grid[1] * 161 * 161 * 3 * 4 * 4, f"a {grid} PSF grid", lower="--grid", path="--grid")

    if not plan_only and output is None:
        raise LensoptError("needed unless --plan", path="--output")
    if output is not None:
        check_output(output, (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr"), what="image file")
    if not 0.0 <= overlap < 1.0:
        raise LensoptError("must lie in [0, 1)", path="--overlap", got=overlap)
    result = run_simulate(load_model(lens, dev), image, output, region=region, effects=effects, reference=reference,
                          plan_only=plan_only, sampling=rays, kernel=kernel, grid=psf_grid, overlap=overlap,
                          seed=seed, on_plan=None if as_json else render_plan, score=score)
    if as_json:
        print_json(result)
    elif not plan_only:
        render_run(result)


# ------------------------------------------------------------------------------------- plot psf


@plot_app.command("psf")
@handle_errors
@with_backend(err_console)
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
    backend: BackendOpt = "auto",
    dpi: DpiOpt = 150,
) -> None:
    """RGB PSFs across the field (the spec's fields)."""
    from lensopt.cli_imaging import plot_psfs

    check_output(output, (".png", ".pdf", ".svg"), what="image file")
    plot_psfs(load_model(lens), output, sampling=rays, kernel=kernel, diffraction=diffraction, pitch_um=pitch_um,
              sqrt=sqrt, seed=seed, dpi=dpi)
    err_console.print(f"wrote {output}", highlight=False)


# ------------------------------------------------------------------------------------ plot field


@plot_app.command("field", short_help="Distortion and relative illumination against field.")
@handle_errors
def plot_field_cmd(lens: LensArg, output: OutOpt, sampling: SamplingOpt = "rings:16", aim: AimOpt = None,
                   aim_steps: AimStepsOpt = None,
                   points: Annotated[int, typer.Option("--points", min=2, max=401,
                                                       help="Field samples from axis to full field.")] = 21,
                   seed: SeedOpt = 0, dpi: DpiOpt = 150) -> None:
    """Distortion (S48) and relative illumination (S51, S52) against field."""
    from lensopt.analysis.field import field_summary
    from lensopt.plot.field import field_figure
    from lensopt.plot.style import save_figure

    out = _check_output(output)
    model = load_model(lens)
    summary = field_summary(model.lens, model.system, parse_sampling(sampling, seed),
                            rel_field=[i / (points - 1) for i in range(points)], aim=check_aim(aim),
                            aim_steps=check_aim_steps(aim_steps))
    title, sub = _titles(model)
    save_figure(field_figure(summary, title=title, subtitle=sub), out, dpi=dpi)
    err_console.print(f"wrote {output}")


# Commands that live in modules of their own (registered last: they need the apps above).
from lensopt import (  # noqa: E402
    cli_accuracy,
    cli_check,
    cli_evaluate,
    cli_optimize,
    cli_restore,
    cli_sweep,
    cli_tolerance,
    cli_warmup,
    cli_zemax,
)

cli_check.register(app)
cli_accuracy.register(app)
cli_evaluate.register(app, plot_app)
cli_tolerance.register(app, plot_app)
cli_zemax.register(app)
cli_restore.register(app)
cli_optimize.register(app)
cli_sweep.register(app)
cli_warmup.register(app)

if __name__ == "__main__":  # pragma: no cover
    app()
