"""The registry of residual terms (S2.2, Table S6; S3.1): one place to add a term.

A term is its name (the group name in ``Problem.slices`` and the progress display), a report line, its
static weight (None = off) read from the problem's settings, the settings object that may carry a weight
``schedule``, and its residual function of a ``TermContext`` (the lens, the traced optimization rays
and their spot statistics at θ). ``Problem`` concatenates the active terms in registry order.

To add a term: write its residual function (pure tensors, fixed length, DESIGN.md rule 1) and call
``register_term`` (``lensopt.optim.gtra`` registers ℓ_GTRA this way).
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import torch
from torch import Tensor

from lensopt.analysis.spot import SpotStats
from lensopt.materials.glass_space import catalog_distance, mesh_distance
from lensopt.optics.bundle import Bundle
from lensopt.optics.differential import HIT_FIELDS
from lensopt.optics.lens import Lens
from lensopt.optim import residuals as res

if TYPE_CHECKING:
    from lensopt.optim.problem import Problem

__all__ = ["TermContext", "Term", "TERMS", "register_term"]


@dataclass(frozen=True)
class TermContext:
    """What a residual function sees at θ.

    Attributes:
        problem: the problem (settings, glass space, gap bounds...).
        theta: (N,) variables.
        lens: the solved lens of θ.
        bundle: every optimization ray (spot sample + rim rays), traced with ``record=True``.
        spot: the spot sample part of ``bundle``; stats: its spot statistics.
    """

    problem: Problem
    theta: Tensor
    lens: Lens
    bundle: Bundle
    spot: Bundle
    stats: SpotStats


@dataclass(frozen=True)
class Term:
    """One residual group.

    Attributes:
        name: group name (``Problem.slices`` key, glossary name of DESIGN.md).
        label: one report line (what it measures, where in the seed).
        weight: problem ↦ static weight, or None when the term is off.
        residual: context ↦ (M_t,) unweighted residuals, length fixed by the problem.
        config: problem ↦ the settings object of the term (its ``schedule`` is used), or None.
        reads: bundle ↦ the fields of the recorded hits (``SurfaceHit``) whose derivatives the
            residual needs at this bundle (``optim.jacobian`` computes only those); all by default.
    """

    name: str
    label: str
    weight: Callable[[Problem], float | None]
    residual: Callable[[TermContext], Tensor]
    config: Callable[[Problem], Any] = lambda p: None
    reads: Callable[[Bundle], Collection[str]] = lambda b: HIT_FIELDS


TERMS: dict[str, Term] = {}
"""The registered terms, in residual order."""


def register_term(term: Term, *, after: str | None = None) -> Term:
    """Add (or replace) ``term``; placed after the term ``after`` (default: at the end)."""
    items = [(k, v) for k, v in TERMS.items() if k != term.name]
    pos = len(items) if after is None else [k for k, _ in items].index(after) + 1
    items.insert(pos, (term.name, term))
    TERMS.clear()
    TERMS.update(items)
    return term


def _cons(name: str) -> Callable[[Problem], Any]:
    return lambda p: getattr(p.opt.constraints, name)


def _cons_weight(name: str) -> Callable[[Problem], float | None]:
    def weight(p: Problem) -> float | None:
        spec = getattr(p.opt.constraints, name)
        return None if spec is None else spec.weight
    return weight


def _glass_weight(name: str) -> Callable[[Problem], float | None]:
    def weight(p: Problem) -> float | None:
        spec = getattr(p.opt.constraints, name)
        if p.num_glasses == 0 or spec is None:
            return None
        return spec.weight if name == "glass_mesh" else 1.0
    return weight


def _refracting(c: TermContext) -> list[int]:
    return [s for s in c.problem.interfaces if not c.problem.surfaces[s].plane]


register_term(Term(
    "tra", "transverse ray aberrations about the field centroids, ‖ℓ‖ = ESR (S37–S39)",
    lambda p: p.opt.tra.weight if p.objective == "spot" else None,
    lambda c: res.tra(c.spot, c.stats, c.problem.system.wavelength_weights, c.problem.field_weights),
    lambda p: p.opt.tra, reads=lambda b: ()))
def _ray_path(c: TermContext) -> Tensor:
    r = res.ray_path(c.bundle, *c.problem.gap_bounds(c.lens))
    if not c.problem.path_spans:
        return r
    return torch.cat([r, res.ray_path_spans(c.bundle, c.problem.path_spans)])


register_term(Term(
    "ray_path", "axial ray path per gap (and per span of gaps) within its bounds (S41–S42)",
    _cons_weight("ray_path"), _ray_path, _cons("ray_path"), reads=lambda b: ("pos",)))
register_term(Term(
    "ray_angle", "angles of incidence and refraction (S43–S45)", _cons_weight("ray_angle"),
    lambda c: res.ray_angle(c.bundle, c.problem.interfaces, c.problem.opt.constraints.ray_angle.max_deg),
    _cons("ray_angle"), reads=lambda b: ("cos2_in", "cos2_out")))
register_term(Term(
    "surface_normal", "surface normal angles where rays hit (S46–S47)", _cons_weight("surface_normal"),
    lambda c: res.surface_normal(c.bundle, _refracting(c), c.problem.opt.constraints.surface_normal.max_deg),
    _cons("surface_normal"), reads=lambda b: ("normal",)))
register_term(Term(
    "distortion", "distortion per field (S48–S50)", _cons_weight("distortion"),
    lambda c: res.distortion(c.lens, c.problem.system, c.spot, c.stats,
                             c.problem.opt.constraints.distortion.max_percent / 100),
    _cons("distortion"), reads=lambda b: ()))
register_term(Term(
    "relative_illumination", "relative illumination per field (S52–S54)", _cons_weight("relative_illumination"),
    lambda c: res.relative_illumination(c.spot, c.problem.system.wavelength_weights,
                                        c.problem.opt.constraints.relative_illumination.min),
    _cons("relative_illumination"), reads=lambda b: ()))
register_term(Term(
    "glass_mesh", "glass variables to the catalog mesh (S55)", _glass_weight("glass_mesh"),
    lambda c: mesh_distance(c.problem.param.glass_g(c.theta), c.problem.mesh), _cons("glass_mesh"),
    reads=lambda b: ()))
register_term(Term(
    "glass_catalog", "glass variables to the nearest catalog glass (S56–S57)", _glass_weight("glass_catalog"),
    lambda c: catalog_distance(c.problem.param.glass_g(c.theta), c.problem.space), _cons("glass_catalog"),
    reads=lambda b: ()))
register_term(Term(
    "ray_failure", "a constant plus the failure margin for every failed ray",
    lambda p: p.opt.constraints.ray_failure.weight or None,
    lambda c: res.failures(c.bundle, c.lens, c.problem.failure_penalty),
    # The failure margins read the hits of failed rays; with none failed the term is constant.
    reads=lambda b: HIT_FIELDS if bool((~b.result.valid).any()) else ()))
