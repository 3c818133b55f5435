"""Image-driven objectives (``[optimize] objective = "raw"``): training batches, rendering, the image
loss, and the values of its two residual terms (``optim.terms``: ``gtra`` and ``image_loss``).

Each optimizer step draws a batch (S3.3.1): ``batch`` patches (dead-leaves scenes or random crops and
flips of an image folder) paired with sensor tiles by the pseudo-random rule (tiles sorted by distance
from the centre, stratified), both seeded by (seed, step) so that a run is reproducible. The loss is the
MSE between the rendered capture (``imaging.render``) and the scene.

- LM uses ``gtra``: ℓ_GTRA (S66–S68) against the control values of the step (``update`` sets them from
  the spot diagrams of the current lens, reverse mode through rendering and loss only).
- Adam uses ``image_loss``: one residual √(2L(θ)), so that ½‖ℓ‖² = L and reverse mode runs through
  trace, rendering and loss.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

from lensopt.analysis.psf_stack import select_wavelengths
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.imaging.camera import Camera
from lensopt.imaging.datasets import DeadLeaves, sample_batch
from lensopt.imaging.metrics import psnr_of_mse
from lensopt.imaging.plan import lens_colour
from lensopt.imaging.regions import stratified_draw, tile_grid
from lensopt.imaging.render import (
    RenderSettings,
    Spots,
    airy_for,
    mse,
    psfs_from_spots,
    render_batch,
    trace_spots,
)
from lensopt.imaging.scene import Region, Sensor
from lensopt.imaging.sources import training_sources
from lensopt.optics.lens import Lens
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import PupilSampling
from lensopt.optim.gtra import GtraTarget, gtra_residual, gtra_target, psf_window
from lensopt.optim.settings import ImageSettings

__all__ = ["ImageObjective"]


def _seed(*parts: object) -> int:
    return int.from_bytes(hashlib.sha256(":".join(map(str, parts)).encode()).digest()[:8], "little") >> 1


class ImageObjective:
    """Batches, rendering and loss of an image objective for a lens on its sensor.

    Args:
        camera: the lens's sensor (pitch, resolution), spectrum (RGB weights) and system (wavelength
            weights); its lens is not used (the objective renders the lens it is given).
        image: the rendering settings (``[optimize.image]``).
        mode: ``gtra`` (LM) or ``scalar`` (Adam).
        dtype: dtype of the image patches (float32 rendering; float64 for identity tests).
        engine: trace backend and memory budget of the rendering rays (default ``Engine()``).

    Raises:
        LensoptError: no ``[sensor]`` (or no resolution), an unusable image folder, no RGB weights.
    """

    def __init__(self, camera: Camera, image: ImageSettings, *, mode: str = "gtra",
                 dtype: torch.dtype = torch.float32, engine: Engine | None = None) -> None:
        if camera.pixel_pitch_um is None:
            raise LensoptError('objective = "raw" needs a [sensor] (pixel_pitch_um and resolution)', path="sensor")
        if camera.resolution is None:
            raise LensoptError('objective = "raw" needs the sensor resolution', path="sensor.resolution")
        self.spec = image
        self.engine = engine or Engine()
        self.mode = mode
        self.dtype = dtype
        self.system = camera.system
        w, h = (int(v) for v in camera.resolution)
        self.sensor = Sensor(camera.pixel_pitch_um * 1e-3, w, h)
        self.settings = RenderSettings(psf_size=image.psf_size, grid=tuple(image.grid), overlap=image.overlap,
                                       kernel=image.kernel, diffraction=image.diffraction, noise_sigma=image.noise,
                                       seed=image.seed)
        self.rel_field = torch.linspace(0.0, 1.0, image.fields, dtype=torch.float64)
        sampling = PupilSampling.parse(image.sampling, seed=image.seed, path="optimize.image.sampling")
        self.pupil, self.half = sampling.points(dtype=torch.float64, engine=self.engine), sampling.half
        cw, _, self.rgb_note = lens_colour(camera.spectrum)
        cw = torch.as_tensor(np.asarray(cw), dtype=torch.float64)
        # Wavelengths that no channel weighs (e.g. a reference wavelength of weight 0) are not rendered.
        self.keep = [i for i in range(cw.shape[0]) if float(cw[i].sum()) > 0]
        self.channel_weights = cw[self.keep]
        self.tiles = tile_grid(self.sensor, image.patch, option="optimize.image.patch")
        if image.images is None:
            self.train: Any = DeadLeaves(seed=image.seed)
            self.held_out: Any = DeadLeaves(seed=image.seed + 1_000_003)
        else:  # a named source (procedural | textured | photos | a+b) or a folder, as train-irm --images
            self.train, self.held_out, _ = training_sources(image.images, image.patch, image.seed,
                                                            engine=self.engine, option="optimize.image.images")
        self.images: Tensor | None = None
        self.regions: list[Region] = []
        self.target: GtraTarget | None = None
        self._held_out: dict[int, tuple[Tensor, list[Region]]] = {}
        self.set_batch(0)

    # ------------------------------------------------------------------------------------ batches

    def batch(self, step: int, *, held_out: bool = False, size: int | None = None) -> tuple[Tensor, list[Region]]:
        """(B, 3, P, P) patches and their sensor regions for ``step`` (a pure function of seed and step)."""
        b = size or self.spec.batch
        gen = torch.Generator().manual_seed(_seed("batch", self.spec.seed, held_out, step))
        images = sample_batch(self.held_out if held_out else self.train, b, self.spec.patch, gen, dtype=self.dtype)
        idx = stratified_draw(len(self.tiles), b, gen)
        return images, [self.tiles.region(int(i)) for i in idx]

    def set_batch(self, step: int) -> None:
        """Use the batch of ``step`` from now on (the GTRA target is cleared). The batch's noise is drawn
        from (seed, step), so no patch slot sees the same noise field at every step; the held-out set keeps
        the fixed noise of ``seed``."""
        self.images, self.regions = self.batch(step)
        self.noise_seed = _seed("noise", self.spec.seed, step) % 2**31
        self.target = None

    # ---------------------------------------------------------------------------------- rendering

    def spots(self, lens: Lens) -> Spots:
        """Spot diagrams ε of the rendering fields (differentiable in the lens)."""
        fo = first_order(lens, self.system)
        sub, system = lens, self.system
        if len(self.keep) < lens.wavelength_um.shape[0]:
            sub, system = select_wavelengths(lens, self.system, self.keep)
        return trace_spots(sub, system, self.rel_field.to(lens.dtype), self.pupil, half=self.half, fo=fo,
                           engine=self.engine)

    def _airy(self, spots: Spots, lens: Lens) -> Tensor | None:
        if not self.settings.diffraction:
            return None
        return airy_for(spots, lens.wavelength_um[self.keep], self.sensor.pitch_mm, float(lens.index[-1, 0].detach()))

    def render(self, xy: Tensor, spots: Spots, airy: Tensor | None, images: Tensor, regions: Sequence[Region],
               *, noise: bool = True) -> Tensor:
        """Captures of ``images`` at ``regions`` for spot diagrams ``xy`` (F, W, P, 2) (validity of ``spots``);
        the current batch gets the noise of its step, other images (held out) the spec's fixed noise."""
        psf, center = psfs_from_spots(xy, spots.valid, spots.wavelength_weights, half=spots.half,
                                      pitch_mm=self.sensor.pitch_mm, settings=self.settings, airy=airy)
        settings = dataclasses.replace(self.settings, seed=self.noise_seed) if images is self.images else self.settings
        return render_batch(psf, center, images, regions, self.sensor, self.channel_weights, settings, noise=noise)

    def loss(self, lens: Lens, images: Tensor | None = None, regions: Sequence[Region] | None = None) -> Tensor:
        """L(θ): MSE of the rendered captures of the batch (reverse mode through trace and rendering)."""
        images = self.images if images is None else images
        regions = self.regions if regions is None else regions
        spots = self.spots(lens)
        out = self.render(spots.xy, spots, self._airy(spots, lens), images, regions)
        return mse(out, images)

    def update(self, lens: Lens) -> GtraTarget:
        """Set the GTRA control values and weight from the current lens and batch (S66)."""
        with torch.no_grad():
            spots = self.spots(lens)
        airy = self._airy(spots, lens)

        def loss_fn(xy: Tensor) -> Tensor:
            return mse(self.render(xy, spots, airy, self.images, self.regions), self.images)

        center = _centroid(spots)
        self.target = gtra_target(spots.xy, spots.valid, loss_fn,
                                  window=psf_window(center, self.settings.psf_size, self.sensor.pitch_mm))
        return self.target

    def gtra(self, lens: Lens) -> Tensor:
        """(2·F·W·P,) ℓ_GTRA at ``lens`` (zeros before the first ``update``)."""
        spots = self.spots(lens)
        if self.target is None:
            return (spots.xy * 0.0).reshape(-1)
        return gtra_residual(spots.xy, spots.valid, self.target)

    def scalar(self, lens: Lens) -> Tensor:
        """(1,) √(2L(θ)) on the current batch."""
        return torch.sqrt(2.0 * self.loss(lens).to(lens.dtype)).reshape(1)

    def held_out_psnr(self, lens: Lens, count: int | None = None) -> float:
        """PSNR (dB) of the captures of ``count`` held-out patches (default ``validation``; the same
        patches and regions on every call), noise included, clipped to [0, 1]; from the mean MSE."""
        n = count or self.spec.validation
        if n not in self._held_out:
            self._held_out[n] = self.batch(-1, held_out=True, size=n)
        images, regions = self._held_out[n]
        with torch.no_grad():
            spots = self.spots(lens)
            airy = self._airy(spots, lens)
            total = 0.0
            for k in range(0, n, self.spec.batch):
                sl = slice(k, k + self.spec.batch)
                out = self.render(spots.xy, spots, airy, images[sl], regions[sl]).clamp(0.0, 1.0)
                total += float(((out - images[sl]) ** 2).mean((1, 2, 3)).sum())
        return psnr_of_mse(total / n)


def _centroid(spots: Spots) -> Tensor:
    from lensopt.imaging.render import weighted_centroid

    return weighted_centroid(spots.xy, spots.valid, spots.wavelength_weights, spots.half)
