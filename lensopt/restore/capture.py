"""How the restoration network's training batches are simulated for a lens (S4.3.2; S3.3.1): the
imaging set-up (sensor, tiles, traced fields, pupil sampling, channel weights), the field PSFs of the
lens, the PSF grids of sensor regions, captures with noise, and seeded batches of scene patches, tiles
and noise draws (three ``torch.Generator``s: scenes, tiles, noise)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.imaging.camera import Camera
from lensopt.imaging.convolve import overlap_add_convolve
from lensopt.imaging.datasets import sample_batch
from lensopt.imaging.plan import lens_colour
from lensopt.imaging.psf_grid import build_psf_grid, cell_centers_mm, field_weights
from lensopt.imaging.regions import TileGrid, stratified_draw, tile_grid
from lensopt.imaging.render import RenderSettings, psfs_from_spots, trace_spots
from lensopt.imaging.scene import Region, Sensor
from lensopt.imaging.sources import PatchSource
from lensopt.optics.lens import Lens, System
from lensopt.optics.sampling import PupilSampling

__all__ = ["ImagingSetup", "imaging_setup", "lens_psfs", "region_grids", "region_grids_for", "capture", "Source",
           "draw_batch", "GridCache", "ValidationSet", "validation_set"]

Source = PatchSource  # dead leaves, textured dead leaves, photographs, image folders, mixtures


@dataclass(frozen=True)
class ImagingSetup:
    """How batches are simulated for a lens (everything but the lens tensors themselves).

    Attributes:
        sensor: the sensor; tiles: its patch-sized tiles sorted centre → corner.
        rel_field: (F,) relative fields whose PSFs are traced (0 … 1 of the system's field).
        sampling: pupil sampling of the PSF rays.
        channel_weights: (W, C) wavelength → channel weights (``imaging.plan.lens_colour``).
        settings: PSF size, sub-tile grid, overlap, kernel, noise σ.
        channels: image channels C (3: R, G, B, the lens's colour model).
        colour: where the channel weights came from (``lens_colour``'s text).
        sampling_text: ``sampling`` as given (``rings:8``).
        engine: trace backend and memory budget of the PSF rays (default ``Engine()``).
    """

    sensor: Sensor
    tiles: TileGrid
    rel_field: Tensor
    sampling: PupilSampling
    channel_weights: Tensor
    settings: RenderSettings
    channels: int
    sampling_text: str = "rings:8"
    colour: str = ""
    engine: Engine | None = None

    @property
    def patch(self) -> int:
        return self.tiles.patch[0]

    def describe(self) -> dict[str, Any]:
        s = self.settings
        return {"patch": self.patch, "sampling": self.sampling_text, "sensor": [self.sensor.width, self.sensor.height],
                "fields": len(self.rel_field),
                "psf_size": s.psf_size, "grid": list(s.grid), "overlap": s.overlap, "channels": self.channels,
                "noise_sigma": s.noise_sigma, "colour": self.colour}


def imaging_setup(camera: Camera, *, patch: int, fields: int = 9, sampling: str = "rings:8", psf_size: int = 31,
                  grid: tuple[int, int] = (3, 3), noise_sigma: float = 0.005, diffraction: bool = False,
                  dtype: torch.dtype = torch.float64, device: torch.device | str | None = None,
                  engine: Engine | None = None) -> ImagingSetup:
    """The setup for a lens on its sensor (``lensopt.spec.camera_of(model)`` / ``model.camera()``): the
    sensor's pitch and resolution are required; the channels are the lens's colour model
    (``imaging.plan.lens_colour``: R, G, B from ``rgb_weights`` or the spectrum), as ``simulate`` and
    ``evaluate`` render."""
    if camera.pixel_pitch_um is None or camera.resolution is None:
        raise LensoptError("needs pixel_pitch_um and resolution to simulate captures", path="sensor")
    w, h = camera.resolution
    sensor = Sensor(camera.pixel_pitch_um * 1e-3, int(w), int(h))
    cw, names, colour = lens_colour(camera.spectrum)
    settings = RenderSettings(psf_size=psf_size, grid=grid, noise_sigma=noise_sigma, diffraction=diffraction)
    rel = torch.linspace(0.0, 1.0, fields, dtype=dtype, device=device) if fields > 1 else torch.zeros(
        1, dtype=dtype, device=device)
    return ImagingSetup(sensor=sensor, tiles=tile_grid(sensor, patch, option="--patch"), rel_field=rel,
                        sampling=PupilSampling.parse(sampling, seed=0, path="--sampling"),
                        channel_weights=torch.as_tensor(cw, dtype=dtype, device=device), settings=settings,
                        channels=len(names), sampling_text=sampling, colour=colour, engine=engine)


def lens_psfs(lens: Lens, system: System, setup: ImagingSetup) -> tuple[Tensor, Tensor]:
    """Field PSFs (F, W, S, S) at the sensor pitch and their centres (F, 2), differentiable in the lens."""
    sp = setup.sampling
    spots = trace_spots(lens, system, setup.rel_field.to(lens.dtype),
                        sp.points(dtype=lens.dtype, device=lens.device, engine=setup.engine), half=sp.half,
                        engine=setup.engine)
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


def draw_batch(source: Source, setup: ImagingSetup, batch: int, gens: dict[str, torch.Generator], *,
               dtype: torch.dtype = torch.float32, device: torch.device | str | None = None
               ) -> tuple[Tensor, Tensor, Tensor]:
    """(scenes (B, C, P, P), tile indices (B,), standard normal noise (B, C, P, P)) from the generators."""
    scenes = sample_batch(source, batch, setup.patch, gens["scenes"], dtype=dtype)
    if scenes.shape[1] != setup.channels:  # gray scenes (1 channel) become R = G = B
        scenes = scenes.expand(-1, setup.channels, -1, -1).contiguous()
    tiles = stratified_draw(len(setup.tiles), batch, gens["tiles"])
    noise = torch.randn(scenes.shape, generator=gens["noise"], dtype=dtype)
    return scenes.to(device), tiles, noise.to(device)


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
