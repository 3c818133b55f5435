"""Sequential real-ray trace (S1.2–S1.3): batched over rays, looped over surfaces, fixed shapes.

A ray that fails keeps its row: ``status`` holds the first failure reason, the row carries finite
placeholder values, and every value and gradient stays finite (DESIGN.md rules 1–3). Backtracking
(t < 0 with the ray going forward, i.e. overlapping surfaces, S1.2.1) is *flagged*, not failed: the
ray is well behaved and keeps being traced, as in the seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import torch
from torch import Tensor

from lensopt.optics.interact import bend
from lensopt.optics.intersect import NEWTON_ITERATIONS, intersect_asphere, intersect_quadric
from lensopt.optics.lens import Lens
from lensopt.optics.surfaces import normal_from_slope, phase_slope, sag

__all__ = ["Status", "REASONS", "Rays", "SurfaceHit", "RayTrace", "trace", "failure_counts"]


class Status(IntEnum):
    """First failure of a ray (0 = traced to the end)."""

    OK = 0
    MISSED = 1  # no intersection, or the sag is undefined where the ray meets the surface
    TIR = 2  # total internal reflection (or an evanescent diffraction order)
    NEWTON = 3  # Newton did not converge on an asphere
    CLIPPED = 4  # outside a clipping clear aperture
    BLOCKED = 5  # stopped by the front aperture in object space (set by optics.bundle)


_OK = int(Status.OK)
"""Plain-int OK code: ``tensor == IntEnum`` breaks the ``torch.compile`` graph, ``tensor == int`` does not."""

REASONS = {
    Status.MISSED: "missed surface",
    Status.TIR: "total internal reflection",
    Status.NEWTON: "Newton not converged",
    Status.CLIPPED: "clipped by aperture",
    Status.BLOCKED: "blocked by front aperture",
}


@dataclass(frozen=True)
class Rays:
    """Rays in object space (global coordinates: surface 1 vertex at the origin, axis +z).

    Attributes:
        pos: (*B, 3) positions, mm.
        dir: (*B, 3) unit directions.
        wavelength: (*B') integer indices into ``lens.wavelength_um``, broadcastable to (*B).
    """

    pos: Tensor
    dir: Tensor
    wavelength: Tensor


@dataclass(frozen=True)
class SurfaceHit:
    """What a ray did at one surface (recorded on request, for constraints and plots).

    Attributes:
        pos: (*B, 3) intersection point, global mm.
        dir_in: (*B, 3) direction before the surface.
        dir_out: (*B, 3) direction after the surface.
        normal: (*B, 3) unit surface normal (towards +z).
        t: (*B) ray-marching distance to this surface, mm.
        cos2_in: (*B) cos² of the angle of incidence (ζ_I).
        cos2_out: (*B) cos² of the angle of refraction (ζ_R; negative: TIR).
    """

    pos: Tensor
    dir_in: Tensor
    dir_out: Tensor
    normal: Tensor
    t: Tensor
    cos2_in: Tensor
    cos2_out: Tensor


@dataclass(frozen=True)
class RayTrace:
    """Result of a trace.

    Attributes:
        pos: (*B, 3) ray positions on the last surface reached (the image surface by default).
        dir: (*B, 3) ray directions there.
        status: (*B) int64 first failure reason (see ``Status``).
        backtrack: (*B) bool, True where some ray-marching distance was negative.
        hits: per-surface records when traced with ``record=True``, else empty.
        failed_at: (*B) int64 index of the surface where the ray failed (S = the image surface),
            −1 for rays that reached the end; None when not recorded.
    """

    pos: Tensor
    dir: Tensor
    status: Tensor
    backtrack: Tensor
    hits: tuple[SurfaceHit, ...] = ()
    failed_at: Tensor | None = None

    @property
    def valid(self) -> Tensor:
        """(*B) bool: rays that reached the end."""
        return self.status == _OK


def trace(
    lens: Lens,
    rays: Rays,
    *,
    upto: int | None = None,
    record: bool = False,
    newton_iterations: int = NEWTON_ITERATIONS,
) -> RayTrace:
    """Trace ``rays`` through ``lens`` to the image surface (or to surface ``upto``).

    Args:
        lens: the lens.
        rays: object-space rays; the first intersection may lie behind the start point (rays start
            on the entrance pupil, which can sit inside the lens) without being flagged.
        upto: stop at the intersection with this surface (before it bends the rays); e.g. the stop.
        record: keep a ``SurfaceHit`` per surface.
        newton_iterations: iteration cap of the asphere intersection.

    Returns:
        A ``RayTrace`` with shapes (*B, …) of the broadcast ray batch.
    """
    pos, dir = torch.broadcast_tensors(rays.pos, rays.dir)
    batch = pos.shape[:-1]
    status = torch.zeros(batch, dtype=torch.int64, device=pos.device)
    failed_at = torch.full(batch, -1, dtype=torch.int64, device=pos.device)
    backtrack = torch.zeros(batch, dtype=torch.bool, device=pos.device)
    vertex = lens.vertex_z()
    lam_mm = lens.wavelength_um[rays.wavelength] * 1e-3
    forward = torch.tensor([0.0, 0.0, 1.0], dtype=pos.dtype, device=pos.device).expand_as(pos)
    hits: list[SurfaceHit] = []
    last = lens.num_surfaces - 1 if upto is None else upto
    for s in range(last + 1):
        shape = lens.shapes[s]
        c, k = lens.curvature[s], lens.conic[s]
        origin = torch.stack([torch.zeros_like(vertex[s]), torch.zeros_like(vertex[s]), vertex[s]])
        local = pos - origin
        if shape.kind == "asphere":
            t, defined, converged = intersect_asphere(local, dir, c, k, lens.asphere[s],
                                                      iterations=newton_iterations)
            missed, newton_failed = ~defined, ~converged
        else:
            t, hit = intersect_quadric(local, dir, c, k)
            missed, newton_failed = ~hit, torch.zeros_like(hit)
        point = local + t.unsqueeze(-1) * dir
        if s > 0:
            backtrack = backtrack | ((t < 0) & (status == _OK))
        status = _fail(status, missed, Status.MISSED)
        status = _fail(status, newton_failed, Status.NEWTON)
        u = point[..., 0] ** 2 + point[..., 1] ** 2
        if shape.clip:
            status = _fail(status, u > lens.semi_diameter[s] ** 2, Status.CLIPPED)
        hit_pos = point + origin
        failed_at = _first_failure(failed_at, status, s)
        if upto is not None and s == upto:
            ok = (status == _OK).unsqueeze(-1)
            pos = torch.where(ok, hit_pos, pos)
            break
        asph = lens.asphere[s] if shape.kind == "asphere" else None
        _, dz_du, _ = sag(u, c, k, asph)
        normal = normal_from_slope(point[..., :2], dz_du)
        grating = None
        if shape.diffractive:
            # m λ/(2π) ∇φ with ∇φ = 2 dφ/du (x, y, 0): finite at r = 0 (S16–S17).
            g = shape.order * lam_mm / math.pi * phase_slope(u, lens.phase[s])
            grating = torch.cat([g.unsqueeze(-1) * point[..., :2], torch.zeros_like(g).unsqueeze(-1)], -1)
        n1 = lens.index[s][rays.wavelength]
        n2 = lens.index[s + 1][rays.wavelength]
        dir_out, cos2_in, cos2_out, tir = bend(dir, normal, n1, n2, grating)
        status = _fail(status, tir, Status.TIR)
        failed_at = _first_failure(failed_at, status, s)
        if record:
            hits.append(SurfaceHit(hit_pos, dir, dir_out, normal, t, cos2_in, cos2_out))
        ok = (status == _OK).unsqueeze(-1)
        pos = torch.where(ok, hit_pos, pos)
        dir = torch.where(ok, dir_out, forward)
    else:
        # Flat image surface at the end of the last gap.
        dz = dir[..., 2]
        safe_dz = torch.where(dz.abs() > torch.finfo(dz.dtype).eps, dz, torch.ones_like(dz))
        t = (vertex[-1] - pos[..., 2]) / safe_dz
        status = _fail(status, dz.abs() <= torch.finfo(dz.dtype).eps, Status.MISSED)
        failed_at = _first_failure(failed_at, status, lens.num_surfaces)
        backtrack = backtrack | ((t < 0) & (status == _OK))
        ok = (status == _OK).unsqueeze(-1)
        pos = torch.where(ok, pos + t.unsqueeze(-1) * dir, pos)
    return RayTrace(pos=pos, dir=dir, status=status, backtrack=backtrack, hits=tuple(hits), failed_at=failed_at)


def _first_failure(failed_at: Tensor, status: Tensor, surface: int) -> Tensor:
    """Record ``surface`` for rays that have failed by now and had no failure surface yet."""
    return torch.where((status != _OK) & (failed_at < 0), torch.full_like(failed_at, surface), failed_at)


def _fail(status: Tensor, failed: Tensor, reason: Status) -> Tensor:
    """Record ``reason`` for rays that fail now and had not failed before."""
    return torch.where((status == _OK) & failed, torch.full_like(status, int(reason)), status)


def failure_counts(result: RayTrace) -> dict[str, int]:
    """Number of rays per failure reason, plus backtracking flags (for reports, not for autograd)."""
    counts = {REASONS[r]: int((result.status == r).sum()) for r in REASONS}
    counts["backtracking (flagged)"] = int(result.backtrack.sum())
    return counts
