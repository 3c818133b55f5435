"""Training the restoration network on a fixed lens (S4.3.2; the network step of S3.3.1).

One step: a batch of scene patches and pseudo-random sensor tiles (``imaging.regions``), the captures
through the lens (``imaging.render``: per-tile 3×3 PSF grid, overlap-add, 0.5 % noise), the conditioned
network restores them with the mean of each tile's sub-tile PSFs, Adam on the MAE with a cosine
learning rate. Every random draw comes from three seeded ``torch.Generator``s (scenes, tiles, noise),
so a checkpoint (``lensopt.checkpoint``) holding their states, the weights and Adam's moments continues
bit-identically.

The loop stops cleanly at a step boundary when ``stop()`` returns true (the CLI sets it on Ctrl-C or
SIGTERM) and checkpoints there.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import torch
from torch import Tensor, nn

from lensopt.errors import LensoptError
from lensopt.imaging.camera import Camera
from lensopt.imaging.convolve import overlap_add_convolve
from lensopt.imaging.datasets import DeadLeaves, ImageFolder, sample_batch
from lensopt.imaging.plan import channel_weights as plan_channel_weights
from lensopt.imaging.psf_grid import build_psf_grid, cell_centers_mm, field_weights
from lensopt.imaging.regions import TileGrid, stratified_draw, tile_grid
from lensopt.imaging.render import RenderSettings, psfs_from_spots, trace_spots
from lensopt.imaging.scene import Region, Sensor
from lensopt.optics.lens import Lens, System
from lensopt.optics.sampling import PupilSampling
from lensopt.restore.config import TrainConfig
from lensopt.restore.model import mean_patch_psf

__all__ = ["ImagingSetup", "imaging_setup", "lens_psfs", "region_grids", "capture", "cosine_lr", "psnr_db",
           "NetworkRun", "network_step", "validation_set", "validate", "train_network", "make_optimizer",
           "run_state", "load_run_state", "draw_batch", "GridCache", "region_grids_for"]

Source = DeadLeaves | ImageFolder


@dataclass(frozen=True)
class ImagingSetup:
    """How batches are simulated for a lens (everything but the lens tensors themselves).

    Attributes:
        sensor: the sensor; tiles: its patch-sized tiles sorted centre → corner.
        rel_field: (F,) relative fields whose PSFs are traced (0 … 1 of the system's field).
        sampling: pupil sampling of the PSF rays.
        channel_weights: (W, C) wavelength → channel weights.
        settings: PSF size, sub-tile grid, overlap, kernel, noise σ.
        channels: image channels C (3: RGB; 1: the spectrum summed into one channel).
    """

    sensor: Sensor
    tiles: TileGrid
    rel_field: Tensor
    sampling: PupilSampling
    channel_weights: Tensor
    settings: RenderSettings
    channels: int
    sampling_text: str = "rings:8"

    @property
    def patch(self) -> int:
        return self.tiles.patch[0]

    def describe(self) -> dict[str, Any]:
        s = self.settings
        return {"patch": self.patch, "sampling": self.sampling_text, "sensor": [self.sensor.width, self.sensor.height],
                "fields": len(self.rel_field),
                "psf_size": s.psf_size, "grid": list(s.grid), "overlap": s.overlap, "channels": self.channels,
                "noise_sigma": s.noise_sigma}


def imaging_setup(camera: Camera, *, patch: int, fields: int = 9, sampling: str = "rings:8", psf_size: int = 31,
                  grid: tuple[int, int] = (3, 3), noise_sigma: float = 0.005, diffraction: bool = False,
                  dtype: torch.dtype = torch.float64, device: torch.device | str | None = None) -> ImagingSetup:
    """The setup for a lens on its sensor (``lensopt.spec.camera_of(model)`` / ``model.camera()``): the
    sensor's pitch and resolution are required; RGB if the spectrum gives ``rgb_weights`` or has 3
    wavelengths, else one channel."""
    if camera.pixel_pitch_um is None or camera.resolution is None:
        raise LensoptError("needs pixel_pitch_um and resolution to simulate captures", path="sensor")
    w, h = camera.resolution
    sensor = Sensor(camera.pixel_pitch_um * 1e-3, int(w), int(h))
    wl = list(camera.spectrum.wavelengths_nm)
    channels = 3 if (camera.spectrum.rgb_weights is not None or len(wl) == 3) else 1
    cw, _, _ = plan_channel_weights(camera.spectrum, channels, wl)
    settings = RenderSettings(psf_size=psf_size, grid=grid, noise_sigma=noise_sigma, diffraction=diffraction)
    rel = torch.linspace(0.0, 1.0, fields, dtype=dtype, device=device) if fields > 1 else torch.zeros(
        1, dtype=dtype, device=device)
    return ImagingSetup(sensor=sensor, tiles=tile_grid(sensor, patch, option="--patch"), rel_field=rel,
                        sampling=PupilSampling.parse(sampling, seed=0, path="--sampling"),
                        channel_weights=torch.as_tensor(cw, dtype=dtype, device=device), settings=settings,
                        channels=channels, sampling_text=sampling)


def lens_psfs(lens: Lens, system: System, setup: ImagingSetup) -> tuple[Tensor, Tensor]:
    """Field PSFs (F, W, S, S) at the sensor pitch and their centres (F, 2), differentiable in the lens."""
    sp = setup.sampling
    spots = trace_spots(lens, system, setup.rel_field.to(lens.dtype), sp.points(dtype=lens.dtype, device=lens.device),
                        half=sp.half)
    return psfs_from_spots(spots.xy, spots.valid, spots.wavelength_weights, half=spots.half,
                           pitch_mm=setup.sensor.pitch_mm, settings=setup.settings)


def region_grids(psf: Tensor, center: Tensor, regions: list[Region], setup: ImagingSetup) -> Tensor:
    """(B, H_g, W_g, C, K, K) PSF grids of the patches at ``regions`` (S1.5.1), as ``render_batch``."""
    return region_grids_for(psf, center, regions, setup.sensor, setup.channel_weights, setup.settings)


def region_grids_for(psf: Tensor, center: Tensor, regions: list[Region], sensor: Sensor, channel_weights: Tensor,
                     settings: RenderSettings) -> Tensor:
    """``region_grids`` with the sensor, channel weights and settings given one by one."""
    import numpy as np

    radius = np.abs(center[:, 1].detach().cpu().double().numpy())
    out = []
    for region in regions:
        wf = torch.from_numpy(field_weights(radius, region, sensor, settings.grid)).to(psf.device)
        out.append(build_psf_grid(psf, channel_weights, wf, cell_centers_mm(region, sensor, settings.grid),
                                  pitch_mm=sensor.pitch_mm, pixel_mm=region.pixel_mm(sensor)[0]))
    return torch.stack(out)


def capture(images: Tensor, grids: Tensor, settings: RenderSettings, noise: Tensor | None) -> Tensor:
    """Captures (B, C, H, W) of ``images`` through the PSF ``grids``; ``noise`` (B, C, H, W) standard
    normal draws scaled by σ × each image's maximum (S3.3.1), or None."""
    out = torch.stack([overlap_add_convolve(img, g.to(images.dtype), overlap=settings.overlap)
                       for img, g in zip(images, grids, strict=True)])
    if noise is not None and settings.noise_sigma > 0:
        peak = out.detach().amax((1, 2, 3), keepdim=True).clamp_min(0.0)
        out = out + settings.noise_sigma * peak * noise
    return out


def cosine_lr(step: int, steps: int, lr: float, lr_min: float = 0.0) -> float:
    """Cosine schedule: ``lr`` at step 0 down to ``lr_min`` at ``steps``."""
    return lr_min + 0.5 * (lr - lr_min) * (1.0 + math.cos(math.pi * min(step, steps) / max(steps, 1)))


def psnr_db(reference: Tensor, test: Tensor) -> Tensor:
    """(B,) PSNR in dB of each image against its reference (data range 1)."""
    mse = ((test.clamp(0, 1) - reference) ** 2).flatten(1).mean(1)
    return 10 * torch.log10(1.0 / mse.clamp_min(1e-20))


def make_optimizer(model: nn.Module, cfg: TrainConfig) -> torch.optim.Adam:
    return torch.optim.Adam(model.parameters(), lr=cfg.lr, betas=tuple(cfg.betas))


@dataclass
class NetworkRun:
    """The mutable state of a network-training run (what a checkpoint holds)."""

    model: nn.Module
    optimizer: torch.optim.Optimizer
    generators: dict[str, torch.Generator]
    step: int = 0
    history: list[dict[str, float]] = field(default_factory=list)

    @staticmethod
    def fresh(model: nn.Module, cfg: TrainConfig, seed: int) -> NetworkRun:
        gens = {name: torch.Generator().manual_seed(seed * 1000 + k) for k, name in
                enumerate(("scenes", "tiles", "noise"))}
        return NetworkRun(model=model, optimizer=make_optimizer(model, cfg), generators=gens)


def draw_batch(source: Source, setup: ImagingSetup, batch: int, gens: dict[str, torch.Generator], *,
               dtype: torch.dtype = torch.float32, device: torch.device | str | None = None
               ) -> tuple[Tensor, Tensor, Tensor]:
    """(scenes (B, C, P, P), tile indices (B,), standard normal noise (B, C, P, P)) from the generators."""
    scenes = sample_batch(source, batch, setup.patch, gens["scenes"], dtype=dtype)
    if setup.channels == 1 and scenes.shape[1] != 1:
        scenes = scenes.mean(1, keepdim=True)
    tiles = stratified_draw(len(setup.tiles), batch, gens["tiles"])
    noise = torch.randn(scenes.shape, generator=gens["noise"], dtype=dtype)
    return scenes.to(device), tiles, noise.to(device)


def network_step(model: nn.Module, optimizer: torch.optim.Optimizer, captured: Tensor, kpsf: Tensor,
                 target: Tensor, lr: float) -> float:
    """One Adam step on the MAE between restored captures and scenes (lens frozen); returns the loss."""
    for g in optimizer.param_groups:
        g["lr"] = lr
    optimizer.zero_grad(set_to_none=True)
    loss = (model(captured, kpsf) - target).abs().mean()
    loss.backward()
    optimizer.step()
    return float(loss.detach())


class GridCache:
    """PSF grids of a fixed lens, per tile index (computed once, no gradient)."""

    def __init__(self, psf: Tensor, center: Tensor, setup: ImagingSetup) -> None:
        self.psf, self.center, self.setup = psf.detach(), center.detach(), setup
        self.grids: dict[int, Tensor] = {}

    def __call__(self, tiles: Tensor) -> Tensor:
        missing = [int(t) for t in tiles.tolist() if int(t) not in self.grids]
        if missing:
            with torch.no_grad():
                new = region_grids(self.psf, self.center, [self.setup.tiles.region(t) for t in missing], self.setup)
            self.grids.update(zip(missing, new, strict=True))
        return torch.stack([self.grids[int(t)] for t in tiles.tolist()])


@dataclass(frozen=True)
class ValidationSet:
    scenes: Tensor
    tiles: Tensor
    noise: Tensor


def validation_set(source: Source, setup: ImagingSetup, count: int, *, seed: int = 12345) -> ValidationSet:
    """Held-out patches (from the validation source), tiles covering the field evenly (S4.3.1), noise."""
    gens = {name: torch.Generator().manual_seed(seed + k) for k, name in enumerate(("scenes", "tiles", "noise"))}
    scenes, tiles, noise = draw_batch(source, setup, count, gens)
    return ValidationSet(scenes, tiles, noise)


def validate(model: nn.Module, grids_of: Callable[[Tensor], Tensor], val: ValidationSet, setup: ImagingSetup, *,
             chunk: int = 8, examples: dict[str, Tensor] | None = None) -> dict[str, float]:
    """Mean PSNR (dB) and MAE of the captures and of their restorations on the validation set.

    ``examples`` (a dict) receives the first chunk's scenes, captures, restorations and conditioning
    PSFs (for TensorBoard images)."""
    raw, rest, mae = [], [], []
    device = next(model.parameters()).device
    with torch.no_grad():
        for i in range(0, len(val.tiles), chunk):
            sl = slice(i, i + chunk)
            scenes = val.scenes[sl].to(device)
            grids = grids_of(val.tiles[sl]).to(device)
            cap = capture(scenes, grids, setup.settings, val.noise[sl].to(device))
            kpsf = mean_patch_psf(grids.flatten(1, 2)).to(cap.dtype)
            out = model(cap, kpsf)
            if examples is not None and i == 0:
                examples.update(scene=scenes, capture=cap, restored=out, psf=kpsf)
            raw.append(psnr_db(scenes, cap))
            rest.append(psnr_db(scenes, out))
            mae.append((out - scenes).abs().flatten(1).mean(1))
    return {"psnr_raw": float(torch.cat(raw).mean()), "psnr_restored": float(torch.cat(rest).mean()),
            "mae": float(torch.cat(mae).mean())}


def train_network(
    run: NetworkRun,
    lens: Lens,
    system: System,
    setup: ImagingSetup,
    source: Source,
    cfg: TrainConfig,
    *,
    steps: int,
    val: ValidationSet | None = None,
    checkpoint: Callable[[NetworkRun], None] | None = None,
    on_progress: Callable[[dict[str, Any]], None] | None = None,
    stop: Callable[[], bool] = lambda: False,
    on_validate: Callable[[int, dict[str, Tensor]], None] | None = None,
    share: slice | None = None,
    mean: Callable[[Tensor], Tensor] | None = None,
) -> bool:
    """Continue ``run`` up to ``steps`` steps; returns True if stopped early by ``stop()``.

    ``on_validate(step, examples)`` receives the first validation patches (scene, capture, restored,
    psf) at each validation.

    Data parallel (``torch.distributed``): every rank draws the same combined batch from the same
    generators and trains on its ``share`` of it; ``run.model`` is then a ``DistributedDataParallel``
    module (gradients averaged) and ``mean`` averages the reported loss over ranks.
    """
    device = next(run.model.parameters()).device
    with torch.no_grad():
        psf, center = lens_psfs(lens, system, setup)
    grids_of = GridCache(psf, center, setup)
    interrupted = False
    while run.step < steps:
        if stop():
            interrupted = True
            break
        t0 = time.perf_counter()
        scenes, tiles, noise = draw_batch(source, setup, cfg.batch, run.generators, device=device)
        if share is not None:
            scenes, tiles, noise = scenes[share], tiles[share], noise[share]
        grids = grids_of(tiles).to(device)
        cap = capture(scenes, grids, setup.settings, noise)
        kpsf = mean_patch_psf(grids.flatten(1, 2)).to(cap.dtype)
        lr = cosine_lr(run.step, steps, cfg.lr, cfg.lr_min)
        loss = network_step(run.model, run.optimizer, cap, kpsf, scenes, lr)
        if mean is not None:
            loss = float(mean(torch.tensor(loss, dtype=torch.float64)))
        run.step += 1
        rec: dict[str, Any] = {"step": run.step, "loss": loss, "lr": lr, "wall_s": time.perf_counter() - t0}
        if val is not None and cfg.validate_every and (run.step % cfg.validate_every == 0 or run.step == steps):
            ex: dict[str, Tensor] = {}
            rec.update(validate(run.model, grids_of, val, setup, examples=ex))
            if on_validate is not None:
                on_validate(run.step, ex)
        run.history.append(rec)
        if on_progress is not None:
            on_progress(rec)
        if checkpoint is not None and cfg.checkpoint_every and run.step % cfg.checkpoint_every == 0:
            checkpoint(run)
    if checkpoint is not None:
        checkpoint(run)
    return interrupted


def run_state(run: NetworkRun, prefix: str = "adam") -> tuple[dict[str, Tensor], dict[str, Tensor], dict[str, Any]]:
    """(network weights, other tensors, JSON part) of ``run`` for ``lensopt.checkpoint``."""
    from lensopt.checkpoint import flatten_optimizer

    model = getattr(run.model, "module", run.model)  # unwrap DDP
    opt_t, opt_info = flatten_optimizer(prefix, run.optimizer.state_dict())
    state = dict(opt_t)
    state.update({f"rng.{k}": g.get_state() for k, g in run.generators.items()})
    return dict(model.state_dict()), state, {prefix: opt_info, "history": run.history}


def load_run_state(run: NetworkRun, network: dict[str, Tensor], state: dict[str, Tensor], info: dict[str, Any],
                   step: int, prefix: str = "adam") -> None:
    """Put a checkpoint's weights, Adam moments, generator states and step into ``run``."""
    from lensopt.checkpoint import CheckpointError, unflatten_optimizer

    model = getattr(run.model, "module", run.model)
    device = next(model.parameters()).device
    try:
        model.load_state_dict({k: v.to(device) for k, v in network.items()})
        run.optimizer.load_state_dict(unflatten_optimizer(prefix, {k: v.to(device) for k, v in state.items()},
                                                          info[prefix]))
        for k, g in run.generators.items():
            g.set_state(state[f"rng.{k}"])
    except (KeyError, RuntimeError, ValueError) as err:
        raise CheckpointError(f"does not fit this network: {str(err).splitlines()[0]}", path="--resume") from None
    run.step = step
    run.history = list(info.get("history", []))


def log_examples(writer: Any, tag: str, step: int, ex: dict[str, Tensor], count: int = 4) -> None:
    """TensorBoard images: scene | capture | restored side by side per patch, and the conditioning PSFs
    (each scaled to its maximum)."""
    if not ex:
        return
    n = min(count, ex["scene"].shape[0])
    rows = torch.cat([ex["scene"][:n], ex["capture"][:n], ex["restored"][:n]], dim=-1).clamp(0, 1)
    if rows.shape[1] == 1:
        rows = rows.expand(-1, 3, -1, -1)
    writer.add_images(f"{tag}/scene_capture_restored", (rows ** (1 / 2.2)).cpu(), step)  # ~sRGB for display
    k = ex["psf"][:n]
    k = k / k.amax((-2, -1), keepdim=True).clamp_min(1e-12)
    if k.shape[1] == 1:
        k = k.expand(-1, 3, -1, -1)
    writer.add_images(f"{tag}/conditioning_psf", k.cpu(), step)
