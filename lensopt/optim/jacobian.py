"""The LM Jacobian of a spot-type problem in three forward-mode stages (the same derivatives as
``torch.func.jacfwd`` over the whole residual function, to rounding, at a fraction of its cost).

``jacfwd`` carries N tangents (one per variable) through every elementwise operation of ℓ(θ); on the
seed's 90-variable studies most of that work is the trace of the optimization rays, thousands of
passes over (N × rays) arrays. Here ℓ(θ) is cut where its inputs are few and its outputs many:

- **A.** θ ↦ the solved lens and the launched rays (first-order data, aiming, vignetting, the front
  aperture: a few rays per field and wavelength), by ``jacfwd``;
- **B.** the trace of the launched rays, by the differential ray trace (``optics.differential``:
  each surface differentiated locally, tangents chained surface to surface by matrix products);
- **C.** the residual terms of (θ, lens, launch, trace), by ``jvp`` batched over the N tangents of A
  and B (``vmap``).

Objects cross the stages as their floating-point tensors (``split``); tangents travel in objects of
the primal's own classes with a trailing dimension of N variables.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from lensopt.optics.bundle import Bundle, Launch, finish_bundle
from lensopt.optics.differential import Wanted, trace_with_tangents
from lensopt.optics.lens import Lens, System
from lensopt.optics.trace import RayTrace

__all__ = ["split", "tangent_leaves", "staged_jacobian", "RampRows", "RampPlan", "take_rays", "take_trace", "take_rows",
           "place_rows"]


@dataclass(frozen=True)
class RampRows:
    """The active rows of one ramp term (``Term.margin``) at θ, differentiated apart from the rest.

    Attributes:
        name: the term (its block of ℓ: ``Problem.slices[name]``).
        margin: (lens, bundle) ↦ (B', F, W, P) the term's margins on the blocks with an active row
            (``Term.margin``'s ``blocks``), in order.
        weight: the term's static weight.
        sqrt_n: √(F·W·P), the residual's divisor.
        pick: (A,) the active rows among those margins of the selected rays (``RampPlan.rays``), flattened.
        rows: (A,) the same rows in the term's block of ℓ.
    """

    name: str
    margin: Callable[[Lens, Bundle], Tensor]
    weight: float
    sqrt_n: float
    pick: Tensor
    rows: Tensor


@dataclass(frozen=True)
class RampPlan:
    """How the Jacobian takes the ramp terms at θ: ``given`` their rows of ℓ (left out of stage C and
    placed after it, ``place_rows``: each inactive row's derivative is exactly 0), ``ramps`` the active
    rows of each term that has any, ``rays`` (K,) the rays (flat F·W·P index) those rows belong to,
    ``fields`` the recorded hit fields (field, surface) whose derivatives the terms read (``Term.reads``,
    a ramp term's ``Term.reads_at`` its active blocks; none for a term without an active row)."""

    given: dict[str, Tensor]
    ramps: tuple[RampRows, ...]
    rays: Tensor | None
    fields: frozenset[tuple[str, int]]


def take_rows(x: Tensor | None, lead: torch.Size, rays: Tensor | None, front: int = 0) -> Tensor | None:
    """``x`` (*F, *lead, *tail) (``front`` = len(F) leading dimensions, e.g. the variables of a tangent)
    with its ``lead`` dimensions flattened and cut to ``rays`` (K,) (flat indices; None: all, in order,
    a view), as (*F, 1, 1, K, *tail); None stays None."""
    if x is None:
        return None
    head, tail = x.shape[:front], x.shape[front + len(lead):]
    flat = x.reshape(*head, lead.numel(), *tail)
    if rays is not None:
        flat = flat.index_select(front, rays)
    return flat.reshape(*head, 1, 1, -1, *tail)


def take_trace(result: RayTrace, rays: Tensor | None) -> RayTrace:
    """``result`` cut to the rays ``rays`` (``take_rows``): batch (1, 1, K)."""
    take = lambda x: take_rows(x, result.status.shape, rays)  # noqa: E731
    hits = tuple(type(h)(**{f.name: take(getattr(h, f.name)) for f in dataclasses.fields(h)}) for h in result.hits)
    return RayTrace(take(result.pos), take(result.dir), take(result.status), take(result.backtrack), hits,
                    take(result.failed_at))


def take_rays(bundle: Bundle, rays: Tensor) -> Bundle:
    """``bundle`` with its trace cut to the rays ``rays`` (K,) (flat F·W·P indices), batch (1, 1, K): what
    the margins of ramp terms read (the hits and the end of the trace); the rest is ``bundle``'s."""
    return dataclasses.replace(bundle, result=take_trace(bundle.result, rays))


def ramp_tangent_rows(plan: RampPlan, lens: Lens, cut: Bundle | None) -> list[Tensor]:
    """The active ramp rows of ``plan`` (inside stage C: their derivatives), in order: the margins of the
    selected rays, as the residual weighs them ((m / √n)·w, ramp and mask passing); ``cut``: the traced
    bundle cut to the rays ``plan.rays`` (``take_rays``; ``staged_jacobian``'s ``rays``)."""
    if not plan.ramps:
        return []
    return [(r.margin(lens, cut).reshape(-1)[r.pick] / r.sqrt_n) * r.weight for r in plan.ramps]


def place_rows(J: Tensor, r: Tensor, plan: RampPlan, slices: dict[str, slice]) -> tuple[Tensor, Tensor]:
    """(J (M, N), ℓ (M,)) from a staged result (J, r) whose rows are those of the terms of ``slices`` (each
    term's block of ℓ, in order) but ``plan.given``'s, then ``ramp_tangent_rows``: a given term's rows of
    ℓ are ``plan.given``'s, of J 0 but for its active rows. J is laid out as ``staged_jacobian`` gives it,
    variables first (an (M, N) view of an (N, M) tensor): zeros written once rather than carried as the
    tangents of constants through stage C (most rows of a ramp term are 0)."""
    if not plan.given:
        return J, r
    size = max(sl.stop for sl in slices.values())
    Jt = J.new_zeros(J.shape[1], size)
    out = r.new_empty(size)
    pos = 0
    for name, sl in slices.items():
        if name in plan.given:
            out[sl] = plan.given[name]
            continue
        n = sl.stop - sl.start
        Jt[:, sl] = J[pos:pos + n].T
        out[sl] = r[pos:pos + n]
        pos += n
    for ramp in plan.ramps:
        n = ramp.rows.numel()
        Jt[:, slices[ramp.name].start + ramp.rows] = J[pos:pos + n].T
        pos += n
    return Jt.T, out


def split(obj: Any) -> tuple[list[Tensor], list[Tensor], Callable[[list[Tensor], list[Tensor]], Any]]:
    """(floating-point tensors, other tensors, rebuild) of a tree of dataclasses, tuples and lists;
    ``rebuild(floats, others)`` makes the same tree with those tensors (e.g. tangents) in their places.
    ``rebuild`` holds no tensor (only the static fields), so it may outlive a functorch transform."""
    floats: list[Tensor] = []
    others: list[Tensor] = []

    def walk(o: Any) -> Any:
        if isinstance(o, Tensor):
            bucket = floats if o.is_floating_point() else others
            bucket.append(o)
            return ("f" if bucket is floats else "o", len(bucket) - 1)
        if dataclasses.is_dataclass(o) and not isinstance(o, type):
            return ("d", type(o), tuple((f.name, walk(getattr(o, f.name))) for f in dataclasses.fields(o)))
        if isinstance(o, (tuple, list)):
            return ("t" if isinstance(o, tuple) else "l", tuple(walk(v) for v in o))
        return ("s", o)

    skeleton = walk(obj)

    def build(node: Any, fl: list[Tensor], ot: list[Tensor]) -> Any:
        kind = node[0]
        if kind == "f":
            return fl[node[1]]
        if kind == "o":
            return ot[node[1]]
        if kind == "d":
            return node[1](**{name: build(child, fl, ot) for name, child in node[2]})
        if kind in ("t", "l"):
            items = [build(child, fl, ot) for child in node[1]]
            return tuple(items) if kind == "t" else items
        return node[1]

    return floats, others, lambda fl, ot: build(skeleton, fl, ot)


def tangent_leaves(primal: Any, tangent: Any) -> list[Tensor | None]:
    """The tangents in ``tangent`` (same tree as ``primal``) of the floating-point tensors of
    ``primal``, in ``split``'s order; None where the tangent tree has no tensor (not computed)."""
    out: list[Tensor | None] = []

    def walk(p: Any, t: Any) -> None:
        if isinstance(p, Tensor):
            if p.is_floating_point():
                out.append(t if isinstance(t, Tensor) else None)
        elif dataclasses.is_dataclass(p) and not isinstance(p, type):
            for f in dataclasses.fields(p):
                walk(getattr(p, f.name), None if t is None else getattr(t, f.name))
        elif isinstance(p, (tuple, list)):
            for i, v in enumerate(p):
                walk(v, None if t is None else t[i])

    walk(primal, tangent)
    return out


def staged_jacobian(theta: Tensor, *, lens_of: Callable[[Tensor], Lens], launch_of: Callable[[Lens], Launch],
                    terms_of: Callable[[Tensor, Lens, Bundle, Bundle | None], Tensor],
                    hit_fields: Callable[[Lens, Bundle], Collection[Wanted]], system: System,
                    rays: Callable[[], Tensor | None] = lambda: None) -> tuple[Tensor, Tensor]:
    """(J (M, N), ℓ (M,)) at θ by stages A, B, C (module docstring), for the residual function
    θ ↦ ``terms_of(θ, lens, bundle, cut)`` with ``lens = lens_of(θ)``, ``launch = launch_of(lens)``,
    ``bundle = finish_bundle(system, launch, trace(lens, launch.rays, record=True))``;
    ``hit_fields(lens, bundle)``: the recorded hit fields whose derivatives the terms read (names, or
    (name, surface) pairs: ``differential.Wanted``), at the primal lens and traced bundle (called once,
    before ``terms_of``);
    ``rays()`` (called after ``hit_fields``): the rays (K,) (flat F·W·P indices) of ``cut``, the bundle
    cut to them (``take_rays``; None: ``cut`` is None). The cut is made on the trace and its tangents
    before stage C (an index copy of plain tensors, not of duals), or is a view when ``rays`` are all
    the rays in order. The lens must have no placement (``optics.differential.supported``)."""
    holder: dict[str, Any] = {}

    def stage_a(t: Tensor) -> tuple[tuple[Tensor, ...], tuple[tuple[Tensor, ...], tuple[Tensor, ...]]]:
        lens = lens_of(t)
        fl, ot, rebuild = split((lens, launch_of(lens)))
        holder["rebuild"] = rebuild
        return tuple(fl), (tuple(fl), tuple(ot))

    dots_a, (fl_a, ot_a) = torch.func.jacfwd(stage_a, has_aux=True)(theta)
    rebuild_a = holder["rebuild"]
    lens, start = rebuild_a(list(fl_a), list(ot_a))
    lens_dot, start_dot = rebuild_a(list(dots_a), list(ot_a))

    def reads(result: RayTrace) -> Collection[Wanted]:
        holder["bundle"] = finish_bundle(system, start, result)  # the primal bundle, kept for the cut
        return hit_fields(lens, holder["bundle"])

    # The trace's tangents variables first (the layout stage C takes them in: no copy there).
    result, result_dot = trace_with_tangents(lens, start.rays, lens_dot, start_dot.rays, hit_fields=reads, first=True)
    fl_b, ot_b, rebuild_b = split(result)
    dots_b = tangent_leaves(result, result_dot)
    live_b = [i for i, d in enumerate(dots_b) if d is not None]
    n_a = len(fl_a)
    # The cut bundle: its trace's leaves (the finished status among them) and the tangents of the live
    # ones, cut here; stage C takes those as inputs of their own, or views of the whole trace's.
    picked, lead = rays(), result.status.shape
    cutting = picked is not None
    whole = cutting and picked.numel() == lead.numel() and bool(
        (picked == torch.arange(lead.numel(), device=picked.device)).all())
    if cutting:
        fl_k, ot_k, rebuild_k = split(take_trace(holder["bundle"].result, None if whole else picked))
    cut_live = [take_rows(dots_b[i], lead, picked, front=1) for i in live_b] if cutting and not whole else []

    def stage_c(t: Tensor, *fl: Tensor) -> Tensor:
        lens_c, start_c = rebuild_a(list(fl[:n_a]), list(ot_a))
        leaves_b = list(fl_b)  # fields without tangents stay the primal's (no term reads them)
        for i, v in zip(live_b, fl[n_a:n_a + len(live_b)], strict=True):
            leaves_b[i] = v
        bundle = finish_bundle(system, start_c, rebuild_b(leaves_b, ot_b))
        cut = None
        if cutting:
            leaves_k = list(fl_k)
            taken = [take_rows(leaves_b[i], lead, None) for i in live_b] if whole else fl[n_a + len(live_b):]
            for i, v in zip(live_b, taken, strict=True):
                leaves_k[i] = v
            cut = dataclasses.replace(bundle, result=rebuild_k(leaves_k, ot_k))
        return terms_of(t, lens_c, bundle, cut)

    # Duals need storage of their own: broadcast views (a direction shared by a bundle) are copied.
    primals = tuple(t.contiguous() for t in (theta, *fl_a, *(fl_b[i] for i in live_b),
                                             *(fl_k[i] for i in live_b if cut_live)))
    eye = torch.eye(theta.shape[0], dtype=theta.dtype, device=theta.device)
    # Variables first, each sample contiguous like its primal: jvp then takes the tangents as they are
    # (another layout is copied into fresh zeros, tangent by tangent).
    tangents = (*(t.movedim(-1, 0).contiguous() for t in (eye, *dots_a)), *(dots_b[i] for i in live_b), *cut_live)

    def push(*tan: Tensor) -> tuple[Tensor, Tensor]:
        return torch.func.jvp(stage_c, primals, tan)

    r, J = torch.func.vmap(push, out_dims=(None, -1))(*tangents)
    return J, r
