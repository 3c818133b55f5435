"""From a spec to an optimization problem: the ``[optimize]`` settings as plain dataclasses, the solves
checked against the surfaces, the declared variables of the ``vary`` lists, and the ``Problem`` built on
them (``lensopt.optim`` never sees the spec; this layer sits above both).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import torch

from lensopt.engine import Engine
from lensopt.errors import SpecError
from lensopt.materials import CatalogGlass, Material, ModelGlass, notice
from lensopt.materials.catalog import PLASTICS_VENDOR
from lensopt.optim import settings as st
from lensopt.optim.problem import Problem, ProblemSetup, SurfaceInfo
from lensopt.optim.solves import Solve
from lensopt.optim.variables import Declared, Kind
from lensopt.spec import optim as so
from lensopt.spec.build import build, camera_of
from lensopt.spec.models import DiffractiveSurface, LensSpec

__all__ = ["SpecProblem", "VENDOR_CATALOGS", "binding_catalog", "build_problem", "problem_setup", "settings_of",
           "resolve_solves", "with_varied_powers",
           "declare_variables"]

#: Which plain dataclass each pydantic settings model converts to (``settings_of``).
_KINDS: dict[type, type] = {
    so.OptimizeSpec: st.OptimizeSettings, so.TraSpec: st.TraSettings, so.WavefrontSpec: st.WavefrontSettings,
    so.GapBoundSpec: st.GapBound,
    so.SpanBoundSpec: st.SpanBound, so.RayPathSpec: st.RayPathSettings, so.RayAngleSpec: st.RayAngleSettings,
    so.SurfaceNormalSpec: st.SurfaceNormalSettings, so.DistortionSpec: st.DistortionSettings,
    so.IlluminationSpec: st.IlluminationSettings, so.GlassMeshSpec: st.GlassMeshSettings,
    so.GlassCatalogSpec: st.GlassCatalogSettings, so.RayFailureSpec: st.RayFailureSettings,
    so.ConstraintsSpec: st.ConstraintSettings, so.LMSpec: st.LMSettings, so.AdamSpec: st.AdamSettings,
    so.ImageSpec: st.ImageSettings,
}


def _plain(value: Any) -> Any:
    if type(value) in _KINDS:
        return settings_of(value)
    if isinstance(value, list | tuple):
        return tuple(_plain(v) for v in value)
    return value


def settings_of(model: Any) -> Any:
    """The plain frozen dataclass (``lensopt.optim.settings``) of a pydantic settings model, field by field
    (lists become tuples); e.g. ``settings_of(spec.optimize)`` → ``OptimizeSettings``. Fields the dataclass
    does not have (the solves) are left out."""
    kind = _KINDS[type(model)]
    names = {f.name for f in dataclasses.fields(kind)}
    return kind(**{name: _plain(getattr(model, name)) for name in names})


def resolve_solves(spec: LensSpec) -> list[Solve]:
    """Check the spec's solves against its surfaces; return them in application order."""
    opt = spec.optimize
    if opt is None:
        return []
    S = len(spec.surfaces)
    out: list[Solve] = []
    for i, sol in enumerate(opt.solves):
        path = f"optimize.solves[{i}]"
        surface = None
        if sol.type in ("efl", "image_height"):
            surface = S - 1 if sol.surface is None else sol.surface
            if not -S <= surface < S:
                raise SpecError(f"no such surface (the lens has {S})", path=f"{path}.surface", got=sol.surface)
            surface %= S
            surf = spec.surfaces[surface]
            base = surf.base if surf.type == "diffractive" else surf
            if base.type == "plane":
                raise SpecError("a curvature solve needs a curved surface type (sphere, conic, asphere)",
                                path=f"{path}.surface", got=sol.surface)
            before = "air" if surface == 0 else spec.surfaces[surface - 1].material
            if before == surf.material:
                raise SpecError("a curvature solve needs a change of medium at the surface",
                                path=f"{path}.surface", got=sol.surface)
            if sol.type == "image_height":
                if surface <= spec.stop_index:
                    raise SpecError("an image_height solve must act on a surface after the aperture stop",
                                    path=f"{path}.surface", got=sol.surface)
                if spec.system.field.hfov_deg is None:
                    raise SpecError("an image_height solve needs an angular field (system.field.hfov_deg)",
                                    path=path)
        out.append(Solve(sol.type, surface, sol.value))
    rank = {"ttl": 0, "efl": 1, "image_height": 1, "focus": 2}
    return sorted(out, key=lambda s: rank[s.kind])


def _base_of(surf):  # noqa: ANN001, ANN202 - spec surface → its shape part
    return surf.base if isinstance(surf, DiffractiveSurface) else surf


def with_varied_powers(spec: LensSpec) -> LensSpec:
    """Copy of ``spec`` where every varied coefficient power exists (0 where the spec has none)."""
    spec = spec.model_copy(deep=True)
    for surf in spec.surfaces:
        for item in surf.vary:
            name, _, power = item.partition(".")
            if not power:
                continue
            if name == "coefficients":
                base = _base_of(surf)
                if int(power) not in base.coefficients:
                    base.coefficients = {**base.coefficients, int(power): 0.0}
            elif name == "phase" and int(power) not in surf.phase:
                surf.phase = {**surf.phase, int(power): 0.0}
    return spec


def declare_variables(spec: LensSpec) -> list[Declared]:
    """The variables of the ``vary`` lists in θ order: surface by surface, as declared, with the asphere
    powers of a surface last and ascending (the Bézier basis's control points)."""
    out: list[Declared] = []
    for s, surf in enumerate(spec.surfaces):
        found: list[tuple[Kind, int | None]] = []
        base = _base_of(surf)
        for item in dict.fromkeys(surf.vary):
            name, _, power = item.partition(".")
            if name == "thickness":
                found.append(("thickness", None))
            elif name == "radius":
                found.append(("curvature", None))
            elif name == "conic":
                found.append(("conic", None))
            elif name == "material":
                if surf.is_air:
                    raise SpecError("air cannot vary; give the element a glass to start from",
                                    path=f"surfaces[{s}].vary")
                found.append(("glass", None))
            elif name in ("coefficients", "phase"):
                table = base.coefficients if name == "coefficients" else surf.phase
                powers = [int(power)] if power else sorted(table)
                if not powers:
                    raise SpecError(f"no {name} to vary; name the powers, e.g. {name}.{4 if name[0] == 'c' else 2}",
                                    path=f"surfaces[{s}].vary")
                kind: Kind = "asphere" if name == "coefficients" else "phase"
                found.extend((kind, p) for p in powers)
        asph = sorted(p for k, p in found if k == "asphere")
        out += [Declared(k, s, p) for k, p in found if k != "asphere"]
        out += [Declared("asphere", s, p) for p in asph]
    return out


#: The built-in design catalog of each vendor that has one (what its varied glasses bind to by default).
VENDOR_CATALOGS: dict[str, str] = {"ohara": "ohara-recommended", "schott": "schott-preferred",
                                   PLASTICS_VENDOR: "plastics"}


def _start_vendor(value: object, medium: Material) -> str | None:
    """The vendor of a start material: a catalog glass's, ``plastics`` for a Table S10 plastic named in
    the spec, None for model, tabulated and AGF glasses."""
    if isinstance(medium, CatalogGlass):
        return medium.glass.vendor
    if isinstance(value, str) and isinstance(medium, ModelGlass):
        return PLASTICS_VENDOR
    return None


def binding_catalog(spec: LensSpec, media: Sequence[Material], glass_surfaces: Sequence[int]) -> tuple[str, str]:
    """The design catalog the glass variables of ``spec`` bind to, and the notice that says so ("" if none).

    ``[optimize] catalog``, when the spec sets it. Else a varied catalog glass stays in its own vendor's
    catalog: the design catalog of the vendor of the start materials (:data:`VENDOR_CATALOGS`) when they
    all come from one vendor that has one, else the default ``ohara-recommended``. The notice names the
    surfaces and vendors whenever the catalog was not set, or is another vendor's than a start glass's.

    Args:
        media: (S+1) built materials (object space, then the medium after every surface).
        glass_surfaces: the first surface of every varied glass element.
    """
    opt = spec.optimize
    explicit = opt is not None and "catalog" in opt.model_fields_set
    default = opt.catalog if opt is not None else so.OptimizeSpec().catalog
    if not glass_surfaces:
        return default, ""
    starts = {s: _start_vendor(spec.surfaces[s].material, media[s + 1]) for s in glass_surfaces}
    by_vendor: dict[str | None, list[int]] = {}
    for s, v in starts.items():
        by_vendor.setdefault(v, []).append(s)

    def start(vendors: Sequence[str | None]) -> str:
        parts = [f"{v or 'model'} glasses (surface{'s' * (len(by_vendor[v]) > 1)} "
                 f"{', '.join(str(s) for s in by_vendor[v])})" for v in vendors]
        return "the glass variables start as " + ", ".join(parts)

    choose = "set [optimize] catalog to choose another"
    if explicit:
        own = next((v for v, c in VENDOR_CATALOGS.items() if c == default), None)
        moved = [v for v in by_vendor if v is not None and v != own]
        if not moved:
            return default, ""
        return default, f"{start(moved)}; they bind to {default}, as [optimize] catalog says"
    vendors = [v for v in by_vendor if v is not None]
    if len(vendors) == 1 and None not in by_vendor and vendors[0] in VENDOR_CATALOGS:
        chosen = VENDOR_CATALOGS[vendors[0]]
        return chosen, f"{start(vendors)}; they bind to {chosen}, their vendor's design catalog; {choose}"
    missing = [v for v in vendors if v not in VENDOR_CATALOGS]
    why = (f", as lensopt has no design catalog of {', '.join(missing)}" if missing else
           ", as they are not all from one vendor" if vendors else "")
    return default, f"{start(list(by_vendor))}; they bind to {default}, the default design catalog{why}; {choose}"


def problem_setup(spec: LensSpec, *, dtype: torch.dtype = torch.float64,
                  device: torch.device | str | None = None) -> tuple[ProblemSetup, LensSpec]:
    """The plain ``ProblemSetup`` of ``spec`` (its ``[optimize]`` section or the defaults) and the
    prepared spec it was built from (every varied coefficient power present: what θ writes back into)."""
    opt = settings_of(spec.optimize or so.OptimizeSpec())
    solves = resolve_solves(spec)
    prepared = with_varied_powers(spec)
    declared = declare_variables(prepared)
    model = build(prepared, dtype=dtype, device=device)
    catalog, told = binding_catalog(prepared, model.media, [d.surface for d in declared if d.kind == "glass"])
    if told:
        notice(f"optimize.catalog: {told}")
    if catalog != opt.catalog:
        opt = dataclasses.replace(opt, catalog=catalog)
        if prepared.optimize is not None:  # the written lens records the catalog its glasses bound to
            prepared.optimize = prepared.optimize.model_copy(update={"catalog": catalog})
    surfaces = tuple(SurfaceInfo(glass_after=not s.is_air, plane=s.type == "plane",
                                 material_varies="material" in s.vary) for s in prepared.surfaces)
    camera = camera_of(model) if prepared.sensor is not None else None
    setup = ProblemSetup(lens=model.lens, system=model.system, media=tuple(model.media), surfaces=surfaces,
                         declared=tuple(declared), solves=tuple(solves), settings=opt,
                         defocus=prepared.image.defocus, camera=camera)
    return setup, prepared


class SpecProblem(Problem):
    """A ``Problem`` built from a spec, which it keeps (``spec``: the prepared copy that θ writes back
    into, ``lensopt.design.writeback``)."""

    spec: LensSpec

    def __init__(self, setup: ProblemSetup, spec: LensSpec, **kwargs: Any) -> None:
        super().__init__(setup, **kwargs)
        self.spec = spec


def build_problem(spec: LensSpec, *, seed: int = 0, dtype: torch.dtype = torch.float64, method: str | None = None,
                  image_dtype: torch.dtype = torch.float32, device: torch.device | str | None = None,
                  engine: Engine | None = None) -> SpecProblem:
    """The optimization problem of ``spec`` (variables, solves, residual groups of its ``[optimize]``).

    Args:
        seed: seed of the pupil jitter (``rings`` sampling).
        dtype: float64 for design work.
        method: ``lm`` or ``adam`` (default: the spec's optimizer).
        image_dtype: dtype of rendered image patches (image objectives).
        device: where every tensor of the problem lives (θ, the lens, the rays, the Jacobian).
        engine: trace backend and memory budget of the problem's traces (default ``Engine()``).
    """
    setup, prepared = problem_setup(spec, dtype=dtype, device=torch.device(device or "cpu"))
    return SpecProblem(setup, prepared, seed=seed, method=method, image_dtype=image_dtype, engine=engine)

