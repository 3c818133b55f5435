"""Reference relative illumination by flux counting over a large, fine pupil grid (brute force).

For an object at infinity with uniform radiance, every ray through an entrance-pupil plane cell of
area dA from the direction cosines (α, β) carries the flux L dA dα dβ (the beam's cross-section
dA cos θ times the solid angle dα dβ / cos θ). The flux of field θ that passes every aperture is
therefore L A(θ) dα dβ with A(θ) the pupil area whose rays reach the image, counted on a dense grid;
it lands around the centroid y'(ρ), ρ = sin θ, which maps dα dβ onto the image area
(dy'/dρ)(y'/ρ) dα dβ (rotational symmetry). The image irradiance is E(θ) ∝ A(θ) / [(dy'/dρ)(y'/ρ)],
summed over wavelengths with their weights, and RI(θ) = E(θ)/E(0). No direction cosine of the image
space is used, so this is independent of the S51/S52 estimates it checks.

Apertures: the stop clips at the radius of the on-axis beam (the EPD's definition), surfaces with
``clip`` at their semi-diameter, and the front aperture where it has one.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.optics.aiming import aim_full, stop_radius
from lensopt.optics.bundle import trace_rays
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import field_tangents, first_order
from lensopt.optics.sampling import launch
from lensopt.optics.vignetting import factors_to_ellipse, outside_front_aperture

__all__ = ["FluxIllumination", "relative_illumination_flux"]


@dataclass(frozen=True)
class FluxIllumination:
    """Brute-force relative illumination.

    Attributes:
        rel_field: (F,) relative fields.
        relative_illumination: (F,) E(θ)/E(0), wavelength-weighted.
        pass_area: (F, W) passing pupil area, in (EPD/2)² units.
        centroid_y_mm: (F, W) image centroid of the passing rays.
        jacobian: (F, W) (dy'/dρ)(y'/ρ), mm².
        rays_per_field: grid points per field and wavelength.
        edge_hits: (F,) passing rays on the grid's border (0 when the grid holds the whole beam).
    """

    rel_field: Tensor
    relative_illumination: Tensor
    pass_area: Tensor
    centroid_y_mm: Tensor
    jacobian: Tensor
    rays_per_field: int
    edge_hits: Tensor


def relative_illumination_flux(
    lens: Lens,
    system: System,
    rel_field: Sequence[float] | Tensor,
    *,
    grid: int = 401,
    margin: float = 1.25,
    d_rel: float = 1e-3,
    aim_steps: int = 3,
    max_rays: int = 2_000_000,
    engine: Engine | None = None,
) -> FluxIllumination:
    """Relative illumination by counting passing rays on a ``grid`` × ``grid`` pupil grid per field.

    The grid is centred on the fully aimed pupil of each field and spans ``margin`` times its larger
    semi-axis (``edge_hits`` tells whether that held the whole beam). y'(ρ) is differentiated by
    central differences at fields ±``d_rel``·HFOV (one-sided on axis). The grid is traced in tiles
    of at most ``max_rays`` rays (fields × wavelengths × points), so memory stays bounded.
    """
    if system.object_distance is not None or system.field_type != "angle":
        raise LensoptError("the flux estimate needs an object at infinity and an angle field", path="system")
    dtype, device = lens.dtype, lens.device
    rel = torch.as_tensor(rel_field, dtype=dtype, device=device)
    if not bool((rel == 0).any()):
        rel = torch.cat([torch.zeros(1, dtype=dtype, device=device), rel])
    num_w = lens.wavelength_um.shape[0]
    with torch.no_grad():
        fo = first_order(lens, system)
        r_stop = stop_radius(lens, system, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z,
                             paraxial_mm=fo.stop_semi_diameter)
        shapes = list(lens.shapes)
        shapes[lens.stop] = dataclasses.replace(shapes[lens.stop], clip=True)
        sd = lens.semi_diameter.clone()
        sd[lens.stop] = r_stop
        clipped = dataclasses.replace(lens, shapes=tuple(shapes), semi_diameter=sd)
        c = -1.0 + (2.0 * torch.arange(grid, dtype=dtype, device=device) + 1.0) / grid
        gy, gx = torch.meshgrid(c, c, indexing="ij")
        unit = torch.stack([gx.flatten(), gy.flatten()], -1)
        border = (gx.abs() > 1.0 - 2.0 / grid) | (gy.abs() > 1.0 - 2.0 / grid)
        border = border.flatten()
        # Every field with its neighbours, aimed in one batch (aiming costs per call, not per ray).
        groups = [[u, u + d_rel] if u == 0 else [u - d_rel, u, u + d_rel] for u in rel.tolist()]
        all_fields = torch.tensor([v for g in groups for v in g], dtype=dtype, device=device)
        all_tan = field_tangents(lens, system, all_fields)
        aimed = aim_full(lens, system, all_tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z, steps=aim_steps)
        y_all, a_all, b_all = factors_to_ellipse(aimed.factors)
        areas, cents, jacs, edges = [], [], [], []
        start = 0
        for g in groups:
            sel = slice(start, start + len(g))
            start += len(g)
            tan = all_tan[sel]
            mid = 0 if len(g) == 2 else 1
            half = margin * torch.maximum(a_all[sel][mid], b_all[sel][mid]).max().clamp_min(1.0)
            centre = y_all[sel][mid].mean()
            pupil = torch.stack([unit[:, 0] * half, centre + unit[:, 1] * half], -1)
            count = torch.zeros(len(g), num_w, dtype=dtype, device=device)
            y_sum = torch.zeros_like(count)
            edge = torch.zeros((), dtype=torch.long, device=device)
            tile = max(1, max_rays // (len(g) * num_w))
            for lo in range(0, pupil.shape[0], tile):
                part = pupil[lo:lo + tile]
                rays = launch(clipped, system, part.expand(len(g), num_w, *part.shape), tan,
                              epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
                res = trace_rays(clipped, rays, engine=engine)
                ok = res.valid
                if system.front_aperture is not None:
                    fa = system.front_aperture
                    pos, dirs = torch.broadcast_tensors(rays.pos, rays.dir)
                    ok = ok & ~outside_front_aperture(pos, dirs, fa.distance, fa.diameter)
                count = count + ok.sum(-1).to(dtype)  # (2 or 3, W)
                y_sum = y_sum + torch.where(ok, res.pos[..., 1], 0.0).sum(-1)
                edge = edge + (ok[mid] & border[lo:lo + tile]).sum()
            y = y_sum / count.clamp_min(1.0)
            rho = torch.sin(torch.atan(tan))[:, None]
            if mid == 0:
                jac = (y[1] / rho[1]) ** 2
            else:
                jac = (y[2] - y[0]) / (rho[2] - rho[0]) * y[1] / rho[1]
            cell = (2.0 * half / grid) ** 2
            areas.append(count[mid] * cell)
            cents.append(y[mid])
            jacs.append(jac)
            edges.append(edge)
        area, cent, jac = torch.stack(areas), torch.stack(cents), torch.stack(jacs)
        w = system.wavelength_weights.to(dtype)
        irr = (w * area / jac.abs().clamp_min(torch.finfo(dtype).tiny)).sum(-1)
        axis = int(torch.nonzero(rel == 0)[0, 0])
        ri = irr / irr[axis]
    return FluxIllumination(rel, ri, area, cent, jac, grid * grid, torch.stack(edges))
