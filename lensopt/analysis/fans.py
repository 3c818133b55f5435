"""Ray fans (S1.3.4, Figure S3): transverse ray aberrations along the pupil axes, per field and wavelength.

Tangential fan: rays along the pupil's vertical diameter, py ∈ [−1, 1] (px = 0); the plotted
aberration is ε_y = y − y_chief. Sagittal fan: rays along the horizontal radius, px ∈ [0, 1] (py = 0),
with ε_x = x − x_chief. Both are measured on the image surface against the chief ray of the *reference*
wavelength, so that lateral colour shows as an offset of the other wavelengths' curves at the origin
(as CODE V and Zemax draw them).

Failed rays keep their rows (DESIGN.md rule 1): their aberration is a finite placeholder (0) and the
``*_valid`` masks say which points exist. Turning them into gaps is the plot's job.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.engine import Engine
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import FirstOrder
from lensopt.optics.sampling import fan

__all__ = ["RayFans", "ray_fans"]


@dataclass(frozen=True)
class RayFans:
    """Tangential and sagittal ray fans of every field and wavelength.

    Attributes:
        rel_field: (F,) relative fields.
        field_deg: (F,) object-space chief-ray angles, degrees (for angle and image-height fields).
        wavelength_um: (W,) wavelengths, µm.
        reference: index of the reference wavelength (whose chief ray is the origin of ε).
        working_fnumber: () paraxial working f-number (for diffraction-scale annotations).
        py: (T,) relative pupil coordinates of the tangential fan, −1 … 1.
        tangential: (F, W, T) ε_y = y − y_chief on the image surface, mm (0 where invalid).
        tangential_valid: (F, W, T) bool, the ray reached the image.
        px: (S,) relative pupil coordinates of the sagittal fan, 0 … 1.
        sagittal: (F, W, S) ε_x = x − x_chief on the image surface, mm (0 where invalid).
        sagittal_valid: (F, W, S) bool.
        chief: (F, 2) image-surface (x, y) of the reference-wavelength chief ray, mm.
        chief_valid: (F,) bool; where False, every ε of that field is marked invalid.
    """

    rel_field: Tensor
    field_deg: Tensor
    wavelength_um: Tensor
    reference: int
    working_fnumber: Tensor
    py: Tensor
    tangential: Tensor
    tangential_valid: Tensor
    px: Tensor
    sagittal: Tensor
    sagittal_valid: Tensor
    chief: Tensor
    chief_valid: Tensor


def ray_fans(
    lens: Lens,
    system: System,
    *,
    points: int = 65,
    rel_field: Tensor | None = None,
    aim: str | None = None,
    fo: FirstOrder | None = None,
    engine: Engine | None = None,
) -> RayFans:
    """Trace the tangential and sagittal fans of ``lens`` for every field and wavelength.

    One bundle holds the chief ray (pupil origin), the tangential fan and the sagittal fan, so that
    aiming (``aim="chief"`` shifts every pupil point by the same per-field, per-wavelength offset)
    treats them alike. Differentiable in the lens parameters.

    Args:
        points: rays per fan (≥ 2); odd counts put a ray exactly at the pupil centre.
        rel_field: (F,) relative fields; default: the system's.
        aim: ``none`` or ``chief``; default: the system's.
        fo: precomputed first-order data.
    """
    if points < 2:
        raise ValueError(f"points must be at least 2, got {points}")
    dtype, device = lens.dtype, lens.device
    tan_pts = fan(points, "tangential", dtype=dtype, device=device)
    sag_pts = fan(points, "sagittal", dtype=dtype, device=device)
    origin = torch.zeros(1, 2, dtype=dtype, device=device)
    pupil = torch.cat([origin, tan_pts, sag_pts])  # (1 + 2·points, 2)
    bundle = trace_bundle(lens, system, pupil, rel_field=rel_field, aim=aim, fo=fo, engine=engine)
    pos, valid = bundle.result.pos, bundle.result.valid  # (F, W, P, 3), (F, W, P)

    ref = system.reference
    chief = pos[:, ref, 0, :2]  # (F, 2)
    chief_valid = valid[:, ref, 0]
    tan_slice = slice(1, 1 + points)
    sag_slice = slice(1 + points, 1 + 2 * points)

    t_valid = valid[:, :, tan_slice] & chief_valid[:, None, None]
    s_valid = valid[:, :, sag_slice] & chief_valid[:, None, None]
    eps_y = pos[:, :, tan_slice, 1] - chief[:, None, None, 1]
    eps_x = pos[:, :, sag_slice, 0] - chief[:, None, None, 0]
    return RayFans(
        rel_field=bundle.rel_field,
        field_deg=torch.rad2deg(torch.atan(bundle.tan_field)),
        wavelength_um=lens.wavelength_um,
        reference=ref,
        working_fnumber=bundle.first_order.working_fnumber,
        py=tan_pts[:, 1],
        tangential=torch.where(t_valid, eps_y, torch.zeros_like(eps_y)),
        tangential_valid=t_valid,
        px=sag_pts[:, 0],
        sagittal=torch.where(s_valid, eps_x, torch.zeros_like(eps_x)),
        sagittal_valid=s_valid,
        chief=chief,
        chief_valid=chief_valid,
    )

