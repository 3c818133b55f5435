"""``lensopt plot …``: every figure command (CLI layer: parse, call the analysis, draw with ``lensopt.plot``).

layout, fans, spots, psf, field, regions (sensor tiles, S3.3.1) and mtf; each writes one image file.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from lensopt.cli.common import (
    AimOpt,
    AimStepsOpt,
    BackendOpt,
    LensArg,
    LensoptGroup,
    SamplingOpt,
    SeedOpt,
    check_aim,
    check_aim_steps,
    check_output,
    err_console,
    handle_errors,
    load_model,
    make_engine,
    parse_sampling,
)
from lensopt.errors import LensoptError

if TYPE_CHECKING:
    from lensopt.engine import Engine
    from lensopt.spec import Model

__all__ = ["plot_app"]

plot_app = typer.Typer(cls=LensoptGroup, no_args_is_help=True, help="Figures: layout, fans, spots, PSFs, field curves.")

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
    engine = make_engine()
    model = load_model(lens)
    data = layout(model, aim=check_aim(aim), rays_per_field=rays, engine=engine)
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
    engine = make_engine()
    model = load_model(lens)
    with torch.no_grad():
        fans = ray_fans(model.lens, model.system, points=points, aim=check_aim(aim), engine=engine)
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
    engine = make_engine()
    model = load_model(lens)
    pupil = parse_sampling(sampling, seed)
    with torch.no_grad():
        spots = spot_diagram(model.lens, model.system, pupil, aim=check_aim(aim), engine=engine)
    title, sub = _titles(model)
    save_figure(plot_spots(spots, title=title, subtitle=sub), out, dpi=dpi)
    err_console.print(f"wrote {output}")


#: ``plot psf``'s pupil sampling. rings:32 (the seed's, and ``simulate``'s) leaves the outer pupil rings of an
#: off-axis field as separate loops in the flare (issue 29: Cooke triplet at 20°, 1 µm bins); grid:128
#: (~12 900 rays) gives a continuous PSF: √-intensity RMS error over the PSF against grid:384, 20° field,
#: 0.029 (rings:32) → 0.005, for ~+1–3 s per figure (tests/plot/test_psf_figure.py).
PSF_FIGURE_RAYS = "grid:128"


@plot_app.command("psf")
@handle_errors
def plot_psf(
    lens: LensArg,
    output: Annotated[Path, typer.Option("--output", "-o", help="Figure file (png, pdf, svg).")],
    rays: Annotated[str, typer.Option("--rays", help="Pupil sampling per PSF (grid:N ≈ 0.785 N² rays, "
                                      "rings:N = 2N²).")] = PSF_FIGURE_RAYS,
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
    engine = make_engine(backend)
    check_output(output, (".png", ".pdf", ".svg"), what="image file")
    _plot_psfs(load_model(lens), output, sampling=rays, kernel=kernel, diffraction=diffraction, pitch_um=pitch_um,
               sqrt=sqrt, seed=seed, dpi=dpi, engine=engine)
    err_console.print(f"wrote {output}", highlight=False)


def _plot_psfs(model: Model, output: Path, *, sampling: str = PSF_FIGURE_RAYS, kernel: str = "triangular",
               diffraction: str = "heuristic", pitch_um: float | None = None, sqrt: bool = False,
               seed: int = 0, dpi: int = 150, engine: Engine | None = None) -> None:
    """RGB PSFs at the spec's fields, bins of ``pitch_um`` (default: the sensor pitch, else 1 µm)."""
    import torch

    from lensopt.analysis.psf_stack import PsfSettings, compute_psfs
    from lensopt.analysis.spot import spot_stats
    from lensopt.imaging.plan import channel_weights
    from lensopt.optics.bundle import trace_bundle
    from lensopt.optics.sampling import PupilSampling
    from lensopt.plot.psf import save_psf_figure
    from lensopt.spec import camera_of

    spec = model.spec
    if pitch_um is None:
        pitch_um = spec.sensor.pixel_pitch_um if spec.sensor is not None else 1.0
    if not pitch_um > 0:
        raise LensoptError("must be positive", path="--pitch-um", got=pitch_um)
    settings = PsfSettings(sampling=sampling, kernel=kernel, diffraction=diffraction, pitch_mm=pitch_um * 1e-3,
                           seed=seed, max_size=161)
    lens, system = model.lens, model.system
    rel = torch.tensor(system.rel_field, dtype=lens.dtype)
    with torch.no_grad():
        stack = compute_psfs(lens, system, rel, settings, engine=engine)
    wl = list(spec.spectrum.wavelengths_nm)
    ww, _, _ = channel_weights(camera_of(model).spectrum, 3, wl)  # rgb_weights, 3 wavelengths, or S4.1.2
    ps = PupilSampling.parse(sampling, seed=seed, path="--rays")
    with torch.no_grad():
        b = trace_bundle(lens, system, ps.points(dtype=lens.dtype, engine=engine), half_pupil=ps.half, rel_field=rel,
                         engine=engine)
        rms = (spot_stats(b, system.wavelength_weights).rms_radius * 1e3).tolist()
    save_psf_figure(output, stack, ww, title=spec.name, sqrt=sqrt, rms_um=rms, dpi=dpi)


@plot_app.command("field", short_help="Distortion and relative illumination against field.")
@handle_errors
def plot_field_cmd(lens: LensArg, output: OutOpt, sampling: SamplingOpt = "rings:16", aim: AimOpt = None,
                   aim_steps: AimStepsOpt = None,
                   points: Annotated[int, typer.Option("--points", min=2, max=401,
                                                       help="Field samples from axis to full field.")] = 21,
                   seed: SeedOpt = 0, dpi: DpiOpt = 150) -> None:
    """Distortion (spot centroid vs paraxial height) and relative illumination (three rays; all rays)
    against field (seed S48, S51, S52)."""
    from lensopt.analysis.field import field_summary
    from lensopt.plot.field import field_figure
    from lensopt.plot.style import save_figure

    out = _check_output(output)
    engine = make_engine()
    model = load_model(lens)
    summary = field_summary(model.lens, model.system, parse_sampling(sampling, seed),
                            rel_field=[i / (points - 1) for i in range(points)], aim=check_aim(aim),
                            aim_steps=check_aim_steps(aim_steps), engine=engine)
    title, sub = _titles(model)
    save_figure(field_figure(summary, title=title, subtitle=sub), out, dpi=dpi)
    err_console.print(f"wrote {output}")


@plot_app.command("regions")
@handle_errors
def plot_regions_cmd(
    lens: LensArg,
    output: Annotated[Path, typer.Option("--output", "-o", help="Figure file (png, pdf, svg).")],
    patch: Annotated[int, typer.Option("--patch", help="Tile size, pixels.")] = 256,
    batch: Annotated[int, typer.Option("--batch", help="Tiles drawn (one batch).")] = 16,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the draw.")] = 0,
    dpi: Annotated[int, typer.Option("--dpi", help="Raster resolution.")] = 150,
) -> None:
    """Sensor tiles by distance from the centre and one pseudo-random batch of them (S3.3.1, Figure S8)."""
    from lensopt.imaging.regions import RegionSampler, tile_grid
    from lensopt.imaging.simulate import sensor_of
    from lensopt.plot.regions import plot_regions
    from lensopt.plot.style import save_figure
    from lensopt.spec import camera_of

    camera = camera_of(load_model(lens))
    grid = tile_grid(sensor_of(camera, patch, patch)[0], patch, option="--patch")
    if batch < 1:
        raise LensoptError("must be at least 1", path="--batch", got=batch)
    tiles = RegionSampler(grid, seed=seed).sample(batch)
    save_figure(plot_regions(grid, tiles), output, dpi=dpi)
    err_console.print(f"wrote {output}")


@plot_app.command("mtf")
@handle_errors
def plot_mtf_cmd(
    lens: LensArg,
    output: OutOpt,
    method: Annotated[str, typer.Option("--method", help="heuristic | geometric | reference.")] = "heuristic",
    max_frequency: Annotated[float | None, typer.Option("--max-frequency", help="cycles/mm (default: "
                                                        "the diffraction cutoff).")] = None,
    points: Annotated[int, typer.Option("--points", min=2, max=401, help="Frequencies plotted.")] = 41,
    sampling: SamplingOpt = "rings:32",
    dpi: DpiOpt = 150,
) -> None:
    """Sagittal and tangential MTF against frequency for every field of the lens."""
    import torch

    from lensopt.analysis.mtf import MTF_METHODS, diffraction_limited_mtf, lens_mtf
    from lensopt.optics.paraxial import first_order
    from lensopt.plot.mtf import mtf_figure
    from lensopt.plot.style import save_figure

    out = _check_output(output)
    if method not in MTF_METHODS:
        raise LensoptError(f"must be one of {', '.join(MTF_METHODS)}", path="--method", got=method)
    engine = make_engine()
    model = load_model(lens)
    fo = first_order(model.lens, model.system)
    wn = float(fo.working_fnumber)
    ref_um = float(model.lens.wavelength_um[model.system.reference])
    top = max_frequency or 1.0 / (float(model.lens.wavelength_um.min()) * 1e-3 * abs(wn))
    if not top > 0:
        raise LensoptError("must be positive", path="--max-frequency", got=max_frequency)
    nu = torch.linspace(0.0, top, points, dtype=model.lens.dtype)
    res = lens_mtf(model.lens, model.system, nu, method=method, sampling=sampling, engine=engine)
    field_deg = None
    if model.system.field_type == "angle":
        field_deg = [r * model.system.field_max for r in model.system.rel_field]
    title, sub = _titles(model)
    limit = diffraction_limited_mtf(nu, ref_um, wn).numpy()
    save_figure(mtf_figure(res, title=title, subtitle=sub, field_deg=field_deg, limit=limit), out, dpi=dpi)
    err_console.print(f"wrote {output}")
