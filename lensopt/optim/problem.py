"""The optimization problem: θ, the one residual function ℓ(θ), its Jacobian, and the checks that reject
non-physical steps (DESIGN.md rule 4). Plain tensors and dataclasses only: the setup from a spec (reading
the spec, the solves, the declared variables, the settings) is ``lensopt.design.setup.build_problem``,
and θ → spec is ``lensopt.design.writeback``.

``residuals(θ)`` is pure: it rebuilds the lens from θ, applies the solves, traces the optimization
rays with ``trace_bundle`` (so aiming, vignetting and apertures of the optics core apply) and
concatenates the residual groups, each multiplied by its static weight. Time-varying weights (the
glass-catalog schedule) are row multipliers applied by the optimizer (``row_scale``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from lensopt.analysis.spot import spot_stats
from lensopt.analysis.wavefront import map_grid
from lensopt.engine import Engine
from lensopt.errors import LensoptError, SpecError
from lensopt.imaging.camera import Camera
from lensopt.materials import Material, design_catalog
from lensopt.materials.glass_space import GlassMesh, GlassSpace, glass_mesh, glass_space
from lensopt.optics.bundle import Bundle, Launch, PupilShape, launch_bundle, trace_bundle
from lensopt.optics.differential import supported
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import PupilSampling
from lensopt.optim import residuals
from lensopt.optim.image_objective import ImageObjective
from lensopt.optim.jacobian import RampPlan, RampRows, place_rows, ramp_tangent_rows, staged_jacobian
from lensopt.optim.rays import head, with_rim
from lensopt.optim.schedule import schedule_weight
from lensopt.optim.settings import ImageSettings, OptimizeSettings
from lensopt.optim.solves import Solve, apply_solves, solved_quantities
from lensopt.optim.terms import TERMS, TermContext, TermSetup, term
from lensopt.optim.variables import Declared, Parameterization
from lensopt.transforms import carries_derivatives

__all__ = ["Evaluation", "Problem", "ProblemSetup", "SurfaceInfo"]


@dataclass(frozen=True)
class SurfaceInfo:
    """What the residual terms and reports need to know about one surface.

    Attributes:
        glass_after: the medium after the surface is not air (the gap is an element).
        plane: the surface is of type ``plane`` (no surface-normal residual).
        material_varies: the medium after the surface is a glass variable.
    """

    glass_after: bool
    plane: bool
    material_varies: bool = False


@dataclass(frozen=True)
class ProblemSetup:
    """Everything a ``Problem`` is made of, as plain data (``lensopt.design.setup`` reads it from a spec).

    Attributes:
        lens: the lens at its start values (dtype and device of the whole problem), with a column for
            every varied coefficient power.
        system: aperture, field, object, wavelength and field weights.
        media: (S+1) materials: object space, then the medium after every surface.
        surfaces: (S) per-surface facts.
        declared: the variables in θ order.
        solves: resolved solves in application order.
        settings: the optimization settings.
        defocus: image defocus (mm) kept by a focus solve.
        camera: the lens on its sensor (sensor, spectrum): needed by image objectives.
    """

    lens: Lens
    system: System
    media: tuple[Material, ...]
    surfaces: tuple[SurfaceInfo, ...]
    declared: tuple[Declared, ...]
    solves: tuple[Solve, ...] = ()
    settings: OptimizeSettings = OptimizeSettings()
    defocus: float = 0.0
    camera: Camera | None = None


@dataclass(frozen=True)
class Evaluation:
    """ℓ(θ) with what the optimizer needs to accept or reject a step.

    Attributes:
        residuals: (M,) statically weighted residuals.
        physical: whether the lens is physical (finite residuals, solves well posed, positive glass
            thicknesses and image distance, glass variables in the model's range, some ray traced).
        reason: why not, for messages.
        valid_fraction: share of optimization rays that reached the image.
    """

    residuals: Tensor
    physical: bool
    reason: str
    valid_fraction: float


class Problem:
    """Variables, solves and residual groups of a ``ProblemSetup``.

    Args:
        setup: the lens, its declared variables, solves and settings (dtype and device: those of
            ``setup.lens``; design work runs in float64).
        seed: seed of the pupil jitter (``rings`` sampling).
        method: ``lm`` or ``adam`` (default: the settings' optimizer): image objectives use GTRA for LM,
            the scalar loss for Adam.
        image_dtype: dtype of the rendered image patches.
        engine: trace backend and memory budget of its traces (``lensopt.engine``; default ``Engine()``).
    """

    def __init__(self, setup: ProblemSetup, *, seed: int = 0, method: str | None = None,
                 image_dtype: torch.dtype = torch.float32, engine: Engine | None = None) -> None:
        self.setup = setup
        self.engine = engine or Engine()
        self.opt: OptimizeSettings = setup.settings
        self.objective: str = self.opt.objective or "spot"
        self.image: ImageObjective | None = None
        self.seed = seed
        lens0 = setup.lens
        self.dtype = dtype = lens0.dtype
        self.device = lens0.device
        self.system = setup.system
        self.media = setup.media
        self.surfaces = setup.surfaces
        self.solves = list(setup.solves)
        skip = solved_quantities(self.solves, len(setup.surfaces))
        self.space: GlassSpace | None = None
        if any(d.kind == "glass" for d in setup.declared):
            try:
                cat = design_catalog(self.opt.catalog)
            except LensoptError as err:
                raise err.at("optimize.catalog") from None
            self.space = glass_space(cat, self.opt.glass_parameters)
        alpha = self.opt.alpha
        if alpha is None:
            alpha = float(first_order(lens0, self.system).epd) / 2.0
        self.param = Parameterization(lens0, setup.media, setup.declared, alpha=alpha, glass=self.space,
                                      asphere_basis=self.opt.asphere_basis, skip=skip)
        self.alpha = alpha
        self.defocus = setup.defocus
        cons = self.opt.constraints
        self.mesh: GlassMesh | None = None
        if self.space is not None and cons.glass_mesh is not None:
            self.mesh = glass_mesh(self.space, cons.glass_mesh.max_edge)
        self.sampling = PupilSampling.parse(self.opt.sampling, seed=seed, path="optimize.sampling")
        self.num_spot = self.sampling.points(dtype=dtype, engine=self.engine).shape[0]
        self.pupil = with_rim(self.sampling.points(dtype=dtype, engine=self.engine), self.opt.rim_rays,
                              half=self.sampling.half).to(self.device)
        fw = self.system.field_weights or (1.0,) * self.system.num_fields
        self.field_weights = torch.tensor(fw, dtype=dtype, device=self.device)
        self.glass_gap = [s.glass_after for s in setup.surfaces]
        self.interfaces = [
            s for s in range(lens0.num_surfaces)
            if lens0.shapes[s].diffractive or bool((lens0.index[s] != lens0.index[s + 1]).any())
            or setup.surfaces[s].material_varies
            or (s > 0 and setup.surfaces[s - 1].material_varies)
        ]
        self.failure_penalty = cons.ray_failure.penalty_mm or alpha
        self.path_spans = self._path_spans()
        self.theta0 = self.param.initial()
        if self.objective in ("raw", "restored"):  # "restored": design.joint replaces it with RestoredObjective
            if setup.camera is None:
                raise LensoptError('objective = "raw" needs a [sensor] (pixel_pitch_um and resolution)',
                                   path="sensor")
            mode = "scalar" if (method or self.opt.optimizer) == "adam" else "gtra"
            self.image = ImageObjective(setup.camera, self.opt.image or ImageSettings(), mode=mode,
                                        dtype=image_dtype, engine=self.engine)
        self._shape_memo: tuple[Tensor, PupilShape] | None = None
        wf_pupil = None
        if self.opt.wavefront is not None:
            pts, inside = map_grid(self.opt.wavefront.n, dtype=dtype)
            wf_pupil = pts[inside].to(self.device)
        self.term_setup = TermSetup(
            self.opt, self.objective, self.system, self.field_weights, self.num_glasses, tuple(self.interfaces),
            tuple(s for s in self.interfaces if not self.surfaces[s].plane), tuple(self.path_spans),
            self.failure_penalty, self.gap_bounds, self.param.glass_g, self.space, self.mesh, self.image, wf_pupil)
        self.slices = self._layout()
        self.size = max((sl.stop for sl in self.slices.values()), default=0)

    def use_image(self, image: ImageObjective | Any) -> None:
        """Make ``image`` the image objective (``design.joint`` puts its ``RestoredObjective`` here)."""
        self.image = image
        self.term_setup = dataclasses.replace(self.term_setup, image=image)

    # ------------------------------------------------------------------------------------ structure

    @property
    def num_variables(self) -> int:
        return self.param.size

    @property
    def num_glasses(self) -> int:
        return len(self.param.of_kind("glass"))

    def _weight(self, group: str) -> float | None:
        """Static weight of a term, None when it is off."""
        return term(group).weight(self.term_setup)

    def _layout(self) -> dict[str, slice]:
        with torch.no_grad():
            parts = self.terms(self.theta0)
        out, pos = {}, 0
        for name, t in parts.items():
            out[name] = slice(pos, pos + t.shape[0])
            pos += t.shape[0]
        return out

    # -------------------------------------------------------------------------------- lens and rays

    def lens(self, theta: Tensor) -> tuple[Lens, Tensor]:
        """The solved lens for θ and whether its solves were well posed."""
        return apply_solves(self.param.lens(theta), self.system, self.solves, defocus=self.defocus)

    def bundle(self, lens: Lens, theta: Tensor | None = None) -> Bundle:
        """The optimization rays of ``lens`` traced (``record``); with ``theta`` (the variables ``lens``
        was made from) the detached aiming solves are taken from, or kept for, that θ (``solved``)."""
        bundle = trace_bundle(lens, self.system, self.pupil, half_pupil=self.sampling.half, record=True,
                              solved=self.solved_shape(theta), engine=self.engine)
        self._remember(theta, bundle.shape)
        return bundle

    def launch(self, lens: Lens, theta: Tensor | None = None) -> Launch:
        """The optimization rays of ``bundle`` before their trace (``optim.jacobian``'s stage A)."""
        return launch_bundle(lens, self.system, self.pupil, half_pupil=self.sampling.half,
                             solved=self.solved_shape(theta), engine=self.engine)

    def solved_shape(self, theta: Tensor | None) -> PupilShape | None:
        """The pupil shape last computed at exactly this θ (its detached aiming solves are a function of
        θ alone, so reusing them changes no number: ``pupil_shape``), else None."""
        memo = self._shape_memo
        if theta is None or memo is None or not torch.equal(memo[0], theta.detach()):
            return None
        return memo[1]

    def _remember(self, theta: Tensor | None, shape: PupilShape | None) -> None:
        if theta is not None and shape is not None and not carries_derivatives(theta):
            self._shape_memo = (theta.detach().clone(), shape)

    def gap_bounds(self, lens: Lens) -> tuple[Tensor, Tensor]:
        """(S,), (S,) lower and upper t_z bounds per gap (mm), relative to centre thickness in glass."""
        rp = self.opt.constraints.ray_path
        S = lens.num_surfaces
        big = residuals.BIG
        # Numbers, except where glass_ratio ties a bound to its thickness: those are taken from the
        # whole thickness vector at once (a dual with a plain operand costs ≈ 15× a plain operation
        # under forward-mode AD, so a few whole-vector operations rather than some per gap).
        lo, hi, tie_lo, tie_hi = [], [], [], []
        for s in range(S):
            tied = s < S - 1 and self.glass_gap[s] and rp.glass_ratio is not None
            if s == S - 1:
                low = rp.image_min if rp.image_min is not None else -big
                high = rp.image_max if rp.image_max is not None else big
            elif self.glass_gap[s]:
                low, high = rp.glass_min, big if rp.glass_max is None else rp.glass_max
            else:
                low, high = rp.air_min, big if rp.air_max is None else rp.air_max
            t_lo = t_hi = tied
            for g in rp.gaps:
                if g.gap % S == s:
                    low, t_lo = (low, t_lo) if g.min is None else (g.min, False)
                    high, t_hi = (high, t_hi) if g.max is None else (g.max, False)
            lo.append(0.0 + low)  # as the sum with zeros_like(thickness) gave them
            hi.append(0.0 + high)
            tie_lo.append(t_lo)
            tie_hi.append(t_hi)
        like = {"dtype": lens.dtype, "device": lens.device}
        lower, upper = torch.tensor(lo, **like), torch.tensor(hi, **like)
        if any(tie_lo):
            ratio = torch.maximum(lower, lens.thickness / rp.glass_ratio)
            lower = torch.where(torch.tensor(tie_lo, device=lens.device), ratio, lower)
        if any(tie_hi):
            ratio = torch.minimum(upper, lens.thickness * rp.glass_ratio)
            upper = torch.where(torch.tensor(tie_hi, device=lens.device), ratio, upper)
        return lower, upper

    def _path_spans(self) -> list[tuple[int, int, float, float]]:
        """``ray_path.spans`` as (first surface, end surface, lower, upper); the image is surface S."""
        rp = self.opt.constraints.ray_path
        S = len(self.surfaces)
        out = []
        for i, sp in enumerate((rp.spans if rp is not None else None) or []):
            path = f"optimize.constraints.ray_path.spans[{i}]"
            if not -S <= sp.first < S:
                raise SpecError(f"no such surface (the lens has {S})", path=f"{path}.first", got=sp.first)
            first = sp.first % S
            stop = S if sp.to is None else sp.to
            if sp.to is not None and not -S <= sp.to < S:
                raise SpecError(f"no such surface (the lens has {S}; leave `to` out for the image)",
                                path=f"{path}.to", got=sp.to)
            stop = stop % S if sp.to is not None else S
            if stop <= first:
                raise SpecError("`to` must come after `first`", path=f"{path}.to", got=sp.to)
            lo = -residuals.BIG if sp.min is None else sp.min
            hi = residuals.BIG if sp.max is None else sp.max
            out.append((first, stop, lo, hi))
        return out

    # ----------------------------------------------------------------------------------- residuals

    def terms(self, theta: Tensor) -> dict[str, Tensor]:
        """Residual groups (statically weighted) of θ, in a fixed order; groups that are off are absent."""
        lens, _ = self.lens(theta)
        return self._terms(theta, lens, self.bundle(lens))

    def _context(self, theta: Tensor, lens: Lens, bundle: Bundle) -> TermContext:
        return TermContext(self.term_setup, theta, lens, bundle, head(bundle, self.num_spot))

    def _terms(self, theta: Tensor, lens: Lens, bundle: Bundle,
               given: dict[str, Tensor] | None = None) -> dict[str, Tensor]:
        """The registered terms (``lensopt.optim.terms``), each times its static weight: spot terms
        (TRA, distortion, illumination) from the spot sample; geometric constraints and failures from
        every ray, the rim rays included. ``given``: rows of terms already computed (by name)."""
        ctx = self._context(theta, lens, bundle)
        out: dict[str, Tensor] = {}
        for t in TERMS:
            w = t.weight(self.term_setup)
            if w is None:
                continue
            out[t.name] = given[t.name] if given and t.name in given else t.residual(ctx) * w
        return out

    def ramp_plan(self, theta: Tensor, lens: Lens, bundle: Bundle) -> RampPlan:
        """How the staged Jacobian takes the ramp terms (``Term.margin``) at the traced ``bundle`` of
        ``lens``: their rows of ℓ, the active rows of each (margin ≥ 0 on a valid ray: the only ones
        whose derivative is not exactly 0) and the hit fields the terms read (``RampPlan``)."""
        ctx = self._context(theta, lens, bundle)
        valid = bundle.result.valid
        n_r = valid.numel()
        given: dict[str, Tensor] = {}
        fields: set[tuple[str, int]] = set()
        everywhere = lambda names: {(f, s) for f in names for s in range(lens.num_surfaces)}  # noqa: E731
        found = []
        for t in TERMS:
            w = t.weight(self.term_setup)
            if w is None:
                continue
            if t.margin is None:
                fields.update(everywhere(t.reads(bundle)))
                continue
            given[t.name] = t.residual(ctx) * w
            act = residuals.active(t.margin(self.term_setup, lens, bundle), valid).reshape(-1, n_r)
            if bool(act.any()):
                found.append((t, w, act))
        if not found:
            return RampPlan(given, (), None, frozenset(fields))
        rays = torch.stack([act.any(0) for _, _, act in found]).any(0).nonzero().squeeze(1)
        ramps = []
        for t, w, act in found:
            b, k = act[:, rays].nonzero(as_tuple=True)
            blocks = torch.unique(b)  # sorted: the margins are taken on these blocks alone
            fields.update(t.reads_at(self.term_setup, lens, blocks.tolist()) if t.reads_at
                          else everywhere(t.reads(bundle)))
            margin = functools.partial(t.margin, self.term_setup, blocks=blocks.tolist())
            ramps.append(RampRows(t.name, margin, w, math.sqrt(n_r), torch.searchsorted(blocks, b) * rays.numel() + k,
                                  b * n_r + rays[k]))
        return RampPlan(given, tuple(ramps), rays, frozenset(fields))

    def residuals(self, theta: Tensor) -> Tensor:
        """(M,) ℓ(θ): the one residual function (pure in θ)."""
        return torch.cat(list(self.terms(theta).values()))

    def jacobian(self, theta: Tensor) -> tuple[Tensor, Tensor]:
        """(M, N) Jacobian by forward-mode AD and ℓ(θ) (M,): in stages (``optim.jacobian``) where they
        apply, else ``torch.func.jacfwd`` over the whole residual function (the same derivatives)."""
        if self.image is not None or not supported(self.setup.lens):
            return self.jacobian_jacfwd(theta)
        # Ramp terms (``Term.margin``) stay out of stage C (their rows of ℓ are the plan's); the
        # derivatives of their active rows (on the aimed studies ≤ 10 % of them, often none) are taken
        # on those rows' rays and blocks alone and put in place (``place_rows``); every other row of
        # theirs has a derivative of exactly 0. The trace differentiates only the hits the terms read.
        plan: list[RampPlan] = []

        def hit_fields(lens: Lens, bundle: Bundle) -> frozenset[tuple[str, int]]:
            plan.append(self.ramp_plan(theta.detach(), lens, bundle))
            return plan[0].fields

        def terms_of(t: Tensor, lens: Lens, bundle: Bundle, cut: Bundle | None) -> Tensor:
            parts = [v for name, v in self._terms(t, lens, bundle, plan[0].given).items() if name not in plan[0].given]
            parts += ramp_tangent_rows(plan[0], lens, cut)
            return torch.cat(parts) if parts else t[:0]  # no row: still one of θ's (J (0, N) under vmap)

        J, r = staged_jacobian(theta, lens_of=lambda t: self.lens(t)[0],
                               launch_of=lambda lens: self.launch(lens, theta), terms_of=terms_of,
                               hit_fields=hit_fields, system=self.system, rays=lambda: plan[0].rays)
        return place_rows(J, r, plan[0], self.slices)

    def jacobian_jacfwd(self, theta: Tensor) -> tuple[Tensor, Tensor]:
        """(M, N) Jacobian by ``torch.func.jacfwd`` over ``residuals`` and ℓ(θ) (M,): the reference."""
        def both(t: Tensor) -> tuple[Tensor, Tensor]:
            r = self.residuals(t)
            return r, r

        J, r = torch.func.jacfwd(both, has_aux=True)(theta)
        return J, r

    def schedules(self) -> dict[str, list[tuple[float, float]]]:
        """Weight schedules of the active groups (the glass-catalog one, and any group's own)."""
        out = {}
        for name in self.slices:
            spec = term(name).config(self.term_setup)
            knots = getattr(spec, "schedule", None)
            if knots:
                out[name] = list(knots)
        return out

    def row_scale(self, fraction: float) -> Tensor:
        """(M,) time-varying multipliers of the residual rows at ``fraction`` of the run."""
        scale = torch.ones(self.size, dtype=self.dtype, device=self.device)
        for name, knots in self.schedules().items():
            scale[self.slices[name]] = schedule_weight(knots, fraction)
        return scale

    def schedules_settled(self, fraction: float) -> bool:
        """Whether every weight schedule has reached its final value (the merit no longer changes)."""
        return all(schedule_weight(k, fraction) == schedule_weight(k, 1.0) for k in self.schedules().values())

    # ---------------------------------------------------------------------------- step acceptance

    def evaluate(self, theta: Tensor) -> Evaluation:
        """ℓ(θ) (no gradients) and whether the lens is physical."""
        with torch.no_grad():
            lens, solved = self.lens(theta)
            reason = self._lens_reason(theta, lens, bool(solved))
            if reason:
                nan = torch.full((self.size,), math.nan, dtype=self.dtype, device=self.device)
                return Evaluation(nan, False, reason, 0.0)
            bundle = self.bundle(lens, theta)
            r = torch.cat(list(self._terms(theta, lens, bundle).values()))
            valid = float(bundle.result.valid.to(self.dtype).mean())
        if not bool(torch.isfinite(r).all()):
            reason = "non-finite residuals"
        elif valid == 0.0:
            reason = "no ray reaches the image"
        return Evaluation(r, not reason, reason, valid)

    def failure_summary(self, theta: Tensor) -> tuple[int, int, dict[str, int]]:
        """(failed rays, rays, failed rays per reason) of the optimization rays at θ."""
        from lensopt.optics.trace import REASONS

        with torch.no_grad():
            lens, _ = self.lens(theta)
            status = self.bundle(lens).result.status
        counts = {REASONS[r]: int((status == r).sum()) for r in REASONS if bool((status == r).any())}
        return int((status != 0).sum()), int(status.numel()), counts

    def check(self, theta: Tensor) -> str:
        """Why the lens of θ is non-physical ("" when it is fine); paraxial only, no ray trace."""
        with torch.no_grad():
            lens, solved = self.lens(theta)
            return self._lens_reason(theta, lens, bool(solved))

    def _lens_reason(self, theta: Tensor, lens: Lens, solved: bool) -> str:
        if not bool(torch.isfinite(theta).all()):
            return "non-finite variables"
        if not solved:
            return "a solve has no solution (zero slope)"
        for s, glass in enumerate(self.glass_gap):
            if glass and not float(lens.thickness[s]) > 0:
                return f"surfaces[{s}].thickness: glass element thickness {float(lens.thickness[s]):.4g} mm ≤ 0"
        if not float(lens.thickness[-1]) > 0:
            return f"image distance {float(lens.thickness[-1]):.4g} mm ≤ 0"
        if not bool(torch.isfinite(lens.curvature).all()):
            return "non-finite curvature"
        x = self.param.glass_physical(theta)
        for i, (nd, vd, dp) in enumerate(x.tolist()):
            if not (1.0 < nd < 3.0 and 10.0 <= vd <= 120.0 and abs(dp) <= 0.1):
                return f"glass {i}: nd={nd:.4f}, vd={vd:.2f}, ΔPgF={dp:.4f} outside the model's range"
        return ""

    def merits(self, r: Tensor, scale: Tensor | None = None) -> dict[str, float]:
        """½‖ℓ_group‖² of every group (with the row multipliers ``scale``)."""
        if scale is not None:
            r = r * scale
        return {name: 0.5 * float((r[sl] ** 2).sum()) for name, sl in self.slices.items()}

    def spot_esr_mm(self, theta: Tensor) -> float:
        """Effective spot radius of the optimization rays' spot sample at θ (a trace; any objective)."""
        with torch.no_grad():
            lens, _ = self.lens(theta)
            spot = head(self.bundle(lens), self.num_spot)
            return float(spot_stats(spot, self.system.wavelength_weights, self.field_weights).effective_radius)

    def esr_mm(self, r: Tensor) -> float:
        """Effective spot radius of the optimization rays from the TRA rows (‖ℓ_TRA‖/w_TRA)."""
        w = self.opt.tra.weight
        if "tra" not in self.slices or w == 0:
            return math.nan
        return float(torch.linalg.vector_norm(r[self.slices["tra"]])) / w
