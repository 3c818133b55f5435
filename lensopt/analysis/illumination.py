"""Relative illumination per field from image-space direction cosines (S51–S52).

- ``three_ray``: Rimmer's estimate (S51) from the lateral (px = 1), inferior (py = −1) and superior
  (py = +1) rays, ``R_h = |α_l,h| |β_i,h − β_s,h| / (2 β_s,0²)``, normalised so that R = 1 on axis.
- ``std``: the all-ray estimate (S52), ``R_h = α_std,h β_std,h / (α_std,0 β_std,0)`` with the
  wavelength-weighted standard deviations of the image-space direction cosines of every valid ray.

The normalising field (subscript 0) is the bundle's field with the smallest relative field (the axis
when the field list starts at 0, as it usually does).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from lensopt.analysis.spot import safe_sqrt
from lensopt.optics.bundle import Bundle
from lensopt.optics.trace import Status

__all__ = ["relative_illumination_std", "relative_illumination_three_ray", "THREE_RAY_PUPIL"]

THREE_RAY_PUPIL = ((1.0, 0.0), (0.0, -1.0), (0.0, 1.0))
"""Relative pupil points of the lateral, inferior and superior rays, in this order."""


def _reference_field(bundle: Bundle) -> Tensor:
    """(1,) index of the field closest to the axis, a tensor: no Python int and no indexing by a 0-d
    tensor (both read a value out of the tensor, which a captured graph of the residuals,
    ``accel.jacobian``, cannot do); use with ``index_select``."""
    return torch.argmin(bundle.rel_field.detach()).reshape(1)


def _at(values: Tensor, ref: Tensor) -> Tensor:
    """``values[ref]`` for the (1,) index of ``_reference_field``, broadcastable against (F,)."""
    return values.index_select(0, ref)


def relative_illumination_std(bundle: Bundle, wavelength_weights: Tensor) -> Tensor:
    """(F,) S52 estimate from every valid ray of a full bundle (batch F × W × P), differentiable;
    0 for a field none of whose rays reaches the image."""
    res = bundle.result
    valid = res.valid
    w = wavelength_weights.to(res.dir.dtype)[None, :, None] * valid.to(res.dir.dtype)
    if bundle.pupil_weights is not None:  # a quadrature's pupil-area weights
        w = w * bundle.pupil_weights.to(w.dtype)
    total = w.sum((1, 2)).clamp_min(torch.finfo(w.dtype).tiny)

    def std(v: Tensor, zero_mean: bool) -> Tensor:
        v = torch.where(valid, v, 0.0)
        mean = torch.zeros_like(total) if zero_mean else (w * v).sum((1, 2)) / total
        return safe_sqrt((w * (v - mean[:, None, None]) ** 2).sum((1, 2)) / total)

    # With half-pupil sampling the x-mean of the full bundle is 0 by symmetry.
    a_std = std(res.dir[..., 0], zero_mean=bundle.half_pupil)
    b_std = std(res.dir[..., 1], zero_mean=False)
    ref = _reference_field(bundle)
    lit = valid.any(-1).any(-1)
    r = a_std * b_std / (_at(a_std, ref) * _at(b_std, ref))
    return torch.where(lit, r, torch.zeros_like(r))  # no ray through: no light (not sqrt(tiny)²)


def relative_illumination_three_ray(bundle: Bundle, wavelength: int) -> Tensor:
    """(F,) S51 estimate from a bundle traced with the pupil points ``THREE_RAY_PUPIL`` (P = 3)
    at wavelength index ``wavelength``. A field whose three rays are all stopped by the front aperture
    gives 0 (no light); one where any of them fails otherwise gives NaN (not measurable, never 0)."""
    d = bundle.result.dir[:, wavelength]  # (F, 3, 3)
    ok = bundle.result.valid[:, wavelength].all(-1)
    blocked = (bundle.result.status[:, wavelength] == Status.BLOCKED).all(-1)
    alpha_l = d[:, 0, 0]
    beta_i, beta_s = d[:, 1, 1], d[:, 2, 1]
    ref = _reference_field(bundle)
    r = alpha_l.abs() * (beta_i - beta_s).abs() / (2.0 * _at(beta_s, ref) ** 2)
    r = torch.where(ok & _at(ok, ref), r, torch.full_like(r, math.nan))
    return torch.where(blocked, torch.zeros_like(r), r)
