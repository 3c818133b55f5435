"""Run a scene plan: PSFs for the planned fields and wavelengths, the PSF grid, the spatially varying
convolution, and the optional effects, timing each stage. Takes a ``Camera`` (plain data; build one from
a spec with ``lensopt.spec.camera_of``)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from lensopt.analysis.psf_stack import PsfSettings, PsfStack, compute_psfs, select_wavelengths
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.imaging.camera import Camera, ProvidesCamera, as_camera
from lensopt.imaging.convolve import overlap_add_convolve
from lensopt.imaging.effects import add_noise, apply_relative_illumination, warp_distortion
from lensopt.imaging.pilot import Pilot, run_pilot
from lensopt.imaging.plan import Effects, PlanOptions, ScenePlan, make_plan
from lensopt.imaging.psf_grid import build_psf_grid, cell_centers_mm, field_weights
from lensopt.imaging.scene import Region, Sensor, parse_region
from lensopt.optics.paraxial import first_order

__all__ = ["PsfCache", "SimulationResult", "plan_scene", "run_plan", "sensor_of"]


@dataclass
class SimulationResult:
    """The simulated (linear) image (H, W, C), the PSF grid used (or None) and stage times (s)."""

    image: np.ndarray
    psf_grid: torch.Tensor | None
    psfs: PsfStack | None
    timings: dict[str, float] = field(default_factory=dict)


@dataclass
class PsfCache:
    """PSF stacks and PSF grids already computed for one lens, reused across many scenes (``evaluate``).

    A stack depends only on the lens, the wavelengths, the traced fields and the PSF settings; a grid
    also on the region (cell centres, azimuths), the channel weights and the image pixel. Tiles at the
    same distance from the axis (mirror images, and x ↔ y on a square sensor) get the same fields, so
    their stacks are shared; a tile drawn again reuses its grid. A hit returns the tensors that the first
    computation made, so the images are bit-identical to recomputing them.
    """

    lens: object | None = None
    stacks: dict[tuple, PsfStack] = field(default_factory=dict)
    grids: dict[tuple, torch.Tensor] = field(default_factory=dict)
    hits: int = 0
    misses: int = 0

    def bind(self, lens: object) -> None:
        """Use the cache for ``lens`` (emptied when another lens comes)."""
        if self.lens is not lens:
            self.lens, self.stacks, self.grids = lens, {}, {}


@contextmanager
def _timed(timings: dict[str, float], name: str) -> Iterator[None]:
    t0 = time.perf_counter()
    yield
    timings[name] = timings.get(name, 0.0) + time.perf_counter() - t0


def sensor_of(camera: Camera | ProvidesCamera, image_w: int, image_h: int) -> tuple[Sensor, list[str]]:
    """The camera's sensor; without a resolution the image is taken to fill the sensor at its pitch."""
    camera = as_camera(camera)
    if camera.pixel_pitch_um is None:
        raise LensoptError("needed to simulate an image: give [sensor] pixel_pitch_um (and resolution)",
                           path="sensor")
    notes = []
    pitch_mm = camera.pixel_pitch_um * 1e-3
    if camera.resolution is None:
        notes.append("sensor.resolution not given: the image is taken to cover the sensor pixel for pixel")
        return Sensor(pitch_mm, image_w, image_h), notes
    return Sensor(pitch_mm, int(camera.resolution[0]), int(camera.resolution[1])), notes


def plan_scene(
    camera: Camera | ProvidesCamera, image_info: dict[str, Any], *, region: str | Region | None,
    effects: Effects, options: PlanOptions, timings: dict[str, float] | None = None, pilot: Pilot | None = None,
               engine: Engine | None = None,
) -> tuple[ScenePlan, Pilot, Region, Sensor]:
    """Make the plan (runs only the cheap pilot trace, or reuses ``pilot`` from an earlier plan of the
    same camera). ``region``: ``--region`` text or a ``Region`` (e.g. ``TileGrid.region(k)``)."""
    timings = {} if timings is None else timings
    camera = as_camera(camera)
    sensor, notes = sensor_of(camera, image_info["width"], image_info["height"])
    reg = region if isinstance(region, Region) else parse_region(region, sensor, image_info["width"],
                                                                 image_info["height"])
    if pilot is None:
        with _timed(timings, "pilot trace"):
            pilot = run_pilot(camera.lens, camera.system, camera.system.wavelength_weights, engine=engine)
    plan = make_plan(lens_name=camera.name, spectrum=camera.spectrum, sensor=sensor, region=reg,
                     image=image_info, pilot=pilot, effects=effects, options=options, notes=notes)
    return plan, pilot, reg, sensor


def run_plan(camera: Camera | ProvidesCamera, plan: ScenePlan, pilot: Pilot, region: Region, sensor: Sensor,
             image: np.ndarray, options: PlanOptions, timings: dict[str, float] | None = None,
             cache: PsfCache | None = None, *, engine: Engine | None = None) -> SimulationResult:
    """Simulate ``image`` (H, W, C linear float32) as planned, on the device of the camera's lens (the
    result comes back as a NumPy array). ``cache``: reuse PSF stacks and grids of earlier scenes of the
    same camera (``PsfCache``; same images)."""
    timings = {} if timings is None else timings
    camera = as_camera(camera)
    device = camera.lens.device
    # (C, H, W): no copy when ``image`` is the (H, W, C) view of a planar buffer (``read_image`` returns one)
    source = torch.from_numpy(np.asarray(image, dtype=np.float32)).permute(2, 0, 1).contiguous().to(device)
    out = source
    eff = plan.effects
    px_mm = plan.pixel_um * 1e-3
    if eff["distortion"]["on"]:
        with _timed(timings, "distortion warp"):
            out = warp_distortion(out, pilot, region, sensor)
    if eff["relative_illumination"]["on"]:
        with _timed(timings, "relative illumination"):
            out = apply_relative_illumination(out, pilot, region, sensor)
    grid = stack = None
    if eff["convolution"]["on"]:
        lens, system = select_wavelengths(camera.lens, camera.system, plan.wavelength_index)
        settings = PsfSettings(sampling=options.sampling, kernel=options.kernel, support=options.support,
                               pitch_mm=plan.psf["pitch_um"] * 1e-3, oversample=options.oversample,
                               diffraction="heuristic" if plan.diffraction["on"] else "none", seed=options.seed)
        key = (tuple(plan.wavelength_index), tuple(plan.fields_relative), settings)
        grid_key = (key, region, plan.psf_grid, tuple(map(tuple, plan.channel_weights)), px_mm)
        if cache is not None:
            cache.bind(camera.lens)
            stack, grid = cache.stacks.get(key), cache.grids.get(grid_key)
            cache.hits += stack is not None
            cache.misses += stack is None
        if stack is None:
            with _timed(timings, "trace + PSFs"), torch.no_grad():
                rel = torch.tensor(plan.fields_relative, dtype=lens.dtype, device=device)
                fo = first_order(camera.lens, camera.system)
                stack = compute_psfs(lens, system, rel, settings, fo=fo, engine=engine)
        if grid is None:
            with _timed(timings, "PSF grid"), torch.no_grad():
                radius = np.abs(stack.center[:, 1].cpu().numpy())
                wf = torch.from_numpy(field_weights(radius, region, sensor, plan.psf_grid)).to(device)
                ww = torch.tensor(plan.channel_weights, dtype=torch.float64, device=device)
                grid = build_psf_grid(stack.psf, ww, wf, cell_centers_mm(region, sensor, plan.psf_grid),
                                      pitch_mm=stack.pitch_mm, pixel_mm=px_mm).to(torch.float32)
        if cache is not None:
            cache.stacks[key], cache.grids[grid_key] = stack, grid
        with _timed(timings, "convolution"):
            out = overlap_add_convolve(out, grid, overlap=plan.overlap)
    if eff["noise"]["on"]:
        with _timed(timings, "noise"):
            out = add_noise(out, eff["noise"]["sigma"], seed=eff["noise"]["seed"])
    if out is source:  # nothing applied: never hand back the caller's own buffer
        out = out.clone()
    del source
    result = out.permute(1, 2, 0).cpu().numpy()  # on the CPU a view; made contiguous by the caller if needed
    return SimulationResult(result, grid, stack, timings)
