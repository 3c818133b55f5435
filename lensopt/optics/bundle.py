"""Trace a lens as a system: first-order data, field angles, pupil sampling, aiming, real rays.

This is the entry point analysis and plots use: it ties ``paraxial`` (entrance pupil, EPD, field
slopes), ``aiming`` and ``sampling.launch`` to ``trace``.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.optics.aiming import ChiefAim, aim_chief
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import FirstOrder, field_tangents, first_order
from lensopt.optics.sampling import launch
from lensopt.optics.trace import Rays, RayTrace, trace
from lensopt.optics.vignetting import apply_vignetting

__all__ = ["Bundle", "trace_bundle"]


@dataclass(frozen=True)
class Bundle:
    """Rays of every field × wavelength × pupil sample and what became of them.

    Attributes:
        first_order: paraxial data used to place the rays.
        rel_field: (F,) relative fields.
        tan_field: (F,) object-space chief-ray slopes.
        pupil: (F, W, P, 2) relative pupil coordinates actually launched (after aiming).
        rays: the object-space rays, batch (F, W, P).
        result: the trace.
        aim: chief-ray aiming result, or None.
        half_pupil: True when only x ≥ 0 was sampled (x̄ = 0 by symmetry).
    """

    first_order: FirstOrder
    rel_field: Tensor
    tan_field: Tensor
    pupil: Tensor
    rays: Rays
    result: RayTrace
    aim: ChiefAim | None
    half_pupil: bool


def trace_bundle(
    lens: Lens,
    system: System,
    pupil: Tensor,
    *,
    half_pupil: bool = False,
    rel_field: Tensor | None = None,
    aim: str | None = None,
    record: bool = False,
    fo: FirstOrder | None = None,
    vignetting: Tensor | None = None,
) -> Bundle:
    """Trace pupil points ``pupil`` ((P, 2) or (F, W, P, 2)) for every field and wavelength.

    Args:
        rel_field: (F,) relative fields; default: the system's.
        aim: ``none`` or ``chief``; default: the system's.
        record: keep per-surface hits (for constraints and layout plots).
        fo: precomputed first-order data (saves a paraxial trace).
        vignetting: (F, W or 1, 3) factors (V_i, V_s, V_l) applied to the pupil (S19–S20); default:
            the system's fixed factors when they match the fields, else none.
    """
    fo = first_order(lens, system) if fo is None else fo
    if rel_field is None:
        rel_field = torch.tensor(system.rel_field, dtype=lens.dtype, device=lens.device)
    tan = field_tangents(lens, system, rel_field)
    mode = system.aim if aim is None else aim
    chief = None
    pupil = pupil.to(lens.dtype)
    if pupil.dim() == 2:
        pupil = pupil.expand(rel_field.shape[0], lens.wavelength_um.shape[0], *pupil.shape)
    if vignetting is None and system.vignetting and len(system.vignetting) == rel_field.shape[0]:
        vignetting = torch.tensor(system.vignetting, dtype=lens.dtype, device=lens.device).unsqueeze(1)
    if vignetting is not None:
        pupil = apply_vignetting(pupil, vignetting)
    if mode == "chief":
        chief = aim_chief(lens, system, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
        shift = torch.stack([torch.zeros_like(chief.offset), chief.offset], -1).unsqueeze(-2)
        pupil = pupil + shift
    elif mode != "none":
        raise ValueError(f"aim must be 'none' or 'chief', got {mode!r}")
    rays = launch(lens, system, pupil, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
    result = trace(lens, rays, record=record)
    return Bundle(fo, rel_field, tan, pupil, rays, result, chief, half_pupil)
