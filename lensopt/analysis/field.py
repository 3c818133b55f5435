"""Per-field imaging summary: distortion (S48), relative illumination (S51, S52), the pupil each field
was launched with (vignetting factors, aiming residuals) and plain-language notes on what went wrong.

``field_summary`` is what ``lensopt trace`` reports per field and what ``lensopt plot field`` plots.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.analysis.distortion import distortion, paraxial_heights
from lensopt.analysis.illumination import (
    THREE_RAY_PUPIL,
    relative_illumination_std,
    relative_illumination_three_ray,
)
from lensopt.analysis.spot import spot_stats
from lensopt.engine import Engine
from lensopt.optics.bundle import Bundle, pupil_shape, trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import field_tangents, first_order
from lensopt.optics.sampling import PupilSampling
from lensopt.optics.trace import REASONS, Status

__all__ = ["FieldSummary", "field_summary", "field_notes", "RAY_NAMES", "AIM_NOTE_FRACTION"]

RAY_NAMES = ("inferior", "superior", "lateral", "chief")
"""The rays full aiming puts on the stop, in the order of ``PupilAim.residual_mm``."""

AIM_NOTE_FRACTION = 0.01
"""Aiming that leaves a stop miss above this fraction of the stop radius (or loses a ray) gets a note;
smaller misses are the expected result of the seed's single step and only show in the residuals."""


@dataclass(frozen=True)
class FieldSummary:
    """Imaging properties per field (tensors on the lens's dtype, detached).

    Attributes:
        rel_field: (F,) relative fields.
        angle_deg: (F,) object-space field angles, degrees.
        paraxial_height_mm: (F,) paraxial image heights y'_h.
        centroid_y_mm: (F,) weighted spot centroids ȳ_h.
        distortion: (F,) D_h (S48), a fraction.
        ri_three_ray: (F,) relative illumination, Rimmer's three-ray estimate (S51).
        ri_std: (F,) relative illumination, all-ray estimate (S52).
        vignetting: (F, W, 3) factors (V_i, V_s, V_l) the bundles were launched with (zeros: none).
        aim_residual_mm: (F, W, 4) stop misses after full aiming (inferior, superior, lateral, chief),
            or None when not aiming fully.
        aim_converged: (F, W) bool, or None.
        aim_traced: (F, W, 4) bool, which of those four rays reached the stop, or None.
        stop_radius_mm: stop radius the full aiming aimed at, or None.
        valid_fraction: (F,) fraction of the bundle's rays that reached the image.
        bundle: the full bundle the spot statistics came from.
        notes: plain-language warnings (fields blocked, aiming not converged, clipping stop ...).
    """

    rel_field: Tensor
    angle_deg: Tensor
    paraxial_height_mm: Tensor
    centroid_y_mm: Tensor
    distortion: Tensor
    ri_three_ray: Tensor
    ri_std: Tensor
    vignetting: Tensor
    aim_residual_mm: Tensor | None
    aim_converged: Tensor | None
    aim_traced: Tensor | None
    stop_radius_mm: float | None
    valid_fraction: Tensor
    bundle: Bundle
    notes: tuple[str, ...]


def field_summary(
    lens: Lens,
    system: System,
    sampling: PupilSampling,
    *,
    rel_field: Tensor | Sequence[float] | None = None,
    aim: str | None = None,
    aim_steps: int | None = None,
    engine: Engine | None = None,
) -> FieldSummary:
    """Distortion and relative illumination per field, with the pupil data behind them.

    The relative illumination is normalised on axis: when ``rel_field`` lacks 0 the axis is traced
    too and dropped from the result. Wavelength-weighted where the estimate allows (S48 centroid, S52);
    S51 uses the reference wavelength.
    """
    dtype, device = lens.dtype, lens.device
    if rel_field is None:
        rel_field = torch.tensor(system.rel_field, dtype=dtype, device=device)
    rel_field = torch.as_tensor(rel_field, dtype=dtype, device=device)
    has_axis = bool((rel_field == 0).any())
    fields = rel_field if has_axis else torch.cat([torch.zeros(1, dtype=dtype, device=device), rel_field])
    mode = system.aim if aim is None else aim
    if aim_steps is not None:
        system = dataclasses.replace(system, aim_steps=aim_steps)
    steps = system.aim_steps
    with torch.no_grad():
        fo = first_order(lens, system)
        tan = field_tangents(lens, system, fields)
        fixed = None
        if system.vignetting and len(system.vignetting) == fields.shape[0]:
            fixed = torch.tensor(system.vignetting, dtype=dtype, device=device).unsqueeze(1)
        shape = pupil_shape(lens, system, tan, fo, aim=mode, aim_steps=steps, vignetting=fixed)
        opts = {"rel_field": fields, "aim": mode, "aim_steps": steps, "fo": fo, "shape": shape}
        pts = sampling.points(dtype=dtype, device=device, engine=engine)
        bundle = trace_bundle(lens, system, pts, half_pupil=sampling.half,
                              pupil_weights=sampling.weights(dtype=dtype, device=device), **opts, engine=engine)
        stats = spot_stats(bundle, system.wavelength_weights)
        dist = distortion(lens, system, bundle, stats)
        y_par = paraxial_heights(lens, system, bundle)
        ri_std = relative_illumination_std(bundle, system.wavelength_weights)
        three = trace_bundle(lens, system, torch.tensor(THREE_RAY_PUPIL, dtype=dtype, device=device), **opts,
                             engine=engine)
        ri_three = relative_illumination_three_ray(three, system.reference)
    keep = slice(None) if has_axis else slice(1, None)
    num_w = lens.wavelength_um.shape[0]
    factors = shape.factors if shape.factors is not None else torch.zeros(fields.shape[0], num_w, 3, dtype=dtype)
    full = shape.full
    summary = FieldSummary(
        rel_field=fields[keep],
        angle_deg=torch.rad2deg(torch.atan(tan))[keep],
        paraxial_height_mm=y_par[keep],
        centroid_y_mm=stats.centroid[keep, 1],
        distortion=dist[keep],
        ri_three_ray=ri_three[keep],
        ri_std=ri_std[keep],
        vignetting=factors[keep],
        aim_residual_mm=full.residual_mm[keep] if full is not None else None,
        aim_converged=full.converged[keep] if full is not None else None,
        aim_traced=full.traced[keep] if full is not None else None,
        stop_radius_mm=float(full.stop_radius_mm) if full is not None else None,
        valid_fraction=bundle.result.valid.to(dtype).mean((1, 2))[keep],
        bundle=bundle,
        notes=(),
    )
    return dataclasses.replace(summary, notes=field_notes(lens, system, summary, bundle, keep))


def field_notes(lens: Lens, system: System, s: FieldSummary, bundle: Bundle, keep: slice) -> tuple[str, ...]:
    """Plain-language notes: fields the front aperture blocks, aiming that did not converge, rays
    clipped by a stop smaller than the beam, fields where no ray reached the image."""
    notes: list[str] = []
    status = bundle.result.status[keep]
    wl_nm = [1e3 * float(w) for w in lens.wavelength_um]
    for h in range(s.rel_field.shape[0]):
        where = f"field {float(s.angle_deg[h]):.3f}°"
        st = status[h]
        total = st.numel()
        blocked = int((st == Status.BLOCKED).sum())
        if blocked == total:
            notes.append(f"{where}: the front aperture blocks the whole beam (no ray reaches the image)")
        elif int((st == Status.OK).sum()) == 0:
            reasons = {REASONS[Status(r)]: int((st == r).sum()) for r in REASONS if (st == r).any()}
            notes.append(f"{where}: no ray reaches the image ({', '.join(f'{k}: {v}' for k, v in reasons.items())})")
        if s.aim_converged is not None and s.aim_residual_mm is not None and s.aim_traced is not None:
            limit = AIM_NOTE_FRACTION * (s.stop_radius_mm or 0.0)
            bad = [w for w in range(s.aim_converged.shape[1])
                   if not bool(s.aim_traced[h, w].all()) or float(s.aim_residual_mm[h, w].abs().max()) > limit]
            if bad:
                lost = [name for k, name in enumerate(RAY_NAMES) if not bool(s.aim_traced[h, bad, k].all())]
                res = float(s.aim_residual_mm[h, bad].abs().max())
                why = (f"the {', '.join(lost)} ray(s) do not reach the stop; the chief-aimed circle is used" if lost
                       else f"largest stop miss {res:.3g} mm, over {100 * AIM_NOTE_FRACTION:g} % of the stop radius")
                notes.append(f"{where}: full aiming not converged after {system.aim_steps} step(s) at "
                             f"{', '.join(f'{wl_nm[w]:g}' for w in bad)} nm ({why}; more --aim-steps may help)")
    if s.aim_converged is None and bundle.aim is not None:
        chief = bundle.aim
        bad = ~chief.converged[keep]
        for h in range(bad.shape[0]):
            ws = bad[h].nonzero().flatten().tolist()
            if ws:
                res = float(chief.residual_mm[keep][h, ws].abs().max())
                notes.append(f"field {float(s.angle_deg[h]):.3f}°: chief-ray aiming not converged at "
                             f"{', '.join(f'{wl_nm[w]:g}' for w in ws)} nm (stop miss {res:.3g} mm, or the chief "
                             "ray does not reach the stop)")
    stop = lens.stop
    sd = float(lens.semi_diameter[stop])
    if lens.shapes[stop].clip and sd > 0:
        axial = status[0] if float(s.rel_field[0]) == 0 else None
        if axial is not None and bool((axial == Status.CLIPPED).any()):
            frac = float((axial == Status.CLIPPED).to(torch.float64).mean())
            notes.append(f"the stop (surface {stop + 1}, semi-diameter {sd:g} mm, clip) is smaller than the "
                         f"axial beam: {100 * frac:.1f} % of the axial rays are clipped, the EPD is not reached")
    return tuple(notes)


