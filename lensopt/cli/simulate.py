"""``lensopt simulate`` and ``lensopt evaluate``: images through the lens (CLI layer: parse options, call
``lensopt.imaging``, render with rich). ``run_simulate`` is the command's glue (spec in, plain data out)."""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from lensopt.cli.common import (
    BackendOpt,
    DeviceOpt,
    JsonOpt,
    LensArg,
    SeedOpt,
    check_output,
    console,
    err_console,
    handle_errors,
    load_model,
    make_engine,
    print_json,
)
from lensopt.errors import LensoptError

if TYPE_CHECKING:
    from lensopt.engine import Engine
    from lensopt.spec import Model

__all__ = ["commands", "parse_grid", "run_simulate"]

commands = typer.Typer()  # its commands, put in order by lensopt.cli.app


@commands.command("simulate", short_help="Simulate a scene image through the lens.")
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
                                                   "(PSNR/SSIM); implies --score.")] = None,
    score: Annotated[bool, typer.Option("--score", help="Score PSNR/SSIM against the input scene (or "
                                        "--reference); off by default: it costs more than the simulation.")] = False,
    plan_only: Annotated[bool, typer.Option("--plan", help="Print the plan and stop (nothing simulated).")] = False,
    rays: Annotated[str, typer.Option("--rays", help="Pupil sampling per PSF (rings:N = 2N² rays).")] = "rings:32",
    kernel: Annotated[str, typer.Option("--kernel", help="PSF from the rays: count (histogram) | "
                                                       "triangular | cosine (kernel density).")] = "triangular",
    grid: Annotated[str | None, typer.Option("--grid", help="Force the PSF grid, e.g. 5x4.")] = None,
    overlap: Annotated[float, typer.Option("--overlap", help="Overlap of neighbouring PSF patches, "
                                                          "fraction of a patch.")] = 0.25,
    seed: SeedOpt = 0,
    as_json: JsonOpt = False,
    backend: BackendOpt = "auto",
    device: DeviceOpt = "cpu",
) -> None:
    """Simulate a scene through the lens, computing only the effects the scene calls for."""
    from lensopt.devices import resolve_device

    engine = make_engine(backend)
    dev = resolve_device(device)
    psf_grid = parse_grid(grid)
    if psf_grid is not None:  # each cell holds RGB PSFs of up to 161×161 float32 bins, a few copies
        engine.require(psf_grid[0] * psf_grid[1] * 161 * 161 * 3 * 4 * 4, f"a {grid} PSF grid", lower="--grid",
                       path="--grid")

    if not plan_only and output is None:
        raise LensoptError("needed unless --plan", path="--output")
    if output is not None:
        check_output(output, (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr"), what="image file")
    if not 0.0 <= overlap < 1.0:
        raise LensoptError("must lie in [0, 1)", path="--overlap", got=overlap)
    result = run_simulate(load_model(lens, dev), image, output, region=region, effects=effects, reference=reference,
                          plan_only=plan_only, sampling=rays, kernel=kernel, grid=psf_grid, overlap=overlap,
                          seed=seed, on_plan=None if as_json else render_plan, score=score, engine=engine)
    if as_json:
        print_json(result)
    elif not plan_only:
        render_run(result)


def parse_grid(text: str | None) -> tuple[int, int] | None:
    """``5x4`` → (5, 4) (columns × rows)."""
    if text is None:
        return None
    m = re.fullmatch(r"\s*(\d+)\s*[x×]\s*(\d+)\s*", text)
    if not m or int(m.group(1)) < 1 or int(m.group(2)) < 1:
        raise LensoptError("expected WxH with positive integers, e.g. 5x4", path="--grid", got=text)
    return int(m.group(1)), int(m.group(2))


def run_simulate(
    model: Model,
    image_path: Path,
    output: Path | None,
    *,
    region: str | None = None,
    effects: str | None = None,
    reference: Path | None = None,
    plan_only: bool = False,
    sampling: str = "rings:32",
    kernel: str = "triangular",
    grid: tuple[int, int] | None = None,
    overlap: float = 0.25,
    seed: int = 0,
    on_plan: Callable[[dict[str, Any]], None] | None = None,
    score: bool = False,
    engine: Engine | None = None,
) -> dict[str, Any]:
    """Plan, report the plan through ``on_plan`` (before running), simulate, write, and score (PSNR/SSIM)
    against ``reference``, or against the input scene when ``score`` — only when asked: SSIM of a
    4000 × 3000 image costs seconds and gigabytes, more than the simulation itself.

    Returns the plan (``plan_only``) or {plan, timings, output, encodings, metrics}.
    """
    import torch

    from lensopt.analysis.psf import KERNELS
    from lensopt.imaging.io import read_image, write_image
    from lensopt.imaging.plan import PlanOptions, parse_effects
    from lensopt.imaging.simulate import plan_scene, run_plan
    from lensopt.optics.sampling import PupilSampling
    from lensopt.spec.build import camera_of
    if kernel not in KERNELS:
        raise LensoptError(f"must be one of {', '.join(KERNELS)}", path="--kernel", got=kernel)
    PupilSampling.parse(sampling, path="--rays")
    # Every stage is timed, reading and writing included, so that the table accounts for the wall time.
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    img, info = read_image(image_path, option="IMAGE", engine=engine)
    timings["read image"] = time.perf_counter() - t0
    opts = PlanOptions(sampling=sampling, kernel=kernel, grid=grid, overlap=overlap, seed=seed)
    image_info = {"width": info.width, "height": info.height, "channels": info.channels, "bits": info.bits,
                  "encoding": info.encoding, "format": info.format, "path": str(image_path)}
    camera = camera_of(model)
    plan, pilot, reg, sensor = plan_scene(camera, image_info, region=region, effects=parse_effects(effects),
                                          options=opts, timings=timings, engine=engine)
    plan_json = plan.as_json()
    if on_plan is not None:
        on_plan(plan_json)
    if plan_only:
        return plan_json
    assert output is not None  # checked by the caller
    with torch.inference_mode():
        res = run_plan(camera, plan, pilot, reg, sensor, img, opts, timings, engine=engine)
    if reference is not None or not score:  # the scene is needed now only to score against it: free it
        del img
    t0 = time.perf_counter()
    encoding = write_image(output, res.image, info)
    timings["write image"] = time.perf_counter() - t0
    metrics = None
    if reference is not None or score:
        import lensopt.imaging.metrics  # noqa: F401 - skimage (and scipy), imported only when scoring, untimed

        t0 = time.perf_counter()
        metrics = _score(res.image, img if reference is None else None, reference, engine)
        timings["scores (PSNR, SSIM)"] = time.perf_counter() - t0
    return {"plan": plan_json, "timings": timings, "output": str(output), "output_encoding": encoding,
            "input_encoding": f"{info.encoding} {info.bits}-bit {'float' if info.is_float else 'integer'}"
                              + (" (linearized)" if info.encoding == "sRGB" else ""),
            "metrics": metrics}


def _score(image: Any, scene: Any, reference: Path | None, engine: Engine | None) -> dict[str, Any]:
    """PSNR and SSIM (sRGB-encoded) of the simulated ``image`` against ``reference`` (a file of its shape) or
    else against the input ``scene``."""
    from lensopt.imaging.io import linear_to_srgb, read_image
    from lensopt.imaging.metrics import psnr, ssim  # skimage (and scipy) only when scoring

    if reference is not None:
        ref, _ = read_image(reference, option="--reference", engine=engine)
        if ref.shape != image.shape:
            raise LensoptError(f"must have the simulated image's shape {image.shape}", path="--reference",
                               got=ref.shape)
        against = str(reference)
    else:
        ref, against = scene, "the input scene"
    return {"against": against, "psnr_db": psnr(ref, image, transform=linear_to_srgb),
            "ssim": ssim(ref, image, transform=linear_to_srgb), "space": "sRGB-encoded [0, 1]"}


def render_plan(p: dict[str, Any]) -> None:
    """The simulation plan as a table (before the run)."""
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


def render_run(r: dict[str, Any]) -> None:
    """Stage timings, scores and the file written."""
    t = Table(title="stages")
    t.add_column("stage")
    t.add_column("s", justify="right")
    for k, v in r["timings"].items():
        t.add_row(k, f"{v:.3f}")
    console.print(t)
    m = r.get("metrics")
    if m:
        psnr = "∞ (identical)" if m["psnr_db"] == math.inf else f"{m['psnr_db']:.2f} dB"
        ssim = f"{m['ssim']:.4f}" if math.isfinite(m["ssim"]) else "— (image smaller than the 11-pixel window)"
        console.print(f"vs {m['against']}: PSNR {psnr}, SSIM {ssim} ({m['space']})")
    err_console.print(f"wrote {r['output']} ({r['output_encoding']}; input {r['input_encoding']})", highlight=False)


@commands.command("evaluate")
@handle_errors
def evaluate(
    lens: LensArg,
    images: Annotated[str | None, typer.Option("--images", help="Folder of PNG/JPEG/TIFF/EXR images (DIV2K: "
                                               "its valid_HR/), or photos (tiles of the held-out bundled "
                                               "photographs), textured (textured dead leaves); default: "
                                               "procedural dead-leaves scenes.")] = None,
    count: Annotated[int, typer.Option("--count", help="Number of scenes (images: the first N by name).")] = 100,
    patch: Annotated[int, typer.Option("--patch", help="Central crop and sensor tile size, pixels.")] = 256,
    rays: Annotated[str, typer.Option("--rays", help="Pupil sampling per PSF (rings:N = 2N² rays).")] = "rings:32",
    kernel: Annotated[str, typer.Option("--kernel", help="PSF from the rays: count (histogram) | "
                                                       "triangular | cosine (kernel density).")] = "triangular",
    grid: Annotated[str | None, typer.Option("--grid", help="Force the PSF grid per tile, e.g. 3x3 "
                                             "(default: the simulation plan's choice).")] = None,
    noise: Annotated[float, typer.Option("--noise", help="Additive Gaussian noise σ, fraction of the maximum "
                                         "(the seed's training value: 0.005).")] = 0.0,
    rings: Annotated[int, typer.Option("--rings", help="Rings of relative tile radius in the breakdown.")] = 4,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the scene ↔ tile pairing, the dead-leaves "
                                      "scenes, the noise and the pupil jitter.")] = 0,
    as_json: JsonOpt = False,
    irm: Annotated[Path | None, typer.Option("--irm", help="Restoration network checkpoint (train-irm or "
                                             "joint): score before and after restoration.")] = None,
    backend: BackendOpt = "auto",
    device: DeviceOpt = "cpu",
) -> None:
    """Pre-restoration PSNR and SSIM of central crops, each paired with a sensor tile (S4.3.1)."""
    from lensopt.devices import resolve_device
    from lensopt.imaging.evaluate import evaluate as run_evaluate
    from lensopt.imaging.evaluate import scene_source
    from lensopt.imaging.plan import PlanOptions
    from lensopt.optics.sampling import PupilSampling
    from lensopt.spec import camera_of

    engine = make_engine(backend)
    dev = resolve_device(device)
    if patch < 8:
        raise LensoptError("must be at least 8 pixels", path="--patch", got=patch)
    PupilSampling.parse(rays, path="--rays")
    from lensopt.analysis.psf import KERNELS

    if kernel not in KERNELS:
        raise LensoptError(f"must be one of {', '.join(KERNELS)}", path="--kernel", got=kernel)
    from lensopt.imaging.regions import tile_grid
    from lensopt.imaging.simulate import sensor_of

    model = load_model(lens, dev)
    camera = camera_of(model)
    tile_grid(sensor_of(camera, patch, patch)[0], patch, option="--patch")  # bad sensor/patch: before the bar
    scenes, names, desc = scene_source(images, count=count, patch=patch, seed=seed, engine=engine)
    options = PlanOptions(sampling=rays, kernel=kernel, grid=parse_grid(grid), seed=seed)
    hooks: list[Any] = [None]
    if irm is not None:
        from lensopt.restore.apply import restoration_hook

        hooks.append(restoration_hook(model, irm, engine=engine))
    results = []
    for hook in hooks:
        with Progress(TextColumn("evaluating" if hook is None else "restoring"), BarColumn(),
                      MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(), console=err_console,
                      transient=True, disable=as_json) as bar:
            task = bar.add_task("scenes", total=len(names))
            results.append(run_evaluate(camera, scenes, names, patch=patch, seed=seed, options=options,
                                        noise_sigma=noise, rings=rings, images=desc, restore=hook, engine=engine,
                                        progress=lambda done, total, b=bar, t=task: b.update(t, completed=done)))
    if as_json:
        out = results[0].as_json()
        if len(results) > 1:
            out["after_restoration"] = results[1].as_json()
        print_json(out)
    else:
        for result in results:
            _render_evaluation(result.as_json())


def _render_evaluation(r: dict[str, Any]) -> None:
    s = r["sensor"]
    title = (f"{r['lens']}: {r['images']}, central {r['patch']}² crops on {r['tiles']} tiles "
             f"({s['grid'][0]}×{s['grid'][1]} of a {s['resolution'][0]}×{s['resolution'][1]} sensor, "
             f"{s['pixel_pitch_um']:g} µm)")
    t = Table(title=title)
    for col in ("ring (relative radius)", "tiles", "scenes", "PSNR dB", "SSIM"):
        t.add_column(col, justify="left" if col.startswith("ring") else "right")
    for row in r["rings"]:
        lo, hi = row["radius_rel"]
        t.add_row(f"{row['ring']} ({lo:.2f}–{hi:.2f})", str(row["tiles"]), str(row["count"]),
                  "—" if row["psnr_db"] is None else f"{row['psnr_db']:.2f}",
                  "—" if row["ssim"] is None else f"{row['ssim']:.4f}")
    t.add_row("[bold]all[/]", str(r["tiles"]), str(r["count"]), f"[bold]{r['psnr_db']:.2f}[/]",
              f"[bold]{r['ssim']:.4f}[/]")
    console.print(t)
    what = "restored" if r["restored"] else "pre-restoration"
    noise = f", noise σ = {r['noise_sigma']:g}" if r["noise_sigma"] > 0 else ", no noise"
    console.print(f"{what} PSNR {r['psnr_db']:.2f} dB, SSIM {r['ssim']:.4f} ({r['space']}{noise}; seed {r['seed']})")
    for note in r["notes"]:
        console.print(f"note: {note}")
    console.print("time: " + ", ".join(f"{k} {v:.1f} s" for k, v in r["timings"].items()))
