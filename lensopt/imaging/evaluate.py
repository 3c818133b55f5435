"""Pre-restoration image quality of a lens (seed S4.3.1): PSNR and SSIM of simulated captures.

Each scene (the central ``patch`` crop of an image, or a procedural dead-leaves scene rendered at the patch
size) is paired with a sensor tile by the pseudo-random stratified rule of S3.3.1 (``imaging.regions``):
over N scenes every tile is used ⌊N/T⌋ times and the rest are spread evenly from centre to corner. The
scene is simulated on its tile through ``lensopt simulate``'s path (``imaging.simulate``: the plan picks
the fields, PSF grid and diffraction for the tile), optionally noised and restored, and scored against
itself with scikit-image's PSNR and SSIM on sRGB-encoded values in [0, 1] (as ``lensopt simulate`` scores).
Scores are averaged over all scenes and per ring of relative tile radius (centre → corner).

``restore`` (optional) maps the capture ``[1, C, H, W]`` (linear, float32) to a restored image of the
same shape: the hook for a restoration network (issue 11); without it the scores are pre-restoration.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.imaging.camera import Camera
from lensopt.imaging.datasets import DeadLeaves, ImageFolder, center_crop, is_div2k
from lensopt.imaging.effects import add_noise
from lensopt.imaging.io import linear_to_srgb
from lensopt.imaging.metrics import psnr, ssim
from lensopt.imaging.plan import Effects, PlanOptions
from lensopt.imaging.regions import ring_of, stratified_draw, tile_grid
from lensopt.imaging.simulate import PsfCache, plan_scene, run_plan, sensor_of
from lensopt.imaging.sources import PHOTOS_HELD_OUT, photo_tiles
from lensopt.imaging.textured import TexturedLeaves

__all__ = ["EvalItem", "Evaluation", "evaluate", "scene_source"]

Restore = Callable[[torch.Tensor, dict[str, Any]], torch.Tensor]


@dataclass(frozen=True)
class EvalItem:
    """One scene: where it came from, the tile it was paired with, its scores."""

    scene: str
    tile: str
    radius_rel: float
    ring: int
    psnr_db: float
    ssim: float


@dataclass
class Evaluation:
    """Mean scores, per-ring scores (centre → corner), per-scene items and the settings used."""

    lens: str
    images: str
    count: int
    patch: int
    tiles: int
    sensor: dict[str, Any]
    seed: int
    noise_sigma: float
    restored: bool
    space: str
    psnr_db: float
    ssim: float
    rings: list[dict[str, Any]]
    items: list[EvalItem]
    notes: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)

    def as_json(self) -> dict[str, Any]:
        return asdict(self)


SceneFn = Callable[[int], torch.Tensor]


def scene_source(images: str | Path | None, *, count: int, patch: int, seed: int,
                 option: str = "--images", engine: Engine | None = None) -> tuple[SceneFn, list[str], str]:
    """The scenes to evaluate: ``(scene(k) -> [3, patch, patch] linear float32, names, description)``.

    ``images``: None or ``procedural`` (``count`` dead-leaves scenes of seed ``seed``), ``textured``
    (``count`` textured dead-leaves scenes of seed ``seed``), ``photos`` (the held-out photographs of
    ``imaging.sources``, every non-overlapping ``patch``² tile, the first ``count``), or a folder (all its
    images, or ``valid_HR/`` of a DIV2K layout; the first ``count`` in name order, central crops).
    """
    if count < 1:
        raise LensoptError("must be at least 1", path="--count", got=count)
    name = None if images is None else str(images)
    if name in (None, "procedural"):
        src = DeadLeaves(seed=seed)
        names = [f"dead-leaves:{seed}:{k}" for k in range(count)]
        return (lambda k: src.scene(k, patch, patch)), names, f"{count} dead-leaves scenes (seed {seed})"
    if name == "textured":
        tex = TexturedLeaves(seed=seed)
        names = [f"textured-leaves:{seed}:{k}" for k in range(count)]
        return (lambda k: tex.scene(k, patch, patch)), names, f"{count} textured dead-leaves scenes (seed {seed})"
    if name == "photos":
        loaders, names = photo_tiles(patch, engine=engine, option=option)
        loaders, names = loaders[:count], names[:count]
        return (lambda k: loaders[k]()), names, (f"{len(names)} {patch}² tiles of the held-out photographs "
                                                 f"({', '.join(PHOTOS_HELD_OUT)})")
    folder = ImageFolder(images, split="val" if is_div2k(images) else "all", patch=patch, option=option,
                         cache=0, engine=engine)
    n = min(count, len(folder))
    names = [str(p.relative_to(folder.root)) for p in folder.files[:n]]
    return (lambda k: center_crop(folder.load(k), patch)), names, f"{n} images from {folder.root} ({folder.layout})"


def evaluate(
    camera: Camera,
    scenes: SceneFn,
    names: list[str],
    *,
    patch: int = 256,
    seed: int = 0,
    options: PlanOptions | None = None,
    noise_sigma: float = 0.0,
    rings: int = 4,
    restore: Restore | None = None,
    images: str = "",
    progress: Callable[[int, int], None] | None = None,
    reuse_psfs: bool = True,
    engine: Engine | None = None,
) -> Evaluation:
    """Score ``len(names)`` scenes (``scenes(k)``: ``[C, patch, patch]``) simulated through ``camera``.

    Args:
        patch: scene and tile size, sensor pixels.
        seed: the scene ↔ tile pairing (and the noise).
        options: simulation settings (``lensopt simulate``'s; default ``PlanOptions()``).
        noise_sigma: additive Gaussian noise, fraction of the maximum (0: none).
        rings: rings of relative tile radius in the breakdown.
        restore: optional restoration of each capture (see the module doc).
        progress: called with (done, total) after each scene.
        reuse_psfs: compute each PSF stack (per set of traced fields) and each tile's PSF grid once and
            reuse them for later scenes (``imaging.simulate.PsfCache``: the same images as recomputing).
    """
    options = options or PlanOptions()
    if not 0.0 <= noise_sigma < 1.0:
        raise LensoptError("noise σ is a fraction of the maximum, in [0, 1)", path="--noise", got=noise_sigma)
    if rings < 1:
        raise LensoptError("must be at least 1", path="--rings", got=rings)
    count = len(names)
    sensor, notes = sensor_of(camera, patch, patch)
    grid = tile_grid(sensor, patch, option="--patch")
    draws = stratified_draw(len(grid), count, torch.Generator().manual_seed(int(seed)))
    ring_idx = ring_of(grid.radius_rel.numpy(), rings)
    timings = {"scenes": 0.0, "simulation": 0.0, "restoration": 0.0, "metrics": 0.0}
    items: list[EvalItem] = []
    pilot = None
    cache = PsfCache() if reuse_psfs else None
    for k in range(count):
        t0 = time.perf_counter()
        scene = scenes(k).to(torch.float32)
        if scene.shape[-2:] != (patch, patch):
            raise LensoptError(f"scene {names[k]} is not {patch}×{patch}", path="--images", got=tuple(scene.shape))
        img = scene.permute(1, 2, 0).contiguous().numpy()
        t1 = time.perf_counter()
        tile = int(draws[k])
        region = grid.region(tile)
        plan, pilot, out = _capture(camera, img, region, options, pilot, cache, engine,
                                    noise=(noise_sigma, int(seed) * 1_000_003 + k))
        if k == 0:
            notes += [n for n in plan.notes if n.startswith("channel weights")]
        t2 = time.perf_counter()
        if restore is not None:
            with torch.inference_mode():
                out = restore(out.unsqueeze(0), {"region": region, "plan": plan, "index": k})[0]
        t3 = time.perf_counter()
        ref_s = linear_to_srgb(img)
        out_s = linear_to_srgb(out.permute(1, 2, 0).numpy())
        items.append(EvalItem(scene=names[k], tile=region.name, radius_rel=float(grid.radius_rel[tile]),
                              ring=int(ring_idx[tile]), psnr_db=psnr(ref_s, out_s), ssim=ssim(ref_s, out_s)))
        t4 = time.perf_counter()
        for key, dt in (("scenes", t1 - t0), ("simulation", t2 - t1), ("restoration", t3 - t2),
                        ("metrics", t4 - t3)):
            timings[key] += dt
        if progress is not None:
            progress(k + 1, count)
    if restore is None:
        timings.pop("restoration")
    if cache is not None and cache.hits + cache.misses:
        notes.append(f"PSF stacks: {cache.misses} computed, reused {cache.hits} times (tiles at the same distance "
                     "from the axis share their fields)")
    ring_rows = _ring_rows(items, ring_idx, rings)
    return Evaluation(
        lens=camera.name, images=images, count=count, patch=patch, tiles=len(grid),
        sensor={"pixel_pitch_um": sensor.pitch_mm * 1e3, "resolution": [sensor.width, sensor.height],
                "grid": [grid.cols, grid.rows]},
        seed=int(seed), noise_sigma=float(noise_sigma), restored=restore is not None,
        space="sRGB-encoded [0, 1] (simulated in linear light)",
        psnr_db=float(np.mean([it.psnr_db for it in items])), ssim=float(np.mean([it.ssim for it in items])),
        rings=ring_rows, items=items, notes=notes, timings=timings)


def _capture(camera: Camera, img: np.ndarray, region: Any, options: PlanOptions, pilot: Any, cache: Any,
             engine: Engine | None, *, noise: tuple[float, int]) -> tuple[Any, Any, Tensor]:
    """(plan, pilot, capture (C, H, W)) of the scene ``img`` (H, W, C) on the sensor ``region``: simulated
    as ``lensopt simulate`` does, then the additive noise (σ, seed) ``noise``."""
    info = {"width": img.shape[1], "height": img.shape[0], "channels": img.shape[-1]}
    plan, pilot, reg, sens = plan_scene(camera, info, region=region, effects=Effects(), options=options,
                                        pilot=pilot, engine=engine)
    sigma, seed = noise
    with torch.inference_mode():
        sim = run_plan(camera, plan, pilot, reg, sens, img, options, cache=cache, engine=engine)
        out = torch.from_numpy(np.ascontiguousarray(sim.image)).permute(2, 0, 1)
        if sigma > 0:
            out = add_noise(out, sigma, seed=seed)
    return plan, pilot, out


def _ring_rows(items: list[EvalItem], ring_idx: np.ndarray, rings: int) -> list[dict[str, Any]]:
    """Mean PSNR and SSIM per ring of relative tile radius (None where no scene fell)."""
    rows = []
    for r in range(rings):
        sel = [it for it in items if it.ring == r]
        rows.append({"ring": r, "radius_rel": [r / rings, (r + 1) / rings], "count": len(sel),
                     "tiles": int((ring_idx == r).sum()),
                     "psnr_db": float(np.mean([it.psnr_db for it in sel])) if sel else None,
                     "ssim": float(np.mean([it.ssim for it in sel])) if sel else None})
    return rows
