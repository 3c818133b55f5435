"""Differentiable rendering of training batches (S1.5, S3.3.1): spot diagrams → KDE PSFs of a fixed
size → per-region PSF grids → overlap-add convolution of image patches → noise.

The pipeline is split where the gradient needs to be cut for GTRA (S3.1): ``trace_spots`` gives the
spot diagrams ε (float64), ``psfs_from_spots`` turns any ε (a leaf tensor for GTRA, the traced one for
Adam) into PSFs, and ``render_batch`` simulates the captures of a batch of patches at their sensor
regions. Every step reuses the PSF and simulation code of ``lensopt simulate`` (``analysis.psf``,
``analysis.psf_diffraction``, ``imaging.psf_grid``, ``imaging.convolve``, ``imaging.effects``), so a
rendered patch equals ``lensopt simulate`` on the same region with the same settings.

No shape depends on the data: the PSF array has ``settings.psf_size`` bins at the sensor pitch
(energy falling outside is spread uniformly over it, S1.4.1), the PSF grid is ``settings.grid`` per
region. PSFs are built in the dtype of ε (float64 for design) and rendering runs in the dtype of the
images (float32).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from lensopt.analysis.psf import KERNELS, deposit, mirror_half_pupil
from lensopt.analysis.psf_diffraction import airy_field, diffraction_heuristic
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.imaging.convolve import overlap_add_convolve
from lensopt.imaging.effects import add_noise
from lensopt.imaging.psf_grid import build_psf_grid, cell_centers_mm, field_weights
from lensopt.imaging.scene import Region, Sensor
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import FirstOrder, first_order
from lensopt.optics.sampling import PupilSampling

__all__ = ["RenderSettings", "Spots", "trace_spots", "weighted_centroid", "psfs_from_spots", "airy_for",
           "render_batch", "render_lens", "mse"]


@dataclass(frozen=True)
class RenderSettings:
    """How patches are rendered (defaults: the seed's C-mount/telephoto settings).

    Attributes:
        psf_size: PSF array side in sensor pixels (odd, fixed: 49 = 49×49 px).
        grid: (W_g, H_g) sub-tile PSF grid per region (S3.3.1: 3×3).
        overlap: OP, overlap of neighbouring sub-tiles (S1.5.2).
        kernel: KDE kernel (``triangular``, S1.4.2, or ``cosine``); support in bins (even).
        diffraction: apply the diffraction heuristic (S1.4.3).
        noise_sigma: σ of the additive Gaussian noise as a fraction of the maximum (0: none).
        seed: noise seed (image b of a batch uses seed + b).
    """

    psf_size: int = 49
    grid: tuple[int, int] = (3, 3)
    overlap: float = 0.25
    kernel: str = "triangular"
    support: int = 2
    diffraction: bool = False
    noise_sigma: float = 0.005
    seed: int = 0

    def __post_init__(self) -> None:
        if not (isinstance(self.psf_size, int) and self.psf_size > 0 and self.psf_size % 2 == 1):
            raise LensoptError("must be a positive odd number of pixels", path="optimize.image.psf_size",
                               got=self.psf_size)
        if self.kernel not in KERNELS or self.kernel == "count":
            raise LensoptError("must be triangular or cosine (KDE, differentiable)", path="optimize.image.kernel",
                               got=self.kernel)
        if len(self.grid) != 2 or min(self.grid) < 1:
            raise LensoptError("must be two positive integers", path="optimize.image.grid", got=self.grid)
        if not 0 <= self.noise_sigma < 1:
            raise LensoptError("must lie in [0, 1)", path="optimize.image.noise", got=self.noise_sigma)


@dataclass(frozen=True)
class Spots:
    """Spot diagrams ε of the rendering fields.

    Attributes:
        xy: (F, W, P, 2) ray intercepts on the image surface, mm (half pupil when ``half``).
        valid: (F, W, P) rays that reached the image.
        half: whether only the half pupil x ≥ 0 was traced (mirrored for PSFs).
        rel_field: (F,) relative fields.
        wavelength_weights: (W,) spectrum weights (for the wavelength-averaged centroid).
        working_fnumber: paraxial working f-number (Airy pattern), detached.
    """

    xy: Tensor
    valid: Tensor
    half: bool
    rel_field: Tensor
    wavelength_weights: Tensor
    working_fnumber: float


def trace_spots(lens: Lens, system: System, rel_field: Tensor, pupil: Tensor, *, half: bool,
                fo: FirstOrder | None = None, engine: Engine | None = None) -> Spots:
    """Spot diagrams of ``lens`` at relative fields ``rel_field`` (F,) for every wavelength of the lens,
    differentiable in the lens tensors (forward and reverse mode).

    Args:
        pupil: (P, 2) pupil points (``PupilSampling.points``; drawn outside so that ``jacfwd`` sees no
            random draw); half: they cover the half pupil x ≥ 0.
    """
    fo = first_order(lens, system) if fo is None else fo
    bundle = trace_bundle(lens, system, pupil.to(lens.dtype), half_pupil=half, rel_field=rel_field, fo=fo,
                          engine=engine)
    res = bundle.result
    return Spots(res.pos[..., :2], res.valid, bundle.half_pupil, rel_field, system.wavelength_weights,
                 float(fo.working_fnumber.detach()))


def weighted_centroid(xy: Tensor, valid: Tensor, wavelength_weights: Tensor, half: bool) -> Tensor:
    """(F, 2) wavelength-weighted centroid of each field over valid rays (as ``spot_stats``, S24; x = 0
    on a half pupil, by symmetry): the PSF grid centre of S1.4.1; differentiable in ``xy``."""
    w = wavelength_weights.to(xy.dtype)[None, :, None] * valid.to(xy.dtype)  # (F, W, P)
    total = w.sum((1, 2)).clamp_min(torch.finfo(xy.dtype).tiny)
    cen = (torch.where(valid.unsqueeze(-1), xy, 0.0) * w.unsqueeze(-1)).sum((1, 2)) / total.unsqueeze(-1)
    if half:
        cen = torch.stack([torch.zeros_like(cen[:, 0]), cen[:, 1]], -1)
    return cen


def airy_for(spots: Spots, wavelength_um: Tensor, pitch_mm: float, image_index: float = 1.0) -> Tensor:
    """(W, A, A) Airy fields for the diffraction heuristic (S1.4.3) at the PSF pitch."""
    return airy_field(wavelength_um, spots.working_fnumber, pitch_mm, image_index=image_index,
                      dtype=spots.xy.dtype)


def psfs_from_spots(xy: Tensor, valid: Tensor, wavelength_weights: Tensor, *, half: bool, pitch_mm: float,
                    settings: RenderSettings, airy: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """KDE PSFs (S1.4.2) of fixed size from spot diagrams.

    Args:
        xy: (F, W, P, 2) intercepts, mm (any dtype; float64 for design); valid: (F, W, P).
        half: mirror the half pupil.
        pitch_mm: bin size (the sensor pixel pitch).
        airy: (W, A, A) Airy fields from ``airy_for`` to apply the diffraction heuristic (S1.4.3), or None.

    Returns:
        psf (F, W, S, S) each summing to 1 (energy outside the array spread over it), and the grid
        centres (F, 2) in mm.
    """
    center = weighted_centroid(xy, valid, wavelength_weights, half)
    if half:
        xy, valid = mirror_half_pupil(xy, valid, 0.0)
    cen = center.unsqueeze(1).expand(-1, xy.shape[1], -1)
    psf = deposit(xy, valid, cen, pitch=pitch_mm, size=settings.psf_size, kernel=settings.kernel,
                  support=settings.support)
    if airy is not None:
        psf = diffraction_heuristic(psf, airy)
    return psf, center


def render_batch(psf: Tensor, center: Tensor, images: Tensor, regions: Sequence[Region], sensor: Sensor,
                 channel_weights: Tensor, settings: RenderSettings, *, pitch_mm: float | None = None,
                 noise: bool = True) -> Tensor:
    """Simulated captures of a batch of patches.

    Args:
        psf: (F, W, S, S) field PSFs (``psfs_from_spots``), differentiable.
        center: (F, 2) their centres, mm (only the radius |y| is used, to assign fields to sub-tiles).
        images: (B, C, H, W) linear scene patches; their dtype is the rendering dtype.
        regions: B sensor regions (``Region``), one per patch.
        channel_weights: (W, C) wavelength → channel weights W_w, columns summing to 1.
        pitch_mm: PSF bin size (default: the sensor pitch).
        noise: add the seeded Gaussian noise of ``settings``.

    Returns:
        (B, C, H, W) captures, dtype of ``images``.
    """
    if images.dim() != 4:
        raise LensoptError("images must be (B, C, H, W)", path="images", got=tuple(images.shape))
    b, c = images.shape[:2]
    if len(regions) != b:
        raise LensoptError(f"need one region per image ({b})", path="regions", got=len(regions))
    if channel_weights.shape != (psf.shape[1], c):
        raise LensoptError(f"channel weights must be (W={psf.shape[1]}, C={c})", path="channel_weights",
                           got=tuple(channel_weights.shape))
    pitch = sensor.pitch_mm if pitch_mm is None else pitch_mm
    radius = np.abs(center[:, 1].detach().cpu().double().numpy())
    out = []
    for k, region in enumerate(regions):
        wf = torch.from_numpy(field_weights(radius, region, sensor, settings.grid)).to(psf.device)
        px_mm = region.pixel_mm(sensor)[0]
        grid = build_psf_grid(psf, channel_weights, wf, cell_centers_mm(region, sensor, settings.grid),
                              pitch_mm=pitch, pixel_mm=px_mm).to(images.dtype)
        img = overlap_add_convolve(images[k], grid, overlap=settings.overlap)
        if noise and settings.noise_sigma > 0:
            img = add_noise(img, settings.noise_sigma, seed=settings.seed + k)
        out.append(img)
    return torch.stack(out)


def render_lens(lens: Lens, system: System, rel_field: Tensor, sampling: PupilSampling, images: Tensor,
                regions: Sequence[Region], sensor: Sensor, channel_weights: Tensor, settings: RenderSettings,
                *, noise: bool = True, engine: Engine | None = None) -> Tensor:
    """Trace, PSFs and rendering in one differentiable call (reverse mode through all of it)."""
    spots = trace_spots(lens, system, rel_field, sampling.points(dtype=lens.dtype, device=lens.device, engine=engine),
                        half=sampling.half, engine=engine)
    airy = None
    if settings.diffraction:
        airy = airy_for(spots, lens.wavelength_um, sensor.pitch_mm, float(lens.index[-1, 0].detach()))
    psf, center = psfs_from_spots(spots.xy, spots.valid, spots.wavelength_weights, half=spots.half,
                                  pitch_mm=sensor.pitch_mm, settings=settings, airy=airy)
    return render_batch(psf, center, images, regions, sensor, channel_weights, settings, noise=noise)


def mse(captured: Tensor, scene: Tensor) -> Tensor:
    """Mean squared error between captures and scenes (the ``raw`` objective), a scalar."""
    return ((captured - scene) ** 2).mean()
