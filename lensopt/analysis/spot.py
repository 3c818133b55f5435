"""Spot diagrams: centroids, RMS spot radius per field (S23–S24) and the effective spot radius (S4.2.1).

All statistics are masked: failed rays are excluded (their rows stay, with zero weight), and every
result is a differentiable tensor. A bundle with ``pupil_weights`` (a quadrature such as ``gauss:N``)
weighs every ray by its pupil area.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.engine import Engine
from lensopt.optics.bundle import Bundle
from lensopt.optics.lens import Lens, System

__all__ = ["SpotStats", "spot_stats", "spot_centroid", "safe_sqrt", "seed_esr", "seed_spot_stats", "SEED_FIELDS",
           "SEED_SAMPLING", "SEED_MEASURE"]


def safe_sqrt(x: Tensor) -> Tensor:
    """sqrt with a finite gradient at 0 (the spot of a perfect lens)."""
    tiny = torch.finfo(x.dtype).tiny
    return torch.sqrt(x.clamp_min(tiny))


@dataclass(frozen=True)
class SpotStats:
    """Spot statistics of a bundle, lengths in mm.

    Attributes:
        centroid: (F, 2) wavelength-weighted centroid (x̄, ȳ) per field (S24).
        rms_radius: (F,) wavelength-weighted RMS spot radius SR_h about that centroid (S23).
        centroid_w: (F, W, 2) centroid per field and wavelength.
        rms_radius_w: (F, W) RMS spot radius per wavelength, about that wavelength's own centroid.
        effective_radius: () ESR = sqrt(Σ_h w_h SR_h² / Σ_h w_h) (S4.2.1).
        num_valid: (F, W) rays that reached the image.
    """

    centroid: Tensor
    rms_radius: Tensor
    centroid_w: Tensor
    rms_radius_w: Tensor
    effective_radius: Tensor
    num_valid: Tensor


def _weighted(bundle: Bundle, wavelength_weights: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """xy (F, W, P, 2) on the image, valid (F, W, P), the rays' weights m (validity times pupil weights)
    and the spectral weights W_w·m (F, W, P)."""
    res = bundle.result
    xy = res.pos[..., :2]
    valid = res.valid
    m = valid.to(xy.dtype)
    if bundle.pupil_weights is not None:
        m = m * bundle.pupil_weights.to(xy.dtype)
    return xy, valid, m, wavelength_weights.to(xy.dtype)[None, :, None] * m


def _centroid(bundle: Bundle, xy: Tensor, valid: Tensor, weights: Tensor, dims: tuple[int, ...]) -> Tensor:
    total = weights.sum(dims).clamp_min(torch.finfo(xy.dtype).tiny)
    c = (torch.where(valid.unsqueeze(-1), xy, 0.0) * weights.unsqueeze(-1)).sum(dims) / total.unsqueeze(-1)
    if bundle.half_pupil:  # x̄ = 0 by symmetry about the meridional plane (S37)
        c = torch.stack([torch.zeros_like(c[..., 0]), c[..., 1]], -1)
    return c


def spot_centroid(bundle: Bundle, wavelength_weights: Tensor) -> Tensor:
    """(F, 2) the wavelength-weighted centroid per field of ``spot_stats`` alone (the same numbers), for
    callers that read no radius (the residual terms)."""
    xy, valid, _, ww = _weighted(bundle, wavelength_weights)
    return _centroid(bundle, xy, valid, ww, (1, 2))


def spot_stats(bundle: Bundle, wavelength_weights: Tensor, field_weights: Tensor | None = None) -> SpotStats:
    """RMS spot radii and centroids of ``bundle`` (batch F × W × P) on the image surface.

    Args:
        wavelength_weights: (W,) spectral weights W_w.
        field_weights: (F,) weights for the ESR; uniform by default.
    """
    xy, valid, m, ww = _weighted(bundle, wavelength_weights)

    def rms(weights: Tensor, c: Tensor, dims: tuple[int, ...]) -> Tensor:
        d2 = ((xy - c) ** 2).sum(-1)
        d2 = torch.where(valid, d2, 0.0)
        total = weights.sum(dims).clamp_min(torch.finfo(xy.dtype).tiny)
        return safe_sqrt((weights * d2).sum(dims) / total)

    c_h = _centroid(bundle, xy, valid, ww, (1, 2))  # (F, 2)
    sr_h = rms(ww, c_h[:, None, None, :], (1, 2))
    c_hw = _centroid(bundle, xy, valid, m, (2,))  # (F, W, 2)
    sr_hw = rms(m, c_hw[:, :, None, :], (2,))
    if field_weights is None:
        field_weights = torch.ones_like(sr_h)
    esr = safe_sqrt((field_weights * sr_h**2).sum() / field_weights.sum())
    return SpotStats(c_h, sr_h, c_hw, sr_hw, esr, valid.sum(-1))


SEED_FIELDS = 11
"""Relative fields of the seed's ESR: 0, 0.1, …, 1 (as the seed's code base configures its studies)."""
SEED_SAMPLING = "grid:61"
"""Pupil sampling of the seed's ESR: a 61 × 61 cell-centred grid over the full pupil (dense)."""


SEED_MEASURE = f"{SEED_FIELDS} fields, {SEED_SAMPLING}"
"""The seed's measure in words, as the reports label it."""


def seed_spot_stats(lens: Lens, system: System, *, engine: Engine | None = None) -> SpotStats:
    """Spot statistics on the seed's measure (S4.2.1, S7): ``SEED_FIELDS`` equally spaced relative fields
    0 … 1 with equal weights, the system's wavelength weights, a dense full-pupil grid (``SEED_SAMPLING``)
    and the system's aiming and front aperture, whatever fields and sampling the spec optimizes with.
    Its ``effective_radius`` is ``seed_esr``."""
    from lensopt.optics.bundle import trace_bundle
    from lensopt.optics.sampling import PupilSampling

    rel = torch.linspace(0.0, 1.0, SEED_FIELDS, dtype=lens.dtype, device=lens.device)
    pupil = PupilSampling.parse(SEED_SAMPLING).points(dtype=lens.dtype, device=lens.device, engine=engine)
    bundle = trace_bundle(lens, system, pupil, rel_field=rel, engine=engine)
    return spot_stats(bundle, system.wavelength_weights)


def seed_esr(lens: Lens, system: System, *, engine: Engine | None = None) -> Tensor:
    """() Effective spot radius (mm) on the seed's measure (``seed_spot_stats``). Comparable between
    lenses of one study and with the seed's published ESRs."""
    return seed_spot_stats(lens, system, engine=engine).effective_radius
