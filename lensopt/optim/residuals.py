"""Residual terms (S2.2, Table S6): pure tensor functions of a traced bundle (or glass variables).

Each returns a flat vector whose length depends only on the bundle's shape, never on the data
(DESIGN.md rule 1): failed rays keep their rows with value 0 (and the ``failures`` term counts them).
ramp(x) = max(x, 0). n_r = F·W·P rays; lengths in mm.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from lensopt.analysis.distortion import distortion as distortion_per_field
from lensopt.analysis.illumination import relative_illumination_std
from lensopt.analysis.spot import SpotStats
from lensopt.optics.bundle import Bundle
from lensopt.optics.lens import Lens, System

__all__ = [
    "BIG",
    "tra",
    "gap_lengths",
    "ray_path",
    "ray_angle",
    "surface_normal",
    "distortion",
    "relative_illumination",
    "failures",
]

BIG = 1e9
"""Stand-in for an absent bound (mm): finite, so that values and tangents stay finite."""


def _ramp(x: Tensor) -> Tensor:
    return torch.clamp_min(x, 0.0)


def tra(bundle: Bundle, stats: SpotStats, wavelength_weights: Tensor, field_weights: Tensor) -> Tensor:
    """(2 n_r,) transverse ray aberrations about each field's weighted centroid (S37–S39).

    Every ray of field h, wavelength w is weighted by sqrt(f_h/Σf · W_w/ΣW / P), so that with no
    failed rays ‖ℓ_TRA‖² = Σ_h f̂_h SR_h² = ESR² (S40 generalized to weights).
    """
    res = bundle.result
    F, W, P = res.status.shape
    xy = res.pos[..., :2] - stats.centroid[:, None, None, :]
    ww = wavelength_weights.to(xy.dtype) / wavelength_weights.sum()
    fw = field_weights.to(xy.dtype) / field_weights.sum()
    scale = torch.sqrt(fw[:, None, None] * ww[None, :, None] / P)
    d = torch.where(res.valid.unsqueeze(-1), xy * scale.unsqueeze(-1), 0.0)
    return d.reshape(-1)


def gap_lengths(bundle: Bundle) -> Tensor:
    """(S, F, W, P) axial distance t_z each ray travels in the gap after every surface (needs a
    bundle traced with ``record=True``); the last gap ends on the image surface."""
    res = bundle.result
    z = torch.stack([h.pos[..., 2] for h in res.hits] + [res.pos[..., 2]])
    return z[1:] - z[:-1]


def ray_path(bundle: Bundle, lower: Tensor, upper: Tensor) -> Tensor:
    """(S n_r,) ray path residuals (S41–S42) for per-gap bounds ``lower``/``upper`` (S,) in mm."""
    tz = gap_lengths(bundle)
    lo, hi = lower[:, None, None, None], upper[:, None, None, None]
    d = _ramp(torch.maximum(tz - hi, lo - tz))
    d = torch.where(bundle.result.valid.unsqueeze(0), d, 0.0)
    return d.reshape(-1) / math.sqrt(bundle.result.status.numel())


def ray_angle(bundle: Bundle, surfaces: list[int], max_deg: float) -> Tensor:
    """(2 I n_r,) ray angle residuals (S43–S45) at the interfaces ``surfaces``: ramp(cos²θmax − ζ)
    for ζ_I = cos² of incidence and ζ_R = cos² of refraction (negative on TIR)."""
    res = bundle.result
    c2 = math.cos(math.radians(max_deg)) ** 2
    out = []
    for s in surfaces:
        h = res.hits[s]
        out += [_ramp(c2 - h.cos2_in), _ramp(c2 - h.cos2_out)]
    if not out:
        return res.pos.new_zeros(0)
    d = torch.where(res.valid.unsqueeze(0), torch.stack(out), 0.0)
    return d.reshape(-1) / math.sqrt(res.status.numel())


def surface_normal(bundle: Bundle, surfaces: list[int], max_deg: float) -> Tensor:
    """(I n_r,) surface normal residuals (S46–S47): ramp(cos²θmax − n_z²) where rays hit."""
    res = bundle.result
    c2 = math.cos(math.radians(max_deg)) ** 2
    if not surfaces:
        return res.pos.new_zeros(0)
    nz2 = torch.stack([res.hits[s].normal[..., 2] ** 2 for s in surfaces])
    d = torch.where(res.valid.unsqueeze(0), _ramp(c2 - nz2), 0.0)
    return d.reshape(-1) / math.sqrt(res.status.numel())


def distortion(lens: Lens, system: System, bundle: Bundle, stats: SpotStats, max_fraction: float) -> Tensor:
    """(F,) distortion residuals (S48–S50): ramp(|D_h| − D_max)/√n_h, D as a fraction."""
    d = distortion_per_field(lens, system, bundle, stats)
    return _ramp(d.abs() - max_fraction) / math.sqrt(d.shape[0])


def relative_illumination(bundle: Bundle, wavelength_weights: Tensor, minimum: float) -> Tensor:
    """(F,) relative illumination residuals (S52–S54): ramp(R_min − R_h)/√n_h, all-ray estimate."""
    r = relative_illumination_std(bundle, wavelength_weights)
    return _ramp(minimum - r) / math.sqrt(r.shape[0])


def failures(bundle: Bundle, penalty_mm: float) -> Tensor:
    """(n_r,) ``penalty_mm``/√n_r for every failed ray, 0 for the others (constant: no gradient, but
    a step that fails rays raises the merit and is rejected)."""
    res = bundle.result
    bad = (~res.valid).to(res.pos.dtype)
    return (bad * penalty_mm).reshape(-1) / math.sqrt(res.status.numel())
