"""Tolerancing from a built spec: the ``Job`` of a lens spec and its ``[tolerance]`` settings, the LM
compensators from the spec's variables, and trial lenses written back as specs (``lensopt.tolerance``
never imports the spec; this layer sits above both).

``trial_spec`` writes one trial as a lens spec (radii, thicknesses, decenters/tilts, elements;
perturbed media as tabulated glasses exact at the spec's wavelengths; the compensators applied: the
back focus in the last thickness, LM offsets on their variables), so the worst trials can be
inspected with every other command.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import torch

from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.optics.sampling import PupilSampling
from lensopt.spec.build import Model
from lensopt.spec.models import LensSpec
from lensopt.tolerance.job import Job
from lensopt.tolerance.model import ARCMIN, Tolerance, TrialParams, elements_of
from lensopt.tolerance.setup import make_job

__all__ = ["tolerance_job", "lm_variables", "trial_spec"]


def tolerance_job(model: Model, settings: Any, tols: list[Tolerance] | None = None, *,
                  restore: Any = None, engine: Engine | None = None) -> Job:
    """The tolerance ``Job`` of a built spec and its ``ToleranceSpec`` settings; ``restore``: the
    restoration hook of the ``psnr`` metric (``imaging.evaluate``'s, e.g. ``restore.apply.restoration_hook``)."""
    job = make_job(model.lens, model.system, model.media, settings, lm_vars=lm_variables(model), tols=tols,
                   engine=engine)
    if settings.metric != "psnr":
        if restore is not None:
            raise LensoptError("a restoration network is used by the psnr metric only", path="--irm",
                               got=settings.metric)
        return job
    if job.setup.placement is not None:
        raise LensoptError("the psnr metric images through the rotationally symmetric simulation path: "
                           "decenter/tilt tolerances and decentered lenses are not supported with it",
                           path="tolerance.metric", got="psnr")
    from lensopt.imaging.regions import tile_grid
    from lensopt.imaging.simulate import sensor_of
    from lensopt.spec.build import camera_of
    from lensopt.tolerance.evaluate import evaluate
    from lensopt.tolerance.psnr import PsnrSetup

    # Settings errors are reported here, once (a trial whose imaging fails scores −inf instead).
    PupilSampling.parse(settings.psnr_sampling, path="tolerance.psnr_sampling")
    camera = camera_of(model)
    tile_grid(sensor_of(camera, settings.psnr_patch, settings.psnr_patch)[0], settings.psnr_patch,
              option="tolerance.psnr_patch")
    with torch.no_grad():
        nominal = evaluate(job.setup, job.params(torch.zeros(1, len(job.tols), dtype=torch.float64)))
    lm_ref = tuple(float(v) for v in nominal["lm_offsets"][0]) if "lm_offsets" in nominal else None
    psnr = PsnrSetup(camera, count=settings.psnr_count, patch=settings.psnr_patch, seed=settings.seed,
                     sampling=settings.psnr_sampling, noise_sigma=settings.psnr_noise, restore=restore,
                     focus_reference=float(nominal["focus_shift"][0]), lm_reference=lm_ref,
                     lm_vars=job.setup.lm_vars, engine=engine)
    return dataclasses.replace(job, psnr=psnr)


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


def trial_spec(model: Model, params: TrialParams, focus_shift: float, *, name: str,
               lm_vars: tuple[tuple[str, int], ...] = (), lm_offsets: Any = None) -> LensSpec:
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
    return LensSpec.model_validate(data)


def _material_name(material: Any) -> str:
    return material if isinstance(material, str) else (getattr(material, "name", None) or "glass")
