"""Sequential real-ray trace (S1.2–S1.3): batched over rays, looped over surfaces, fixed shapes.

A ray that fails keeps its row: ``status`` holds the first failure reason, the row carries finite
placeholder values, and every value and gradient stays finite (DESIGN.md rules 1–3). Backtracking
(t < 0 with the ray going forward, i.e. overlapping surfaces, S1.2.1) is *flagged*, not failed: the
ray is well behaved and keeps being traced, as in the seed.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from enum import IntEnum

import torch
from torch import Tensor

from lensopt.optics.interact import bend_xyz, refract_ratio_xyz
from lensopt.optics.intersect import NEWTON_ITERATIONS, asphere_xyz, quadric_flag_xyz, quadric_near_xyz
from lensopt.optics.lens import Lens, SurfaceShape
from lensopt.optics.placement import Frames, surface_frames, to_global, to_local
from lensopt.optics.surfaces import conic_normal_xyz, normal_xyz, phase_slope, sag
from lensopt.transforms import carries_derivatives

__all__ = ["Status", "REASONS", "Rays", "SurfaceHit", "RayTrace", "trace", "failure_counts", "KernelOptions",
           "trace_kernel", "index_ratio"]


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
            −1 for rays that reached the end; with ``record=True`` only, else None.
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
    if _chunked(lens, rays, pos):
        return _trace_in_chunks(lens, rays, pos, dir, upto=upto, record=record, newton_iterations=newton_iterations)
    return _trace(lens, rays, pos, dir, upto, record, newton_iterations, shortcuts=False)


def trace_kernel(lens: Lens, rays: Rays, options: KernelOptions, *, upto: int | None = None, record: bool = False,
                 newton_iterations: int = NEWTON_ITERATIONS, ratio: Tensor | None = None) -> RayTrace:
    """``trace`` in the compiled kernel's formulation (``KernelOptions``): the function that
    ``accel.compiled`` compiles; eager, it lets tests check the formulation without a compiler.
    Never chunked. ``ratio``: ``index_ratio(lens)``, computed by the caller (default: here); the
    compiled trace passes it in, so that the kernel loads 3 numbers per surface instead of redoing
    the table's divisions for every block of rays (Inductor inlines such scalar work in the loop)."""
    pos, dir = torch.broadcast_tensors(rays.pos, rays.dir)
    return _trace(lens, rays, pos, dir, upto, record, newton_iterations, shortcuts=False, kernel=options,
                  ratio=index_ratio(lens) if ratio is None else ratio)


def index_ratio(lens: Lens) -> Tensor:
    """(S, W) n/n' at each surface per wavelength (the refraction table of ``trace_kernel``)."""
    return lens.index[:-1] * (1.0 / lens.index[1:])


def _trace(lens: Lens, rays: Rays, pos: Tensor, dir: Tensor, upto: int | None, record: bool, newton_iterations: int,
           *, shortcuts: bool, kernel: KernelOptions | None = None, ratio: Tensor | None = None) -> RayTrace:
    """The trace of ``trace``: ``surface_step`` for every surface, then ``image_step``. ``shortcuts``
    (eager, nothing watching: the chunked path) skips work that a look at the values shows cannot
    change them (a select whose condition holds for every ray, the far root of a quadric that no ray
    needs): the same numbers, fewer full-array passes. Never inside torch.compile, vmap or forward mode,
    where a branch on values is not allowed. ``kernel``: the compiled trace's formulation
    (``KernelOptions``, with its ``ratio`` table); None: the reference one."""
    compiling = torch.compiler.is_compiling()
    fast = kernel is not None
    batch = pos.shape[:-1]
    # First failure code and the backtracking flag, kept in the rays' float dtype (int64 and bool
    # on return), and every mask used only as the condition of a select, never combined by boolean
    # algebra: inside torch.compile each boolean &, |, ~ costs mask-format conversions lane by lane
    # (more than the arithmetic around it). The running mask of live rays is ``status == 0``.
    status = torch.zeros(batch, dtype=pos.dtype, device=pos.device)
    book = Book(status, status == _OK,
                torch.full(batch, -1.0, dtype=pos.dtype, device=pos.device) if record else None,
                torch.zeros(batch, dtype=pos.dtype, device=pos.device))
    geometry = lens_geometry(lens)
    if any(shape.diffractive for shape in lens.shapes):
        lam_mm = lens.wavelength_um[rays.wavelength] * 1e-3
    inv_index = 1.0 / lens.index  # (S+1, W): one division per medium, not per ray and surface
    # Per-wavelength tables: a gather per surface in eager torch; inside torch.compile a short chain
    # of selects on the wavelength index as a float (Inductor turns a gather into scalar loads and
    # bounds checks inside the fused loop; the selects vectorize). Same values either way.
    wl_select = rays.wavelength.to(pos.dtype) if compiling and lens.index.shape[-1] <= _MAX_SELECT else None
    # Components: fused kernels vectorize over rays only when x, y, z are separate tensors.
    ray: Ray6 = (*pos.unbind(-1), *dir.unbind(-1))
    hits: list[SurfaceHit] = []
    # The compiled kernel writes its outputs component-major ((*B, 3) views of (3, *B) planes, as
    # ``compiled.component_major_rays`` stores rays): vector stores instead of strided scalar ones.
    planes = fast and kernel.component_major
    stack = (lambda v: torch.stack(v, 0).movedim(0, -1)) if planes else (lambda v: torch.stack(v, -1))
    last = lens.num_surfaces - 1 if upto is None else upto
    for s in range(last + 1):
        shape = lens.shapes[s]
        mode = StepMode(shape, stop_here=upto is not None and s == upto, record=record,
                        near_only=fast and kernel.near_only[s], ratio=fast and kernel.ratio_refraction,
                        newton_iterations=newton_iterations, shortcuts=shortcuts)
        if mode.stop_here:
            media: tuple[Tensor, ...] = ()
        elif mode.ratio and not shape.diffractive:
            media = (_per_ray(ratio[s], rays.wavelength, wl_select),)
        else:
            media = (_per_ray(lens.index[s], rays.wavelength, wl_select),
                     _per_ray(inv_index[s + 1], rays.wavelength, wl_select))
            if shape.diffractive:
                media = media + (lam_mm,)
        ray, book, rec = surface_step(s, geometry.surface(s), ray, media, book, mode)
        if rec is not None:
            hits.append(SurfaceHit(*(stack(v) for v in rec[:4]), *rec[4:7]))
        if mode.stop_here:
            break
    else:
        ray, book = image_step(geometry.vertex[-1], geometry.image_frame(), ray, book, lens.num_surfaces, shortcuts)
    x, y, z, dx, dy, dz = ray
    return RayTrace(pos=stack([x, y, z]), dir=stack([dx, dy, dz]), status=book.status.long(),
                    backtrack=book.backtrack > 0, hits=tuple(hits),
                    failed_at=None if book.failed_at is None else book.failed_at.long())


Ray6 = tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor]
"""A ray batch as its components (x, y, z, dx, dy, dz), each of shape (*B): position and direction."""


@dataclass(frozen=True)
class Book:
    """What a trace records about its rays besides their values (no derivatives).

    Attributes:
        status: (*B) first failure code, in the rays' float dtype (int64 on return).
        ok: (*B) bool, ``status == 0``: the live rays.
        failed_at: (*B) surface of the first failure (float; −1: none), when recording, else None.
        backtrack: (*B) float flag (0/1), some ray-marching distance was negative.
    """

    status: Tensor
    ok: Tensor
    failed_at: Tensor | None
    backtrack: Tensor


@dataclass(frozen=True)
class SurfaceGeometry:
    """One surface's prescription as the step sees it (0-d tensors unless stated).

    Attributes:
        curvature, conic: c (1/mm) and κ.
        asphere: (A,) even-asphere coefficients; phase: (D,) diffractive phase coefficients.
        vertex: axial vertex position from surface 1 (lens on its axis), mm.
        semi_diameter: clear semi-aperture, mm.
        origin, rotation: (3,), (3, 3) the surface frame of a placed lens (``optics.placement``), else None.
    """

    curvature: Tensor
    conic: Tensor
    asphere: Tensor
    phase: Tensor
    vertex: Tensor
    semi_diameter: Tensor
    origin: Tensor | None = None
    rotation: Tensor | None = None


@dataclass(frozen=True)
class LensGeometry:
    """Where every surface sits: vertex positions (S+1,) and the frames of a placed lens, else None."""

    lens: Lens
    vertex: Tensor
    frames: Frames | None

    def surface(self, s: int) -> SurfaceGeometry:
        lens, f = self.lens, self.frames
        return SurfaceGeometry(lens.curvature[s], lens.conic[s], lens.asphere[s], lens.phase[s], self.vertex[s],
                               lens.semi_diameter[s], None if f is None else f.origin[s],
                               None if f is None else f.rotation[s])

    def image_frame(self) -> tuple[Tensor, Tensor] | None:
        """(origin (3,), rotation (3, 3)) of the image surface of a placed lens, else None."""
        return None if self.frames is None else (self.frames.origin[-1], self.frames.rotation[-1])


def lens_geometry(lens: Lens) -> LensGeometry:
    """Vertex positions and, for a decentered or tilted lens, the surface frames (``optics.placement``);
    a lens on its axis skips every transform (the symmetric fast path)."""
    frames = None if lens.placement is None else surface_frames(lens.thickness, lens.placement)
    return LensGeometry(lens, lens.vertex_z(), frames)


@dataclass(frozen=True)
class StepMode:
    """How ``surface_step`` treats one surface (static).

    Attributes:
        shape: the surface's kind and flags.
        stop_here: the trace ends on this surface (``upto``): the rays are not bent.
        record: return the ``SurfaceHit`` components.
        near_only: a closed-form quadric with 1 + κ ≥ 0, decided by the caller (``KernelOptions``).
        ratio: refract with one ratio n/n' per ray (``media`` is then ``(mu,)``).
        newton_iterations: iteration cap of the asphere intersection.
        shortcuts: eager, nothing watching (see ``_trace``).
    """

    shape: SurfaceShape
    stop_here: bool = False
    record: bool = False
    near_only: bool = False
    ratio: bool = False
    newton_iterations: int = NEWTON_ITERATIONS
    shortcuts: bool = False


def surface_step(s: int, geo: SurfaceGeometry, ray: Ray6, media: tuple[Tensor, ...], book: Book, mode: StepMode,
                 ) -> tuple[Ray6, Book, tuple | None]:
    """Carry rays from the previous surface (or object space) to surface ``s`` and bend them there.

    Args:
        geo: the surface's prescription.
        ray: (x, y, z, dx, dy, dz), each (*B), global coordinates.
        media: per ray (*B): ``(n, 1/n')`` (plus λ in mm for a diffractive surface), or ``(n/n',)``
            with ``mode.ratio``; empty with ``mode.stop_here``.
        book: the rays' failure bookkeeping so far.

    Returns:
        The rays after the surface (failed rays keep their last valid position and travel on as
        placeholders along the axis; on the stop surface of ``upto``: the hits, not bent), the
        bookkeeping, and with ``mode.record`` the hit's components ``((hx, hy, hz), (dx, dy, dz) in,
        d_out, normal, t, cos2_in, cos2_out, meets)`` in global coordinates (``meets``: bool, the ray
        meets the surface and ``t`` is its distance, else ``t`` is a placeholder 0), else None.
    """
    shape, shortcuts = mode.shape, mode.shortcuts
    status, ok, failed_at, backtrack = book.status, book.ok, book.failed_at, book.backtrack
    x, y, z, dx, dy, dz = ray
    c, k = geo.curvature, geo.conic
    placed = geo.rotation is not None
    if placed:
        x, y, z = to_local((x, y, z), geo.origin, geo.rotation)
        dx, dy, dz = to_local((dx, dy, dz), None, geo.rotation)
        lz = z
    else:
        lz = z - geo.vertex
    if shape.kind == "asphere":
        t, defined, converged = asphere_xyz((x, y, lz), (dx, dy, dz), c, k, geo.asphere,
                                            iterations=mode.newton_iterations)
        status, ok = _fail(status, ok, ~defined, Status.MISSED, shortcuts)
        status, ok = _fail(status, ok, ~converged, Status.NEWTON, shortcuts)
        meets = converged
    else:
        if mode.near_only:
            t, hit = quadric_near_xyz((x, y, lz), (dx, dy, dz), c, k)
        else:
            t, hit = quadric_flag_xyz((x, y, lz), (dx, dy, dz), c, k, shortcuts=shortcuts)
        status, ok = _fail(status, ok, hit == 0, Status.MISSED, shortcuts)
        meets = hit > 0
    if s > 0:
        backtrack = _flag(backtrack, ok, t < 0, shortcuts)
    hx, hy, hz = x + t * dx, y + t * dy, lz + t * dz
    u = hx * hx + hy * hy
    if shape.clip:
        status, ok = _fail(status, ok, u > geo.semi_diameter ** 2, Status.CLIPPED, shortcuts)
    failed_at = _first_failure(failed_at, ok, s)
    if shape.kind == "asphere":
        _, dz_du, _ = sag(u, c, k, geo.asphere)
        normal = normal_xyz(hx, hy, dz_du)
    elif shape.kind == "conic":
        normal = conic_normal_xyz(hx, hy, hz, c, k)
    else:  # sphere or plane: (−cx, −cy, 1 − cz) is a unit vector on the surface, no normalisation
        normal = (-c * hx, -c * hy, 1.0 - c * hz)
    if not placed:
        hz = hz + geo.vertex
    if mode.stop_here:
        x, y, z = torch.where(ok, hx, x), torch.where(ok, hy, y), torch.where(ok, hz, z)
        if placed:
            x, y, z = to_global((x, y, z), geo.origin, geo.rotation)
            dx, dy, dz = to_global((dx, dy, dz), None, geo.rotation)
        return (x, y, z, dx, dy, dz), Book(status, ok, failed_at, backtrack), None
    grating = None
    if shape.diffractive:
        # m λ/(2π) ∇φ with ∇φ = 2 dφ/du (x, y, 0): finite at r = 0 (S16–S17).
        g = shape.order * media[2] / math.pi * phase_slope(u, geo.phase)
        grating = (g * hx, g * hy)
    if mode.ratio and grating is None:
        d_out, cos2_in, cos2_out, tir = refract_ratio_xyz((dx, dy, dz), normal, media[0])
    else:
        d_out, cos2_in, cos2_out, tir = bend_xyz((dx, dy, dz), normal, media[0], media[1], grating)
    status, ok = _fail(status, ok, tir, Status.TIR, shortcuts)
    failed_at = _first_failure(failed_at, ok, s)
    rec = None
    if mode.record:
        rec = ((hx, hy, hz), (dx, dy, dz), d_out, normal)
        if placed:
            rec = (to_global(rec[0], geo.origin, geo.rotation),) + tuple(to_global(v, None, geo.rotation)
                                                                         for v in rec[1:])
        rec = rec + (t, cos2_in, cos2_out, meets)
    if shortcuts and bool(ok.all()):
        (x, y, z), (dx, dy, dz) = (hx, hy, hz), d_out
    else:
        x, y, z = torch.where(ok, hx, x), torch.where(ok, hy, y), torch.where(ok, hz, z)
        # Failed rays keep their last valid position and continue as placeholders along the axis.
        dx, dy, dz = (torch.where(ok, d_out[0], 0.0), torch.where(ok, d_out[1], 0.0),
                      torch.where(ok, d_out[2], 1.0))
    if placed:
        x, y, z = to_global((x, y, z), geo.origin, geo.rotation)
        dx, dy, dz = to_global((dx, dy, dz), None, geo.rotation)
    return (x, y, z, dx, dy, dz), Book(status, ok, failed_at, backtrack), rec


def image_step(image_z: Tensor, frame: tuple[Tensor, Tensor] | None, ray: Ray6, book: Book, num_surfaces: int,
               shortcuts: bool = False) -> tuple[Ray6, Book]:
    """Carry rays to the flat image surface at ``image_z`` (the end of the last gap); with a placement
    (``frame``: ``LensGeometry.image_frame``) in the image frame, whose x, y are reported, at the
    nominal image z."""
    status, ok, failed_at, backtrack = book.status, book.ok, book.failed_at, book.backtrack
    x, y, z, dx, dy, dz = ray
    if frame is not None:
        x, y, z = to_local((x, y, z), frame[0], frame[1])
        dx, dy, dz = to_local((dx, dy, dz), None, frame[1])
        x, y, z = x, y, z + image_z
    eps = torch.finfo(dz.dtype).eps
    parallel = dz.abs() <= eps
    t = (image_z - z) / torch.where(parallel, 1.0, dz)
    status, ok = _fail(status, ok, parallel, Status.MISSED, shortcuts)
    failed_at = _first_failure(failed_at, ok, num_surfaces)
    backtrack = _flag(backtrack, ok, t < 0, shortcuts)
    x, y, z = torch.where(ok, x + t * dx, x), torch.where(ok, y + t * dy, y), torch.where(ok, z + t * dz, z)
    return (x, y, z, dx, dy, dz), Book(status, ok, failed_at, backtrack)


@dataclass(frozen=True)
class KernelOptions:
    """The formulation of the compiled trace's kernel (``accel.compiled``). It differs from the
    reference (eager) trace only in rounding, and only where that saves work per ray:

    - refraction from one per-wavelength table of n/n' (``interact.refract_ratio_xyz``);
    - outputs written component-major ((*B, 3) views of (3, *B) planes);
    - ``near_only[s]``: surface s is a closed-form quadric with 1 + κ ≥ 0, decided from the
      prescription by the caller, so its far root is never needed (``intersect.quadric_near_xyz``).

    Attributes:
        near_only: (S,) per surface.
        ratio_refraction: refract with ``refract_ratio_xyz`` (False: ``bend_xyz``, as eager).
        component_major: write the outputs component-major (False: interleaved, as eager).

    The last two are switches for an ablation benchmark (each change measured; in git history:
    benchmarks/trace_kernel_ablation.py).
    """

    near_only: tuple[bool, ...]
    ratio_refraction: bool = True
    component_major: bool = True


CHUNK_RAYS = 1 << 16
"""Rays per chunk of the eager trace when nothing needs gradients: every eager op writes a full
array, and on arrays of ≈ 0.5 MB (64 Ki rays, float64) that stays in the CPU caches instead of
main memory (1.5–2× faster at 1e6 rays, git history of benchmarks/RESULTS.md; the same numbers bit for bit)."""


def _chunked(lens: Lens, rays: Rays, pos: Tensor) -> bool:
    """Whether ``trace`` should run in chunks of ``CHUNK_RAYS``: many rays on the CPU (a GPU has no
    such cache effect, and each chunk would cost kernel launches), eager, and no autograd, forward-mode
    or functorch transform watching (the optimizer's paths stay one call)."""
    if pos.numel() < 6 * CHUNK_RAYS or pos.device.type != "cpu" or torch.compiler.is_compiling():
        return False
    return not carries_derivatives(pos, rays.dir, rays.wavelength, *lens_tensors(lens))


def lens_tensors(lens: Lens) -> list[Tensor]:
    """Every tensor of ``lens``, its placement's included."""
    out = []
    for holder in (lens, lens.placement):
        if holder is not None:
            out += [v for f in dataclasses.fields(holder) if isinstance(v := getattr(holder, f.name), Tensor)]
    return out


def _trace_in_chunks(lens: Lens, rays: Rays, pos: Tensor, dir: Tensor, **kwargs) -> RayTrace:
    """``trace`` over consecutive chunks of the flattened ray batch, concatenated (same values)."""
    batch = pos.shape[:-1]
    pos, dir = pos.reshape(-1, 3), dir.reshape(-1, 3)
    wavelength = torch.broadcast_to(rays.wavelength, batch).reshape(-1)
    parts = [_trace(lens, Rays(pos[i:i + CHUNK_RAYS], dir[i:i + CHUNK_RAYS], wavelength[i:i + CHUNK_RAYS]),
                    pos[i:i + CHUNK_RAYS], dir[i:i + CHUNK_RAYS], kwargs["upto"], kwargs["record"],
                    kwargs["newton_iterations"], shortcuts=True)
             for i in range(0, pos.shape[0], CHUNK_RAYS)]

    def cat(values: list[Tensor]) -> Tensor:
        return torch.cat(values).reshape(batch + values[0].shape[1:])

    hits = tuple(SurfaceHit(*(cat([getattr(p.hits[i], f.name) for p in parts]) for f in dataclasses.fields(SurfaceHit)))
                 for i in range(len(parts[0].hits)))
    return RayTrace(pos=cat([p.pos for p in parts]), dir=cat([p.dir for p in parts]),
                    status=cat([p.status for p in parts]), backtrack=cat([p.backtrack for p in parts]), hits=hits,
                    failed_at=None if parts[0].failed_at is None else cat([p.failed_at for p in parts]))


def _first_failure(failed_at: Tensor | None, ok: Tensor, surface: int) -> Tensor | None:
    """Record ``surface`` for rays that have failed by now and had no failure surface yet (when
    recording; the plain trace skips the bookkeeping)."""
    if failed_at is None:
        return None
    return torch.where(ok, failed_at, torch.where(failed_at < 0, float(surface), failed_at))


def _fail(status: Tensor, ok: Tensor, failed: Tensor, reason: Status, shortcuts: bool) -> tuple[Tensor, Tensor]:
    """Record ``reason`` for rays that fail now and had not failed before (``ok``: the live rays);
    the new status and running mask (unchanged, with ``shortcuts``, when no ray fails here)."""
    if shortcuts and not bool(failed.any()):
        return status, ok
    status = torch.where(failed, torch.where(ok, _CODE[reason], status), status)
    return status, status == _OK


def _flag(flag: Tensor, ok: Tensor, now: Tensor, shortcuts: bool) -> Tensor:
    """The float flag (0/1) set where ``now`` holds for a live ray (``ok``), else kept."""
    if shortcuts and not bool(now.any()):
        return flag
    return torch.where(now, torch.where(ok, 1.0, flag), flag)


_MAX_SELECT = 8
"""Largest number of wavelengths looked up by selects rather than a gather inside torch.compile."""


def _per_ray(row: Tensor, wavelength: Tensor, wl_select: Tensor | None) -> Tensor:
    """``row[wavelength]`` (row: (W,) per-wavelength values); with ``wl_select`` (the wavelength
    index as a float tensor) by ``torch.where`` selects, which give the same values."""
    if wl_select is None:
        return row[wavelength]
    out = torch.where(wl_select == 0.0, row[0], row[-1])
    for j in range(1, row.shape[0] - 1):
        out = torch.where(wl_select == float(j), row[j], out)
    return out


_CODE = {reason: float(reason.value) for reason in Status}


def failure_counts(result: RayTrace) -> dict[str, int]:
    """Number of rays per failure reason, plus backtracking flags (for reports, not for autograd)."""
    counts = {REASONS[r]: int((result.status == r).sum()) for r in REASONS}
    counts["backtracking (flagged)"] = int(result.backtrack.sum())
    return counts
