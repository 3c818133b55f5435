"""Plain-data reports of a traced lens (what ``lensopt trace --json`` and ``lensopt ray`` print).

Units in reports: mm for lengths, µm for spot radii, nm for wavelengths, degrees for angles.
"""

from __future__ import annotations

import math
from typing import Any

import torch

from lensopt.analysis.spot import spot_stats
from lensopt.optics.aiming import aim_chief
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import PupilSampling, launch, pupil_grid
from lensopt.optics.trace import REASONS, Rays, Status, trace
from lensopt.spec.build import Model, build
from lensopt.spec.models import DiffractiveSurface

__all__ = ["trace_report", "ray_report", "auto_semi_diameters"]


def trace_report(model: Model, sampling: PupilSampling, *, aim: str | None = None) -> dict[str, Any]:
    """First-order data, per-field spot sizes and failures, and the resolved prescription."""
    lens, system = model.lens, model.system
    with torch.no_grad():
        fo = first_order(lens, system)
        bundle = trace_bundle(lens, system, sampling.points(dtype=lens.dtype), half_pupil=sampling.half,
                              aim=aim, fo=fo)
        field_weights = (torch.tensor(system.field_weights, dtype=lens.dtype, device=lens.device)
                         if system.field_weights else None)
        stats = spot_stats(bundle, system.wavelength_weights, field_weights)
        chief = trace_bundle(lens, system, torch.zeros(1, 2, dtype=lens.dtype), aim=aim, fo=fo)
        sd = auto_semi_diameters(model, aim=aim)
    ref = system.reference
    fields = []
    for h in range(len(system.rel_field)):
        status = bundle.result.status[h]
        fields.append({
            "relative": system.rel_field[h],
            "angle_deg": math.degrees(math.atan(float(bundle.tan_field[h]))),
            "rms_spot_radius_um": [1e3 * float(v) for v in stats.rms_radius_w[h]],
            "rms_spot_radius_weighted_um": 1e3 * float(stats.rms_radius[h]),
            "centroid_y_mm": float(stats.centroid[h, 1]),
            "chief_ray_y_mm": float(chief.result.pos[h, ref, 0, 1]),
            "failed_rays": int((status != Status.OK).sum()),
            "failures": {REASONS[r]: int((status == r).sum()) for r in REASONS if (status == r).any()},
            "backtracking_rays": int(bundle.result.backtrack[h].sum()),
            "rays": int(status.numel()),
        })
    report: dict[str, Any] = {
        "name": model.spec.name,
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
        "wavelengths_nm": list(model.spec.spectrum.wavelengths_nm),
        "wavelength_weights": [float(w) for w in system.wavelength_weights],
        "reference_nm": model.spec.spectrum.wavelengths_nm[ref],
        "sampling": str(sampling),
        "aim": aim or system.aim,
        "effective_spot_radius_um": 1e3 * float(stats.effective_radius),
        "fields": fields,
        "surfaces": _surfaces(model, sd),
    }
    return report


def _surfaces(model: Model, auto_sd: list[float]) -> list[dict[str, Any]]:
    out = []
    lens = model.lens
    for i, surf in enumerate(model.spec.surfaces):
        base = surf.base if isinstance(surf, DiffractiveSurface) else surf
        c = float(lens.curvature[i])
        entry: dict[str, Any] = {
            "type": surf.type,
            "radius": math.inf if c == 0 else 1.0 / c,
            "thickness": float(lens.thickness[i]),
            "conic": float(lens.conic[i]),
            "asphere": {str(p): v for p, v in getattr(base, "coefficients", {}).items()},
            "material": model.media[i + 1].name,
            "index": [float(v) for v in lens.index[i + 1]],
            "semi_diameter": surf.semi_diameter if surf.semi_diameter is not None else auto_sd[i],
            "stop": i == lens.stop,
        }
        if isinstance(surf, DiffractiveSurface):
            entry["base"] = base.type
            entry["diffractive"] = {**{str(p): v for p, v in surf.phase.items()},
                                    "design_wavelength_nm": surf.design_wavelength_nm, "order": surf.order}
        out.append(entry)
    return out


def auto_semi_diameters(model: Model, *, aim: str | None = None, n: int = 21) -> list[float]:
    """Clear semi-apertures from traced rays: the largest ray height on each surface over all fields
    and wavelengths (``grid:n`` pupil plus its rim), as optical design programs do when none is given."""
    lens, system = model.lens, model.system
    theta = torch.linspace(0, 2 * math.pi, 65, dtype=lens.dtype)[:-1]
    rim = torch.stack([torch.cos(theta), torch.sin(theta)], -1)
    pupil = torch.cat([pupil_grid(n, dtype=lens.dtype), rim])
    with torch.no_grad():
        bundle = trace_bundle(lens, system, pupil, aim=aim, record=True)
    out = []
    for hit in bundle.result.hits:
        h = torch.linalg.vector_norm(hit.pos[..., :2], dim=-1)
        h = torch.where(bundle.result.valid, h, torch.zeros_like(h))
        out.append(float(h.max()))
    return out


def ray_report(
    model: Model, *, field_deg: float, px: float, py: float, wavelength_nm: float, aim: str = "none"
) -> dict[str, Any]:
    """One real ray, surface by surface (like CODE V's RSI): position, direction cosines, angles.

    The ray is launched like the rays of ``trace_bundle``: relative pupil coordinates on the system's
    paraxial entrance pupil (reference wavelength), whatever ``wavelength_nm`` is.
    """
    spec = model.spec.model_copy(deep=True)
    spec.spectrum = spec.spectrum.model_copy(update={
        "wavelengths_nm": [wavelength_nm], "weights": None, "reference_nm": None, "rgb_weights": None})
    single = build(spec, dtype=model.lens.dtype)
    lens, system = single.lens, single.system
    tan = torch.tensor([math.tan(math.radians(field_deg))], dtype=lens.dtype)
    with torch.no_grad():
        # The entrance pupil (position, diameter) is the system's, at its reference wavelength, for
        # every wavelength, exactly as in ``trace_bundle``; not the paraxial pupil of the ray's own one.
        fo = first_order(model.lens, model.system)
        pupil = torch.tensor([[[[px, py]]]], dtype=lens.dtype)
        offset = 0.0
        if aim == "chief":
            chief = aim_chief(lens, system, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
            offset = float(chief.offset[0, 0])
        pupil = pupil + torch.tensor([0.0, offset], dtype=lens.dtype)
        rays: Rays = launch(lens, system, pupil, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
        result = trace(lens, rays, record=True)
    surfaces = []
    for i, hit in enumerate(result.hits):
        p, d = hit.pos.reshape(3), hit.dir_out.reshape(3)
        aoi = math.degrees(math.acos(min(1.0, math.sqrt(max(0.0, float(hit.cos2_in.reshape(()).item()))))))
        c2o = float(hit.cos2_out.reshape(()).item())
        aor = math.degrees(math.acos(min(1.0, math.sqrt(c2o)))) if c2o >= 0 else None
        surfaces.append({"surface": i + 1, "x": float(p[0]), "y": float(p[1]), "z": float(p[2]),
                         "L": float(d[0]), "M": float(d[1]), "N": float(d[2]),
                         "aoi_deg": aoi, "aor_deg": aor})
    img = result.pos.reshape(3)
    d = result.dir.reshape(3)
    status = int(result.status.reshape(()).item())
    return {
        "field_deg": field_deg, "pupil": [px, py + offset], "wavelength_nm": wavelength_nm, "aim": aim,
        "start": [float(v) for v in rays.pos.reshape(3)],
        "surfaces": surfaces,
        "image": {"x": float(img[0]), "y": float(img[1]), "z": float(img[2]),
                  "L": float(d[0]), "M": float(d[1]), "N": float(d[2])},
        "status": "ok" if status == 0 else REASONS[Status(status)],
        "backtracking": bool(result.backtrack.reshape(()).item()),
    }
