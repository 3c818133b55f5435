"""Plain-data reports of a traced lens (what ``lensopt trace --json`` (with ``--mtf``) and ``lensopt ray`` print).

Units in reports: mm for lengths, µm for spot radii, nm for wavelengths, degrees for angles.
The functions take any ``LensModel`` (a name, the traced lens and system, the media): ``lensopt.spec``'s
``Model`` is one; no spec (pydantic) is read here.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Protocol

import torch

from lensopt.analysis.field import field_summary
from lensopt.analysis.spot import seed_spot_stats, spot_stats
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.materials import Material
from lensopt.optics.bundle import pupil_shape, trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import PupilSampling, launch, pupil_grid
from lensopt.optics.trace import REASONS, Rays, Status, trace
from lensopt.optics.vignetting import apply_vignetting, outside_front_aperture

__all__ = ["LensModel", "trace_report", "seed_esr_um", "ray_report", "mtf_report", "auto_semi_diameters",
           "prescription"]


class LensModel(Protocol):
    """What the reports read: ``lensopt.spec.Model`` satisfies it."""

    @property
    def name(self) -> str: ...
    @property
    def lens(self) -> Lens: ...
    @property
    def system(self) -> System: ...
    @property
    def media(self) -> tuple[Material, ...]: ...


def _nm(wavelength_um: float) -> float:
    """µm → nm, rounded so that the spec's 550.0 comes back as 550.0 (not 550.0000000000001)."""
    return round(wavelength_um * 1e3, 9)


def trace_report(
    model: LensModel, sampling: PupilSampling, *, aim: str | None = None, aim_steps: int | None = None,
    engine: Engine | None = None
) -> dict[str, Any]:
    """First-order data, per-field spot sizes, failures, distortion, relative illumination, pupil
    (vignetting, aiming) data, notes, and the resolved prescription."""
    lens, system = model.lens, model.system
    if aim_steps is not None:
        system = dataclasses.replace(system, aim_steps=aim_steps)
    mode = aim or system.aim
    with torch.no_grad():
        fo = first_order(lens, system)
        summary = field_summary(lens, system, sampling, aim=mode, engine=engine)
        bundle = summary.bundle
        field_weights = (torch.tensor(system.field_weights, dtype=lens.dtype, device=lens.device)
                         if system.field_weights else None)
        stats = spot_stats(bundle, system.wavelength_weights, field_weights)
        # The chief ray is the reference ray through the stop centre (aimed) or the paraxial pupil
        # centre (not aimed), whatever vignetting does to the bundle around it.
        bare = dataclasses.replace(system, vignetting=(), front_aperture=None)
        chief = trace_bundle(lens, bare, torch.zeros(1, 2, dtype=lens.dtype), aim="chief" if mode == "full" else mode,
                             fo=fo, engine=engine)
        sd = auto_semi_diameters(dataclasses.replace(model, system=system), aim=mode, engine=engine)
    ref = system.reference
    fields = []
    for h in range(len(system.rel_field)):
        status = bundle.result.status[h]
        lit = bool((status == Status.OK).any())
        dark = bool((status == Status.BLOCKED).all())
        v = summary.vignetting[h, ref]
        pupil: dict[str, Any] = {"inferior": float(v[0]), "superior": float(v[1]), "lateral": float(v[2])}
        if summary.aim_residual_mm is not None and summary.aim_converged is not None:
            res = summary.aim_residual_mm[h].abs().amax(0)
            pupil["aim_residual_mm"] = {k: float(res[i]) for i, k in enumerate(("inferior", "superior", "lateral",
                                                                                "chief"))}
            pupil["aim_converged"] = bool(summary.aim_converged[h].all())
            pupil["aim_rays_traced"] = bool(summary.aim_traced[h].all()) if summary.aim_traced is not None else False
        # Failed quantities are None (null in JSON, "—" in tables), never 0: a wavelength (or field) where
        # no ray reaches the image has no spot to measure; the reason is in "failures" and the notes.
        lit_w = (status == Status.OK).flatten(1).any(-1).tolist()
        chief_ok = bool(chief.result.status[h, ref, 0] == Status.OK)
        fields.append({
            "relative": system.rel_field[h],
            "angle_deg": math.degrees(math.atan(float(bundle.tan_field[h]))),
            "rms_spot_radius_um": [_finite(1e3 * float(v)) if lit_w[w] else None
                                   for w, v in enumerate(stats.rms_radius_w[h])],
            "rms_spot_radius_weighted_um": _finite(1e3 * float(stats.rms_radius[h])) if lit else None,
            "centroid_y_mm": _finite(float(stats.centroid[h, 1])) if lit else None,
            "chief_ray_y_mm": _finite(float(chief.result.pos[h, ref, 0, 1])) if chief_ok else None,
            "failed_rays": int((status != Status.OK).sum()),
            "failures": {REASONS[r]: int((status == r).sum()) for r in REASONS if (status == r).any()},
            "backtracking_rays": int(bundle.result.backtrack[h].sum()),
            "rays": int(status.numel()),
            # None where no ray reached the image (nothing to measure); the illumination is 0 where the
            # front aperture blocks the whole beam (nothing gets through).
            "distortion_percent": 100.0 * float(summary.distortion[h]) if lit else None,
            "paraxial_image_height_mm": float(summary.paraxial_height_mm[h]),
            "relative_illumination": {"three_ray": _finite(float(summary.ri_three_ray[h])) if lit or dark else None,
                                      "std": _finite(float(summary.ri_std[h])) if lit or dark else None},
            "vignetting": pupil,
        })
    report: dict[str, Any] = {
        "name": model.name,
        "first_order": {
            "efl": float(fo.efl),
            "bfl": float(fo.bfl),
            "ffl": float(fo.ffl),
            "epd": float(fo.epd),
            "entrance_pupil_z": float(fo.entrance_pupil_z),
            "exit_pupil_z": float(fo.exit_pupil_z),
            "exit_pupil_diameter": float(fo.exit_pupil_diameter),
            "fnumber": float(fo.fnumber),
            "working_fnumber": float(fo.working_fnumber),
            "paraxial_image_height": float(fo.paraxial_image_height),
            "total_track": float(fo.total_track),
        },
        "wavelengths_nm": [_nm(float(w)) for w in lens.wavelength_um],
        "wavelength_weights": [float(w) for w in system.wavelength_weights],
        "reference_nm": _nm(float(lens.wavelength_um[ref])),
        "sampling": str(sampling),
        "aim": mode,
        "aim_steps": system.aim_steps,
        "front_aperture": (dataclasses.asdict(system.front_aperture) if system.front_aperture is not None
                           else None),
        "stop_radius_mm": summary.stop_radius_mm,
        "effective_spot_radius_um": (_finite(1e3 * float(stats.effective_radius))
                                     if all(f["rms_spot_radius_weighted_um"] is not None for f in fields) else None),
        "fields": fields,
        "notes": list(summary.notes),
        "surfaces": prescription(model, sd),
    }
    return report


def seed_esr_um(model: LensModel, *, engine: Engine | None = None) -> float | None:
    """ESR in µm on the seed's measure (``analysis.spot.seed_esr``: 11 equally spaced fields, equal weights,
    grid:61 pupil), reported beside the spec's own; None (null in JSON, "—" in tables) where a field has no
    ray that reaches the image, as ``trace_report``'s ESR."""
    with torch.no_grad():
        stats = seed_spot_stats(model.lens, model.system, engine=engine)
    if not bool((stats.num_valid.sum(-1) > 0).all()):
        return None
    return _finite(1e3 * float(stats.effective_radius))


def _finite(v: float) -> float | None:
    return v if math.isfinite(v) else None


def _table(row: torch.Tensor, first_power: int) -> dict[str, float]:
    return {str(first_power + 2 * j): float(v) for j, v in enumerate(row.tolist()) if v != 0.0}


def prescription(model: LensModel, auto_sd: list[float]) -> list[dict[str, Any]]:
    """The resolved surfaces, read from the traced lens (``auto_sd``: semi-diameters where none is given)."""
    out = []
    lens = model.lens
    for i, shape in enumerate(lens.shapes):
        c = float(lens.curvature[i])
        given = float(lens.semi_diameter[i])
        entry: dict[str, Any] = {
            "type": "diffractive" if shape.diffractive else shape.kind,
            "radius": math.inf if c == 0 else 1.0 / c,
            "thickness": float(lens.thickness[i]),
            "conic": float(lens.conic[i]),
            "asphere": _table(lens.asphere[i], 4) if lens.asphere.shape[-1] else {},
            "material": model.media[i + 1].name,
            "index": [float(v) for v in lens.index[i + 1]],
            "semi_diameter": given if given > 0 else auto_sd[i],
            "stop": i == lens.stop,
        }
        if shape.diffractive:
            entry["base"] = shape.kind
            entry["diffractive"] = {**(_table(lens.phase[i], 2) if lens.phase.shape[-1] else {}),
                                    "design_wavelength_nm": _nm(shape.design_wavelength_um or 0.0),
                                    "order": shape.order}
        out.append(entry)
    return out


def auto_semi_diameters(model: LensModel, *, aim: str | None = None, n: int = 21,
                        engine: Engine | None = None) -> list[float]:
    """Clear semi-apertures from traced rays: the largest ray height on each surface over all fields
    and wavelengths (``grid:n`` pupil plus its rim), as optical design programs do when none is given."""
    lens, system = model.lens, model.system
    theta = torch.linspace(0, 2 * math.pi, 65, dtype=lens.dtype)[:-1]
    rim = torch.stack([torch.cos(theta), torch.sin(theta)], -1)
    pupil = torch.cat([pupil_grid(n, dtype=lens.dtype), rim])
    with torch.no_grad():
        bundle = trace_bundle(lens, system, pupil, aim=aim, record=True, engine=engine)
    out = []
    for hit in bundle.result.hits:
        h = torch.linalg.vector_norm(hit.pos[..., :2], dim=-1)
        h = torch.where(bundle.result.valid, h, torch.zeros_like(h))
        out.append(float(h.max()))
    return out


def ray_report(
    model: LensModel, *, field_deg: float, px: float, py: float, wavelength_nm: float, aim: str = "none"
) -> dict[str, Any]:
    """One real ray, surface by surface (like CODE V's RSI): position, direction cosines, angles.

    The ray is launched like the rays of ``trace_bundle``: relative pupil coordinates on the system's
    paraxial entrance pupil (reference wavelength), whatever ``wavelength_nm`` is.
    """
    # The same lens at one wavelength: indices of every medium at that wavelength (as the builder does,
    # with the same check of each glass's valid range).
    for i, medium in enumerate(model.media[1:]):
        medium.check_wavelengths([wavelength_nm * 1e-3], path=f"surfaces[{i}].material")
    wl = torch.tensor([wavelength_nm * 1e-3], dtype=model.lens.dtype, device=model.lens.device)
    lens = dataclasses.replace(model.lens, wavelength_um=wl, index=torch.stack([m.index(wl) for m in model.media]))
    system = dataclasses.replace(model.system, wavelength_weights=torch.ones_like(wl), reference=0)
    tan = torch.tensor([math.tan(math.radians(field_deg))], dtype=lens.dtype)
    with torch.no_grad():
        # The entrance pupil (position, diameter) is the system's, at its reference wavelength, for
        # every wavelength, exactly as in ``trace_bundle``; not the paraxial pupil of the ray's own one.
        fo = first_order(model.lens, model.system)
        pupil = torch.tensor([[[[px, py]]]], dtype=lens.dtype)
        # (px, py) are relative to the aimed pupil, cut by the front aperture if there is one.
        shape = pupil_shape(lens, system, tan, fo, aim=aim, aim_steps=system.aim_steps)
        if shape.factors is not None:
            pupil = apply_vignetting(pupil, shape.factors)
        rays: Rays = launch(lens, system, pupil, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
        result = trace(lens, rays, record=True)
        fa = system.front_aperture
        if fa is not None:
            pos, dirs = torch.broadcast_tensors(rays.pos, rays.dir)
            out = outside_front_aperture(pos, dirs, fa.distance, fa.diameter)
            result = dataclasses.replace(result, status=torch.where(
                out, torch.full_like(result.status, int(Status.BLOCKED)), result.status))
    status = int(result.status.reshape(()).item())
    # Where the ray failed, numbers past the failure are meaningless: None (null, "—"), never shown.
    failed_at = len(result.hits) + 1
    if status != 0:
        failed_at = -1 if status == int(Status.BLOCKED) or result.failed_at is None else int(result.failed_at.item())
    none3 = {k: None for k in ("x", "y", "z", "L", "M", "N")}
    surfaces = []
    for i, hit in enumerate(result.hits):
        p, d = hit.pos.reshape(3), hit.dir_out.reshape(3)
        aoi = math.degrees(math.acos(min(1.0, math.sqrt(max(0.0, float(hit.cos2_in.reshape(()).item()))))))
        c2o = float(hit.cos2_out.reshape(()).item())
        aor = math.degrees(math.acos(min(1.0, math.sqrt(c2o)))) if c2o >= 0 else None
        entry: dict[str, Any] = {"surface": i + 1, "x": float(p[0]), "y": float(p[1]), "z": float(p[2]),
                                 "L": float(d[0]), "M": float(d[1]), "N": float(d[2]), "aoi_deg": aoi, "aor_deg": aor}
        if i > failed_at or (i == failed_at and status != int(Status.TIR)):
            entry.update(none3, aoi_deg=None, aor_deg=None)
        elif i == failed_at:  # TIR: the ray reaches the surface but does not leave it
            entry.update(L=None, M=None, N=None, aor_deg=None)
        surfaces.append(entry)
    img = result.pos.reshape(3)
    d = result.dir.reshape(3)
    image = ({"x": float(img[0]), "y": float(img[1]), "z": float(img[2]), "L": float(d[0]), "M": float(d[1]),
              "N": float(d[2])} if status == 0 else dict(none3))
    return {
        "field_deg": field_deg, "pupil": [float(pupil[0, 0, 0, 0]), float(pupil[0, 0, 0, 1])],
        "wavelength_nm": wavelength_nm, "aim": aim,
        "start": [float(v) for v in rays.pos.reshape(3)],
        "surfaces": surfaces,
        "image": image,
        "status": "ok" if status == 0 else REASONS[Status(status)],
        "failed_at_surface": None if status == 0 or failed_at < 0 else failed_at + 1,
        "backtracking": bool(result.backtrack.reshape(()).item()),
    }


def mtf_report(model: LensModel, frequencies: list[float], *, method: str = "heuristic",
               sampling: str = "rings:32", engine: Engine | None = None) -> dict[str, Any]:
    """MTF per field at ``frequencies`` (cycles/mm) as plain data (``trace --json --mtf``)."""
    from lensopt.analysis.mtf import MTF_METHODS, lens_mtf  # PSF machinery: only when asked for

    if method not in MTF_METHODS:
        raise LensoptError(f"must be one of {', '.join(MTF_METHODS)}", path="--mtf-method", got=method)
    if not frequencies or any(not (f >= 0 and math.isfinite(f)) for f in frequencies):
        raise LensoptError("expected non-negative frequencies in cycles/mm, comma-separated", path="--mtf",
                           got=frequencies)
    nu = torch.tensor(frequencies, dtype=model.lens.dtype)
    r = lens_mtf(model.lens, model.system, nu, method=method, sampling=sampling, engine=engine)
    return {"method": method, "frequencies_per_mm": frequencies, "cutoff_per_mm": r.cutoff,
            "rel_field": r.rel_field.tolist(), "sagittal": r.sagittal.tolist(), "tangential": r.tangential.tolist()}
