"""Ray aiming (S1.3.2). Mode ``chief``: shift each (field, wavelength) bundle on the entrance pupil so
that its chief ray passes through the centre of the real aperture stop, by Newton's method on the
real ray with the derivative from forward-mode autodiff.

The shift is a relative pupil offset δ (in units of EPD/2) added to every pupil y coordinate. Newton
runs on detached values; one final step on the attached lens makes δ exactly differentiable in the
lens parameters at convergence (implicit function theorem), as for the asphere intersection. The
traces of the final steps (and of ``stop_radius``) take their values from the detached lens and their
first derivatives from the trace's explicit partials (``attached_stop_hit``): under ``jacfwd`` a few
linear operations carry the N tangents instead of the whole trace to the stop.

Decentered and tilted lenses (``lens.placement``) and two-dimensional fields: the stop centre is the
stop surface's own vertex (its frame, ``optics.placement``), hits on the stop are measured in that
frame, and ``chief`` aiming solves for a two-dimensional offset (δ_x, δ_y) by 2 × 2 Newton steps on
the placed lens. ``full`` aiming of a placed lens centres the pupil ellipse on the chief ray's x
offset and aims the meridional rays in y and the lateral (+x) ray in radius about the stop centre,
on the placed lens: exact when the y–z plane through the chief ray stays a plane of symmetry (e.g.
decenters in y, tilts about x, a decentered front stop), approximate otherwise (the −x side of the
ellipse mirrors the +x side). The stop radius r is that of the centred lens.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.optics.differential import LEAVES, stop_partials
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import first_order
from lensopt.optics.placement import surface_frames, to_local
from lensopt.optics.sampling import launch
from lensopt.optics.trace import Rays, RayTrace, lens_tensors, trace
from lensopt.transforms import all_settled, carries_derivatives, vmapped

__all__ = ["ChiefAim", "aim_chief", "PupilAim", "aim_full", "stop_radius", "stop_hit"]


@dataclass(frozen=True)
class ChiefAim:
    """Result of chief-ray aiming.

    Attributes:
        offset: (F, W) relative pupil y offsets δ.
        residual_mm: (F, W) chief-ray height on the stop after aiming, mm.
        converged: (F, W) bool, residual below tolerance and the chief ray traced.
        iterations: Newton iterations used.
        offset_x: (F, W) relative pupil x offsets δ_x for placed lenses and two-dimensional fields
            (then ``residual_mm`` is the distance from the stop centre), else None.
    """

    offset: Tensor
    residual_mm: Tensor
    converged: Tensor
    iterations: int
    offset_x: Tensor | None = None
    solve: ChiefSolve | None = None


@dataclass(frozen=True)
class ChiefSolve:
    """The detached part of chief aiming (``aim_chief``), a function of the lens values only: the
    Newton iterate δ (F, W) the final step is taken from, the chief ray's stop height y there (mm), the
    slope dy/dδ (a fourth-order central difference, within ~1e-11 of the exact one), where that slope is
    usable (``ok``) and where the ray reached the stop (``valid``). Handing it back to ``aim_chief`` for
    the same lens values skips the iterations (a Jacobian after an evaluation at the same θ) and gives
    the same numbers bit for bit."""

    delta: Tensor
    y: Tensor
    slope: Tensor
    ok: Tensor
    valid: Tensor


def stop_hit(lens: Lens, rays) -> tuple[Tensor, Tensor, RayTrace]:
    """x, y of ``rays`` on the stop surface in the stop's own frame (global x, y for a lens without a
    placement), and the trace up to the stop."""
    hit = trace(lens, rays, upto=lens.stop)
    x, y = hit.pos[..., 0], hit.pos[..., 1]
    if lens.placement is not None:
        frames = surface_frames(lens.thickness, lens.placement)
        x, y, _ = to_local((x, y, hit.pos[..., 2]), frames.origin[lens.stop], frames.rotation[lens.stop])
    return x, y, hit


def attached_stop_hit(lens: Lens, rays: Rays) -> tuple[Tensor, Tensor, RayTrace]:
    """``stop_hit`` for the attached final steps of the aiming solves: the values of the plain trace of
    the detached lens and rays (the same bits), the first derivatives those of the trace (to rounding)
    by its explicit partials in the lens tensors and the rays (``differential.stop_partials``), applied
    as x + Σ ∂x/∂p (p − p̄) with p̄ the detached p (0 in value). Any mode of differentiation then passes
    a few linear operations instead of the whole trace to the stop (under ``jacfwd``: N-column dual
    arithmetic on every operation). A placed lens, or one without derivatives, is traced as it is."""
    if lens.placement is not None or not carries_derivatives(*lens_tensors(lens), rays.pos, rays.dir):
        return stop_hit(lens, rays)
    detached = _detach_lens(lens)
    pos, dir = torch.broadcast_tensors(rays.pos, rays.dir)
    plain = Rays(pos.detach(), dir.detach(), rays.wavelength)
    if vmapped(*lens_tensors(detached), plain.pos, plain.dir):
        # Values batched by a vmap (e.g. tolerance trials): the partials' trace has no batching rule for its
        # in-place products (a per-sample loop); the plain trace is as exact and far cheaper there.
        return stop_hit(lens, rays)
    hit, partials = stop_partials(detached, plain)  # the trace to the stop (stop_hit's) and its partials
    x, y, partials = hit.pos[..., 0], hit.pos[..., 1], partials[..., :2, :]  # (*B, 2, 6 + L)
    keep = hit.valid[..., None, None] & torch.isfinite(partials)  # a lost ray's values are not used
    partials = torch.where(keep, partials, torch.zeros_like(partials))
    moved = torch.cat([pos, dir], -1)
    moved = moved - moved.detach()
    leaves = torch.cat([getattr(lens, name).reshape(-1) for name in LEAVES])
    leaves = leaves - leaves.detach()
    lin = (partials[..., :6] @ moved.unsqueeze(-1)).squeeze(-1) + partials[..., 6:] @ leaves
    return x + lin[..., 0], y + lin[..., 1], hit


def aim_chief(
    lens: Lens,
    system: System,
    tan_field: Tensor,
    *,
    epd: Tensor,
    entrance_pupil_z: Tensor,
    iterations: int = 8,
    tol_mm: float | None = None,
    tan_field_x: Tensor | None = None,
    solved: ChiefSolve | None = None,
) -> ChiefAim:
    """Pupil offsets that put the real chief ray of every field and wavelength on the stop centre.

    Args:
        tan_field: (F,) object-space chief-ray slopes.
        epd, entrance_pupil_z: paraxial entrance pupil diameter and position, mm.
        iterations: Newton iterations (at most; they stop at convergence where values may be looked
            at, ``transforms.all_settled``; the residual is reported).
        tol_mm: convergence tolerance on the stop, default 1e3·eps·(1 + EPD).
        tan_field_x: (F,) slopes in x of two-dimensional fields (``launch``), or None.
        solved: the ``ChiefSolve`` of an earlier call on the same lens values (``ChiefAim.solve``).

    A placed lens (or ``tan_field_x``) is aimed in x and y (``offset_x``; see the module docstring).
    """
    if lens.placement is not None or tan_field_x is not None:
        return _aim_chief_2d(lens, system, tan_field, tan_field_x, epd=epd, entrance_pupil_z=entrance_pupil_z,
                             iterations=iterations, tol_mm=tol_mm)
    def stop_y(delta: Tensor, lens_: Lens, tan_: Tensor, epd_: Tensor, ep_z: Tensor) -> tuple[Tensor, Tensor]:
        """Chief-ray stop heights (mm) and validity for pupil offsets δ (F, W) or (F, W, P)."""
        d = delta if delta.dim() == 3 else delta.unsqueeze(-1)
        rays = launch(lens_, system, torch.stack([torch.zeros_like(d), d], -1), tan_, epd=epd_, entrance_pupil_z=ep_z)
        hit = trace(lens_, rays, upto=lens_.stop)
        y, valid = hit.pos[..., 1], hit.valid
        return (y, valid) if delta.dim() == 3 else (y[..., 0], valid[..., 0])

    tol = tol_mm if tol_mm is not None else 1e3 * torch.finfo(lens.dtype).eps * (1.0 + epd.detach())
    solve = solved if solved is not None else _chief_solve(stop_y, lens, tan_field, epd, entrance_pupil_z,
                                                           iterations, tol)
    delta, slope, ok = solve.delta, solve.slope, solve.ok
    # Final step on the attached lens: first derivatives of δ at convergence (the implicit function
    # theorem, with the solve's slope). Without derivatives the attached trace is the detached one
    # (same values): skipped.
    if carries_derivatives(*lens_tensors(lens), tan_field, epd, entrance_pupil_z):
        pupil = torch.stack([torch.zeros_like(delta), delta], -1).unsqueeze(-2)
        _, y, hit = attached_stop_hit(lens, launch(lens, system, pupil, tan_field, epd=epd,
                                                   entrance_pupil_z=entrance_pupil_z))
        y, valid = y[..., 0], hit.valid[..., 0]
    else:
        y, valid = solve.y, solve.valid
    offset = torch.where(ok, delta - y / slope, delta)
    converged = valid & (solve.y.abs() <= tol)
    return ChiefAim(offset=offset, residual_mm=solve.y, converged=converged, iterations=iterations, solve=solve)


FULL_FD_STEP = 2.0**-12
"""Step (relative pupil units) of chief and full aiming's fourth-order central differences: truncation
(~h⁴ f⁽⁵⁾/30 f') and rounding (~eps |y| / h) both below 1e-11 of the slope."""


def _chief_solve(stop_y, lens: Lens, tan_field: Tensor, epd: Tensor, entrance_pupil_z: Tensor,  # noqa: ANN001
                 iterations: int, tol: Tensor | float) -> ChiefSolve:
    """Newton on δ with detached values (``aim_chief``), to convergence or ``iterations − 1`` steps.

    The slopes are fourth-order central differences, the chief ray and four neighbours at δ ± h, δ ± 2h
    (``FULL_FD_STEP``) traced in one batch: one plain trace per iteration instead of a forward-mode
    one, which dispatches about three times the operations, and a slope within ~1e-11 of the exact
    one, which the derivatives of the final step use (the implicit function theorem)."""
    num_f, num_w = tan_field.shape[0], lens.wavelength_um.shape[0]
    detached = _detach_lens(lens)
    args = (detached, tan_field.detach(), epd.detach(), entrance_pupil_z.detach())
    delta = torch.zeros(num_f, num_w, dtype=lens.dtype, device=lens.device)

    h = FULL_FD_STEP

    def newton_terms(d: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        y5, valid5 = stop_y(torch.stack([d, d - 2 * h, d - h, d + h, d + 2 * h], -1), *args)
        y, valid = y5[..., 0], valid5[..., 0]
        slope = (y5[..., 1] - 8.0 * y5[..., 2] + 8.0 * y5[..., 3] - y5[..., 4]) / (12.0 * h)
        ok = valid5.all(-1) & (slope.abs() > 1e-12)
        return y, torch.where(ok, slope, torch.ones_like(slope)), ok, valid

    y, slope, ok, valid = newton_terms(delta)
    for _ in range(iterations - 1):
        # Converged everywhere (eager only, ``all_settled``): the remaining steps would move δ by
        # rounding only, and the final step is taken from here.
        if all_settled((y.abs() <= tol) | ~ok):
            break
        delta = torch.where(ok, delta - y / slope, delta)
        y, slope, ok, valid = newton_terms(delta)
    return ChiefSolve(delta, y, slope, ok, valid)


def _aim_chief_2d(lens: Lens, system: System, tan_field: Tensor, tan_field_x: Tensor | None, *, epd: Tensor,
                  entrance_pupil_z: Tensor, iterations: int, tol_mm: float | None) -> ChiefAim:
    """``aim_chief`` in x and y: 2 × 2 Newton on (δ_x, δ_y), the Jacobian by two forward-mode jvps."""
    num_f, num_w = tan_field.shape[0], lens.wavelength_um.shape[0]

    def stop_xy(d: Tensor, lens_: Lens, tan_: Tensor, tanx_: Tensor | None, epd_: Tensor,
                ep_z: Tensor) -> tuple[Tensor, Tensor]:
        rays = launch(lens_, system, d.unsqueeze(-2), tan_, epd=epd_, entrance_pupil_z=ep_z, tan_field_x=tanx_)
        x, y, hit = stop_hit(lens_, rays)
        return torch.stack([x[..., 0], y[..., 0]], -1), hit.valid[..., 0]

    detached = _detach_lens(lens)
    tanx_det = None if tan_field_x is None else tan_field_x.detach()
    args = (detached, tan_field.detach(), tanx_det, epd.detach(), entrance_pupil_z.detach())
    delta = torch.zeros(num_f, num_w, 2, dtype=lens.dtype, device=lens.device)
    ex, ey = torch.zeros_like(delta), torch.zeros_like(delta)
    ex[..., 0] = 1.0
    ey[..., 1] = 1.0

    def newton_terms(d: Tensor) -> tuple[Tensor, Tensor, Tensor, tuple[Tensor, Tensor, Tensor]]:
        """Residual (F, W, 2), Newton step J⁻¹ r (F, W, 2) and where J is invertible."""
        fn = lambda v: stop_xy(v, *args)[0]  # noqa: E731
        r, jx = torch.func.jvp(fn, (d,), (ex,))
        _, jy = torch.func.jvp(fn, (d,), (ey,))
        det = jx[..., 0] * jy[..., 1] - jy[..., 0] * jx[..., 1]
        ok = det.abs() > 1e-24
        safe = torch.where(ok, det, torch.ones_like(det))
        step = torch.stack([(jy[..., 1] * r[..., 0] - jy[..., 0] * r[..., 1]) / safe,
                            (jx[..., 0] * r[..., 1] - jx[..., 1] * r[..., 0]) / safe], -1)
        return r, step, ok, (jx, jy, safe)

    tol = tol_mm if tol_mm is not None else 1e3 * torch.finfo(lens.dtype).eps * (1.0 + epd.detach())
    r_det, step, ok, (jx, jy, safe) = newton_terms(delta)
    for _ in range(iterations - 1):
        if all_settled((torch.sqrt((r_det * r_det).sum(-1)) <= tol) | ~ok):  # as in ``aim_chief``
            break
        delta = torch.where(ok[..., None], delta - step, delta)
        r_det, step, ok, (jx, jy, safe) = newton_terms(delta)
    # Final step on the attached lens (detached Jacobian, attached residual): exact first derivatives.
    r, valid = stop_xy(delta, lens, tan_field, tan_field_x, epd, entrance_pupil_z)
    step = torch.stack([(jy[..., 1] * r[..., 0] - jy[..., 0] * r[..., 1]) / safe,
                        (jx[..., 0] * r[..., 1] - jx[..., 1] * r[..., 0]) / safe], -1)
    offset = torch.where(ok[..., None], delta - step, delta)
    miss = torch.sqrt((r_det * r_det).sum(-1))
    converged = valid & (miss <= tol)
    return ChiefAim(offset=offset[..., 1], residual_mm=miss, converged=converged, iterations=iterations,
                    offset_x=offset[..., 0])


def _detach_lens(lens: Lens) -> Lens:
    """The same lens with every tensor detached (no gradient, no forward-mode tangent), placement too."""
    names = ("curvature", "conic", "asphere", "phase", "thickness", "index", "wavelength_um", "semi_diameter")
    placement = lens.placement
    if placement is not None:
        placement = dataclasses.replace(
            placement, decenter=placement.decenter.detach(), tilt=placement.tilt.detach(),
            group_decenter=None if placement.group_decenter is None else placement.group_decenter.detach(),
            group_tilt=None if placement.group_tilt is None else placement.group_tilt.detach())
    return Lens(shapes=lens.shapes, stop=lens.stop, placement=placement,
                **{n: getattr(lens, n).detach() for n in names})


# ------------------------------------------------------------------------------- full aiming (S21–S22)

MAX_AIM_STEP = 0.5
"""Largest change of a relative pupil coordinate in one aiming step (a guard against wild steps)."""


@dataclass(frozen=True)
class PupilAim:
    """Result of full ray aiming: the pupil ellipse whose marginal rays meet the stop edge.

    Attributes:
        factors: (F, W, 3) vignetting factors (V_i, V_s, V_l) relative to the paraxial entrance pupil
            (S19–S20): the launched pupil spans y ∈ [−1 + V_i, 1 − V_s], x ∈ ±(1 − V_l). Negative
            factors mean a real pupil larger than the paraxial one. Differentiable in the lens. Where
            a marginal ray does not reach the stop after the last step, the chief-aimed unit circle.
        chief: the chief-ray aiming.
        stop_radius_mm: () semi-diameter of the stop filled by the on-axis beam (real marginal ray at
            the reference wavelength, as in S1.3.2).
        residual_mm: (F, W, 4) after aiming, stop misses of the inferior (y + r), superior (y − r) and
            lateral (ρ − r) marginal rays and of the chief ray (y), mm; 0 where a ray failed.
        traced: (F, W, 4) bool, whether those rays reached the stop.
        converged: (F, W) bool, every residual below ``tol_mm`` and every ray traced.
        steps: Newton steps taken (S21–S22 updates).
        tol_mm: () the convergence tolerance used for ``converged``, mm.
        held: (F, W, 2) bool where the inferior / superior ray is held on the edge of the front aperture
            (``aperture`` given and the aimed ray would fall outside it), else None. A held ray counts
            as converged when it reaches the stop inside its edge; its residual is then reported as 0.
    """

    factors: Tensor
    chief: ChiefAim
    stop_radius_mm: Tensor
    residual_mm: Tensor
    traced: Tensor
    converged: Tensor
    steps: int
    tol_mm: Tensor
    held: Tensor | None = None
    solve: FullSolve | None = None


@dataclass(frozen=True)
class FullSolve:
    """The detached part of full aiming (``aim_full``), a function of the lens values only: the
    unknowns u (F, W, 3) the final step is taken from and the last point that traced (``u_good``),
    the stop misses ``res``, slopes and usable-slope mask there, and the report of the aimed rays
    (``residual``, ``traced``). Handed back for the same lens values it skips the detached traces and
    gives the same numbers bit for bit (as ``ChiefSolve``)."""

    u: Tensor
    u_good: Tensor
    res: Tensor
    slope: Tensor
    ok: Tensor
    residual: Tensor
    traced: Tensor


def stop_radius(lens: Lens, system: System, *, epd: Tensor, entrance_pupil_z: Tensor,
                paraxial_mm: Tensor | None = None) -> Tensor:
    """() height on the stop of the real on-axis marginal ray (pupil (0, 1), reference wavelength), mm;
    the paraxial marginal height when that ray fails (``paraxial_mm``: ``first_order``'s
    ``stop_semi_diameter`` where the caller has it, else computed here). A placed lens's stop keeps its
    size: the radius is that of the centred lens (a decentered stop would otherwise shrink by its decenter)."""
    lens = dataclasses.replace(lens, placement=None)
    ref = system.reference
    pupil = torch.zeros(1, lens.wavelength_um.shape[0], 1, 2, dtype=lens.dtype, device=lens.device)
    pupil[..., 1] = 1.0
    tan0 = torch.zeros(1, dtype=lens.dtype, device=lens.device)
    _, y, hit = attached_stop_hit(lens, launch(lens, system, pupil, tan0, epd=epd, entrance_pupil_z=entrance_pupil_z))
    real = y[0, ref, 0].abs()
    if paraxial_mm is None:
        paraxial_mm = first_order(lens, system).stop_semi_diameter
    return torch.where(hit.valid[0, ref, 0], real, paraxial_mm)


def aim_full(
    lens: Lens,
    system: System,
    tan_field: Tensor,
    *,
    epd: Tensor,
    entrance_pupil_z: Tensor,
    steps: int = 1,
    chief: ChiefAim | None = None,
    tol_mm: float | None = None,
    aperture: tuple[Tensor, Tensor] | None = None,
    solved: FullSolve | None = None,
    paraxial_stop_mm: Tensor | None = None,
) -> PupilAim:
    """Full ray aiming (S1.3.2, S21–S22): pupil factors that put the marginal rays on the stop edge.

    For every field and wavelength the inferior and superior meridional rays, launched at pupil
    (0, y_lo) and (0, y_hi), are driven to y = −r and +r on the stop, and the lateral ray, launched at
    (x_l, (y_lo + y_hi)/2) (where S19–S20 put the pupil point (1, 0)), to radius r; r is the stop
    radius of the on-axis beam. Each step is S21–S22: Δu = −(stop − target) / (d stop / d u), with the
    derivative by forward-mode autodiff, from the chief-aimed unit circle (y_c ± 1, 1). ``steps − 1``
    steps run on detached values, the last on the attached lens, which makes the factors
    differentiable (exactly so at convergence, by the implicit function theorem, as ``aim_chief``).

    Args:
        tan_field: (F,) object-space chief-ray slopes.
        epd, entrance_pupil_z: paraxial entrance pupil diameter and position, mm.
        steps: Newton steps (1 by default, as in the seed; more for strong pupil aberration).
        chief: a chief-ray aiming already computed for these fields, else it is computed here.
        tol_mm: tolerance of ``converged``, default 1e3·eps·(1 + EPD) mm.
        aperture: (centre, radius), broadcastable to (F, W): a front aperture's opening in relative
            pupil coordinates (``vignetting.front_aperture_disc``). Then the vignetting it causes comes
            first (S1.3.2, last paragraph): the meridional rays start inside the opening, y ∈ [c − ρ,
            c + ρ], and every step is projected back into it, so a marginal ray the aperture cuts is
            held on its edge (the bottom, on a vignetting telephoto) while the others (top, sagittal)
            are aimed at the stop edge; the lateral ray starts on the opening's chord. Without it the
            unvignetted pupil is aimed, whose cut-off rays may miss the front elements altogether.
        solved: the ``FullSolve`` of an earlier call on the same lens values (``PupilAim.solve``).
        paraxial_stop_mm: ``first_order``'s ``stop_semi_diameter`` of the lens, where the caller has it
            (``stop_radius``'s fallback; else computed there).

    Returns:
        A ``PupilAim`` with the factors, residuals on the stop and convergence flags.
    """
    if steps < 1:
        raise ValueError(f"steps must be ≥ 1, got {steps}")
    if chief is None:
        chief = aim_chief(lens, system, tan_field, epd=epd, entrance_pupil_z=entrance_pupil_z)
    detached = _detach_lens(lens)
    # A placed lens: every ray is launched beside the chief ray's x offset (the ellipse is centred on it).
    x_off = chief.offset_x
    det_args = (detached, tan_field.detach(), epd.detach(), entrance_pupil_z.detach(),
                None if x_off is None else x_off.detach())
    att_args = (lens, tan_field, epd, entrance_pupil_z, x_off)
    radius = stop_radius(lens, system, epd=epd, entrance_pupil_z=entrance_pupil_z, paraxial_mm=paraxial_stop_mm)
    r_det = radius.detach()

    def stop_hits(u: Tensor, y0: Tensor, args: tuple) -> tuple[Tensor, Tensor]:
        """u: (F, W, 3) = (y_lo, y_hi, x_l) or (F, W, K, 3) (K sets traced in one batch), y0: (F, W)
        launch height of the lateral ray → stop coordinates (y, y, ρ) of the three rays and their
        validity, (F, W, 3) or (F, W, K, 3)."""
        lens_, tan_, epd_, ep_z, x0 = args
        sets = u if u.dim() == 4 else u.unsqueeze(-2)
        zero = (torch.zeros_like(y0) if x0 is None else x0).unsqueeze(-1).expand_as(sets[..., 0])
        pupil = torch.stack([torch.stack([zero, sets[..., 0]], -1), torch.stack([zero, sets[..., 1]], -1),
                             torch.stack([sets[..., 2] + zero, y0.unsqueeze(-1).expand_as(zero)], -1)], -2)
        num_f, num_w, k = sets.shape[:3]
        rays = launch(lens_, system, pupil.reshape(num_f, num_w, 3 * k, 2), tan_, epd=epd_, entrance_pupil_z=ep_z)
        x, y, hit = attached_stop_hit(lens_, rays)
        x, y, valid = (t.reshape(num_f, num_w, k, 3) for t in (x, y, hit.valid))
        rho = torch.sqrt((x[..., 2] ** 2 + y[..., 2] ** 2).clamp_min(torch.finfo(u.dtype).tiny))
        g = torch.stack([y[..., 0], y[..., 1], rho], -1)
        return (g, valid) if u.dim() == 4 else (g[..., 0, :], valid[..., 0, :])

    sign = torch.tensor([-1.0, 1.0, 1.0], dtype=lens.dtype, device=lens.device)

    def newton(u: Tensor, args: tuple, r: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Residuals, diagonal derivatives and validity at u. Each ray depends on its own unknown once
        the lateral ray's launch height y0 is held, so the derivatives are the fourth-order central
        differences of the three rays, all fifteen traced in one batch (``FULL_FD_STEP``)."""
        y0 = 0.5 * (u[..., 0] + u[..., 1])
        h = FULL_FD_STEP
        g5, valid5 = stop_hits(torch.stack([u, u - 2 * h, u - h, u + h, u + 2 * h], -2), y0, args)
        dg = (g5[..., 1, :] - 8.0 * g5[..., 2, :] + 8.0 * g5[..., 3, :] - g5[..., 4, :]) / (12.0 * h)
        return g5[..., 0, :] - sign * r, dg, valid5.all(-2)

    y_c = chief.offset.detach()
    u = torch.stack([y_c - 1.0, y_c + 1.0, torch.ones_like(y_c)], -1)
    lo_b = hi_b = None
    if aperture is not None:
        centre, rho = (torch.broadcast_to(t.to(lens.dtype), y_c.shape) for t in aperture)
        lo_b, hi_b = centre - rho, centre + rho  # attached: the held rays' pupil heights are differentiable
        lo_d, hi_d, c_d, rho_d = lo_b.detach(), hi_b.detach(), centre.detach(), rho.detach()
        u = _into_opening(u, lo_d, hi_d)
        mid = 0.5 * (u[..., 0] + u[..., 1])
        chord = torch.sqrt((rho_d**2 - (mid - c_d) ** 2).clamp_min(0.0))
        u = torch.stack([u[..., 0], u[..., 1], torch.minimum(u[..., 2], chord.clamp_min(1e-3))], -1)
    u_good = u.clone()
    if solved is not None:
        u, u_good = solved.u, solved.u_good
    for _ in range(steps - 1 if solved is None else 0):
        res, slope, ok = newton(u, det_args, r_det)
        good_slope = ok & (slope.abs() > 1e-12)
        step = (res / torch.where(good_slope, slope, torch.ones_like(slope))).clamp(-MAX_AIM_STEP, MAX_AIM_STEP)
        u_good = torch.where(ok, u, u_good)
        # Where the ray failed, fall back half-way to the last point that traced.
        u = torch.where(good_slope, u - step, torch.where(ok, u, 0.5 * (u + u_good)))
        if lo_b is not None:
            u = _into_opening(u, lo_d, hi_d)
    # Final step on the attached lens: meridional rays first, then the lateral ray launched at the
    # attached y0, so that its derivative includes the coupling (exact at convergence).
    res_d, slope, ok = newton(u, det_args, r_det) if solved is None else (solved.res, solved.slope, solved.ok)
    good = ok & (slope.abs() > 1e-12)
    safe_slope = torch.where(good, slope, torch.ones_like(slope))
    full_step = good & ((res_d / safe_slope).abs() <= MAX_AIM_STEP)
    fallback = torch.where(good, u - (res_d / safe_slope).clamp(-MAX_AIM_STEP, MAX_AIM_STEP),
                           torch.where(ok, u, u_good))
    if carries_derivatives(*lens_tensors(lens), tan_field, epd, entrance_pupil_z, radius):
        g_att, _ = stop_hits(u, 0.5 * (u[..., 0] + u[..., 1]), att_args)
        miss = g_att - sign * radius
    else:  # the attached trace would repeat the detached one: same values
        miss = res_d
    new = torch.where(full_step, u - miss / safe_slope, fallback)
    held = None
    if lo_b is not None:
        held = torch.stack([new[..., 0].detach() <= lo_d, new[..., 1].detach() >= hi_d], -1)
        new = _into_opening(new, lo_b, hi_b)
    g_lat, _ = stop_hits(u, 0.5 * (new[..., 0] + new[..., 1]), att_args)
    lat = torch.where(full_step[..., 2], u[..., 2] - (g_lat[..., 2] - radius) / safe_slope[..., 2], new[..., 2])
    final = torch.stack([new[..., 0], new[..., 1], lat], -1)

    # Report where the final marginal rays and the aimed chief ray meet the stop.
    eps = torch.finfo(lens.dtype).eps
    tol = torch.as_tensor(tol_mm if tol_mm is not None else 1e3 * eps * (1.0 + epd.detach()), dtype=lens.dtype,
                          device=lens.device)
    if solved is not None:
        residual, traced = solved.residual, solved.traced
    else:
        residual, traced = _aim_report(final, held, chief, detached, det_args, r_det, sign, y_c, stop_hits, system,
                                       epd)
    valid_fin = traced[..., :3]
    converged = traced.all(-1) & (residual.abs() <= tol).all(-1)
    y_lo, y_hi, x_l = final.unbind(-1)
    factors = torch.stack([1.0 + y_lo, 1.0 - y_hi, 1.0 - x_l], -1)
    # Where a marginal ray is lost at the end, the ellipse means nothing: fall back to the chief-aimed
    # unit circle (the ``chief`` mode's pupil) for that field and wavelength.
    lost = ~valid_fin.all(-1, keepdim=True)
    offset = chief.offset
    circle = torch.stack([offset, -offset, torch.zeros_like(offset)], -1)
    factors = torch.where(lost, circle, factors)
    solve = FullSolve(u.detach(), u_good.detach(), res_d, slope, ok, residual, traced)
    return PupilAim(factors=factors, chief=chief, stop_radius_mm=radius, residual_mm=residual, traced=traced,
                    converged=converged, steps=steps, tol_mm=tol, held=held, solve=solve)


def _aim_report(final: Tensor, held: Tensor | None, chief: ChiefAim, detached: Lens, det_args: tuple, r_det: Tensor,
                sign: Tensor, y_c: Tensor, stop_hits, system: System, epd: Tensor) -> tuple[Tensor, Tensor]:  # noqa: ANN001
    """(F, W, 4) stop misses of the aimed inferior, superior and lateral rays and of the chief ray, and
    whether each traced (``PupilAim.residual_mm``, ``traced``)."""
    with torch.no_grad():
        fin = final.detach()
        g_fin, valid_fin = stop_hits(fin, 0.5 * (fin[..., 0] + fin[..., 1]), det_args)
        res_fin = torch.where(valid_fin, g_fin - sign * r_det, torch.zeros_like(g_fin))
        if held is not None:  # a held ray that meets the stop inside its edge is where it should be
            eps_ = 1e3 * torch.finfo(detached.dtype).eps * (1.0 + epd.detach())
            inside = held & (sign[:2] * res_fin[..., :2] <= eps_)
            res_fin = torch.cat([torch.where(inside, torch.zeros_like(inside, dtype=res_fin.dtype),
                                             res_fin[..., :2]), res_fin[..., 2:]], -1)
        if chief.solve is not None:  # the chief ray's miss where its final step was taken from
            chief_ok, chief_y = chief.solve.valid, chief.solve.y
        else:
            px = torch.zeros_like(y_c) if det_args[4] is None else det_args[4]
            pupil = torch.stack([px, chief.offset.detach()], -1).unsqueeze(-2)
            _, chief_y, hit = stop_hit(detached, launch(detached, system, pupil, det_args[1], epd=det_args[2],
                                                        entrance_pupil_z=det_args[3]))
            chief_ok, chief_y = hit.valid[..., 0], chief_y[..., 0]
        chief_res = torch.where(chief_ok, chief_y, torch.zeros_like(y_c))
    return torch.cat([res_fin, chief_res.unsqueeze(-1)], -1), torch.cat([valid_fin, chief_ok.unsqueeze(-1)], -1)


def _into_opening(u: Tensor, lo: Tensor, hi: Tensor) -> Tensor:
    """(F, W, 3) pupil unknowns with the inferior and superior heights moved into [lo, hi]."""
    return torch.stack([torch.maximum(u[..., 0], lo), torch.minimum(u[..., 1], hi), u[..., 2]], -1)
