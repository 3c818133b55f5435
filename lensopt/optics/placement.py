"""Decentered and tilted surfaces and elements: where each surface sits in space (rigid frames).

A nominal lens is rotationally symmetric: surface s has its vertex at (0, 0, z_s) and its axis along
+z. A ``Placement`` moves surfaces and elements off that axis, exactly and differentiably; the trace
(``optics.trace``) carries rays into each surface's own frame, intersects and bends there, and carries
them back (global coordinates: surface 1's nominal vertex at the origin, axis +z).

Conventions (as CODE V's DEC/ADE/BDE and Zemax's coordinate break with order flag 0):

- **Surface decenter** (dx, dy), mm, and **tilt** (α about x, then β about the *new* y), radians,
  taken in the current axis frame at that surface's vertex: the surface frame is
  ``origin = O + M (dx, dy, 0)``, ``rotation = M · Rx(α) · Ry(β)`` where (O, M) is the axis frame.
  Rotations are right-handed: ``Rx(α)`` turns +y towards +z, ``Ry(β)`` turns +z towards +x.
- **Mode** per surface: ``return`` (CODE V DAR, decenter-and-return: only this surface moves; the
  gap after it and every later surface stay on the axis) or ``basic`` (CODE V's default DEC, a Zemax
  coordinate break: the axis itself follows, so the gap after the surface runs along the tilted axis
  and every later surface, the image included, is moved with it).
- **Element decenter/tilt**: a rigid motion of surfaces ``first..last`` about the axis frame at the
  vertex of ``first`` (the pivot), decenter (dx, dy) then tilt α, β as above; surfaces after ``last``
  stay where they were (the element is moved *and returned*, as Zemax's "tilt/decenter elements"
  tool does with a pair of coordinate breaks).

The image surface keeps the axis frame after the last gap; the trace reports image positions in that
frame's own x, y (a detector's coordinates), so that a ``basic`` decenter moves the detector along.

Paraxial (first-order) data ignore the placement: they describe the centred lens (entrance pupil
position and diameter of the launch, EFL, f-numbers, paraxial image heights). Decenters and tilts
change first-order properties only in second order; their first-order effect (image shift and tilt)
is in the real trace. Chief-ray aiming (``optics.aiming``) does honour the placement: it aims at the
stop surface's own vertex, in x and y.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["Placement", "Frames", "rotation_xy", "surface_frames", "to_local", "to_global", "no_placement"]


@dataclass(frozen=True)
class Placement:
    """Decenters and tilts of S surfaces and G elements.

    Attributes:
        decenter: (S, 2) surface decenter (dx, dy), mm.
        tilt: (S, 2) surface tilt (α about x, β about the new y), radians.
        basic: (S,) static: True where the axis follows the surface (``basic``), False for
            decenter-and-return.
        groups: (G,) static (first, last) surface indices of each moved element (inclusive).
        group_decenter: (G, 2) element decenter, mm.
        group_tilt: (G, 2) element tilt (α, β), radians.
    """

    decenter: Tensor
    tilt: Tensor
    basic: tuple[bool, ...]
    groups: tuple[tuple[int, int], ...] = ()
    group_decenter: Tensor | None = None
    group_tilt: Tensor | None = None

    def to(self, dtype: torch.dtype) -> Placement:
        cast = {n: None if getattr(self, n) is None else getattr(self, n).to(dtype)
                for n in ("decenter", "tilt", "group_decenter", "group_tilt")}
        return Placement(basic=self.basic, groups=self.groups, **cast)


def no_placement(num_surfaces: int, *, dtype: torch.dtype, device: torch.device | None = None) -> Placement:
    """A placement with every surface on the axis (zeros), decenter-and-return: a start for perturbations."""
    zeros = torch.zeros(num_surfaces, 2, dtype=dtype, device=device)
    return Placement(decenter=zeros, tilt=zeros.clone(), basic=(False,) * num_surfaces)


@dataclass(frozen=True)
class Frames:
    """Rigid frames of every surface and of the image surface in global coordinates.

    Attributes:
        origin: (S+1, 3) vertex of each surface, then of the image surface, mm.
        rotation: (S+1, 3, 3) columns are the frame's x, y, z axes in global coordinates
            (local → global: ``p = origin + rotation @ p_local``).
    """

    origin: Tensor
    rotation: Tensor


def rotation_xy(alpha: Tensor, beta: Tensor) -> Tensor:
    """``Rx(α) · Ry(β)``: (*, 3, 3) rotation of a frame turned by α about x, then β about its new y."""
    ca, sa, cb, sb = torch.cos(alpha), torch.sin(alpha), torch.cos(beta), torch.sin(beta)
    zero, one = torch.zeros_like(ca), torch.ones_like(ca)
    rx = torch.stack([torch.stack([one, zero, zero], -1),
                      torch.stack([zero, ca, -sa], -1),
                      torch.stack([zero, sa, ca], -1)], -2)
    ry = torch.stack([torch.stack([cb, zero, sb], -1),
                      torch.stack([zero, one, zero], -1),
                      torch.stack([-sb, zero, cb], -1)], -2)
    return rx @ ry


def _vec(x: Tensor, y: Tensor, z: Tensor) -> Tensor:
    return torch.stack(torch.broadcast_tensors(x, y, z), -1)


def surface_frames(thickness: Tensor, placement: Placement) -> Frames:
    """Frames of every surface and of the image surface (see the module docstring for conventions).

    Args:
        thickness: (S,) gap after each surface, mm (along the axis frame at that surface).
        placement: decenters and tilts.

    Returns:
        ``Frames`` with (S+1, 3) origins and (S+1, 3, 3) rotations; differentiable in every input.
    """
    num = thickness.shape[0]
    dtype, device = thickness.dtype, thickness.device
    zero = torch.zeros((), dtype=dtype, device=device)
    axis_o = torch.zeros(3, dtype=dtype, device=device)
    axis_m = torch.eye(3, dtype=dtype, device=device)
    surf_rot = rotation_xy(placement.tilt[:, 0], placement.tilt[:, 1])  # (S, 3, 3)
    group_of = {}
    for g, (first, last) in enumerate(placement.groups):
        for s in range(first, last + 1):
            group_of.setdefault(s, []).append(g)
    pivots: dict[int, tuple[Tensor, Tensor]] = {}  # group → (translation, rotation) in global terms
    origins, rotations = [], []
    for s in range(num):
        for g, (first, _) in enumerate(placement.groups):
            if first == s:
                gd, gt = placement.group_decenter[g], placement.group_tilt[g]
                r_e = axis_m @ rotation_xy(gt[0], gt[1]) @ axis_m.T
                shift = axis_o + axis_m @ _vec(gd[0], gd[1], zero)
                pivots[g] = (axis_o, shift, r_e)
        d = placement.decenter[s]
        o = axis_o + axis_m @ _vec(d[0], d[1], zero)
        r = axis_m @ surf_rot[s]
        if placement.basic[s]:
            axis_o, axis_m = o, r
        for g in group_of.get(s, ()):
            pivot, shift, r_e = pivots[g]
            o = shift + r_e @ (o - pivot)
            r = r_e @ r
        origins.append(o)
        rotations.append(r)
        axis_o = axis_o + axis_m[:, 2] * thickness[s]
    origins.append(axis_o)
    rotations.append(axis_m)
    return Frames(torch.stack(origins), torch.stack(rotations))


def to_local(p: tuple[Tensor, Tensor, Tensor], origin: Tensor | None, rot: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Global components (x, y, z) → local: ``rotationᵀ (p − origin)`` (``origin`` None: a direction)."""
    x, y, z = p
    if origin is not None:
        x, y, z = x - origin[0], y - origin[1], z - origin[2]
    return (rot[0, 0] * x + rot[1, 0] * y + rot[2, 0] * z,
            rot[0, 1] * x + rot[1, 1] * y + rot[2, 1] * z,
            rot[0, 2] * x + rot[1, 2] * y + rot[2, 2] * z)


def to_global(p: tuple[Tensor, Tensor, Tensor], origin: Tensor | None, rot: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Local components → global: ``origin + rotation p`` (``origin`` None: a direction)."""
    x, y, z = p
    gx = rot[0, 0] * x + rot[0, 1] * y + rot[0, 2] * z
    gy = rot[1, 0] * x + rot[1, 1] * y + rot[1, 2] * z
    gz = rot[2, 0] * x + rot[2, 1] * y + rot[2, 2] * z
    if origin is not None:
        gx, gy, gz = gx + origin[0], gy + origin[1], gz + origin[2]
    return gx, gy, gz
