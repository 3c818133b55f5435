"""Plain-data report of where a lens stands against its constraints (for ``lensopt optimize``'s
summary and the benchmark records): the measured quantities, not the residuals."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import torch

from lensopt.analysis.distortion import distortion
from lensopt.analysis.illumination import relative_illumination_std
from lensopt.analysis.spot import spot_stats
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.optim.problem import Problem
from lensopt.optim.rays import head, with_rim
from lensopt.optim.residuals import BIG, gap_lengths

__all__ = ["constraint_report", "TOLERANCE"]

TOLERANCE = {"mm": 5e-3, "deg": 1e-2, "percent": 2e-2, "fraction": 1e-3}
"""How far past its threshold a soft constraint may end and still count as met: soft constraints end a
hair past their thresholds, and the summary measures them on a denser sample than the optimizer used
(a centroid moves by ~0.01 % of the image height between rings:6 and rings:48). A spec that must meet
a requirement strictly asks for it with these margins."""


def _deg(cos2: torch.Tensor) -> float:
    return math.degrees(math.acos(min(1.0, math.sqrt(max(0.0, float(cos2))))))


def constraint_report(problem: Problem, theta: torch.Tensor, sampling: PupilSampling | None = None) -> dict[str, Any]:
    """Measured constraint quantities of θ (valid rays only), on the optimization rays or on
    ``sampling`` (e.g. ``gauss:16``, as ``lensopt trace`` samples; its quadrature weights weigh the spot,
    distortion and illumination, the rim rays only enter the geometric constraints).

    Returns a dict with ``gaps`` (per gap: kind, centre thickness, min/max axial ray path t_z, bounds,
    satisfied), ``max_angle_deg`` (incidence/refraction over all interfaces), ``max_normal_deg``,
    ``distortion_percent`` and ``relative_illumination`` per field, ``materials`` per element,
    ``failed_rays``, ``violated`` (the requirements not met, in words), and ``satisfied``: no failed ray
    and every enabled constraint met within
    ``TOLERANCE`` (soft constraints settle a hair past their thresholds; specs that must meet a
    requirement strictly ask for a small margin).
    """
    cons = problem.opt.constraints
    with torch.no_grad():
        lens, _ = problem.lens(theta)
        if sampling is None:
            bundle, n_spot = problem.bundle(lens), problem.num_spot
        else:
            pts = sampling.points(dtype=lens.dtype, engine=problem.engine)
            n_spot = pts.shape[0]
            bundle = trace_bundle(lens, problem.system, with_rim(pts, problem.opt.rim_rays, half=sampling.half),
                                  half_pupil=sampling.half, record=True, engine=problem.engine)
        valid = bundle.result.valid
        spot = head(bundle, n_spot)
        if sampling is not None and sampling.weights(dtype=lens.dtype) is not None:  # a quadrature (gauss:N)
            spot = dataclasses.replace(spot, pupil_weights=sampling.weights(dtype=lens.dtype))
        stats = spot_stats(spot, problem.system.wavelength_weights, problem.field_weights)
        tz = gap_lengths(bundle)
        big = torch.tensor(BIG, dtype=tz.dtype)
        out: dict[str, Any] = {"failed_rays": int((~valid).sum()), "rays": int(valid.numel()),
                               "sampling": f"{sampling or problem.sampling} + {problem.opt.rim_rays} rim rays + centre"}
        ok = out["failed_rays"] == 0
        violated = [] if ok else [f"{out['failed_rays']} rays fail"]
        if cons.ray_path is not None:
            lo, hi = problem.gap_bounds(lens)
            gaps = []
            for s in range(lens.num_surfaces):
                kind = "image" if s == lens.num_surfaces - 1 else ("glass" if problem.glass_gap[s] else "air")
                tmin = float(torch.where(valid, tz[s], big).min())
                tmax = float(torch.where(valid, tz[s], -big).max())
                good = tmin >= float(lo[s]) - TOLERANCE["mm"] and tmax <= float(hi[s]) + TOLERANCE["mm"]
                ok &= good
                if not good:
                    violated.append(f"{kind} gap {s} ray path")
                gaps.append({"gap": s, "kind": kind, "centre": float(lens.thickness[s]), "min": tmin, "max": tmax,
                             "lower": float(lo[s]), "upper": None if float(hi[s]) >= BIG else float(hi[s]),
                             "satisfied": good})
            out["gaps"] = gaps
        zero = torch.zeros((), dtype=tz.dtype)
        worst = torch.ones((), dtype=tz.dtype)
        for s in problem.interfaces:
            h = bundle.result.hits[s]
            worst = torch.minimum(worst, torch.where(valid, torch.minimum(h.cos2_in, h.cos2_out), worst).min())
        out["max_angle_deg"] = _deg(torch.maximum(worst, zero))
        if cons.ray_angle is not None:
            good = out["max_angle_deg"] <= cons.ray_angle.max_deg + TOLERANCE["deg"]
            ok &= good
            violated += [] if good else [f"ray angle {out['max_angle_deg']:.2f}° > {cons.ray_angle.max_deg:g}°"]
        normals = [s for s in problem.interfaces if not problem.surfaces[s].plane]
        nz2 = torch.ones((), dtype=tz.dtype)
        for s in normals:
            nz2 = torch.minimum(nz2, torch.where(valid, bundle.result.hits[s].normal[..., 2] ** 2, 1.0).min())
        out["max_normal_deg"] = _deg(nz2)
        if cons.surface_normal is not None:
            good = out["max_normal_deg"] <= cons.surface_normal.max_deg + TOLERANCE["deg"]
            ok &= good
            violated += [] if good else [f"surface normal {out['max_normal_deg']:.2f}° > "
                                         f"{cons.surface_normal.max_deg:g}°"]
        d = distortion(lens, problem.system, spot, stats)
        out["distortion_percent"] = [100 * float(v) for v in d]
        if cons.distortion is not None:
            worst_d = max(abs(v) for v in out["distortion_percent"])
            good = worst_d <= cons.distortion.max_percent + TOLERANCE["percent"]
            ok &= good
            violated += [] if good else [f"distortion {worst_d:.3f} % > {cons.distortion.max_percent:g} %"]
        ri = relative_illumination_std(spot, problem.system.wavelength_weights)
        out["relative_illumination"] = [float(v) for v in ri]
        if cons.relative_illumination is not None:
            good = min(out["relative_illumination"]) >= cons.relative_illumination.min - TOLERANCE["fraction"]
            ok &= good
            violated += [] if good else [f"relative illumination {min(out['relative_illumination']):.3f} < "
                                         f"{cons.relative_illumination.min:g}"]
        glass = problem.param.glass_physical(theta).tolist()
        gvars = [v.surface for v in problem.param.of_kind("glass")]
        mats = []
        for s, surf in enumerate(problem.surfaces):
            if not surf.glass_after:
                continue
            if s in gvars:
                nd, vd, dp = glass[gvars.index(s)]
                mats.append({"surface": s, "material": "model (free)", "nd": nd, "vd": vd, "dpgf": dp})
            else:
                m = problem.media[s + 1]
                mats.append({"surface": s, "material": m.label, "nd": m.nd, "vd": m.vd})
        out["materials"] = mats
        out["violated"] = violated
        out["satisfied"] = bool(ok)
    return out
