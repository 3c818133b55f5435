"""Spot diagrams (S1.3.3): image-surface ray positions per field and wavelength, with their statistics
and the diffraction scale (Airy radius 1.22 λ N_w) to judge them against.

This is the data behind ``lensopt plot spots``; the numbers (RMS radii, centroids) are those of
:func:`lensopt.analysis.spot.spot_stats`, i.e. the same as ``lensopt trace`` for the same sampling.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.analysis.spot import SpotStats, spot_stats
from lensopt.engine import Engine
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import FirstOrder
from lensopt.optics.sampling import PupilSampling

__all__ = ["SpotDiagram", "spot_diagram", "airy_radius"]


def airy_radius(wavelength_um: Tensor, working_fnumber: Tensor) -> Tensor:
    """Radius of the Airy disc's first dark ring, 1.22 λ N_w, in mm.

    Args:
        wavelength_um: (*) wavelengths, µm.
        working_fnumber: () or broadcastable paraxial working f-number N_w.
    """
    return 1.22 * wavelength_um * 1e-3 * working_fnumber


@dataclass(frozen=True)
class SpotDiagram:
    """Spot diagrams of every field and wavelength.

    Attributes:
        rel_field: (F,) relative fields.
        field_deg: (F,) object-space chief-ray angles, degrees.
        wavelength_um: (W,) wavelengths, µm.
        wavelength_weights: (W,) spectral weights W_w.
        reference: index of the reference wavelength.
        xy: (F, W, P, 2) ray positions on the image surface, mm (finite placeholders where invalid).
        valid: (F, W, P) bool, the ray reached the image.
        half_pupil: only x ≥ 0 was sampled; the full spot is this one and its mirror image x → −x.
        stats: centroids and RMS radii (S23–S24), mm.
        chief: (F, 2) image-surface (x, y) of the reference-wavelength chief ray, mm.
        airy_radius: (W,) 1.22 λ N_w, mm.
        working_fnumber: () paraxial working f-number N_w.
        sampling: the pupil sampling used, e.g. ``rings:24``.
    """

    rel_field: Tensor
    field_deg: Tensor
    wavelength_um: Tensor
    wavelength_weights: Tensor
    reference: int
    xy: Tensor
    valid: Tensor
    half_pupil: bool
    stats: SpotStats
    chief: Tensor
    airy_radius: Tensor
    working_fnumber: Tensor
    sampling: str


def spot_diagram(
    lens: Lens,
    system: System,
    sampling: PupilSampling,
    *,
    aim: str | None = None,
    rel_field: Tensor | None = None,
    fo: FirstOrder | None = None,
    engine: Engine | None = None,
) -> SpotDiagram:
    """Trace the pupil ``sampling`` for every field and wavelength and collect the spot diagrams.

    Args:
        sampling: pupil sampling scheme (``rings:N`` and ``gauss:N`` sample the half pupil, ``grid:N`` the full
            one; ``gauss:N`` weighs the statistics by its quadrature weights).
        aim: ``none`` or ``chief``; default: the system's.
        rel_field: (F,) relative fields; default: the system's.
        fo: precomputed first-order data.
    """
    pts = sampling.points(dtype=lens.dtype, device=lens.device, engine=engine)
    bundle = trace_bundle(lens, system, pts, half_pupil=sampling.half, rel_field=rel_field, aim=aim, fo=fo,
                          pupil_weights=sampling.weights(dtype=lens.dtype, device=lens.device), engine=engine)
    fo = bundle.first_order
    chief = trace_bundle(lens, system, torch.zeros(1, 2, dtype=lens.dtype, device=lens.device),
                         rel_field=bundle.rel_field, aim=aim, fo=fo, engine=engine)
    return SpotDiagram(
        rel_field=bundle.rel_field,
        field_deg=torch.rad2deg(torch.atan(bundle.tan_field)),
        wavelength_um=lens.wavelength_um,
        wavelength_weights=system.wavelength_weights,
        reference=system.reference,
        xy=bundle.result.pos[..., :2],
        valid=bundle.result.valid,
        half_pupil=sampling.half,
        stats=spot_stats(bundle, system.wavelength_weights),
        chief=chief.result.pos[:, system.reference, 0, :2],
        airy_radius=airy_radius(lens.wavelength_um, fo.working_fnumber),
        working_fnumber=fo.working_fnumber,
        sampling=str(sampling),
    )
