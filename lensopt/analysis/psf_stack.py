"""PSF stacks K ∈ R^{F×W×S×S} of a lens (S1.4): trace spot diagrams, deposit them on grids centred on
the wavelength-averaged centroid of each field, and optionally apply the diffraction heuristic.

The ray trace is called in one place (``_trace``) so that a compiled trace can replace it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.analysis.psf import KERNELS, bin_down, deposit, grid_size_for, mirror_half_pupil
from lensopt.analysis.psf_diffraction import airy_field, diffraction_heuristic, incoherent_airy
from lensopt.analysis.spot import spot_stats
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.optics.bundle import Bundle, trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import FirstOrder, first_order
from lensopt.optics.sampling import PupilSampling

__all__ = ["PsfSettings", "PsfStack", "compute_psfs", "select_wavelengths", "DIFFRACTION_MODES"]

DIFFRACTION_MODES = ("none", "heuristic", "incoherent")


@dataclass(frozen=True)
class PsfSettings:
    """How PSFs are estimated.

    Attributes:
        sampling: pupil sampling (``rings:N`` → N² rays on the half pupil, mirrored; ``grid:N``).
        kernel: ``count`` (S1.4.1), ``triangular`` or ``cosine`` (KDE, S1.4.2).
        support: KDE support in bins (even).
        pitch_mm: bin size, mm (the sensor pixel pitch by default, set by the caller).
        size: bins per side (odd), or None: just enough for the largest spot (+ Airy rings), capped.
        diffraction: ``none``, ``heuristic`` (S1.4.3) or ``incoherent`` (naive, S7.1).
        oversample: estimate on bins ``oversample`` times finer, then sum blocks (1 = the seed's).
        seed: seed of the pupil jitter.
        max_size: cap of the automatic size.
    """

    sampling: str = "rings:32"
    kernel: str = "triangular"
    support: int = 2
    pitch_mm: float = 0.001
    size: int | None = None
    diffraction: str = "heuristic"
    oversample: int = 1
    seed: int = 0
    max_size: int = 255

    def __post_init__(self) -> None:
        if self.kernel not in KERNELS:
            raise LensoptError(f"must be one of {', '.join(KERNELS)}", path="psf.kernel", got=self.kernel)
        if self.diffraction not in DIFFRACTION_MODES:
            raise LensoptError(f"must be one of {', '.join(DIFFRACTION_MODES)}", path="psf.diffraction",
                               got=self.diffraction)
        if not self.pitch_mm > 0:
            raise LensoptError("must be positive", path="psf.pitch_mm", got=self.pitch_mm)
        if self.oversample < 1:
            raise LensoptError("must be ≥ 1", path="psf.oversample", got=self.oversample)


@dataclass(frozen=True)
class PsfStack:
    """PSFs per field and wavelength.

    Attributes:
        psf: (F, W, S, S) PSFs, each summing to 1 (see ``lensopt.analysis.psf`` for the orientation).
        geometric: (F, W, S, S) the geometric PSFs before any diffraction step.
        center: (F, 2) grid centres (wavelength-averaged centroids), mm.
        rel_field: (F,) relative fields.
        field_deg: (F,) object-space field angles, degrees.
        wavelength_um: (W,) wavelengths, µm.
        pitch_mm: bin size, mm.
        working_fnumber: paraxial working f-number (sets the Airy pattern).
        failed: (F, W) fraction of rays that failed.
        settings: what produced it.
    """

    psf: Tensor
    geometric: Tensor
    center: Tensor
    rel_field: Tensor
    field_deg: Tensor
    wavelength_um: Tensor
    pitch_mm: float
    working_fnumber: float
    failed: Tensor
    settings: PsfSettings


def select_wavelengths(lens: Lens, system: System, keep: list[int]) -> tuple[Lens, System]:
    """The same lens and system restricted to wavelength indices ``keep`` (reference kept if present,
    else the first kept wavelength)."""
    idx = torch.tensor(keep, dtype=torch.int64, device=lens.device)
    lens2 = dataclasses.replace(lens, index=lens.index[:, idx], wavelength_um=lens.wavelength_um[idx])
    ref = keep.index(system.reference) if system.reference in keep else 0
    system2 = dataclasses.replace(system, wavelength_weights=system.wavelength_weights[idx], reference=ref)
    return lens2, system2


def _trace(lens: Lens, system: System, sampling: PupilSampling, rel_field: Tensor, fo: FirstOrder, *,
           engine: Engine | None = None) -> Bundle:
    """The one place where PSFs trace rays."""
    return trace_bundle(lens, system, sampling.points(dtype=lens.dtype, device=lens.device, engine=engine),
                        half_pupil=sampling.half, rel_field=rel_field, fo=fo, engine=engine)


def compute_psfs(
    lens: Lens,
    system: System,
    rel_field: Tensor,
    settings: PsfSettings,
    *,
    fo: FirstOrder | None = None,
    engine: Engine | None = None,
) -> PsfStack:
    """PSF stack of ``lens`` for relative fields ``rel_field`` at every wavelength of the lens.

    Args:
        rel_field: (F,) relative fields in [0, 1].
        settings: estimation settings.
        fo: first-order data (pupil, working f-number) to use, e.g. of the full lens when ``lens`` is a
            wavelength subset (``select_wavelengths``); default: computed from ``lens``/``system``.

    Returns:
        The stack; differentiable in the lens tensors for KDE kernels.
    """
    sampling = PupilSampling.parse(settings.sampling, seed=settings.seed, path="psf.sampling")
    fo = first_order(lens, system) if fo is None else fo
    bundle = _trace(lens, system, sampling, rel_field, fo, engine=engine)
    res = bundle.result
    stats = spot_stats(bundle, system.wavelength_weights)
    center = stats.centroid  # (F, 2)
    xy, valid = res.pos[..., :2], res.valid
    if bundle.half_pupil:
        xy, valid = mirror_half_pupil(xy, valid, 0.0)
    wn = float(fo.working_fnumber.detach())
    o = settings.oversample
    fine = settings.pitch_mm / o
    field = None
    if settings.diffraction != "none":
        n_img = float(lens.index[-1, 0].detach())
        field = airy_field(lens.wavelength_um, wn, fine, image_index=n_img, dtype=lens.dtype)
    size = settings.size
    if size is None:
        d = (xy.detach() - center.detach()[:, None, None, :]).abs().amax(-1)
        d = torch.where(valid, d, torch.zeros_like(d))
        half = float(d.max()) if d.numel() else 0.0
        if field is not None:
            half += (field.shape[-1] // 2) * fine
        size = grid_size_for(half, settings.pitch_mm, margin_bins=settings.support // 2,
                             max_size=settings.max_size)
    if size % 2 == 0:
        raise LensoptError("PSF grid size must be odd", path="psf.size", got=size)
    cen = center.unsqueeze(1).expand(-1, xy.shape[1], -1)
    # The fine grid (S·o bins of pitch/o) tiles the S coarse bins exactly; for an even o it has an even
    # number of bins and its centre falls on a bin corner, which ``bin_down`` turns back into the centre
    # of the odd coarse grid.
    geo = deposit(xy, valid, cen, pitch=fine, size=size * o, kernel=settings.kernel, support=settings.support,
                  allow_even=True)
    psf = geo
    if field is not None:
        psf = diffraction_heuristic(geo, field) if settings.diffraction == "heuristic" else incoherent_airy(geo, field)
    failed = 1.0 - res.valid.to(lens.dtype).mean(-1)
    field_deg = torch.rad2deg(torch.atan(bundle.tan_field.detach()))
    return PsfStack(psf=bin_down(psf, o), geometric=bin_down(geo, o), center=center, rel_field=rel_field,
                    field_deg=field_deg, wavelength_um=lens.wavelength_um, pitch_mm=settings.pitch_mm,
                    working_fnumber=wn, failed=failed, settings=settings)

