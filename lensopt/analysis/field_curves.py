"""Field curves: sagittal and tangential field curvature, distortion and lateral colour against field,
and the chromatic focal shift against wavelength.

**Field curvature** (real rays): about the chief ray of each field and wavelength, two close rays at
pupil (0, ±δ) (tangential) and two at (±δ, 0) (sagittal) are traced; where each pair crosses (in the
y–z plane, respectively the x–z plane) is the tangential / sagittal focus of the thin bundle around
the chief ray (the central differences converge to Coddington's foci as O(δ²)). The curves give the
axial distance of those foci from the image surface, mm (positive: behind it, away from the lens).

**Distortion** (real chief ray): ``(y_chief − y_paraxial) / y_paraxial`` at the reference wavelength,
the chief ray's image height against the paraxial image height of the same field (Zemax's and CODE V's
"distortion" curve). ``analysis.distortion`` (S48) is the seed's variant (the spot centroid against
the paraxial height of the outermost field).

**Lateral colour**: the chief ray's image height at each wavelength minus the reference wavelength's, mm.

**Chromatic focal shift** (paraxial): the paraxial focus of the marginal ray at each wavelength,
relative to the reference wavelength's, mm (Zemax's "chromatic focal shift"). Wavelengths between the
spec's need the media (``Model.media``) to evaluate the indices there.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.analysis.checks import fields_of
from lensopt.engine import Engine
from lensopt.materials import Material
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import FirstOrder, chief_image_height, first_order, trace_paraxial

__all__ = ["FieldCurves", "field_curves", "FocalShift", "chromatic_focal_shift", "DEFAULT_DELTA"]

DEFAULT_DELTA = 1e-4
"""Relative pupil offset of the differential rays (O(δ²) from the limit; round-off ≈ 1e-16/δ relative)."""


@dataclass(frozen=True)
class FieldCurves:
    """Field curves per field and wavelength.

    Attributes:
        rel_field: (F,) relative fields; field_deg: (F,) object-space chief-ray angles, degrees.
        wavelength_um: (W,) wavelengths; reference: index of the reference wavelength.
        tangential_mm, sagittal_mm: (F, W) focus positions of the thin bundles from the image surface.
        valid: (F, W) bool: the chief ray and its four neighbours reached the image.
        distortion: (F,) real chief-ray distortion at the reference wavelength, a fraction (0 on axis).
        chief_y_mm: (F, W) chief-ray image heights.
        paraxial_y_mm: (F,) paraxial image heights (reference wavelength).
        lateral_color_mm: (F, W) chief-ray height minus the reference wavelength's.
    """

    rel_field: Tensor
    field_deg: Tensor
    wavelength_um: Tensor
    reference: int
    tangential_mm: Tensor
    sagittal_mm: Tensor
    valid: Tensor
    distortion: Tensor
    chief_y_mm: Tensor
    paraxial_y_mm: Tensor
    lateral_color_mm: Tensor


def _crossing(q1: Tensor, d1: Tensor, q2: Tensor, d2: Tensor, axis: int) -> Tensor:
    """Axial distance from q1 along d1 to where the two rays cross in the (axis, z) plane."""
    a1, z1, a2, z2 = q1[..., axis], q1[..., 2], q2[..., axis], q2[..., 2]
    m1, n1, m2, n2 = d1[..., axis], d1[..., 2], d2[..., axis], d2[..., 2]
    den = m1 * n2 - m2 * n1
    tiny = torch.finfo(den.dtype).tiny
    den = torch.where(den.abs() > tiny, den, torch.full_like(den, tiny))
    t1 = ((a2 - a1) * n2 - (z2 - z1) * m2) / den
    return t1 * n1


def field_curves(lens: Lens, system: System, rel_field: Tensor, *, delta: float = DEFAULT_DELTA,
                 aim: str | None = None, engine: Engine | None = None) -> FieldCurves:
    """Field curvature, distortion and lateral colour at the relative fields ``rel_field`` ((F,)).
    Differentiable in the lens."""
    dt, dev = lens.dtype, lens.device
    pupil = torch.tensor([[0.0, 0.0], [0.0, -delta], [0.0, delta], [-delta, 0.0], [delta, 0.0]], dtype=dt, device=dev)
    fo = first_order(lens, system)
    b = trace_bundle(lens, system, pupil, rel_field=fields_of(lens, system, rel_field), aim=aim, fo=fo, engine=engine)
    q, d, ok = b.result.pos, b.result.dir, b.result.valid  # (F, W, 5, ...)
    tan = _crossing(q[:, :, 1], d[:, :, 1], q[:, :, 2], d[:, :, 2], 1)
    sag = _crossing(q[:, :, 3], d[:, :, 3], q[:, :, 4], d[:, :, 4], 0)
    valid = ok.all(-1)
    zero = torch.zeros_like(tan)
    chief_y = torch.where(ok[:, :, 0], q[:, :, 0, 1], zero)
    ref = system.reference
    y_par = chief_image_height(lens, system, b.tan_field, ep_z=fo.entrance_pupil_z)
    safe = torch.where(y_par.abs() > 0, y_par, torch.ones_like(y_par))
    dist = torch.where(y_par.abs() > 0, (chief_y[:, ref] - y_par) / safe, torch.zeros_like(y_par))
    lateral = torch.where(ok[:, :, 0] & ok[:, ref:ref + 1, 0], chief_y - chief_y[:, ref:ref + 1], zero)
    return FieldCurves(rel_field=b.rel_field, field_deg=torch.rad2deg(torch.atan(b.tan_field)),
                       wavelength_um=lens.wavelength_um, reference=ref,
                       tangential_mm=torch.where(valid, tan, zero), sagittal_mm=torch.where(valid, sag, zero),
                       valid=valid, distortion=dist, chief_y_mm=chief_y, paraxial_y_mm=y_par,
                       lateral_color_mm=lateral)


@dataclass(frozen=True)
class FocalShift:
    """Chromatic focal shift.

    Attributes:
        wavelength_um: (K,) wavelengths.
        shift_mm: (K,) paraxial focus minus the reference wavelength's, mm (positive: further from the lens).
        reference_um: the reference wavelength.
        spec_wavelength_um: (W,) the spec's wavelengths (marked on plots).
    """

    wavelength_um: Tensor
    shift_mm: Tensor
    reference_um: float
    spec_wavelength_um: Tensor


def _paraxial_focus(lens: Lens, system: System, w: int, fo: FirstOrder) -> Tensor:
    """z of the paraxial marginal ray's focus at wavelength index ``w``, relative to the image surface
    (the marginal ray through the edge of the reference wavelength's entrance pupil ``fo``)."""
    n = lens.index[:, w]
    h = fo.epd / 2
    if system.object_distance is None:
        y0, u0 = h, 0.0 * h
    else:
        u0 = h / (fo.entrance_pupil_z + system.object_distance)
        y0 = h - u0 * fo.entrance_pupil_z
    y, om = trace_paraxial(lens, w, y0, n[0] * u0)
    return -y[-1] * n[-1] / om[-1]


def chromatic_focal_shift(lens: Lens, system: System, *, media: Sequence[Material] | None = None,
                          samples: int = 41) -> FocalShift:
    """Paraxial focus shift against wavelength: at the spec's wavelengths, or with ``media`` at ``samples``
    wavelengths evenly spread over the spec's range."""
    dt, dev = lens.dtype, lens.device
    ref_um = float(lens.wavelength_um[system.reference])
    if media is None:
        lam = lens.wavelength_um
        index = lens.index
    else:
        lo, hi = float(lens.wavelength_um.min()), float(lens.wavelength_um.max())
        lam = torch.linspace(lo, hi, max(samples, 2), dtype=dt, device=dev)
        lam = torch.sort(torch.cat([lam, lens.wavelength_um[system.reference:system.reference + 1]])).values
        index = torch.stack([m.index(lam).to(dt) for m in media])
    wide = dataclasses.replace(lens, wavelength_um=lam, index=index)
    fo = first_order(lens, system)
    z = torch.stack([_paraxial_focus(wide, system, k, fo) for k in range(lam.shape[0])])
    z_ref = _paraxial_focus(lens, system, system.reference, fo)
    return FocalShift(wavelength_um=lam, shift_mm=z - z_ref, reference_um=ref_um,
                      spec_wavelength_um=lens.wavelength_um)
