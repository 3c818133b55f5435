"""Geometry and meridional ray paths for a 2D layout drawing (the data behind ``lensopt plot layout``).

The meridional section is the y–z plane. Surface profiles are sampled from −h to h, h being the
surface's semi-diameter from the spec or, where the spec gives none, the clear aperture derived from
traced rays (:func:`lensopt.analysis.report.auto_semi_diameters`). Ray paths are the object-space
start point, every surface intersection and the image point of meridional rays (px = 0) at the
reference wavelength, with a mask saying how far each ray got.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.analysis.report import LensModel, auto_semi_diameters
from lensopt.engine import Engine
from lensopt.materials import Air
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import fan
from lensopt.optics.surfaces import sag
from lensopt.optics.trace import trace

__all__ = ["Layout", "layout"]


@dataclass(frozen=True)
class Layout:
    """A lens in meridional section, with traced rays.

    Attributes:
        vertex_z: (S+1,) z of every surface vertex and of the image surface, mm.
        semi_diameter: (S,) semi-diameters drawn, mm.
        semi_diameter_given: (S,) bool, True where the spec gives the semi-diameter.
        profile_y: (S, K) y samples of each profile, −h … h, mm.
        profile_z: (S, K) z of each profile at ``profile_y`` (vertex + sag), mm.
        profile_defined: (S, K) bool, the sag is defined there (False beyond a conic's rim).
        glass_after: (S,) True where the medium after the surface is not air (an element follows).
        stop: index of the aperture stop surface.
        rel_field: (F,) relative fields of the ray bundles.
        field_deg: (F,) object-space chief-ray angles, degrees.
        rays: (F, R, S+2, 2) meridional ray paths as (z, y): start, surfaces 1…S, image, mm.
        reached: (F, R, S+2) bool, the ray got to that point (a failed ray stops where it failed).
        image_half_height: () half height of the image surface to draw, mm.
        front_aperture: (z from surface 1, semi-diameter) of the system's front aperture, mm, if any.
    """

    vertex_z: Tensor
    semi_diameter: Tensor
    semi_diameter_given: Tensor
    profile_y: Tensor
    profile_z: Tensor
    profile_defined: Tensor
    glass_after: tuple[bool, ...]
    stop: int
    rel_field: Tensor
    field_deg: Tensor
    rays: Tensor
    reached: Tensor
    image_half_height: Tensor
    front_aperture: tuple[float, float] | None = None


def layout(model: LensModel, *, aim: str | None = None, rays_per_field: int = 7, samples: int = 101,
           engine: Engine | None = None) -> Layout:
    """Profiles, semi-diameters and traced meridional rays of ``model`` at the reference wavelength.

    Args:
        aim: ``none`` or ``chief``; default: the system's.
        rays_per_field: meridional rays per field, evenly spaced over py ∈ [−1, 1].
        samples: points per surface profile.
    """
    lens, system = model.lens, model.system
    dtype, device = lens.dtype, lens.device
    with torch.no_grad():
        given = lens.semi_diameter > 0
        auto = torch.tensor(auto_semi_diameters(model, aim=aim, engine=engine), dtype=dtype, device=device)
        sd = torch.where(given, lens.semi_diameter, auto)
        vertex = lens.vertex_z()

        t = torch.linspace(-1.0, 1.0, samples, dtype=dtype, device=device)
        ys, zs, defined = [], [], []
        for s in range(lens.num_surfaces):
            y = t * sd[s]
            asph = lens.asphere[s] if lens.shapes[s].kind == "asphere" else None
            z, _, ok = sag(y * y, lens.curvature[s], lens.conic[s], asph)
            ys.append(y)
            zs.append(vertex[s] + z)
            defined.append(ok)

        bundle = trace_bundle(lens, system, fan(rays_per_field, "tangential", dtype=dtype, device=device),
                              aim=aim, record=True, engine=engine)
        ref = system.reference
        rays = bundle.rays
        start = _start_points(rays.pos[:, ref], rays.dir[:, ref], vertex, model)
        points = [start] + [hit.pos[:, ref] for hit in bundle.result.hits] + [bundle.result.pos[:, ref]]
        path = torch.stack(points, -2)  # (F, R, S+2, 3)
        reached = [torch.ones_like(bundle.result.valid[:, ref])]
        for s in range(lens.num_surfaces):
            reached.append(trace(lens, rays, upto=s).valid[:, ref])
        reached.append(bundle.result.valid[:, ref])
        reached_t = torch.stack(reached, -1)
        reached_t = torch.cummin(reached_t.to(torch.int8), dim=-1).values.bool()

        img_y = torch.where(reached_t[..., -1], path[..., -1, 1].abs(), torch.zeros_like(path[..., -1, 1]))
        half_height = torch.maximum(img_y.max(), bundle.first_order.paraxial_image_height.abs())
    return Layout(
        vertex_z=vertex,
        semi_diameter=sd,
        semi_diameter_given=given,
        profile_y=torch.stack(ys),
        profile_z=torch.stack(zs),
        profile_defined=torch.stack(defined),
        glass_after=tuple(not isinstance(m, Air) for m in model.media[1:]),
        stop=lens.stop,
        rel_field=bundle.rel_field,
        field_deg=torch.rad2deg(torch.atan(bundle.tan_field)),
        rays=torch.stack([path[..., 2], path[..., 1]], -1),
        reached=reached_t,
        image_half_height=1.05 * half_height,
        front_aperture=(None if system.front_aperture is None else
                        (float(system.front_aperture.distance), 0.5 * float(system.front_aperture.diameter))),
    )


def _start_points(pos: Tensor, direction: Tensor, vertex: Tensor, model: LensModel) -> Tensor:
    """Where to start drawing object-space rays: the object point when it is near, otherwise a plane
    a little before the first surface (rays launched on the entrance pupil plane are extended back).

    Args:
        pos: (F, R, 3) launch points; direction: (F, R, 3) unit directions.
    """
    track = float(vertex[-1] - vertex[0])
    z_first = min(0.0, float(pos[..., 2].min()))
    dist = model.system.object_distance
    if dist is not None and dist <= 1.5 * track:
        return pos  # finite, near object: rays are launched at the object point itself
    z0 = z_first - 0.2 * track
    dz = torch.where(direction[..., 2].abs() > 1e-12, direction[..., 2], torch.ones_like(direction[..., 2]))
    step = (z0 - pos[..., 2]) / dz
    return pos + step.unsqueeze(-1) * direction

