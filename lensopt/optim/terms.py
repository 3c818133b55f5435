"""The residual terms (S2.2, Table S6; S3.1): one static, ordered tuple, ``TERMS``.

A term is its name (the group name in ``Problem.slices`` and the progress display), a report line, its
static weight (None = off) read from the problem's ``TermSetup``, the settings object that may carry a
weight ``schedule``, its residual function of a ``TermContext`` (the lens, the traced optimization rays
and their spot statistics at θ), and the recorded hit fields whose derivatives it reads. ``Problem``
concatenates the active terms in the order of ``TERMS``; no import can change that order.

To add a term: write its residual function (pure tensors, fixed length, DESIGN.md rule 1) and put a
``Term`` into ``TERMS`` where its rows belong.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import torch
from torch import Tensor

from lensopt.analysis.spot import SpotStats, spot_centroid, spot_stats
from lensopt.materials.glass_space import GlassMesh, GlassSpace, catalog_distance, mesh_distance
from lensopt.optics.bundle import Bundle
from lensopt.optics.differential import HIT_FIELDS
from lensopt.optics.lens import Lens, System
from lensopt.optim import residuals as res
from lensopt.optim.settings import OptimizeSettings

if TYPE_CHECKING:
    from lensopt.optim.image_objective import ImageObjective

__all__ = ["TermSetup", "TermContext", "Term", "TERMS", "term"]


@dataclass(frozen=True)
class TermSetup:
    """What the residual terms know of their problem (plain data; ``Problem`` makes it once).

    Attributes:
        settings: the optimization settings (weights, constraints, schedules).
        objective: ``spot``, ``raw`` or ``restored``.
        system: aperture, fields, wavelength weights.
        field_weights: (F,) weights of the fields.
        num_glasses: glass variables in θ.
        interfaces: surfaces with a change of medium (or a diffractive phase): the ray-angle surfaces.
        refracting: those of ``interfaces`` that are not planes: the surface-normal surfaces.
        path_spans: ``ray_path.spans`` as (first, end surface, lower, upper).
        failure_penalty: mm, the constant of a failed ray's row.
        gap_bounds: lens ↦ ((S,), (S,)) lower and upper axial ray path per gap.
        glass_g: θ ↦ (G, d) whitened glass coordinates.
        space, mesh: the glass space and its mesh (None without glass variables or the mesh term).
        image: the image objective (objective ``raw``), or None.
        wavefront_pupil: (P, 2) the wavefront term's pupil points (``[optimize.wavefront]``), or None.
    """

    settings: OptimizeSettings
    objective: str
    system: System
    field_weights: Tensor
    num_glasses: int
    interfaces: tuple[int, ...]
    refracting: tuple[int, ...]
    path_spans: tuple[tuple[int, int, float, float], ...]
    failure_penalty: float
    gap_bounds: Callable[[Lens], tuple[Tensor, Tensor]]
    glass_g: Callable[[Tensor], Tensor]
    space: GlassSpace | None = None
    mesh: GlassMesh | None = None
    image: ImageObjective | None = None
    wavefront_pupil: Tensor | None = None


@dataclass(frozen=True)
class TermContext:
    """What a residual function sees at θ.

    Attributes:
        setup: the problem's ``TermSetup``.
        theta: (N,) variables.
        lens: the solved lens of θ.
        bundle: every optimization ray (spot sample + rim rays), traced with ``record=True``.
        spot: the spot sample part of ``bundle``.

    Computed on first use (the Jacobian's stage C carries N tangents through every operation, so
    what no term reads is not computed): ``stats`` the spot statistics of ``spot``, ``centroid`` (F, 2)
    their centroids alone (the same numbers).
    """

    setup: TermSetup
    theta: Tensor
    lens: Lens
    bundle: Bundle
    spot: Bundle

    @functools.cached_property
    def stats(self) -> SpotStats:
        return spot_stats(self.spot, self.setup.system.wavelength_weights, self.setup.field_weights)

    @functools.cached_property
    def centroid(self) -> Tensor:
        return spot_centroid(self.spot, self.setup.system.wavelength_weights)


@dataclass(frozen=True)
class Term:
    """One residual group.

    Attributes:
        name: group name (``Problem.slices`` key, glossary name of DESIGN.md).
        label: one report line (what it measures, where in the seed).
        weight: setup ↦ static weight, or None when the term is off.
        residual: context ↦ (M_t,) unweighted residuals, length fixed by the problem.
        config: setup ↦ the settings object of the term (its ``schedule`` is used), or None.
        reads: bundle ↦ the fields of the recorded hits (``SurfaceHit``) whose derivatives the
            residual needs at this bundle (``optim.jacobian`` computes only those); all by default.
        margin: for a ramp term, (setup, lens, bundle, blocks) ↦ (B, F, W, P) its margins m, such that
            the residual is ``where(valid, ramp(m), 0)`` flattened, divided by √(F·W·P) (block b, ray k
            is row b·F·W·P + k): its derivative is 0 wherever m < 0 (``residuals.inactive``), so the
            Jacobian differentiates the active rows alone (``Problem.jacobian``). ``blocks`` (sorted;
            None: all): the margins of those blocks only, in that order, the same numbers as their
            blocks of all (the Jacobian takes the blocks with an active row). None: every row.
        reads_at: for a ramp term, (setup, lens, blocks) ↦ the recorded hits (field, surface) whose
            derivatives its margins on ``blocks`` read (``optim.jacobian`` computes only those); None:
            ``reads`` at every surface.
    """

    name: str
    label: str
    weight: Callable[[TermSetup], float | None]
    residual: Callable[[TermContext], Tensor]
    config: Callable[[TermSetup], Any] = lambda s: None
    reads: Callable[[Bundle], Collection[str]] = lambda b: HIT_FIELDS
    margin: Callable[[TermSetup, Lens, Bundle, Sequence[int] | None], Tensor] | None = None
    reads_at: Callable[[TermSetup, Lens, Sequence[int]], Collection[tuple[str, int]]] | None = None


def _cons(name: str) -> Callable[[TermSetup], Any]:
    return lambda s: getattr(s.settings.constraints, name)


def _cons_weight(name: str) -> Callable[[TermSetup], float | None]:
    def weight(s: TermSetup) -> float | None:
        spec = getattr(s.settings.constraints, name)
        return None if spec is None else spec.weight
    return weight


def _glass_weight(name: str) -> Callable[[TermSetup], float | None]:
    def weight(s: TermSetup) -> float | None:
        spec = getattr(s.settings.constraints, name)
        if s.num_glasses == 0 or spec is None:
            return None
        return spec.weight if name == "glass_mesh" else 1.0
    return weight


def _image_weight(mode: str) -> Callable[[TermSetup], float | None]:
    def weight(s: TermSetup) -> float | None:
        img = s.image
        return None if img is None or img.mode != mode else img.spec.weight
    return weight


def _ray_path(c: TermContext) -> Tensor:
    r = res.ray_path(c.bundle, *c.setup.gap_bounds(c.lens))
    if not c.setup.path_spans:
        return r
    return torch.cat([r, res.ray_path_spans(c.bundle, list(c.setup.path_spans))])


def _nothing(bundle: Bundle) -> Collection[str]:
    return ()


def _ray_path_margin(s: TermSetup, lens: Lens, bundle: Bundle, blocks: Sequence[int] | None = None) -> Tensor:
    """Blocks 0 … S − 1 the gaps, then one per span."""
    S = lens.num_surfaces
    gaps = None if blocks is None else [b for b in blocks if b < S]
    spans = list(s.path_spans) if blocks is None else [s.path_spans[b - S] for b in blocks if b >= S]
    out = res.ray_path_margin(bundle, *s.gap_bounds(lens), gaps)
    if not spans:
        return out
    return torch.cat([out, res.ray_path_span_margin(bundle, spans)])


def _ray_path_reads(s: TermSetup, lens: Lens, blocks: Sequence[int]) -> set[tuple[str, int]]:
    """The hit positions the gaps and spans of ``blocks`` read: each one's, from its start to its end
    surface (the image's is the end of the trace, always differentiated)."""
    S = lens.num_surfaces
    ends = [(b, b + 1) if b < S else s.path_spans[b - S][:2] for b in blocks]
    return {("pos", j) for first, stop in ends for j in range(first, stop + 1) if j < S}


def _ray_angle_margin(s: TermSetup, lens: Lens, bundle: Bundle, blocks: Sequence[int] | None = None) -> Tensor:
    return res.ray_angle_margin(bundle, list(s.interfaces), s.settings.constraints.ray_angle.max_deg, blocks)


def _ray_angle_reads(s: TermSetup, lens: Lens, blocks: Sequence[int]) -> set[tuple[str, int]]:
    return {("cos2_out" if b % 2 else "cos2_in", s.interfaces[b // 2]) for b in blocks}


def _surface_normal_reads(s: TermSetup, lens: Lens, blocks: Sequence[int]) -> set[tuple[str, int]]:
    return {("normal", s.refracting[b]) for b in blocks}


def _surface_normal_margin(s: TermSetup, lens: Lens, bundle: Bundle, blocks: Sequence[int] | None = None) -> Tensor:
    return res.surface_normal_margin(bundle, list(s.refracting), s.settings.constraints.surface_normal.max_deg,
                                     blocks)


TERMS: tuple[Term, ...] = (
    Term("tra", "transverse ray aberrations about the field centroids, ‖ℓ‖ = ESR (S37–S39)",
         lambda s: s.settings.tra.weight if s.objective == "spot" and s.settings.tra.weight > 0 else None,
         lambda c: res.tra(c.spot, c.centroid, c.setup.system.wavelength_weights, c.setup.field_weights),
         lambda s: s.settings.tra, _nothing),
    Term("wavefront", "RMS wavefront error per field and wavelength, waves, piston and tilt removed",
         lambda s: None if s.settings.wavefront is None else s.settings.wavefront.weight,
         lambda c: res.wavefront(c.lens, c.setup.system, c.setup.wavefront_pupil, c.setup.system.wavelength_weights,
                                 c.setup.field_weights, tilt=c.setup.settings.wavefront.tilt),
         lambda s: s.settings.wavefront, _nothing),
    Term("gtra", "generalized transverse ray aberrations of the image loss (S66–S68)", _image_weight("gtra"),
         lambda c: c.setup.image.gtra(c.lens)),
    Term("image_loss", "√(2 L) of the image loss (scalar, for Adam)", _image_weight("scalar"),
         lambda c: c.setup.image.scalar(c.lens)),
    Term("ray_path", "axial ray path per gap (and per span of gaps) within its bounds (S41–S42)",
         _cons_weight("ray_path"), _ray_path, _cons("ray_path"), lambda b: ("pos",), _ray_path_margin,
         _ray_path_reads),
    Term("ray_angle", "angles of incidence and refraction (S43–S45)", _cons_weight("ray_angle"),
         lambda c: res.ray_angle(c.bundle, list(c.setup.interfaces), c.setup.settings.constraints.ray_angle.max_deg),
         _cons("ray_angle"), lambda b: ("cos2_in", "cos2_out"), _ray_angle_margin,
         _ray_angle_reads),
    Term("surface_normal", "surface normal angles where rays hit (S46–S47)", _cons_weight("surface_normal"),
         lambda c: res.surface_normal(c.bundle, list(c.setup.refracting),
                                      c.setup.settings.constraints.surface_normal.max_deg),
         _cons("surface_normal"), lambda b: ("normal",), _surface_normal_margin,
         _surface_normal_reads),
    Term("distortion", "distortion per field (S48–S50)", _cons_weight("distortion"),
         lambda c: res.distortion(c.lens, c.setup.system, c.spot, c.centroid,
                                  c.setup.settings.constraints.distortion.max_percent / 100),
         _cons("distortion"), _nothing),
    Term("relative_illumination", "relative illumination per field (S52–S54)", _cons_weight("relative_illumination"),
         lambda c: res.relative_illumination(c.spot, c.setup.system.wavelength_weights,
                                             c.setup.settings.constraints.relative_illumination.min),
         _cons("relative_illumination"), _nothing),
    Term("glass_mesh", "glass variables to the catalog mesh (S55)", _glass_weight("glass_mesh"),
         lambda c: mesh_distance(c.setup.glass_g(c.theta), c.setup.mesh), _cons("glass_mesh"), _nothing),
    Term("glass_catalog", "glass variables to the nearest catalog glass (S56–S57)", _glass_weight("glass_catalog"),
         lambda c: catalog_distance(c.setup.glass_g(c.theta), c.setup.space), _cons("glass_catalog"), _nothing),
    # The failure margins read the hits of failed rays; with none failed the term is constant.
    Term("ray_failure", "a constant plus the failure margin for every failed ray",
         lambda s: s.settings.constraints.ray_failure.weight or None,
         lambda c: res.failures(c.bundle, c.lens, c.setup.failure_penalty),
         reads=lambda b: HIT_FIELDS if bool((~b.result.valid).any()) else ()),
)
"""Every residual term, in residual order (static: the same order whatever was imported)."""


def term(name: str) -> Term:
    """The term called ``name``."""
    for t in TERMS:
        if t.name == name:
            return t
    raise KeyError(name)
