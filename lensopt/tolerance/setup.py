"""A tolerance ``Job`` from a built lens and its ``[tolerance]`` settings; trial lenses back to specs.

``tolerances_for`` expands the spec's items (kind, limit, surfaces or elements, distribution) against
the lens: default targets are every surface a kind applies to. ``trial_spec`` writes one trial as a
lens spec (radii, thicknesses, decenters/tilts, elements; perturbed media as tabulated glasses exact
at the spec's wavelengths; the back-focus compensator folded into the last thickness), so the worst
trials can be inspected with every other command.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import torch

from lensopt.errors import LensoptError
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.spec.build import Model
from lensopt.tolerance.evaluate import EvalSetup
from lensopt.tolerance.model import (
    ARCMIN,
    KINDS,
    Tolerance,
    TrialParams,
    elements_of,
    glass_gaps,
    nominal_params,
    s62_profile,
)
from lensopt.tolerance.run import Job

__all__ = ["tolerances_for", "make_job", "trial_spec", "semi_apertures", "d_line_indices", "lm_variables"]

D_LINE_UM = 0.5875618


def tolerances_for(model: Model, settings: Any) -> list[Tolerance]:
    """Expand ``settings`` (a ``ToleranceSpec``-like object: profile, items, distribution) for this lens.

    Raises ``LensoptError`` naming ``tolerance.items[i]…`` for targets that do not exist.
    """
    lens = model.lens
    glass = glass_gaps(lens)
    elements = elements_of(lens)
    num = lens.num_surfaces
    tols: list[Tolerance] = []
    if settings.profile == "s6.2":
        tols += s62_profile(lens, distribution=settings.distribution)
    for i, item in enumerate(settings.items):
        path = f"tolerance.items[{i}]"
        dist = item.distribution or settings.distribution
        kind = item.kind
        if kind.startswith("element_"):
            targets = [tuple(e) for e in item.elements] if item.elements is not None else elements
            for e in targets:
                if e not in elements:
                    raise LensoptError(f"not an element of this lens (elements: {elements})", path=f"{path}.elements",
                                       got=list(e))
                tols.append(Tolerance(kind, e, item.limit, dist, f"{_short(kind)} e{e[0]}-{e[1]}"))
            continue
        if item.surfaces is not None:
            for s in item.surfaces:
                if not 0 <= s < num:
                    raise LensoptError(f"surface index must be in 0..{num - 1}", path=f"{path}.surfaces", got=s)
            targets = list(item.surfaces)
        elif kind in ("curvature", "radius", "fringes"):
            targets = [s for s in range(num) if float(lens.curvature[s]) != 0.0]
        elif kind == "thickness":
            targets = [s for s in range(num - 1) if glass[s]]
        elif kind == "airspace":
            targets = [s for s in range(num - 1) if not glass[s]]
        elif kind in ("index", "abbe"):
            targets = [s for s in range(num) if glass[s]]
        else:
            targets = list(range(num))
        for s in targets:
            if kind in ("index", "abbe") and not glass[s]:
                raise LensoptError("the medium after this surface is air", path=f"{path}.surfaces", got=s)
            core = "thickness" if kind == "airspace" else kind
            tols.append(Tolerance(core, s, item.limit, dist, f"{_short(kind)} s{s}"))
    if not tols:
        raise LensoptError("no tolerance applies to this lens", path="tolerance")
    return tols


def _short(kind: str) -> str:
    return {"curvature": "CUR", "radius": "RAD", "fringes": "FRN", "thickness": "THI", "airspace": "AIR",
            "index": "IND", "abbe": "ABB", "decenter_x": "DCX", "decenter_y": "DCY", "tilt_x": "TLX",
            "tilt_y": "TLY", "element_decenter_x": "EDX", "element_decenter_y": "EDY", "element_tilt_x": "ETX",
            "element_tilt_y": "ETY"}.get(kind, kind)


def d_line_indices(model: Model) -> torch.Tensor:
    """(S+1,) index of every medium at the d line (587.56 nm)."""
    wl = torch.tensor([D_LINE_UM], dtype=model.lens.dtype)
    return torch.stack([m.index(wl)[0] for m in model.media]).to(model.lens.dtype)


def semi_apertures(model: Model) -> torch.Tensor:
    """(S,) semi-aperture per surface: the spec's semi_diameter, else the largest height of the nominal
    rays (full pupil edge, every field and wavelength)."""
    lens, system = model.lens, model.system
    pupil = PupilSampling.parse("rings:4:nojitter").points(dtype=lens.dtype)
    b = trace_bundle(lens, system, pupil, half_pupil=True, record=True, aim="none")
    out = []
    for s, hit in enumerate(b.result.hits):
        r = torch.linalg.vector_norm(hit.pos[..., :2], dim=-1)
        traced = float(torch.where(b.result.valid, r, 0.0).max())
        given = float(lens.semi_diameter[s])
        out.append(given if given > 0 else max(traced, 1e-6))
    return torch.tensor(out, dtype=lens.dtype)


def lm_variables(model: Model) -> tuple[tuple[str, int], ...]:
    """LM compensators from the spec's ``vary`` lists: radius → curvature, thickness (not the last gap,
    the closed-form back focus); other variable kinds are not compensators."""
    out: list[tuple[str, int]] = []
    last = len(model.spec.surfaces) - 1
    for s, surf in enumerate(model.spec.surfaces):
        if "radius" in surf.vary:
            out.append(("curvature", s))
        if "thickness" in surf.vary and s != last:
            out.append(("thickness", s))
    return tuple(out)


def make_job(model: Model, settings: Any, tols: list[Tolerance] | None = None) -> Job:
    """The ``Job`` of a lens and its tolerance settings (``ToleranceSpec``-like)."""
    tols = tolerances_for(model, settings) if tols is None else tols
    lens = model.lens
    placed = lens.placement is not None or any(t.kind not in ("curvature", "radius", "fringes", "thickness",
                                                              "index", "abbe") for t in tols)
    for t in tols:
        if t.kind not in KINDS:
            raise LensoptError(f"unknown kind; one of {', '.join(KINDS)}", path="tolerance.items.kind", got=t.kind)
    placement = nominal_params(lens)[1] if placed else None
    sampling = PupilSampling.parse(settings.sampling, seed=settings.seed, path="tolerance.sampling")
    pupil = sampling.points(dtype=lens.dtype)
    lm_vars = lm_variables(model) if settings.compensator == "lm" else ()
    if settings.compensator == "lm" and not lm_vars:
        raise LensoptError("compensator = \"lm\" needs spec variables (vary = [\"radius\"] or [\"thickness\"] "
                           "on some surface other than the last)", path="tolerance.compensator", got="lm")
    setup = EvalSetup(lens, model.system, placement, pupil, sampling.half,
                      compensate=settings.compensator, focus_range=settings.focus_range,
                      mtf_frequency=settings.mtf_frequency, lm_vars=lm_vars,
                      lm_steps=getattr(settings, "lm_steps", 5))
    return Job(setup, tuple(tols), d_line_indices(model), semi_apertures(model), settings.metric, settings.chunk)


def trial_spec(model: Model, params: TrialParams, focus_shift: float, *, name: str,
               lm_vars: tuple[tuple[str, int], ...] = (), lm_offsets: Any = None) -> Any:
    """One trial (``params`` with K = 1) as a lens spec, the compensators applied (the back focus in the
    last thickness, LM offsets ``lm_offsets`` (V,) on ``lm_vars``)."""
    spec = model.spec
    lens = model.lens
    if lm_vars and lm_offsets is not None:
        curv, thick = params.curvature.clone(), params.thickness.clone()
        for v, (kind, s) in enumerate(lm_vars):
            target = curv if kind == "curvature" else thick
            target[0, s] = target[0, s] + float(lm_offsets[v])
        params = dataclasses.replace(params, curvature=curv, thickness=thick)
    data = spec.model_dump(exclude_none=True)
    data["name"] = name
    data.pop("tolerance", None)
    data.pop("optimize", None)
    wavelengths = list(spec.spectrum.wavelengths_nm)
    order = sorted(range(len(wavelengths)), key=lambda i: wavelengths[i])
    curv = params.curvature[0]
    thick = params.thickness[0].clone()
    thick[-1] = thick[-1] + focus_shift
    thick[-1] = thick[-1] - spec.image.defocus  # build() adds the defocus back
    for s, surf in enumerate(data["surfaces"]):
        base = surf["base"] if surf["type"] == "diffractive" else surf
        if base["type"] != "plane" and float(lens.curvature[s]) != 0.0:
            c = float(curv[s])
            base["radius"] = math.inf if c == 0 else 1.0 / c
        surf["thickness"] = float(thick[s])
        index = params.index[0, s + 1]
        if not torch.equal(index, lens.index[s + 1]):
            surf["material"] = {"name": f"{_material_name(spec.surfaces[s].material)} (trial)",
                                "wavelengths_nm": [wavelengths[i] for i in order],
                                "index": [float(index[i]) for i in order]}
        dec, tilt = params.decenter[0, s], params.tilt[0, s]
        if bool((dec != 0).any()) or bool((tilt != 0).any()):
            surf["decenter"] = [float(dec[0]), float(dec[1])]
            surf["tilt_deg"] = [math.degrees(float(tilt[0])), math.degrees(float(tilt[1]))]
    base_groups = list(lens.placement.groups) if lens.placement is not None else []
    elements = list(data.get("elements", []))
    for g, e in enumerate(elements_of(lens)):
        j = len(base_groups) + g
        if j < params.group_decenter.shape[1]:
            gd, gt = params.group_decenter[0, j], params.group_tilt[0, j]
            if bool((gd != 0).any()) or bool((gt != 0).any()):
                elements.append({"surfaces": list(e), "decenter": [float(gd[0]), float(gd[1])],
                                 "tilt_deg": [float(gt[0]) / ARCMIN / 60.0, float(gt[1]) / ARCMIN / 60.0]})
    if elements:
        data["elements"] = elements
    return dataclasses.replace(model, spec=type(spec).model_validate(data)).spec


def _material_name(material: Any) -> str:
    return material if isinstance(material, str) else (getattr(material, "name", None) or "glass")
