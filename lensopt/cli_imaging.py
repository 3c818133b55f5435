"""CLI glue for ``lensopt simulate`` and ``lensopt plot psf``: spec in, library calls, plain data out
(``lensopt.cli`` parses options and renders). Lives in the CLI layer: it reads the spec and imports
``plot``; the imaging core below takes a ``Camera``."""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

from lensopt.analysis.psf import KERNELS
from lensopt.analysis.psf_stack import PsfSettings, compute_psfs
from lensopt.analysis.spot import spot_stats
from lensopt.errors import LensoptError
from lensopt.imaging.io import linear_to_srgb, read_image, write_image
from lensopt.imaging.plan import PlanOptions, channel_weights, parse_effects
from lensopt.imaging.simulate import plan_scene, run_plan
from lensopt.optics.sampling import PupilSampling
from lensopt.spec.build import Model, camera_of

__all__ = ["parse_grid", "run_simulate", "plot_psfs", "render_plan", "render_run"]


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
) -> dict[str, Any]:
    """Plan, report the plan through ``on_plan`` (before running), simulate, write, and score (PSNR/SSIM)
    against ``reference``, or against the input scene when ``score`` — only when asked: SSIM of a
    4000 × 3000 image costs seconds and gigabytes, more than the simulation itself.

    Returns the plan (``plan_only``) or {plan, timings, output, encodings, metrics}.
    """
    if kernel not in KERNELS:
        raise LensoptError(f"must be one of {', '.join(KERNELS)}", path="--kernel", got=kernel)
    PupilSampling.parse(sampling, path="--rays")
    # Every stage is timed, reading and writing included, so that the table accounts for the wall time.
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    img, info = read_image(image_path, option="IMAGE")
    timings["read image"] = time.perf_counter() - t0
    opts = PlanOptions(sampling=sampling, kernel=kernel, grid=grid, overlap=overlap, seed=seed)
    image_info = {"width": info.width, "height": info.height, "channels": info.channels, "bits": info.bits,
                  "encoding": info.encoding, "format": info.format, "path": str(image_path)}
    camera = camera_of(model)
    plan, pilot, reg, sensor = plan_scene(camera, image_info, region=region, effects=parse_effects(effects),
                                          options=opts, timings=timings)
    plan_json = plan.as_json()
    if on_plan is not None:
        on_plan(plan_json)
    if plan_only:
        return plan_json
    assert output is not None  # checked by the caller
    with torch.inference_mode():
        res = run_plan(camera, plan, pilot, reg, sensor, img, opts, timings)
    if reference is not None or not score:  # the scene is needed now only to score against it: free it
        del img
    t0 = time.perf_counter()
    encoding = write_image(output, res.image, info)
    timings["write image"] = time.perf_counter() - t0
    metrics = None
    if reference is not None or score:
        from lensopt.imaging.metrics import psnr, ssim  # skimage (and scipy) only when scoring

        t0 = time.perf_counter()
        if reference is not None:
            ref, _ = read_image(reference, option="--reference")
            if ref.shape != res.image.shape:
                raise LensoptError(f"must have the simulated image's shape {res.image.shape}", path="--reference",
                                   got=ref.shape)
            against = str(reference)
        else:
            ref, against = img, "the input scene"
        metrics = {"against": against, "psnr_db": psnr(ref, res.image, transform=linear_to_srgb),
                   "ssim": ssim(ref, res.image, transform=linear_to_srgb), "space": "sRGB-encoded [0, 1]"}
        timings["scores (PSNR, SSIM)"] = time.perf_counter() - t0
    return {"plan": plan_json, "timings": timings, "output": str(output), "output_encoding": encoding,
            "input_encoding": f"{info.encoding} {info.bits}-bit {'float' if info.is_float else 'integer'}"
                              + (" (linearized)" if info.encoding == "sRGB" else ""),
            "metrics": metrics}


def plot_psfs(model: Model, output: Path, *, sampling: str = "rings:32", kernel: str = "triangular",
              diffraction: str = "heuristic", pitch_um: float | None = None, sqrt: bool = False,
              seed: int = 0, dpi: int = 150) -> None:
    """RGB PSFs at the spec's fields, bins of ``pitch_um`` (default: the sensor pitch, else 1 µm)."""
    from lensopt.plot.psf import save_psf_figure

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
        stack = compute_psfs(lens, system, rel, settings)
    wl = list(spec.spectrum.wavelengths_nm)
    ww, _, _ = channel_weights(camera_of(model).spectrum, 3, wl)  # rgb_weights, 3 wavelengths, or S4.1.2
    from lensopt.optics.bundle import trace_bundle

    ps = PupilSampling.parse(sampling, seed=seed, path="--rays")
    with torch.no_grad():
        b = trace_bundle(lens, system, ps.points(dtype=lens.dtype), half_pupil=ps.half, rel_field=rel)
        rms = (spot_stats(b, system.wavelength_weights).rms_radius * 1e3).tolist()
    save_psf_figure(output, stack, ww, title=spec.name, sqrt=sqrt, rms_um=rms, dpi=dpi)


def render_plan(p: dict[str, Any]) -> None:
    """The simulation plan as a table (before the run)."""
    from rich.table import Table

    from lensopt.cli_common import console

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
    import math

    from rich.table import Table

    from lensopt.cli_common import console, err_console

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
