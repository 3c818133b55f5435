"""Paraxial (first-order) optics by y–ω ray transfer matrices, differentiable in every lens tensor.

A paraxial ray is (y, ω) with ω = n u the reduced angle. At surface s (power K_s) and across the gap
t_s after it::

    ω' = ω − y K_s,      y_next = y + t_s ω' / n_{s+1}

with ``K_s = (n_{s+1} − n_s) c_s − m λ d2 / π`` (the last term: paraxial power of a diffractive phase
``φ = d2 r² + …``, from the generalized law S15). Conics and asphere terms have no paraxial effect.
All positions are measured along the axis from the vertex of surface 1, in mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import torch
from torch import Tensor

from lensopt.optics.lens import Lens, System

__all__ = [
    "surface_powers",
    "ray_transfer",
    "trace_paraxial",
    "FirstOrder",
    "first_order",
    "field_tangents",
]


def surface_powers(lens: Lens, wavelength: int) -> Tensor:
    """(S,) paraxial power of every surface at wavelength index ``wavelength``, 1/mm."""
    n = lens.index[:, wavelength]
    power = (n[1:] - n[:-1]) * lens.curvature
    orders = torch.tensor([s.order if s.diffractive else 0 for s in lens.shapes],
                          dtype=lens.dtype, device=lens.device)
    if lens.phase.shape[-1] > 0:
        lam_mm = lens.wavelength_um[wavelength] * 1e-3
        power = power - orders * lam_mm * lens.phase[:, 0] / math.pi
    return power


def ray_transfer(lens: Lens, wavelength: int, first: int, last: int) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Matrix (A, B, C, D) from the vertex plane of surface ``first`` (before it refracts) to just
    after surface ``last`` refracts: ``y' = A y + B ω``, ``ω' = C y + D ω``. Gaps between are included.
    """
    power = surface_powers(lens, wavelength)
    n = lens.index[:, wavelength]
    one = torch.ones_like(power[0])
    a, b, c, d = one, 0.0 * one, 0.0 * one, one
    for s in range(first, last + 1):
        if s > first:
            tau = lens.thickness[s - 1] / n[s]
            a, b = a + tau * c, b + tau * d
        c, d = c - power[s] * a, d - power[s] * b
    return a, b, c, d


def trace_paraxial(lens: Lens, wavelength: int, y0: Tensor, omega0: Tensor) -> tuple[Tensor, Tensor]:
    """Trace (y, ω) given at the vertex plane of surface 1 through every surface to the image.

    Returns:
        y: (S+1, *) height at every surface and at the image surface, mm.
        omega: (S+1, *) reduced angle before surface 1, then after every surface.
    """
    power = surface_powers(lens, wavelength)
    n = lens.index[:, wavelength]
    ys, ws = [], [omega0]
    y, w = y0, omega0
    for s in range(lens.num_surfaces):
        ys.append(y)
        w = w - y * power[s]
        ws.append(w)
        y = y + lens.thickness[s] * w / n[s + 1]
    ys.append(y)
    return torch.stack(ys), torch.stack(ws[:-1] + [w])


@dataclass(frozen=True)
class FirstOrder:
    """First-order data at the reference wavelength (tensors, differentiable). Lengths in mm; axial
    positions from the vertex of surface 1.

    Attributes:
        efl: effective focal length 1/Φ.
        bfl: last surface vertex to the rear focal point.
        ffl: surface 1 vertex to the front focal point (negative when in front of the lens).
        epd: entrance pupil diameter.
        entrance_pupil_z: entrance pupil position.
        exit_pupil_z: exit pupil position.
        exit_pupil_diameter: paraxial exit pupil diameter.
        fnumber: EFL / EPD.
        working_fnumber: 1 / (2 n' |u'|) of the paraxial marginal ray in image space.
        paraxial_image_height: full-field paraxial chief-ray height on the image surface.
        total_track: surface 1 vertex to the image surface.
        image_distance: last surface vertex to the image surface.
        stop_semi_diameter: paraxial marginal-ray height on the stop.
    """

    efl: Tensor
    bfl: Tensor
    ffl: Tensor
    epd: Tensor
    entrance_pupil_z: Tensor
    exit_pupil_z: Tensor
    exit_pupil_diameter: Tensor
    fnumber: Tensor
    working_fnumber: Tensor
    paraxial_image_height: Tensor
    total_track: Tensor
    image_distance: Tensor
    stop_semi_diameter: Tensor

    def as_dict(self) -> dict[str, float]:
        return {f.name: float(getattr(self, f.name)) for f in fields(self)}


def _entrance_pupil_z(lens: Lens, wavelength: int) -> Tensor:
    if lens.stop == 0:
        return torch.zeros_like(lens.thickness[0])
    n = lens.index[:, wavelength]
    a, b, c, d = ray_transfer(lens, wavelength, 0, lens.stop - 1)
    tau = lens.thickness[lens.stop - 1] / n[lens.stop]
    a_s, b_s = a + tau * c, b + tau * d
    # The chief ray (ω0 = n0, i.e. u0 = 1) through the stop centre starts at y0 = −b_s n0 / a_s on
    # the plane of surface 1 and crosses the axis in object space at z = −y0 / u0.
    return b_s * n[0] / a_s


def first_order(lens: Lens, system: System) -> FirstOrder:
    """Paraxial first-order data of ``lens`` under ``system`` at the reference wavelength."""
    w = system.reference
    n = lens.index[:, w]
    last = lens.num_surfaces - 1
    a, b, c, d = ray_transfer(lens, w, 0, last)
    power = -c
    efl = 1.0 / power
    bfl = -n[-1] * a / c
    ffl = n[0] * d / c
    ep_z = _entrance_pupil_z(lens, w)
    epd = entrance_pupil_diameter(lens, system, efl=efl)
    z_img = lens.vertex_z()[-1]
    z_last = z_img - lens.thickness[-1]

    # Marginal ray: from the axial object point through the entrance pupil edge.
    h = epd / 2
    if system.object_distance is None:
        y0, u0 = h, torch.zeros_like(h)
    else:
        u0 = h / (ep_z + system.object_distance)
        y0 = h - u0 * ep_z
    ym, wm = trace_paraxial(lens, w, y0, n[0] * u0)
    working_fnumber = n[-1] / (2.0 * wm[-1].abs())
    stop_sd = ym[lens.stop].abs()

    # Exit pupil: image of the stop centre through the rear group. A ray leaving the stop centre
    # with ω = 1 reaches the last surface at y = B and leaves it with ω' = D.
    _, b_r, _, d_r = ray_transfer(lens, w, lens.stop, last)
    xp_z = z_last - b_r * n[-1] / d_r
    y_img, u_img = ym[-1], wm[-1] / n[-1]
    exit_pupil_diameter = 2.0 * (y_img + u_img * (xp_z - z_img)).abs()

    tan_max = field_tangents(lens, system, torch.ones((), dtype=lens.dtype, device=lens.device))
    image_height = chief_image_height(lens, system, tan_max, ep_z=ep_z)
    return FirstOrder(
        efl=efl,
        bfl=bfl,
        ffl=ffl,
        epd=epd,
        entrance_pupil_z=ep_z,
        exit_pupil_z=xp_z,
        exit_pupil_diameter=exit_pupil_diameter,
        fnumber=efl / epd,
        working_fnumber=working_fnumber,
        paraxial_image_height=image_height,
        total_track=z_img,
        image_distance=lens.thickness[-1],
        stop_semi_diameter=stop_sd,
    )


def entrance_pupil_diameter(lens: Lens, system: System, *, efl: Tensor | None = None) -> Tensor:
    """EPD from the spec: given directly, or EFL / f-number (S1.3.1 step 2)."""
    if system.epd is not None:
        return torch.as_tensor(system.epd, dtype=lens.dtype, device=lens.device)
    if efl is None:
        _, _, c, _ = ray_transfer(lens, system.reference, 0, lens.num_surfaces - 1)
        efl = -1.0 / c
    return efl.abs() / system.fnumber


def chief_image_height(lens: Lens, system: System, tan_field: Tensor, *, ep_z: Tensor | None = None) -> Tensor:
    """Paraxial chief-ray height on the image surface for object-space chief-ray slopes ``tan_field``."""
    w = system.reference
    if ep_z is None:
        ep_z = _entrance_pupil_z(lens, w)
    n0 = lens.index[0, w]
    y, _ = trace_paraxial(lens, w, -tan_field * ep_z, n0 * tan_field)
    return y[-1]


def field_tangents(lens: Lens, system: System, rel_field: Tensor) -> Tensor:
    """Object-space chief-ray slopes tan(θ) for relative fields (angle or image-height fields).

    For an angle field the relative values scale the angle, θ_h = u_h · HFOV (S1.3.1 step 4); for an
    image-height field they scale the paraxial image height, and the slope follows from the (linear)
    paraxial chief ray.
    """
    if system.field_type == "angle":
        return torch.tan(rel_field * math.radians(system.field_max))
    per_unit = chief_image_height(lens, system, torch.ones_like(rel_field))
    return rel_field * system.field_max / per_unit
