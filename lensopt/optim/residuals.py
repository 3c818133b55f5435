"""Residual terms (S2.2, Table S6): pure tensor functions of a traced bundle (or glass variables).

Each returns a flat vector whose length depends only on the bundle's shape, never on the data
(DESIGN.md rule 1): failed rays keep their rows with value 0 (and the ``failures`` term counts them).
ramp(x) = max(x, 0). n_r = F·W·P rays; lengths in mm.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from lensopt.analysis.distortion import centroid_distortion
from lensopt.analysis.illumination import relative_illumination_std
from lensopt.optics.bundle import Bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.trace import RayTrace

__all__ = [
    "BIG",
    "tra",
    "gap_lengths",
    "ray_path",
    "ray_path_spans",
    "inactive",
    "active",
    "ray_path_margin",
    "ray_path_span_margin",
    "ray_angle_margin",
    "surface_normal_margin",
    "ray_angle",
    "surface_normal",
    "distortion",
    "relative_illumination",
    "failure_margin",
    "failures",
    "wavefront",
]

BIG = 1e9
"""Stand-in for an absent bound (mm): finite, so that values and tangents stay finite."""


def _ramp(x: Tensor) -> Tensor:
    return torch.clamp_min(x, 0.0)


def tra(bundle: Bundle, centroid: Tensor, wavelength_weights: Tensor, field_weights: Tensor) -> Tensor:
    """(2 n_r,) transverse ray aberrations about each field's weighted centroid ``centroid`` (F, 2)
    (``analysis.spot.spot_centroid``) (S37–S39).

    Every ray of field h, wavelength w is weighted by sqrt(f_h/Σf · W_w/ΣW / P), so that with no
    failed rays ‖ℓ_TRA‖² = Σ_h f̂_h SR_h² = ESR² (S40 generalized to weights).
    """
    res = bundle.result
    F, W, P = res.status.shape
    xy = res.pos[..., :2] - centroid[:, None, None, :]
    ww = wavelength_weights.to(xy.dtype) / wavelength_weights.sum()
    fw = field_weights.to(xy.dtype) / field_weights.sum()
    scale = torch.sqrt(fw[:, None, None] * ww[None, :, None] / P)
    d = torch.where(res.valid.unsqueeze(-1), xy * scale.unsqueeze(-1), 0.0)
    return d.reshape(-1)


def gap_lengths(bundle: Bundle, gaps: Sequence[int] | None = None) -> Tensor:
    """(S, F, W, P) axial distance t_z each ray travels in the gap after every surface (needs a
    bundle traced with ``record=True``); the last gap ends on the image surface. ``gaps``: (G, F, W, P)
    those gaps only, in that order (the same numbers as their rows of all S)."""
    res = bundle.result
    z = [h.pos[..., 2] for h in res.hits] + [res.pos[..., 2]]
    if gaps is not None:
        return torch.stack([z[g + 1] - z[g] for g in gaps]) if gaps else res.pos.new_zeros((0, *res.status.shape))
    z = torch.stack(z)
    return z[1:] - z[:-1]


def inactive(margin: Tensor, valid: Tensor) -> bool:
    """Whether every row ramp(margin) of the valid rays is inactive: margin < 0 strictly. Such rows are 0
    with a zero derivative (``clamp_min``'s derivative passes where margin ≥ 0), so a Jacobian may
    leave them out of forward mode (``Term.margin``) and give exactly the same numbers."""
    return not bool(active(margin, valid).any())


def active(margin: Tensor, valid: Tensor) -> Tensor:
    """(B, *R) bool: the rows of ramp(margin) whose derivative is not 0: margin ≥ 0 on a valid ray
    (``valid`` (*R) broadcast over the leading blocks)."""
    return (margin >= 0) & valid


def ray_path_margin(bundle: Bundle, lower: Tensor, upper: Tensor, gaps: Sequence[int] | None = None) -> Tensor:
    """(S, F, W, P) how far each ray's axial path per gap is outside [lower, upper] (mm; < 0 inside);
    ``gaps``: (G, F, W, P) those gaps' rows only (``gap_lengths``)."""
    tz = gap_lengths(bundle, gaps)
    if gaps is not None:
        lower, upper = lower[list(gaps)], upper[list(gaps)]
    lo, hi = lower[:, None, None, None], upper[:, None, None, None]
    return torch.maximum(tz - hi, lo - tz)


def ray_path(bundle: Bundle, lower: Tensor, upper: Tensor) -> Tensor:
    """(S n_r,) ray path residuals (S41–S42) for per-gap bounds ``lower``/``upper`` (S,) in mm."""
    d = _ramp(ray_path_margin(bundle, lower, upper))
    d = torch.where(bundle.result.valid.unsqueeze(0), d, 0.0)
    return d.reshape(-1) / math.sqrt(bundle.result.status.numel())


def ray_path_spans(bundle: Bundle, spans: list[tuple[int, int, float, float]]) -> Tensor:
    """(K n_r,) ray path residuals on runs of gaps: for each span (first, stop, lower, upper) the axial
    distance t = Σ t_z over the gaps first … stop − 1 (surface ``first`` to surface ``stop``, the image
    being surface S) must lie in [lower, upper]; rows ramp(max(t − upper, lower − t))/√n_r."""
    valid = bundle.result.valid
    margin = ray_path_span_margin(bundle, spans)
    if margin.shape[0] == 0:
        return margin.reshape(-1)
    out = [torch.where(valid, _ramp(m), 0.0) for m in margin.unbind(0)]
    return torch.stack(out).reshape(-1) / math.sqrt(bundle.result.status.numel())


def ray_path_span_margin(bundle: Bundle, spans: list[tuple[int, int, float, float]]) -> Tensor:
    """(K, F, W, P) ``ray_path_spans``' margins: max(t − upper, lower − t) per span and ray (mm)."""
    if not spans:
        return bundle.result.pos.new_zeros((0, *bundle.result.status.shape))
    first = min(a for a, _, _, _ in spans)
    tz = gap_lengths(bundle, range(first, max(b for _, b, _, _ in spans)))  # the gaps the spans cover
    out = [torch.maximum(tz[a - first:b - first].sum(0) - hi, lo - tz[a - first:b - first].sum(0))
           for a, b, lo, hi in spans]
    return torch.stack(out)


def _valid_ramp_rows(res: RayTrace, margin: Tensor) -> Tensor:
    """ramp(margin) on the valid rays, 0 elsewhere, flattened and scaled by 1/√n_r (S45, S47)."""
    d = torch.where(res.valid.unsqueeze(0), _ramp(margin), 0.0)
    return d.reshape(-1) / math.sqrt(res.status.numel())


def ray_angle(bundle: Bundle, surfaces: list[int], max_deg: float) -> Tensor:
    """(2 I n_r,) ray angle residuals (S43–S45) at the interfaces ``surfaces``: ramp(cos²θmax − ζ)
    for ζ_I = cos² of incidence and ζ_R = cos² of refraction (negative on TIR)."""
    res = bundle.result
    if not surfaces:
        return res.pos.new_zeros(0)
    return _valid_ramp_rows(res, ray_angle_margin(bundle, surfaces, max_deg))


def ray_angle_margin(bundle: Bundle, surfaces: list[int], max_deg: float,
                     blocks: Sequence[int] | None = None) -> Tensor:
    """(2 I, F, W, P) ``ray_angle``'s margins cos²θmax − ζ, incidence and refraction of each surface
    (block 2i, 2i + 1 of ``surfaces[i]``); ``blocks``: (B, F, W, P) those blocks only, in that order."""
    res = bundle.result
    c2 = math.cos(math.radians(max_deg)) ** 2
    out = []
    for b in range(2 * len(surfaces)) if blocks is None else blocks:
        h = res.hits[surfaces[b // 2]]
        out.append(c2 - (h.cos2_out if b % 2 else h.cos2_in))
    return torch.stack(out) if out else res.pos.new_zeros((0, *res.status.shape))


def surface_normal(bundle: Bundle, surfaces: list[int], max_deg: float) -> Tensor:
    """(I n_r,) surface normal residuals (S46–S47): ramp(cos²θmax − n_z²) where rays hit."""
    res = bundle.result
    if not surfaces:
        return res.pos.new_zeros(0)
    return _valid_ramp_rows(res, surface_normal_margin(bundle, surfaces, max_deg))


def surface_normal_margin(bundle: Bundle, surfaces: list[int], max_deg: float,
                          blocks: Sequence[int] | None = None) -> Tensor:
    """(I, F, W, P) ``surface_normal``'s margins cos²θmax − n_z²; ``blocks``: (B, F, W, P) those of
    ``surfaces[b]`` for b in ``blocks`` only, in that order."""
    res = bundle.result
    c2 = math.cos(math.radians(max_deg)) ** 2
    if blocks is not None:
        surfaces = [surfaces[b] for b in blocks]
    if not surfaces:
        return res.pos.new_zeros((0, *res.status.shape))
    return c2 - torch.stack([res.hits[s].normal[..., 2] ** 2 for s in surfaces])


def distortion(lens: Lens, system: System, bundle: Bundle, centroid: Tensor, max_fraction: float) -> Tensor:
    """(F,) distortion residuals (S48–S50): ramp(|D_h| − D_max)/√n_h, D as a fraction; ``centroid``:
    (F, 2) the fields' spot centroids."""
    d = centroid_distortion(lens, system, bundle, centroid)
    return _ramp(d.abs() - max_fraction) / math.sqrt(d.shape[0])


def relative_illumination(bundle: Bundle, wavelength_weights: Tensor, minimum: float) -> Tensor:
    """(F,) relative illumination residuals (S52–S54): ramp(R_min − R_h)/√n_h, all-ray estimate."""
    r = relative_illumination_std(bundle, wavelength_weights)
    return _ramp(minimum - r) / math.sqrt(r.shape[0])


def failure_margin(bundle: Bundle, lens: Lens) -> Tensor:
    """(F, W, P) how far each failed ray is from passing (dimensionless, ≥ 0; 0 for valid rays), at
    the surface where it failed (needs ``record=True``):

    - total internal reflection: −cos²θ' there (cos²θ' < 0 on TIR);
    - missed surface: the larger of (1 + κ) c² h² − 1, with h the ray's height on the vertex plane
      (beyond the conic's rim), and c² d² − 1, with d the distance of the ray's line from the centre
      of curvature (a line that passes the sphere by);
    - clipped: h²/sd² − 1 with h the height on the surface.
    Other failures (Newton, grazing the image) get 0 and cost only the constant.
    """
    from lensopt.optics.trace import Status

    res = bundle.result
    at = res.failed_at
    margin = torch.zeros_like(res.pos[..., 0])
    if at is None or not res.hits:
        return margin
    vertex = lens.vertex_z()
    start = bundle.rays.pos.expand_as(res.pos)
    for s in range(lens.num_surfaces):
        here = at == s
        h = res.hits[s]
        prev = start if s == 0 else res.hits[s - 1].pos
        dz = h.dir_in[..., 2]
        safe = torch.where(dz.abs() > 1e-12, dz, torch.ones_like(dz))
        t = (vertex[s] - prev[..., 2]) / safe
        xy = prev[..., :2] + t.unsqueeze(-1) * h.dir_in[..., :2]
        u_plane = (xy**2).sum(-1)
        c = lens.curvature[s]
        missed = (1.0 + lens.conic[s]) * c**2 * u_plane - 1.0
        centre = 1.0 / torch.where(c != 0, c, torch.ones_like(c))
        to_centre = torch.stack(
            [-prev[..., 0], -prev[..., 1], vertex[s] + centre - prev[..., 2]], -1)
        d2 = (torch.linalg.cross(to_centre, h.dir_in) ** 2).sum(-1)
        missed = torch.maximum(missed, torch.where(c != 0, c**2 * d2 - 1.0, torch.zeros_like(d2)))
        tir = -h.cos2_out
        sd2 = lens.semi_diameter[s] ** 2
        u_hit = (h.pos[..., :2] ** 2).sum(-1)
        clipped = u_hit / torch.where(sd2 > 0, sd2, torch.ones_like(sd2)) - 1.0
        m = torch.where(res.status == int(Status.TIR), tir, torch.zeros_like(tir))
        m = torch.where(res.status == int(Status.MISSED), missed, m)
        m = torch.where(res.status == int(Status.CLIPPED), clipped, m)
        margin = torch.where(here, _ramp(m), margin)
    return margin


def _tracing() -> bool:
    """Whether a graph is being captured (Dynamo or make_fx): no branches on tensor values then."""
    from torch.fx.experimental.proxy_tensor import get_proxy_mode

    return torch.compiler.is_compiling() or get_proxy_mode() is not None


def failures(bundle: Bundle, lens: Lens, penalty_mm: float) -> Tensor:
    """(n_r,) ``penalty_mm (1 + margin)/√n_r`` for every failed ray, 0 for the others.

    The constant makes any step that fails rays raise the merit (so it is rejected); the margin
    (``failure_margin``) gives failed rays a gradient towards passing, so a start with many failed
    rays can recover.
    """
    res = bundle.result
    bad = (~res.valid).to(res.pos.dtype)
    if not _tracing() and not bool(bad.any()):
        # No ray failed (the usual case near a design): every row is 0 and the per-surface margin
        # walk (a third of a C-mount Jacobian) cannot contribute. Kept in a graph being traced
        # (torch.compile, make_fx), where a branch on data would be baked in.
        return bad.reshape(-1)
    margin = failure_margin(bundle, lens)
    return (bad * penalty_mm * (1.0 + margin)).reshape(-1) / math.sqrt(res.status.numel())


def wavefront(lens: Lens, system: System, pupil: Tensor, wavelength_weights: Tensor, field_weights: Tensor,
              *, tilt: bool = True) -> Tensor:
    """(F·W·P,) wavefront error residuals, waves: every ray's W (``analysis.wavefront``: the real chief
    ray's reference sphere) minus the least-squares piston (and tilt) of its field and wavelength, weighted
    by sqrt(f_h/Σf · W_w/ΣW / P_h,w) with P_h,w the valid rays, so that ‖ℓ‖² = Σ_h,w f̂_h Ŵ_w RMS_h,w²:
    the weighted mean square RMS wavefront error (as ‖ℓ_TRA‖² is the ESR²). ``pupil``: (P, 2) points
    (equal-area, e.g. ``analysis.wavefront.map_grid``'s inside the circle); failed rays give 0."""
    from lensopt.analysis.wavefront import remove_tilt
    from lensopt.analysis.wavefront import wavefront as wavefront_of

    wf = wavefront_of(lens, system, pupil)
    resid = remove_tilt(wf.pupil, wf.opd, wf.valid, tilt=tilt)
    count = wf.valid.to(resid.dtype).sum(-1, keepdim=True).clamp_min(1.0)
    ww = wavelength_weights.to(resid.dtype) / wavelength_weights.sum()
    fw = field_weights.to(resid.dtype) / field_weights.sum()
    scale = torch.sqrt(fw[:, None, None] * ww[None, :, None] / count)
    return (resid * scale).reshape(-1)
