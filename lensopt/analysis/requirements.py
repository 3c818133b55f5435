"""A lens held to a table of requirements (the seed's Tables S8 and S12, S6.1's list), measured on a dense
sample of real rays, independently of the optimizer's residuals (other sampling, no soft margins).

Every requirement is checked on every ray that reaches the image, over a dense pupil (a square grid plus
the pupil rim) at densely spaced fields (0 … 1) and every wavelength, with the system's own aiming,
vignetting and front aperture:

- glass elements: axial ray path t_z in [glass_min, glass_max] and t_z / CT in [1/ratio, ratio]
  (element thickness and the edge-to-centre thickness ratio across the used diameter);
- air gaps: t_z ≥ air_min; the last gap (to the image) ≥ image_min; spans of several gaps (a mechanical
  flange distance across a filter) in [min, max]; ``exempt`` gaps (a fixed filter) are skipped;
- angles of incidence and refraction ≤ max_angle_deg at every interface; surface normals ≤
  max_normal_deg where rays hit the refracting surfaces;
- |distortion| ≤ max_distortion_percent (S48, centroid against paraxial height) and relative
  illumination ≥ min_illumination (S52, all-ray estimate) at every field;
- every glass a named entry of ``catalog`` (the Ohara recommended list, the Table S10 plastics ...);
- first-order targets (EFL, paraxial image height, total track) within ``first_order_rtol``;
- no failed ray.

``check_requirements`` returns one ``Check`` per requirement (worst value, limit, pass/fail), so a test
can assert them all and a report can list them.

Two samples (``sample=``), because the seed and lensopt probe a requirement with different rays:

- ``"seed"``, the seed's definition (S2.2.2: "rays traced for spot diagram evaluation ... we use to
  enforce constraints"; S1.3.3): the rays the optimizer traces, i.e. the system's own design fields and
  the spec's optimization pupil sampling (the seed's jittered rings, Figure S1), with the system's
  aiming and vignetting. Ray path t_z, angles and surface normals are taken at those rays' hits;
  distortion (S48) and relative illumination (S52) at those fields from those spot diagrams.
- ``"dense"`` (default), lensopt's margin: every ray of a square pupil grid plus the pupil rim at
  densely spaced fields 0 … 1 (the design fields added). It sees the meridional rim rays and the fields
  between the design fields, which the optimizer's rays do not: its ray-path, angle and normal limits
  are at least as strict in practice (distortion and the all-ray illumination estimate move by a few
  10⁻³ either way with the pupil sample). Shipped lenses are held to it.

The seed does not say how far past a threshold its soft constraints (high-weight residuals, S4.1.4)
may end; neither sample adds a tolerance.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import torch

from lensopt.analysis.field import FieldSummary, field_summary
from lensopt.engine import Engine
from lensopt.materials import design_catalog
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import FirstOrder, first_order
from lensopt.optics.sampling import PupilSampling
from lensopt.optics.trace import RayTrace, Status

__all__ = ["Requirements", "Check", "check_requirements", "failed", "table_s8", "table_s12"]


@dataclass(frozen=True)
class Requirements:
    """A table of requirements (mm, degrees, percent, fractions); None: not required.

    Attributes:
        glass_min, glass_max: bounds of the axial ray path in glass (element thickness).
        glass_ratio: the ray path over the centre thickness lies in [1/ratio, ratio].
        air_min: lower bound of the ray path in air gaps (not the last one).
        image_min: lower bound of the ray path in the last gap (image clearance).
        spans: (first surface, end surface or None for the image, min or None, max or None): ray path
            summed over the gaps first … end − 1 (e.g. a mechanical flange distance).
        exempt: gaps (0-based, the gap after that surface) left out of the per-gap checks.
        max_angle_deg: angles of incidence and refraction at every interface.
        max_normal_deg: surface normal angle to the axis where rays hit refracting surfaces.
        max_distortion_percent: |D| at every field.
        min_illumination: relative illumination (S52) at every field.
        catalog: a design catalog name (``ohara-recommended``, ``plastics`` …) or a set of glass names
            every glass element must be one of (compared without a ``vendor:`` prefix, spaces and case).
        efl, image_height, total_track: first-order targets, held within ``first_order_rtol``.
    """

    glass_min: float | None = None
    glass_max: float | None = None
    glass_ratio: float | None = None
    air_min: float | None = None
    image_min: float | None = None
    spans: tuple[tuple[int, int | None, float | None, float | None], ...] = ()
    exempt: tuple[int, ...] = ()
    max_angle_deg: float | None = None
    max_normal_deg: float | None = None
    max_distortion_percent: float | None = None
    min_illumination: float | None = None
    catalog: str | frozenset[str] | None = None
    efl: float | None = None
    image_height: float | None = None
    total_track: float | None = None
    first_order_rtol: float = 1e-3


@dataclass(frozen=True)
class Check:
    """One requirement: the worst value found on the rays, its limit, whether it holds."""

    name: str
    value: float | str
    limit: str
    ok: bool
    detail: dict = field(default_factory=dict)


def failed(checks: list[Check]) -> list[str]:
    """Names of the requirements that do not hold."""
    return [c.name for c in checks if not c.ok]


def _pupil(grid: int, rim: int, *, engine: Engine | None = None) -> torch.Tensor:
    pts = PupilSampling.parse(f"grid:{grid}").points(dtype=torch.float64, engine=engine)
    phi = torch.linspace(0, 2 * math.pi, rim + 1, dtype=torch.float64)[:-1]
    return torch.cat([pts, torch.stack([phi.cos(), phi.sin()], -1)])


def check_requirements(
    lens: Lens,
    system: System,
    req: Requirements,
    *,
    glass_gaps: list[bool],
    materials: list[str | None] = (),  # type: ignore[assignment]
    fields: int = 11,
    grid: int = 41,
    rim: int = 64,
    sample: str = "dense",
    sampling: PupilSampling | None = None,
    rel_field: Sequence[float] | None = None,
    engine: Engine | None = None,
) -> list[Check]:
    """Check ``req`` on a ray sample of the lens (see the module doc for the two samples).

    Args:
        lens, system: the built lens (``lensopt.spec.build(spec).lens/.system``).
        glass_gaps: (S,) whether the gap after each surface is glass.
        materials: the catalog name of each glass element (for ``req.catalog``), None for model glasses.
        fields: ``dense``: number of equidistant relative fields 0 … 1 (the design fields are added).
        grid, rim: ``dense``: pupil grid size and number of rim points.
        sample: ``dense`` (lensopt's margin) or ``seed`` (the optimizer's rays, the seed's definition).
        sampling: ``seed``: the optimization pupil sampling (``spec.optimize.sampling``); required there.
        rel_field: ``seed``: the fields (default: the system's design fields; the seed's code base runs its
            studies on 11 equally spaced ones, ``analysis.spot.SEED_FIELDS``).
        engine: trace backend and memory budget (default ``Engine()``).
    """
    if sample == "seed":
        if sampling is None:
            raise ValueError("sample='seed' needs the optimization pupil sampling (sampling=)")
        rel = list(system.rel_field if rel_field is None else rel_field)
        traced = system if rel_field is None else dataclasses.replace(system, rel_field=tuple(rel), field_weights=(),
                                                                      vignetting=())
        field_sampling = sampling
        pupil = sampling.points(dtype=lens.dtype, device=lens.device, engine=engine)
    elif sample == "dense":
        rel = sorted(set(torch.linspace(0, 1, fields, dtype=torch.float64).tolist()) | set(system.rel_field))
        traced = dataclasses.replace(system, rel_field=tuple(rel), field_weights=(), vignetting=())
        field_sampling = PupilSampling.parse(f"grid:{grid}")
        pupil = _pupil(grid, rim, engine=engine).to(lens.device)
    else:
        raise ValueError(f"sample must be 'dense' or 'seed', got {sample!r}")
    out: list[Check] = []
    with torch.no_grad():
        b = trace_bundle(lens, traced, pupil, record=True, engine=engine)
        res = b.result
        blocked = int((res.status == int(Status.BLOCKED)).sum())
        n_failed = int((~res.valid).sum()) - blocked
        out.append(Check("no failed rays", n_failed, "0 (rays stopped by the front aperture aside)",
                         n_failed == 0, {"blocked_by_front_aperture": blocked}))
        out += _gap_checks(lens, req, res, glass_gaps)
        out += _angle_checks(lens, req, res)
        if req.max_distortion_percent is not None or req.min_illumination is not None:
            summ = field_summary(lens, system, field_sampling, rel_field=rel, engine=engine)
            out += _field_checks(req, summ)
        out += _first_order_checks(req, first_order(lens, system))
    if req.catalog is not None:
        out.append(_catalog_check(req.catalog, materials))
    return out


def _valid_range(x: torch.Tensor, valid: torch.Tensor) -> tuple[float, float]:
    """(min, max) of ``x`` over the valid rays (NaN, NaN when none is valid)."""
    x = x[valid]
    return (float(x.min()), float(x.max())) if x.numel() else (math.nan, math.nan)


def _gap_checks(lens: Lens, req: Requirements, res: RayTrace, glass_gaps: list[bool]) -> list[Check]:
    """Axial ray paths t_z of every gap (glass, air, image) and of the spans, against ``req``."""
    out: list[Check] = []
    z = torch.stack([h.pos[..., 2] for h in res.hits] + [res.pos[..., 2]])
    tz = z[1:] - z[:-1]
    S = lens.num_surfaces
    for s in range(S):
        if s in req.exempt:
            continue
        lo, hi = _valid_range(tz[s], res.valid)
        ct = float(lens.thickness[s])
        if s == S - 1:
            if req.image_min is not None:
                out.append(Check(f"gap {s} (image) ≥ {req.image_min:g} mm", lo, f"≥ {req.image_min:g}",
                                 lo >= req.image_min))
        elif glass_gaps[s]:
            if req.glass_min is not None:
                out.append(Check(f"glass {s} thickness ≥ {req.glass_min:g} mm", lo, f"≥ {req.glass_min:g}",
                                 lo >= req.glass_min))
            if req.glass_max is not None:
                out.append(Check(f"glass {s} thickness ≤ {req.glass_max:g} mm", hi, f"≤ {req.glass_max:g}",
                                 hi <= req.glass_max))
            if req.glass_ratio is not None:
                r = req.glass_ratio
                out.append(Check(f"glass {s} edge/centre ratio in [1/{r:g}, {r:g}]",
                                 f"{lo / ct:.4f} … {hi / ct:.4f}", f"[{1 / r:.4f}, {r:g}]",
                                 lo / ct >= 1 / r and hi / ct <= r))
        elif req.air_min is not None:
            out.append(Check(f"air gap {s} ≥ {req.air_min:g} mm", lo, f"≥ {req.air_min:g}", lo >= req.air_min))
    for first, end, mn, mx in req.spans:
        a = first % S
        e = S if end is None else end % S
        lo, hi = _valid_range(tz[a:e].sum(0), res.valid)
        ok = (mn is None or lo >= mn) and (mx is None or hi <= mx)
        out.append(Check(f"span surface {a} → {'image' if end is None else e}", f"{lo:.4f} … {hi:.4f}",
                         f"[{mn}, {mx}]", ok))
    return out


def _angle_checks(lens: Lens, req: Requirements, res: RayTrace) -> list[Check]:
    """Angles of incidence/refraction and of the surface normals at every interface, against ``req``."""
    out: list[Check] = []
    valid = res.valid
    interfaces = [s for s in range(lens.num_surfaces) if lens.shapes[s].diffractive
                  or bool((lens.index[s] != lens.index[s + 1]).any())]
    if req.max_angle_deg is not None:
        c2 = torch.stack([torch.stack([res.hits[s].cos2_in, res.hits[s].cos2_out]) for s in interfaces])
        c2 = torch.where(valid, c2, torch.ones_like(c2)).clamp(0, 1)
        worst = math.degrees(math.acos(math.sqrt(float(c2.min()))))
        out.append(Check("angles of incidence/refraction", worst, f"≤ {req.max_angle_deg:g}°",
                         worst <= req.max_angle_deg))
    if req.max_normal_deg is not None:
        nz = torch.stack([res.hits[s].normal[..., 2].abs() for s in interfaces])
        nz = torch.where(valid, nz, torch.ones_like(nz)).clamp(0, 1)
        worst = math.degrees(math.acos(float(nz.min())))
        out.append(Check("surface normals", worst, f"≤ {req.max_normal_deg:g}°", worst <= req.max_normal_deg))
    return out


def _field_checks(req: Requirements, summ: FieldSummary) -> list[Check]:
    """Distortion and relative illumination over the dense fields, against ``req``."""
    out: list[Check] = []
    if req.max_distortion_percent is not None:
        d = 100 * float(summ.distortion.abs().max())
        out.append(Check("|distortion|", d, f"≤ {req.max_distortion_percent:g} %", d <= req.max_distortion_percent))
    if req.min_illumination is not None:
        ri = float(summ.ri_std.min())
        out.append(Check("relative illumination (all rays)", ri, f"≥ {req.min_illumination:g}",
                         ri >= req.min_illumination, {"three_ray_min": float(summ.ri_three_ray.min())}))
    return out


def _first_order_checks(req: Requirements, fo: FirstOrder) -> list[Check]:
    """EFL, paraxial image height and total track against their targets (relative tolerance)."""
    out: list[Check] = []
    for name, target, got in (("EFL", req.efl, fo.efl), ("paraxial image height", req.image_height,
                                                        fo.paraxial_image_height),
                              ("total track", req.total_track, fo.total_track)):
        if target is not None:
            v = float(got)
            out.append(Check(name, v, f"{target:g} ± {100 * req.first_order_rtol:g} %",
                             abs(v - target) <= req.first_order_rtol * abs(target)))
    return out


def _catalog_check(catalog: Any, materials: list[str | None]) -> Check:
    """Every glass element is an entry of ``catalog`` (a catalog name or a list of glass names)."""
    def key(name: str) -> str:  # "ohara:S-BAL3" and the catalog's "S-BAL 3" are the same glass
        return name.split(":")[-1].replace(" ", "").upper()

    allowed = {key(n) for n in (design_catalog(catalog).names if isinstance(catalog, str) else catalog)}
    names = [m for m in materials if m is not None]
    bad = [m for m in materials if m is None or key(m) not in allowed]
    return Check("catalog glasses", ", ".join(str(m) for m in names), "named catalog entries", not bad,
                 {"not_in_catalog": bad})


def table_s8(flange_from: int, filter_gap: int, total_track: float) -> Requirements:
    """The telephoto study's Table S8 (with Table S11's thresholds): elements ≥ 0.25 mm and ≤ 4 mm,
    edge/centre 1/3–3, air ≥ 0.1 mm, mechanical flange (surface ``flange_from``, the last lens surface,
    to the sensor) ≥ 5.1 mm, the IR filter gap ``filter_gap`` exempt, normals ≤ 30°, angles ≤ 60°,
    |distortion| ≤ 2 %, relative illumination ≥ 70 %, Table S10 plastics, paraxial image height 5.1 mm,
    total track ``total_track`` (TR × 25.9 mm)."""
    return Requirements(glass_min=0.25, glass_max=4.0, glass_ratio=3.0, air_min=0.1, image_min=0.1,
                        spans=((flange_from, None, 5.1, None),), exempt=(filter_gap,), max_angle_deg=60.0,
                        max_normal_deg=30.0, max_distortion_percent=2.0, min_illumination=0.7, catalog="plastics",
                        image_height=5.1, total_track=total_track)


def table_s12() -> Requirements:
    """The microscope study's Table S12 (with Table S14's thresholds): elements ≥ 1 mm and ≤ 4 mm,
    edge/centre 1/3–3, air ≥ 0.5 mm, normals ≤ 30°, angles ≤ 60°, |distortion| ≤ 2 %, recommended Ohara
    glasses, EFL 10 mm. (The working distance is the fixed last gap; the last gap is checked ≥ 0.5 mm.)"""
    return Requirements(glass_min=1.0, glass_max=4.0, glass_ratio=3.0, air_min=0.5, image_min=0.5, max_angle_deg=60.0,
                        max_normal_deg=30.0, max_distortion_percent=2.0, catalog="ohara-recommended", efl=10.0)
