"""Metrics of K perturbed lenses in one vmapped call, with the back-focus compensator in closed form.

``evaluate(setup, params)`` runs ``torch.vmap`` over the trial dimension of ``TrialParams``: the
whole chain (first-order data, ray launch, trace, spot statistics, compensator, MTF, distortion)
runs once on K × rays, not K times in Python.

Back-focus compensator (closed form): moving the image plane by Δz moves every intercept by
Δz (L/N, M/N) and every centroid by the weighted mean of that, so the squared ESR is a quadratic in
Δz; its minimum is

    Δz* = − Σ_h (w_h / W_h) Σ_r w_r (u_r − ū_h)·(s_r − s̄_h) / Σ_h (w_h / W_h) Σ_r w_r |s_r − s̄_h|²,

exact in one step (no iterations). The compensator is reported as not converged when the
denominator vanishes (no valid rays with spread in slope) or when |Δz*| exceeds the allowed range
(then the plane is left at the range limit).

Failed rays are counted per trial; a trial in which some field lost every ray gets an infinite
metric (never NaN) so it sorts as the worst.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.analysis.spot import safe_sqrt
from lensopt.engine import Engine
from lensopt.optics.bundle import Bundle, trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import chief_image_height, field_tangents
from lensopt.optics.placement import Placement
from lensopt.tolerance.model import TrialParams, params_lens

__all__ = ["EvalSetup", "evaluate", "METRICS", "refocus"]

METRICS = ("esr", "rms", "mtf", "distortion")


@dataclass(frozen=True)
class EvalSetup:
    """What every trial shares.

    Attributes:
        lens: the nominal lens (structure, wavelengths).
        system: aperture, fields, weights.
        placement: the placement structure of the trials, or None (symmetric fast path).
        pupil: (P, 2) pupil points (a half pupil when ``half`` and no placement).
        half: whether ``pupil`` is the half pupil x ≥ 0.
        compensate: ``none`` or ``focus`` (closed-form back focus).
        focus_range: largest allowed |Δz| of the compensator, mm.
        mtf_frequency: cycles/mm of the MTF metric (None: not computed).
        lm_vars: compensators of ``compensate = "lm"``: (``curvature`` | ``thickness``, surface) pairs,
            re-optimized per trial by ``lm_steps`` Levenberg–Marquardt steps on the ESR (the back focus
            still solved in closed form inside every evaluation).
        lm_steps: LM steps per trial.
        field_xy: (F, 2) two-dimensional relative fields (x, y), or None: the system's +y fields. The
            pupil samples of field (x, y) are those of the +y field turned by the field's azimuth (so a
            rotationally symmetric lens gives the same spot, turned, at every azimuth); ``pupil`` must
            then be the full pupil (``half`` False).
        field_weights: (F,) weights of ``field_xy`` in the ESR (None: uniform).
        aim: ``none`` (every trial fills the nominal paraxial entrance pupil) or ``chief`` (each trial's
            chief rays aimed at the centre of its own, possibly decentered or tilted, stop, in x and y;
            ``optics.aiming``).
        engine: trace backend and memory budget of the trials' traces (default ``Engine()``).
    """

    lens: Lens
    system: System
    placement: Placement | None
    pupil: Tensor
    half: bool
    compensate: str = "focus"
    focus_range: float = 1.0
    mtf_frequency: float | None = None
    lm_vars: tuple[tuple[str, int], ...] = ()
    lm_steps: int = 5
    field_xy: Tensor | None = None
    field_weights: tuple[float, ...] | None = None
    aim: str = "none"
    engine: Engine | None = None


def _centroid(u: Tensor, w: Tensor, half: bool) -> Tensor:
    """(F, 2) weighted centroid over (W, P) of (F, W, P, 2) values; x̄ = 0 on a half pupil."""
    total = w.sum((1, 2)).clamp_min(torch.finfo(u.dtype).tiny)
    c = (u * w[..., None]).sum((1, 2)) / total[:, None]
    if half:
        c = torch.stack([torch.zeros_like(c[:, 0]), c[:, 1]], -1)
    return c


def refocus(bundle: Bundle, wavelength_weights: Tensor, field_weights: Tensor, half: bool,
            focus_range: float) -> tuple[Tensor, Tensor, Tensor]:
    """Closed-form ESR-optimal image shift Δz (see the module docstring).

    Returns:
        dz: () shift, mm (clamped to ±focus_range); ok: () bool, converged and in range;
        xy: (F, W, P, 2) intercepts on the shifted plane.
    """
    res = bundle.result
    valid = res.valid
    u = torch.where(valid[..., None], res.pos[..., :2], 0.0)
    dz_dir = torch.where(valid, res.dir[..., 2], 1.0)
    s = torch.where(valid[..., None], res.dir[..., :2] / dz_dir[..., None], 0.0)
    w = wavelength_weights[None, :, None] * valid.to(u.dtype)
    cu, cs = _centroid(u, w, half), _centroid(s, w, half)
    du, ds = u - cu[:, None, None], s - cs[:, None, None]
    wf = field_weights / w.sum((1, 2)).clamp_min(torch.finfo(u.dtype).tiny)  # (F,)
    num = (wf[:, None, None] * w * (du * ds).sum(-1)).sum()
    den = (wf[:, None, None] * w * (ds * ds).sum(-1)).sum()
    tiny = torch.finfo(u.dtype).eps * (1.0 + (wf[:, None, None] * w * (du * du).sum(-1)).sum())
    solvable = den > tiny
    dz = torch.where(solvable, -num / torch.where(solvable, den, 1.0), 0.0)
    ok = solvable & (dz.abs() <= focus_range)
    dz = dz.clamp(-focus_range, focus_range)
    return dz, ok, u + dz * s


def _spot(xy: Tensor, valid: Tensor, ww: Tensor, fw: Tensor, half: bool) -> tuple[Tensor, Tensor, Tensor]:
    """RMS radius per field (F,), ESR (), centroids (F, 2) (as ``analysis.spot``, masked)."""
    w = ww[None, :, None] * valid.to(xy.dtype)
    c = _centroid(torch.where(valid[..., None], xy, 0.0), w, half)
    d2 = torch.where(valid, ((xy - c[:, None, None]) ** 2).sum(-1), 0.0)
    rms = safe_sqrt((w * d2).sum((1, 2)) / w.sum((1, 2)).clamp_min(torch.finfo(xy.dtype).tiny))
    esr = safe_sqrt((fw * rms**2).sum() / fw.sum())
    return rms, esr, c


def _weights(setup: EvalSetup, lens: Lens, num_fields: int) -> tuple[Tensor, Tensor]:
    system = setup.system
    ww = system.wavelength_weights.to(lens.dtype)
    given = setup.field_weights if setup.field_xy is not None else system.field_weights
    fw = (torch.tensor(given, dtype=lens.dtype, device=lens.device) if given
          else torch.ones(num_fields, dtype=lens.dtype, device=lens.device))
    return ww, fw


def _azimuth(lens: Lens, system: System, field_xy: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Object-space slopes (tan θ_x, tan θ_y) (F,) each and the unit field direction (F, 2) (+y for
    the axis)."""
    fxy = field_xy.to(lens.dtype)
    tx, ty = field_tangents(lens, system, fxy[:, 0]), field_tangents(lens, system, fxy[:, 1])
    norm = torch.sqrt(tx * tx + ty * ty)
    on_axis = norm == 0
    safe = torch.where(on_axis, 1.0, norm)
    sx = torch.where(on_axis, 0.0, tx / safe)
    sy = torch.where(on_axis, 1.0, ty / safe)
    return tx, ty, torch.stack([sx, sy], -1)


def _trace(setup: EvalSetup, lens: Lens) -> tuple[Bundle, Tensor | None]:
    """The trial's bundle; for two-dimensional fields also the unit field directions (F, 2)."""
    if setup.field_xy is None:
        return trace_bundle(lens, setup.system, setup.pupil, half_pupil=setup.half, aim=setup.aim,
                            engine=setup.engine), None
    _, _, s = _azimuth(lens, setup.system, setup.field_xy)
    px, py = setup.pupil[:, 0].to(lens.dtype), setup.pupil[:, 1].to(lens.dtype)
    sx, sy = s[:, 0:1], s[:, 1:2]
    # Turn the pupil with the field: (0, 1) → (sx, sy), (1, 0) → (sy, −sx).
    pupil = torch.stack([px * sy + py * sx, -px * sx + py * sy], -1)[:, None]  # (F, 1, P, 2)
    fxy = setup.field_xy.to(lens.dtype)
    b = trace_bundle(lens, setup.system, pupil, half_pupil=False, aim=setup.aim, rel_field=fxy[:, 1],
                     rel_field_x=fxy[:, 0], engine=setup.engine)
    return b, s


def _with_offsets(setup: EvalSetup, p: dict[str, Tensor], theta: Tensor) -> dict[str, Tensor]:
    """``p`` with the LM compensators' offsets ``theta`` (V,) added to curvatures/thicknesses."""
    num = setup.lens.num_surfaces
    eye = torch.eye(num, dtype=theta.dtype, device=theta.device)
    curv, thick = p["curvature"], p["thickness"]
    for v, (kind, s) in enumerate(setup.lm_vars):
        if kind == "curvature":
            curv = curv + eye[s] * theta[v]
        else:
            thick = thick + eye[s] * theta[v]
    return {**p, "curvature": curv, "thickness": thick}


def _lm_residuals(setup: EvalSetup, p: dict[str, Tensor], theta: Tensor) -> Tensor:
    """Weighted ray deviations from the field centroids after the closed-form refocus: ‖r‖² = ESR²."""
    lens = params_lens(setup.lens, setup.placement, _with_offsets(setup, p, theta))
    b, _ = _trace(setup, lens)
    ww, fw = _weights(setup, lens, b.rel_field.shape[0])
    _, _, xy = refocus(b, ww, fw, b.half_pupil, setup.focus_range)
    valid = b.result.valid
    w = ww[None, :, None] * valid.to(xy.dtype)
    c = _centroid(torch.where(valid[..., None], xy, 0.0), w, b.half_pupil)
    scale = fw[:, None, None] / (w.sum((1, 2)).clamp_min(torch.finfo(xy.dtype).tiny)[:, None, None] * fw.sum())
    d = torch.where(valid[..., None], xy - c[:, None, None], 0.0)
    return (torch.sqrt(w * scale)[..., None] * d).reshape(-1)


def _lm(setup: EvalSetup, p: dict[str, Tensor]) -> tuple[dict[str, Tensor], Tensor, Tensor]:
    """A fixed number of Levenberg–Marquardt steps (branch-free, so it runs under vmap) on the LM
    compensators; returns the compensated parameters, whether it converged (at the start of the last
    step the undamped Gauss–Newton model promised less than 0.1 % further decrease of ESR²; False is
    reported as a compensator failure) and the offsets (V,)."""
    from torch.func import jacfwd

    num_v = len(setup.lm_vars)
    theta = torch.zeros(num_v, dtype=p["thickness"].dtype, device=p["thickness"].device)
    fn = lambda t: _lm_residuals(setup, p, t)  # noqa: E731
    r = fn(theta)
    merit = (r * r).sum()
    damping = torch.full_like(merit, 1e-3)
    promise = torch.ones_like(merit)
    eye = torch.eye(num_v, dtype=theta.dtype, device=theta.device)
    for _ in range(setup.lm_steps):
        jac = jacfwd(fn)(theta)  # (M, V)
        a = jac.T @ jac
        g = jac.T @ r
        d = torch.diagonal(a).clamp_min(torch.finfo(a.dtype).tiny)
        # Convergence: what the undamped Gauss–Newton model still promises at this step's start.
        gn = torch.linalg.solve(a + 1e-12 * torch.diag(d) + 1e-30 * eye, -g)
        promise = -0.5 * (g * gn).sum() / merit.clamp_min(torch.finfo(a.dtype).tiny)
        step = torch.linalg.solve(a + damping * torch.diag(d) + 1e-30 * eye, -g)
        r_new = fn(theta + step)
        m_new = (r_new * r_new).sum()
        accept = m_new < merit
        theta = torch.where(accept, theta + step, theta)
        r = torch.where(accept, r_new, r)
        merit = torch.where(accept, m_new, merit)
        damping = torch.where(accept, damping * 0.3, damping * 10.0)
    return _with_offsets(setup, p, theta), promise < 1e-3, theta


def _one(setup: EvalSetup, p: dict[str, Tensor]) -> dict[str, Tensor]:
    lm_ok = lm_theta = None
    if setup.compensate == "lm" and setup.lm_vars:
        p, lm_ok, lm_theta = _lm(setup, p)
    lens = params_lens(setup.lens, setup.placement, p)
    system = setup.system
    b, direction = _trace(setup, lens)
    half = b.half_pupil
    ww, fw = _weights(setup, lens, b.rel_field.shape[0])
    valid = b.result.valid
    if setup.compensate in ("focus", "lm"):
        dz, ok, xy = refocus(b, ww, fw, half, setup.focus_range)
        if lm_ok is not None:
            ok = ok & lm_ok
    else:
        dz = torch.zeros((), dtype=lens.dtype, device=lens.device)
        ok = torch.ones((), dtype=torch.bool, device=lens.device)
        xy = b.result.pos[..., :2]
    rms, esr, centroid = _spot(xy, valid, ww, fw, half)
    lost_field = (valid.sum((1, 2)) == 0).any()
    inf = torch.full_like(esr, math.inf)
    out = {
        "esr": torch.where(lost_field, inf, esr),
        "rms": torch.where(lost_field, inf, rms),
        "centroid": centroid,
        "focus_shift": dz,
        "compensator_ok": ok,
        "failed_rays": (~valid).sum(),
    }
    # Distortion at the outermost field: centroid height against the paraxial chief-ray height, %.
    ep_z = b.first_order.entrance_pupil_z
    if setup.field_xy is None:
        y_par = chief_image_height(lens, system, b.tan_field, ep_z=ep_z)
        out["distortion"] = 100.0 * (centroid[-1, 1] - y_par[-1]) / y_par[-1]
    else:
        out["distortion"] = _distortion_2d(setup, lens, centroid, ep_z)
    if lm_theta is not None:
        out["lm_offsets"] = lm_theta
    if setup.mtf_frequency is not None:
        out["mtf_s"], out["mtf_t"] = _mtf(lens, b, xy, valid, ww, centroid, setup.mtf_frequency, half, direction)
    return out


def _distortion_2d(setup: EvalSetup, lens: Lens, centroid: Tensor, ep_z: Tensor) -> Tensor:
    """Radial distortion (%) of the outermost two-dimensional field with the largest |distortion|: the
    centroid's component along the paraxial image point p = (y_p(tan θ_x), y_p(tan θ_y)) (the paraxial
    chief-ray height is linear in the slope) against |p|."""
    tx, ty, _ = _azimuth(lens, setup.system, setup.field_xy)
    p = torch.stack([chief_image_height(lens, setup.system, tx, ep_z=ep_z),
                     chief_image_height(lens, setup.system, ty, ep_z=ep_z)], -1)  # (F, 2)
    radius = torch.linalg.vector_norm(setup.field_xy.to(torch.float64), dim=-1)
    outer = [i for i, r in enumerate(radius.tolist()) if r >= float(radius.max()) - 1e-12]
    p2 = (p[outer] ** 2).sum(-1)
    off_axis = p2 > 0  # only the axis given: no distortion to speak of (0, not NaN)
    safe = torch.where(off_axis, p2, 1.0)
    d = torch.where(off_axis, 100.0 * ((centroid[outer] * p[outer]).sum(-1) - p2) / safe, 0.0)
    return torch.gather(d, 0, torch.argmax(d.abs(), dim=0, keepdim=True))[0]


def _mtf(lens: Lens, b: Bundle, xy: Tensor, valid: Tensor, ww: Tensor, centroid: Tensor, nu: float,
         half: bool, direction: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """(F,) sagittal and tangential MTF at ``nu`` cycles/mm: the geometric OTF of the (refocused)
    intercepts times the diffraction-limited pupil MTF per wavelength (``analysis.mtf``'s heuristic, with
    the working f-number as a tensor so that it runs under vmap). ``direction``: (F, 2) unit field
    directions of two-dimensional fields (tangential: along it, sagittal: across it), None: +y."""
    d = xy - centroid[:, None, None]
    if direction is not None:
        sx, sy = direction[:, None, None, 0], direction[:, None, None, 1]
        d = torch.stack([d[..., 0] * sy - d[..., 1] * sx, d[..., 0] * sx + d[..., 1] * sy], -1)
    m = valid.to(xy.dtype)
    count = m.sum(-1).clamp_min(1.0)
    wn = b.first_order.working_fnumber.abs()
    s = (nu * lens.wavelength_um * 1e-3 * wn).clamp(0.0, 1.0)
    dl = 2.0 / math.pi * (torch.acos(s) - s * torch.sqrt((1.0 - s * s).clamp_min(0.0)))
    w = ww / ww.sum() * dl  # (W,)
    out = []
    for axis in (0, 1):
        phase = -2.0 * math.pi * nu * d[..., axis]
        re = (m * torch.cos(phase)).sum(-1) / count
        im = (m * torch.sin(phase)).sum(-1) / count
        if half and axis == 0:  # the mirrored half (x → −x) cancels the sine terms, doubles nothing else
            im = torch.zeros_like(im)
        out.append(torch.sqrt(((w * re).sum(-1)) ** 2 + ((w * im).sum(-1)) ** 2))
    return out[0], out[1]


def evaluate(setup: EvalSetup, params: TrialParams) -> dict[str, Tensor]:
    """Metrics of every trial in ``params`` (leading dimension K), in one vmapped call.

    Returns a dict of tensors with leading dimension K: ``esr`` (mm), ``rms`` (K, F) mm, ``centroid``
    (K, F, 2) mm (on the compensated image plane),
    ``distortion`` (%), ``focus_shift`` (mm), ``compensator_ok`` (bool), ``failed_rays`` (int), and
    ``mtf_s``/``mtf_t`` (K, F) when an MTF frequency is set.
    """
    p = {f.name: getattr(params, f.name) for f in dataclasses.fields(params)}
    return torch.vmap(lambda q: _one(setup, q))(p)
