"""Forward-mode derivatives of a trace, surface by surface (the differential ray trace).

``torch.func.jacfwd`` over a whole trace carries one tangent per variable (N of them) through every
elementwise operation of every surface: on a 90-variable problem with 2,500 rays that is thousands
of passes over (N × rays) arrays per Jacobian, all bound by memory traffic. Here each surface is
differentiated *locally*, by the closed-form derivatives of its step (below), with respect to its own
inputs only — per ray the position, the direction and the two indices, and the surface's prescription
(c, κ, the asphere and phase coefficients, the vertex position) — and the chain rule carries the
N-column tangents from surface to surface with one batched matrix product per surface:

    Ṫ_out (n, q, N) = L_ray (n, q, 8) · Ṫ_in (n, 8, N) + L_surface (n, q, p) · Ė_s (p, N)

The ray's own rows (q = 6) and the recorded fields that are asked for are chained apart, so that the
ray's tangents do not depend on which recorded fields the caller reads.

The values are those of ``trace.surface_step`` (the step the trace runs); the derivatives equal
jacfwd's to rounding (tests/optics/test_differential.py).

The local derivatives of a step, for a ray p + t d meeting F(h) = S(h_x² + h_y²) − h_z = 0 (S the sag):

- intersection (implicit function theorem, exact for the closed-form quadrics and the converged
  asphere Newton alike): ṫ = −(∇F·(ṗ + t ḋ) + ∂S/∂(c, κ, a) ·(ċ, κ̇, ȧ)) / (∇F·d), ḣ = ṗ + t ḋ + ṫ d;
- normal N = g/|g|, g = (−2S' h_x, −2S' h_y, 1): Ṅ = (ġ − N (N·ġ))/|g|, Ṡ' = S'' u̇ + ∂S'/∂(c, κ, a);
- refraction (``interact.bend_xyz``'s tangential-momentum form), differentiated term by term.

Tangents use the primal's own classes with a trailing dimension of N variables: a ``Lens`` whose
tensors are (…, N), ``Rays`` with pos/dir (…, 3, N), a ``RayTrace`` likewise (status, masks and
integer fields are the primal's). Lenses with a placement (decentered or tilted surfaces) are not
handled here (``supported``): their callers differentiate the whole trace with jacfwd instead.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection
from dataclasses import replace

import torch
from torch import Tensor

from lensopt.optics.lens import Lens
from lensopt.optics.trace import (
    _OK,
    Book,
    Rays,
    RayTrace,
    StepMode,
    SurfaceGeometry,
    SurfaceHit,
    image_step,
    surface_step,
)

__all__ = ["supported", "trace_with_tangents", "HIT_FIELDS", "Wanted", "LEAVES", "stop_partials"]


def supported(lens: Lens) -> bool:
    """Whether ``trace_with_tangents`` handles ``lens`` (a lens on its axis)."""
    return lens.placement is None


def _dot(a: tuple[Tensor, ...], b: tuple[Tensor, ...]) -> Tensor:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _safe_div(num: Tensor, den: Tensor, ok: Tensor) -> Tensor:
    return torch.where(ok, num / torch.where(ok, den, torch.ones_like(den)), torch.zeros_like(num))


def _sag_terms(u: Tensor, c: Tensor, k: Tensor, a: Tensor):  # noqa: ANN202
    """At u = r² (n, 1): S'(u), S''(u), the partials of S and S' with respect to c and κ, and (lists
    over the asphere coefficients a (A,)) those with respect to each a_j, as in ``surfaces.sag``."""
    eps = torch.finfo(u.dtype).eps
    q = 1.0 - (1.0 + k) * c * c * u
    r = torch.sqrt(torch.where(q > eps, q, torch.full_like(q, eps)))
    live = q > eps  # where the code clamps the root, its derivatives through the root are 0
    one_r = 1.0 + r
    s1 = c / (2.0 * r)
    s2 = torch.where(live, (1.0 + k) * c**3 / (4.0 * r**3), torch.zeros_like(r))
    s_c = u / one_r + torch.where(live, (1.0 + k) * c * c * u * u / (r * one_r * one_r), torch.zeros_like(r))
    s_k = torch.where(live, c**3 * u * u / (2.0 * r * one_r * one_r), torch.zeros_like(r))
    s1_c = 1.0 / (2.0 * r) + torch.where(live, (1.0 + k) * c * c * u / (2.0 * r**3), torch.zeros_like(r))
    s1_k = torch.where(live, c**3 * u / (4.0 * r**3), torch.zeros_like(r))
    s_a, s1_a = [], []
    for j in range(a.shape[0]):  # a_j multiplies u^(j+2)
        p = j + 2
        up1 = u ** (p - 1)
        s1 = s1 + a[j] * p * up1
        s2 = s2 + a[j] * p * (p - 1) * (u ** (p - 2) if p > 2 else torch.ones_like(u))
        s_a.append(up1 * u)
        s1_a.append(p * up1)
    return s1, s2, s_c, s_k, s1_c, s1_k, s_a, s1_a


def _phase_terms(u: Tensor, ph: Tensor):  # noqa: ANN202
    """At u: φ'(u), φ''(u) and ∂φ'/∂d_i of φ(u) = Σ_i d_i u^i (i = 1 … D, ``surfaces.phase_slope``)."""
    slope = torch.zeros_like(u)
    curve = torch.zeros_like(u)
    parts = []
    for j in range(ph.shape[0]):
        i = j + 1
        ui1 = u ** (i - 1) if i > 1 else torch.ones_like(u)
        slope = slope + ph[j] * i * ui1
        if i > 1:
            curve = curve + ph[j] * i * (i - 1) * (u ** (i - 2) if i > 2 else torch.ones_like(u))
        parts.append(i * ui1)
    return slope, curve, parts


def _surface_local(shape, ray, media, geo: SurfaceGeometry, rec, ok: Tensor, lam: Tensor | None, K: int,  # noqa: ANN001
                   ) -> list[Tensor]:
    """Local derivatives of one ``surface_step`` (recorded) of n rays: 18 (n, K) tangents — the new ray
    (x, y, z, dx, dy, dz), the hit (3), the direction out (3), the normal (3), t, cos²θ_in, cos²θ_out —
    with respect to the K directions (x, y, z, dx, dy, dz, n, 1/n' per ray; then c, κ, a_j, the vertex
    and the phase coefficients of the surface), as columns of the identity."""
    dtype, device = ray[0].dtype, ray[0].device
    eye = torch.eye(K, dtype=dtype, device=device)
    col = iter(range(K))
    tX, tY, tZ, tDx, tDy, tDz, tn1, tr2 = (eye[next(col)] for _ in range(8))
    tc, tk = eye[next(col)], eye[next(col)]
    ta = [eye[next(col)] for _ in range(geo.asphere.shape[0])]
    tv = eye[next(col)]
    tph = [eye[next(col)] for _ in range(geo.phase.shape[0])] if shape.diffractive else []
    x, y, z, dx, dy, dz = (v.reshape(-1, 1) for v in ray)
    n1, r2 = (m.reshape(-1, 1) for m in media)
    (hx, hy, hz), _, (ox, oy, oz), (nx, ny, nz), t, _, _, meets = (
        tuple(v.reshape(-1, 1) for v in item) if isinstance(item, tuple) else item.reshape(-1, 1) for item in rec)
    c, k, v = geo.curvature, geo.conic, geo.vertex
    a = geo.asphere if shape.kind == "asphere" else geo.asphere[:0]
    hl = (hx, hy, hz - v)
    u = hl[0] * hl[0] + hl[1] * hl[1]
    s1, s2, s_c, s_k, s1_c, s1_k, s_a, s1_a = _sag_terms(u, c, k, a)
    # Intersection: t from F(p + t d) = 0.
    grad = (2.0 * s1 * hl[0], 2.0 * s1 * hl[1], -torch.ones_like(s1))
    d = (dx, dy, dz)
    fp = _dot(grad, d)
    eps = torch.finfo(dtype).eps
    live_t = meets & (fp.abs() > eps)
    dp = (tX, tY, tZ - tv)
    dd = (tDx, tDy, tDz)
    ds = s_c * tc + s_k * tk
    for sa, t_a in zip(s_a, ta, strict=True):
        ds = ds + sa * t_a
    num = grad[0] * (dp[0] + t * dd[0]) + grad[1] * (dp[1] + t * dd[1]) + grad[2] * (dp[2] + t * dd[2]) + ds
    dt = _safe_div(-num, fp, live_t)
    dt = torch.where(meets, dt, torch.zeros_like(dt))
    dh = tuple(dp[i] + t * dd[i] + dt * d[i] for i in range(3))  # local; global z adds v̇
    dH = (dh[0], dh[1], dh[2] + tv)
    # Normal, each kind by its own formula (``trace.surface_step``), so that the derivative is that
    # formula's also where a ray misses the surface: N = v/|v| gives Ṅ = (v̇ − N (N·v̇))/|v|.
    du = 2.0 * (hl[0] * dh[0] + hl[1] * dh[1])
    nn = (nx, ny, nz)
    if shape.kind == "asphere":  # v = (−2S' h_x, −2S' h_y, 1)
        ds1 = s2 * du + s1_c * tc + s1_k * tk
        for s1a, t_a in zip(s1_a, ta, strict=True):
            ds1 = ds1 + s1a * t_a
        vnorm = torch.sqrt(1.0 + 4.0 * s1 * s1 * u)
        dv = (-2.0 * (ds1 * hl[0] + s1 * dh[0]), -2.0 * (ds1 * hl[1] + s1 * dh[1]), torch.zeros_like(du))
    elif shape.kind == "conic":  # v = (−c h_x, −c h_y, 1 − (1 + κ) c h_z)
        kc = (1.0 + k) * c
        vz = 1.0 - kc * hl[2]
        vnorm = torch.sqrt(c * c * u + vz * vz)
        dv = (-(tc * hl[0] + c * dh[0]), -(tc * hl[1] + c * dh[1]), -((tk * c + (1.0 + k) * tc) * hl[2] + kc * dh[2]))
    else:  # sphere, plane: v = (−c h_x, −c h_y, 1 − c h_z), used as it is (unit on the sphere)
        vnorm = None
        dN = (-(tc * hl[0] + c * dh[0]), -(tc * hl[1] + c * dh[1]), -(tc * hl[2] + c * dh[2]))
    if vnorm is not None:
        along = _dot(nn, dv)
        dN = tuple((dv[i] - nn[i] * along) / vnorm for i in range(3))
    # Refraction (bend_xyz): V = n d (+ grating), T = (V − (V·N) N)/n', d' = T + cos' N.
    vx, vy, vz = n1 * dx, n1 * dy, n1 * dz
    dV = [tn1 * dx + n1 * tDx, tn1 * dy + n1 * tDy, tn1 * dz + n1 * tDz]
    if shape.diffractive:
        lam_r = lam.reshape(-1, 1)
        slope, curve, parts = _phase_terms(u, geo.phase)
        coef = shape.order * lam_r / math.pi
        g = coef * slope
        dgc = coef * curve * du
        for part, t_p in zip(parts, tph, strict=True):
            dgc = dgc + coef * part * t_p
        vx, vy = vx + g * hx, vy + g * hy
        dV[0] = dV[0] + dgc * hx + g * dh[0]
        dV[1] = dV[1] + dgc * hy + g * dh[1]
    V = (vx, vy, vz)
    vn = _dot(V, nn)
    dvn = _dot(dV, nn) + _dot(V, dN)
    T = tuple((V[i] - vn * nn[i]) * r2 for i in range(3))
    dT = tuple((dV[i] - dvn * nn[i] - vn * dN[i]) * r2 + (V[i] - vn * nn[i]) * tr2 for i in range(3))
    c2o = 1.0 - _dot(T, T)
    dc2o = -2.0 * _dot(T, dT)
    cos_i = _dot(d, nn)
    root = torch.sqrt(torch.where(c2o > eps, c2o, torch.full_like(c2o, eps)))
    sign = torch.where(cos_i < 0, -torch.ones_like(cos_i), torch.ones_like(cos_i))
    dcos = torch.where(c2o > eps, sign * dc2o / (2.0 * root), torch.zeros_like(dc2o))
    cos_out = sign * root
    dO = tuple(dT[i] + dcos * nn[i] + cos_out * dN[i] for i in range(3))
    dcos_i = _dot(dd, nn) + _dot(d, dN)
    # The new ray: the hit and the direction out where the ray lives, else its old position and the
    # placeholder direction (0, 0, 1).
    zero = torch.zeros_like(dO[0])
    new = [torch.where(ok, dH[0], tX + zero), torch.where(ok, dH[1], tY + zero), torch.where(ok, dH[2], tZ + zero),
           torch.where(ok, dO[0], zero), torch.where(ok, dO[1], zero), torch.where(ok, dO[2], zero)]
    full = lambda w: w + zero  # noqa: E731 - broadcast (K,) basis rows to (n, K)
    return [*new, *map(full, dH), *dO, *dN, full(dt), 2.0 * cos_i * dcos_i, dc2o]


def _image_local(ray, book_ok: Tensor, image_z: Tensor, K: int) -> list[Tensor]:  # noqa: ANN001
    """Local derivatives of ``image_step`` of n rays: 6 (n, K) tangents of (x, y, z, dx, dy, dz) with
    respect to (x, y, z, dx, dy, dz, image z)."""
    dtype, device = ray[0].dtype, ray[0].device
    eye = torch.eye(K, dtype=dtype, device=device)
    tX, tY, tZ, tDx, tDy, tDz, tv = (eye[i] for i in range(7))
    x, y, z, dx, dy, dz = (v.reshape(-1, 1) for v in ray)
    ok = book_ok.reshape(-1, 1)
    eps = torch.finfo(dtype).eps
    parallel = dz.abs() <= eps
    den = torch.where(parallel, torch.ones_like(dz), dz)
    t = (image_z - z) / den
    dt = (tv - tZ - t * tDz) / den
    zero = torch.zeros_like(dt)
    new = [torch.where(ok, tX + dt * dx + t * tDx, tX + zero), torch.where(ok, tY + dt * dy + t * tDy, tY + zero),
           torch.where(ok, tZ + dt * dz + t * tDz, tZ + zero)]
    return new + [tDx + zero, tDy + zero, tDz + zero]


def _chain(local: list[Tensor], tin: Tensor, per_ray: int, e: Tensor) -> Tensor:
    """(n, q, N) output tangents from the local derivatives (q tensors (n, K)), the per-ray input
    tangents ``tin`` (n, per_ray, N) and the surface's parameter tangents ``e`` (K − per_ray, N)."""
    L = torch.stack(local, 1)  # (n, q, K)
    n, q = L.shape[:2]
    out = torch.bmm(L[:, :, :per_ray].contiguous(), tin)
    if e.shape[0]:
        flat = out.view(n * q, -1)
        flat.addmm_(L[:, :, per_ray:].reshape(n * q, -1), e)  # in place: one pass over the (n, q, N) tangents
    return out


HIT_FIELDS = frozenset(("pos", "dir_in", "dir_out", "normal", "t", "cos2_in", "cos2_out"))
"""The fields of ``SurfaceHit`` that carry derivatives."""

Wanted = str | tuple[str, int]
"""A recorded field whose tangents are wanted: its name (at every surface) or (name, surface)."""


def _per_surface(wanted: Collection[Wanted], S: int) -> list[set[str]]:
    """The fields wanted at each of S surfaces (pairs for surfaces beyond them are left out)."""
    out: list[set[str]] = [set() for _ in range(S)]
    for w in wanted:
        name, surfaces = (w, range(S)) if isinstance(w, str) else (w[0], [w[1]] if w[1] < S else [])
        for s in surfaces:
            out[s].add(name)
    return out

_SIDE_ROWS = {"pos": (6, 7, 8), "dir_out": (9, 10, 11), "normal": (12, 13, 14), "t": (15,), "cos2_in": (16,),
              "cos2_out": (17,)}
"""Rows of ``_surface_local``'s output (after the six of the new ray) for each recorded field."""


def trace_with_tangents(lens: Lens, rays: Rays, lens_dot: Lens, rays_dot: Rays, *,
                        hit_fields: Callable[[RayTrace], Collection[Wanted]] | Collection[Wanted] = HIT_FIELDS,
                        upto: int | None = None, first: bool = False) -> tuple[RayTrace, RayTrace]:
    """``trace(lens, rays, record=True)`` and its tangents.

    Args:
        lens, rays: as for ``trace`` (a lens on its axis: ``supported``).
        lens_dot: tangents of the lens tensors, each with a trailing dimension of N variables.
        rays_dot: tangents of the rays: pos and dir (*B, 3, N) (broadcastable like the primals).
        hit_fields: the ``SurfaceHit`` fields whose tangents are wanted (``HIT_FIELDS``; a name: at every
            surface, (name, s): at surface s alone; ``Wanted``), or a function
            of the traced ``RayTrace`` that says which (e.g. more when some ray failed). The others are
            not computed (None in the tangent hits): most of the cost of a trace's derivatives is
            carrying per-surface records that the residual terms do not read.
        upto: trace surfaces 0 … ``upto`` only (no image step; e.g. the stop): then the values are
            those of ``trace(…, upto=upto)`` (``pos``/``dir``/``status``: the rays on surface ``upto``,
            not bent there; ``hits`` every recorded surface's, ``failed_at`` None), and the tangents
            those of the requested hit fields alone (``pos``/``dir`` None).
        first: the tangents variables first, (N, *B, 3) and (N, *B), each contiguous (the layout in
            which a ``vmap`` of ``jvp`` over the variables takes them without a copy; the same numbers).

    Returns:
        The ``RayTrace`` (the values of ``trace``: the same step function) and its tangents as a
        ``RayTrace`` of (…, N) tensors (``first``: (N, …)): pos, dir and the requested fields of every hit.
    """
    if not supported(lens):
        raise ValueError("trace_with_tangents: lenses with a placement are differentiated with jacfwd")
    pos, dir = torch.broadcast_tensors(rays.pos, rays.dir)
    batch = pos.shape[:-1]
    n = batch.numel()
    N = lens_dot.curvature.shape[-1]
    dtype, device = pos.dtype, pos.device
    ray = (*pos.unbind(-1), *dir.unbind(-1))
    status = torch.zeros(batch, dtype=dtype, device=device)
    book = Book(status, status == _OK, torch.full(batch, -1.0, dtype=dtype, device=device),
                torch.zeros(batch, dtype=dtype, device=device))
    vertex = lens.vertex_z()
    inv_index = 1.0 / lens.index
    wl = torch.broadcast_to(rays.wavelength, batch)
    lam_mm = lens.wavelength_um[wl] * 1e-3 if any(s.diffractive for s in lens.shapes) else None
    # Pass 1: the trace itself, keeping what each step saw.
    steps = []
    shapes = lens.shapes if upto is None else lens.shapes[: upto + 1]
    for s, shape in enumerate(shapes):
        before = book
        media = (lens.index[s][wl], inv_index[s + 1][wl])
        geo = SurfaceGeometry(lens.curvature[s], lens.conic[s], lens.asphere[s], lens.phase[s], vertex[s],
                              lens.semi_diameter[s])
        new, book, rec = surface_step(s, geo, ray, media + ((lam_mm,) if shape.diffractive else ()), book,
                                      StepMode(shape, record=True))
        steps.append((ray, media, geo, rec, book.ok))
        ray = new
    if upto is None:
        new, book = image_step(vertex[-1], None, ray, book, lens.num_surfaces)
    else:  # ``trace(…, upto=upto)``'s values: its step onto the surface (no bending) from the same rays
        new, book, _ = surface_step(upto, steps[upto][2], steps[upto][0], (), before,
                                    StepMode(shapes[upto], stop_here=True))
    x, y, z, dx, dy, dz = new
    result = RayTrace(pos=torch.stack([x, y, z], -1), dir=torch.stack([dx, dy, dz], -1), status=book.status.long(),
                      backtrack=book.backtrack > 0,
                      hits=tuple(SurfaceHit(*(torch.stack(v, -1) for v in rec[:4]), *rec[4:7])
                                 for _, _, _, rec, _ in steps),
                      failed_at=book.failed_at.long() if upto is None else None)
    wanted = _per_surface(hit_fields(result) if callable(hit_fields) else hit_fields, len(steps))
    # Pass 2: the tangents, surface by surface.
    vertex_dot = torch.cat([torch.zeros_like(lens_dot.thickness[:1]), torch.cumsum(lens_dot.thickness, 0)])
    inv_index_dot = -(inv_index * inv_index).unsqueeze(-1) * lens_dot.index
    wl_flat = wl.reshape(-1)
    tray = torch.cat([torch.broadcast_to(rays_dot.pos, (*batch, 3, N)).reshape(n, 3, N),
                      torch.broadcast_to(rays_dot.dir, (*batch, 3, N)).reshape(n, 3, N)], 1)

    def lay(t: Tensor) -> Tensor:
        """(n, q, N) rows of a field as its tangent, (*B, 3, N) or (*B, N); ``first``: (N, *B, 3) or
        (N, *B), contiguous (the rows copied out first: a transpose of contiguous rows takes about
        half the time of one from a strided view)."""
        q = () if t.shape[1] == 1 else (3,)
        if first:
            return t.contiguous().movedim(-1, 0).contiguous().view(N, *batch, *q)
        return t.reshape(*batch, *q, N)

    def field(f: str, tside: Tensor, side: list[int]) -> Tensor:
        """The tangents of recorded field ``f`` (not dir_in): its rows of ``tside`` (the rows ``side``)."""
        at = side.index(_SIDE_ROWS[f][0])  # a field's rows are consecutive in ``side``: a view, no copy
        return lay(tside[:, at:at + len(_SIDE_ROWS[f])])

    hit_dots = []
    for s, (ray_in, media, geo, rec, ok) in enumerate(steps):
        shape = lens.shapes[s]
        A = lens.asphere.shape[1] if shape.kind == "asphere" else 0
        e = [lens_dot.curvature[s][None], lens_dot.conic[s][None], lens_dot.asphere[s][:A], vertex_dot[s][None]]
        if shape.diffractive:
            e.append(lens_dot.phase[s])
        e = torch.cat(e, 0)
        if shape.kind != "asphere":
            geo = replace(geo, asphere=lens.asphere[s][:0])
        local = _surface_local(shape, ray_in, media, geo, rec, ok.reshape(-1, 1), lam_mm, 8 + e.shape[0])
        media_dot = torch.stack([lens_dot.index[s][wl_flat], inv_index_dot[s + 1][wl_flat]], 1)
        tin = torch.cat([tray, media_dot], 1)
        # The ray's own rows by themselves, the recorded fields apart: the ray's tangents (and so
        # the spot's) have the same bits whichever fields the terms read.
        tout = _chain(local[:6], tin, 8, e) if s != upto else None
        side = sorted(r for f in wanted[s] - {"dir_in"} for r in _SIDE_ROWS[f])
        tside = _chain([local[r] for r in side], tin, 8, e) if side else None
        hit_dots.append(SurfaceHit(**{f: (lay(tray[:, 3:6]) if f == "dir_in" else field(f, tside, side))
                                      if f in wanted[s] else None for f in sorted(HIT_FIELDS)}))
        tray = tout
    if upto is not None:
        return result, replace(result, pos=None, dir=None, hits=tuple(hit_dots))
    tray = _chain(_image_local(ray, book.ok, vertex[-1], 7), tray, 6, vertex_dot[-1][None])
    dot = replace(result, pos=lay(tray[:, 0:3]), dir=lay(tray[:, 3:6]), hits=tuple(hit_dots))
    return result, dot


LEAVES = ("curvature", "conic", "asphere", "phase", "thickness", "index")
"""The lens tensors a trace is differentiated in (``stop_partials``'s columns after the ray's six, in
this order, each flattened)."""


def stop_partials(lens: Lens, rays: Rays) -> tuple[RayTrace, Tensor]:
    """``trace(lens, rays, upto=lens.stop)`` (its values, bit for bit) and (*B, 3, 6 + L) the first
    derivatives of its positions (the hits on the stop) with respect to each ray's own position and
    direction (6 columns) and to the L elements of the lens tensors ``LEAVES`` (flattened, in that
    order): one differential trace of the rays to the stop with those inputs as its tangent columns.
    Values of ``lens`` and ``rays`` only (no derivatives through them); a lens on its axis (``supported``)."""
    pos, dir = torch.broadcast_tensors(rays.pos, rays.dir)
    dtype, device = pos.dtype, pos.device
    leaves = [getattr(lens, name) for name in LEAVES]
    sizes = [t.numel() for t in leaves]
    N = 6 + sum(sizes)
    eye = torch.eye(N, dtype=dtype, device=device)
    blocks = eye[6:].split(sizes)
    columns = {name: b.reshape(*t.shape, N) for name, t, b in zip(LEAVES, leaves, blocks, strict=True)}
    lens_dot = replace(lens, **columns,
                       wavelength_um=torch.zeros(*lens.wavelength_um.shape, N, dtype=dtype, device=device),
                       semi_diameter=torch.zeros(*lens.semi_diameter.shape, N, dtype=dtype, device=device))
    rays_dot = Rays(eye[0:3], eye[3:6], rays.wavelength)
    result, dot = trace_with_tangents(lens, Rays(pos, dir, rays.wavelength), lens_dot, rays_dot,
                                      hit_fields=(("pos", lens.stop),), upto=lens.stop)  # the stop's hits alone
    return result, dot.hits[lens.stop].pos
