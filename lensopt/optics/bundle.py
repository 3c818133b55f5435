"""Trace a lens as a system: first-order data, field angles, pupil shaping (aiming, vignetting, front
aperture), real rays.

This is the entry point analysis and plots use: it ties ``paraxial`` (entrance pupil, EPD, field
slopes), ``aiming``, ``vignetting`` and ``sampling.launch`` to ``trace``.

The launched pupil of each field and wavelength is an ellipse in relative entrance-pupil coordinates
(S19–S20), built in three layers: the aimed pupil (``none``: the paraxial unit disc; ``chief``: the
disc shifted so that the chief ray meets the stop centre; ``full``: the ellipse whose marginal rays
meet the stop edge, S21–S22), then fixed factors taken relative to it (``system.vignetting``, as CODE V
applies VUY/VLY/VUX with ray aiming), then the front aperture's cut (S1.3.2, S4.1.5). With ``full``
behind a front aperture the cut comes first (S1.3.2, last paragraph): ``aim_full`` aims only rays
through the opening, holding a marginal ray the aperture cuts on its edge. Rays that fall outside the
front aperture anyway are marked ``Status.BLOCKED``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.engine import BYTES_PER_RAY_SURFACE, Engine
from lensopt.optics.aiming import ChiefAim, PupilAim, aim_chief, aim_full
from lensopt.optics.intersect import NEWTON_ITERATIONS
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import FirstOrder, field_tangents, first_order
from lensopt.optics.sampling import launch
from lensopt.optics.trace import Rays, RayTrace, Status, trace
from lensopt.optics.vignetting import (
    apply_vignetting,
    clip_ellipse_to_disc,
    compose_factors,
    ellipse_to_factors,
    factors_to_ellipse,
    front_aperture_disc,
    outside_front_aperture,
)

__all__ = ["Bundle", "Launch", "PupilShape", "pupil_shape", "trace_bundle", "launch_bundle", "finish_bundle",
           "trace_rays", "AIM_MODES"]

AIM_MODES = ("none", "chief", "full")


@dataclass(frozen=True)
class PupilShape:
    """How the unit pupil is mapped for each field and wavelength.

    Attributes:
        factors: (F, W, 3) effective factors (V_i, V_s, V_l) relative to the paraxial entrance pupil,
            or None when the pupil is the plain unit disc (no aiming, no vignetting).
        chief: chief-ray aiming (modes ``chief`` and ``full``), else None.
        full: full aiming (mode ``full``), else None.
        blocked: (F, W) bool where the front aperture blocks the whole bundle, or None.
    """

    factors: Tensor | None
    chief: ChiefAim | None
    full: PupilAim | None
    blocked: Tensor | None


def pupil_shape(
    lens: Lens,
    system: System,
    tan_field: Tensor,
    fo: FirstOrder,
    *,
    aim: str,
    aim_steps: int = 1,
    vignetting: Tensor | None = None,
    tan_field_x: Tensor | None = None,
    solved: PupilShape | None = None,
) -> PupilShape:
    """Aim, apply fixed factors ``vignetting`` ((F, W|1, 3) or None), cut by the front aperture.
    ``tan_field_x``: x slopes of two-dimensional fields (chief aiming only). ``solved``: the shape of an
    earlier call on the same lens values, whose detached aiming solves are reused (``ChiefSolve``,
    ``FullSolve``: the same numbers, without the iterations)."""
    if aim not in AIM_MODES:
        raise ValueError(f"aim must be one of {AIM_MODES}, got {aim!r}")
    num_f, num_w = tan_field.shape[0], lens.wavelength_um.shape[0]
    opts = {"epd": fo.epd, "entrance_pupil_z": fo.entrance_pupil_z}
    chief = full = blocked = None
    factors: Tensor | None = None
    if aim in ("chief", "full"):
        chief = aim_chief(lens, system, tan_field, tan_field_x=tan_field_x, **opts,
                          solved=None if solved is None or solved.chief is None else solved.chief.solve)
        zero = torch.zeros_like(chief.offset)
        factors = ellipse_to_factors(chief.offset, 1.0 + zero, 1.0 + zero)
    fa = system.front_aperture
    if fa is not None:
        centre, radius = front_aperture_disc(fa.distance, fa.diameter, tan_field,
                                             object_distance=system.object_distance, **opts)
    if aim == "full":
        # Behind a front aperture the vignetting comes first: only rays through the opening are aimed.
        opening = None if fa is None else (centre[:, None], radius)
        full = aim_full(lens, system, tan_field, steps=aim_steps, chief=chief, aperture=opening, **opts,
                        solved=None if solved is None or solved.full is None else solved.full.solve,
                        paraxial_stop_mm=fo.stop_semi_diameter)
        factors = full.factors
    if vignetting is not None:
        vignetting = vignetting.to(lens.dtype).expand(num_f, num_w, 3)
        factors = vignetting if factors is None else compose_factors(factors, vignetting)
    if fa is not None:
        if factors is None:
            factors = torch.zeros(num_f, num_w, 3, dtype=lens.dtype, device=lens.device)
        ellipse, blocked = clip_ellipse_to_disc(factors_to_ellipse(factors), centre[:, None], radius,
                                                lateral=fa.lateral)
        factors = ellipse_to_factors(*ellipse)
    return PupilShape(factors, chief, full, blocked)


@dataclass(frozen=True)
class Bundle:
    """Rays of every field × wavelength × pupil sample and what became of them.

    Attributes:
        first_order: paraxial data used to place the rays.
        rel_field: (F,) relative fields.
        tan_field: (F,) object-space chief-ray slopes.
        pupil: (F, W, P, 2) relative pupil coordinates actually launched (after aiming).
        rays: the object-space rays, batch (F, W, P).
        result: the trace.
        aim: chief-ray aiming result, or None.
        half_pupil: True when only x ≥ 0 was sampled (x̄ = 0 by symmetry).
        vignetting: (F, W, 3) effective factors (V_i, V_s, V_l) the pupil was launched with, relative
            to the paraxial entrance pupil, or None for the plain unit disc.
        pupil_aim: full-aiming result (mode ``full``), or None.
        shape: the pupil shape the rays were launched with (``pupil_shape``), or None.
        pupil_weights: (P,) pupil-area weight of each sample (a quadrature such as ``gauss:N``), read by
            the spot statistics and the relative illumination; None: equal weights.
    """

    first_order: FirstOrder
    rel_field: Tensor
    tan_field: Tensor
    pupil: Tensor
    rays: Rays
    result: RayTrace
    aim: ChiefAim | None
    half_pupil: bool
    vignetting: Tensor | None = None
    pupil_aim: PupilAim | None = None
    shape: PupilShape | None = None
    pupil_weights: Tensor | None = None


def trace_bundle(
    lens: Lens,
    system: System,
    pupil: Tensor,
    *,
    half_pupil: bool = False,
    rel_field: Tensor | None = None,
    aim: str | None = None,
    record: bool = False,
    fo: FirstOrder | None = None,
    vignetting: Tensor | None = None,
    aim_steps: int | None = None,
    shape: PupilShape | None = None,
    rel_field_x: Tensor | None = None,
    engine: Engine | None = None,
    solved: PupilShape | None = None,
    pupil_weights: Tensor | None = None,
) -> Bundle:
    """Trace pupil points ``pupil`` ((P, 2) or (F, W, P, 2)) for every field and wavelength.

    Args:
        rel_field: (F,) relative fields; default: the system's.
        aim: ``none``, ``chief`` or ``full``; default: the system's.
        record: keep per-surface hits (for constraints and layout plots).
        fo: precomputed first-order data (saves a paraxial trace).
        vignetting: (F, W or 1, 3) fixed factors (V_i, V_s, V_l) (S19–S20), relative to the aimed
            pupil; default: the system's fixed factors when they match the fields, else none. The
            front aperture (``system.front_aperture``) cuts the pupil after them.
        aim_steps: Newton steps of ``full`` aiming; default: the system's.
        shape: the pupil shape already computed by ``pupil_shape`` for these fields (saves aiming
            again when several bundles share fields); ``aim``/``vignetting`` are then not used.
        rel_field_x: (F,) relative fields in x (two-dimensional fields, for lenses that are not
            rotationally symmetric), scaled like ``rel_field``; needs ``aim`` ``none`` or ``chief``.
        engine: the trace backend (``accel.dispatch``) and memory budget; default ``Engine()`` (eager).
        solved: the pupil shape of an earlier bundle on the same lens values and fields
            (``Bundle.shape``), whose detached aiming solves are reused (``pupil_shape``).
        pupil_weights: (P,) pupil-area weights of the samples (``PupilSampling.weights``); None: equal.
            Aiming, vignetting factors and the front aperture map the pupil affinely, which scales
            every weight alike, so the weights hold for the launched pupil too.

    A lens with a placement (decentered or tilted surfaces) has no mirror symmetry: a half-pupil
    sampling is mirrored to the full pupil here and ``half_pupil`` becomes False, so centroids are
    computed in x and y.
    """
    start = launch_bundle(lens, system, pupil, half_pupil=half_pupil, rel_field=rel_field, aim=aim, fo=fo,
                          vignetting=vignetting, aim_steps=aim_steps, shape=shape, rel_field_x=rel_field_x,
                          solved=solved, pupil_weights=pupil_weights, engine=engine)
    return finish_bundle(system, start, trace_rays(lens, start.rays, record=record, engine=engine))


def trace_rays(lens: Lens, rays: Rays, *, engine: Engine | None = None, upto: int | None = None,
               record: bool = False, newton_iterations: int = NEWTON_ITERATIONS) -> RayTrace:
    """``trace(lens, rays, ...)`` on the engine's backend: its ``tracer`` (``accel.dispatch.trace_with``)
    when it has one, else the eager trace."""
    if engine is not None and engine.tracer is not None:
        return engine.tracer(lens, rays, engine=engine, upto=upto, record=record, newton_iterations=newton_iterations)
    return trace(lens, rays, upto=upto, record=record, newton_iterations=newton_iterations)


@dataclass(frozen=True)
class Launch:
    """A bundle before its trace: the rays ``trace_bundle`` launches and how they were placed.

    Attributes: those of ``Bundle`` of the same names (``rays`` batch (F, W, P)); ``shape`` the pupil
    shape (aiming, vignetting, front aperture) the rays were launched with.
    """

    first_order: FirstOrder
    rel_field: Tensor
    tan_field: Tensor
    pupil: Tensor
    rays: Rays
    shape: PupilShape
    half_pupil: bool
    pupil_weights: Tensor | None = None


def launch_bundle(
    lens: Lens,
    system: System,
    pupil: Tensor,
    *,
    half_pupil: bool = False,
    rel_field: Tensor | None = None,
    aim: str | None = None,
    fo: FirstOrder | None = None,
    vignetting: Tensor | None = None,
    aim_steps: int | None = None,
    shape: PupilShape | None = None,
    rel_field_x: Tensor | None = None,
    solved: PupilShape | None = None,
    pupil_weights: Tensor | None = None,
    engine: Engine | None = None,
) -> Launch:
    """The first half of ``trace_bundle`` (same arguments): first-order data, pupil shape, launched rays;
    refused (``LensoptError``) when the bundle would not fit the engine's memory budget."""
    fo = first_order(lens, system) if fo is None else fo
    if rel_field is None:
        rel_field = torch.tensor(system.rel_field, dtype=lens.dtype, device=lens.device)
    tan = field_tangents(lens, system, rel_field)
    mode = system.aim if aim is None else aim
    tan_x = None
    if rel_field_x is not None:
        if mode == "full":
            raise ValueError("two-dimensional fields (rel_field_x) are traced with aim = none or chief")
        tan_x = field_tangents(lens, system, rel_field_x.to(lens.dtype))
    pupil = pupil.to(dtype=lens.dtype, device=lens.device)
    if pupil_weights is not None:
        pupil_weights = pupil_weights.to(dtype=lens.dtype, device=lens.device)
        if pupil_weights.shape != pupil.shape[-2:-1]:
            raise ValueError(f"pupil_weights must have shape ({pupil.shape[-2]},), got {tuple(pupil_weights.shape)}")
    if lens.placement is not None and half_pupil:  # no symmetry: the mirrored half too
        pupil = torch.cat([pupil, pupil * torch.tensor([-1.0, 1.0], dtype=pupil.dtype, device=pupil.device)], -2)
        half_pupil = False
        if pupil_weights is not None:
            pupil_weights = torch.cat([pupil_weights, pupil_weights])
    if pupil.dim() == 2:
        pupil = pupil.expand(rel_field.shape[0], lens.wavelength_um.shape[0], *pupil.shape)
    rays_n = pupil.numel() // 2
    (engine or Engine()).require(rays_n * (len(lens.shapes) + 2) * BYTES_PER_RAY_SURFACE, f"tracing {rays_n:,} rays",
                                 lower="the pupil sampling (rings:N / grid:N) or the number of fields and wavelengths")
    if vignetting is None and system.vignetting and len(system.vignetting) == rel_field.shape[0]:
        vignetting = torch.tensor(system.vignetting, dtype=lens.dtype, device=lens.device).unsqueeze(1)
    if shape is None:
        shape = pupil_shape(lens, system, tan, fo, aim=mode, vignetting=vignetting,
                            aim_steps=system.aim_steps if aim_steps is None else aim_steps, tan_field_x=tan_x,
                            solved=solved)
    if shape.factors is not None:
        pupil = apply_vignetting(pupil, shape.factors)
    if shape.chief is not None and shape.chief.offset_x is not None:
        # Placed lenses and 2-D fields: the chief-aimed pupil moves in x too (``aiming``).
        shift = torch.stack([shape.chief.offset_x, torch.zeros_like(shape.chief.offset_x)], -1)
        pupil = pupil + shift[:, :, None]
    rays = launch(lens, system, pupil, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z, tan_field_x=tan_x)
    return Launch(fo, rel_field, tan, pupil, rays, shape, half_pupil, pupil_weights)


def finish_bundle(system: System, start: Launch, result: RayTrace) -> Bundle:
    """The second half of ``trace_bundle``: the trace of ``start.rays`` with the front aperture's
    blocked rays marked, as a ``Bundle``."""
    fa, rays, shape = system.front_aperture, start.rays, start.shape
    if fa is not None:
        # Rays outside the opening (a field blocked entirely, or the corners of an ``extent`` ellipse)
        # are stopped there first, whatever happens to them later.
        pos, dir = torch.broadcast_tensors(rays.pos, rays.dir)
        out = outside_front_aperture(pos, dir, fa.distance, fa.diameter)
        if shape.blocked is not None:
            out = out | shape.blocked[..., None]
        status = torch.where(out, torch.full_like(result.status, int(Status.BLOCKED)), result.status)
        result = dataclasses.replace(result, status=status)
    return Bundle(start.first_order, start.rel_field, start.tan_field, start.pupil, rays, result, shape.chief,
                  start.half_pupil, shape.factors, shape.full, shape, start.pupil_weights)
