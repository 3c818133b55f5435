"""Exit-pupil wavefront: optical path difference (OPD) fans, maps, RMS and P-V wavefront error.

This module is lensopt's one home of the OPD; the reference PSF (``analysis.psf_reference``) and the
Zernike fit (``analysis.zernike``) build on ``trace_to_sphere``.

**Convention** (what every wavefront number in lensopt means):

- *Rays*: each field and wavelength's pupil points are traced with the system's aiming; the optical
  path starts at the object point (finite object) or on the plane through the origin normal to the
  incoming plane wave (object at infinity), and includes a diffractive surface's phase
  ``m λ φ(r) / 2π``.
- *Reference sphere*: centred on the reference point P0 on the image surface — for the wavefront
  analyses the **real chief ray's intercept at the same field and wavelength** (the PSF reference
  uses its grid centre instead) — and passing through E, the point where that **real chief ray,
  extended in image space, crosses the paraxial exit-pupil plane** (reference wavelength). Radius
  R = |P0 − E|. This is CODE V's reference sphere. Zemax OpticStudio and optiland pass the sphere
  through the *on-axis* exit-pupil point instead, R_Z = |P0 − (0, 0, z_XP)|. The spheres are
  concentric, so the two OPDs differ only through the back-propagation distance: a ray passing at
  perpendicular distance ε from P0 meets a sphere of radius R at ``sqrt(R² − ε²)`` from its foot
  point, so ``W_Z − W = n' [sqrt(R_Z² − ε²) − R_Z − sqrt(R² − ε²) + R] ≈ n' ε² (1/R − 1/R_Z) / 2``:
  zero on axis and for the chief ray, second order in the ray's transverse aberration elsewhere
  (``tests/analysis/test_wavefront_optiland.py`` reproduces it ray by ray).
- *Sign*: ``W = OPL(chief) − OPL(ray)``, both to the reference sphere: positive where the wavefront
  is ahead of the sphere. This is the sign of Welford's W (*Aberrations of Optical Systems*, ch. 8),
  of Zemax's OPD and of optiland's, so under-corrected spherical aberration has ``W040 = S_I/8 > 0``
  (``analysis.seidel``). W is 0 at the chief ray (no piston removed).
- *Pupil coordinates*: the relative entrance-pupil coordinates (px, py) the rays were launched at
  (unit circle = the paraxial entrance pupil, or the aimed pupil with aiming), px to the right and
  py up (towards the field). Maps, fans and Zernike fits use them, as Zemax and optiland do.
- *Units*: W is returned in waves of its own wavelength (``opd``); ``opd * wavelength_um * 1e-3`` is mm.

Failed rays keep their rows with W = 0 and ``valid`` False (DESIGN.md rule 1); every statistic is masked.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.analysis.checks import fields_of
from lensopt.analysis.spot import safe_sqrt
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.optics.bundle import Bundle, trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import FirstOrder, first_order

__all__ = ["SphereTrace", "trace_to_sphere", "optical_path", "Wavefront", "wavefront", "OpdFans", "opd_fans",
           "WavefrontMap", "wavefront_map", "WavefrontStats", "wavefront_stats", "remove_tilt", "map_grid",
           "rms_wavefront_error"]


def optical_path(lens: Lens, system: System, bundle: Bundle) -> Tensor:
    """(F, W, P) optical path from the object (or the object-space plane wavefront through the origin) to
    the image surface of a bundle traced with ``record=True``, mm; diffractive phases included."""
    res = bundle.result
    if not res.hits:
        raise ValueError("optical_path needs a bundle traced with record=True")
    nidx = lens.index  # (S+1, W)
    if system.object_distance is None:
        opl = nidx[0][None, :, None] * (bundle.rays.pos * bundle.rays.dir).sum(-1)
        opl = opl.expand(res.pos.shape[:-1])
    else:
        opl = torch.zeros(res.pos.shape[:-1], dtype=lens.dtype, device=lens.device)
    diffractive = [s for s, shape in enumerate(lens.shapes) if shape.diffractive]
    if diffractive and lens.placement is not None:
        raise LensoptError("the OPD of diffractive surfaces on decentered or tilted lenses is not supported",
                           path="lens.placement")
    lam_mm = lens.wavelength_um[None, :, None] * 1e-3
    for s, hit in enumerate(res.hits):
        opl = opl + nidx[s][None, :, None] * hit.t
        if s in diffractive:
            u = hit.pos[..., 0] ** 2 + hit.pos[..., 1] ** 2
            coeffs = lens.phase[s]
            phi = sum(coeffs[i] * u ** (i + 1) for i in range(coeffs.shape[0]))
            opl = opl + lens.shapes[s].order * lam_mm * phi / (2.0 * torch.pi)  # n'd'_t = (nd + mλ∇φ/2π)_t
    return opl + nidx[-1][None, :, None] * torch.linalg.vector_norm(res.pos - res.hits[-1].pos, dim=-1)


@dataclass(frozen=True)
class SphereTrace:
    """Rays carried from the image surface back to the reference sphere (see the module docstring).

    Attributes:
        opl: (F, W, P) optical path to the reference sphere, mm, up to a constant n'R per field and
            wavelength (the same for every ray of it; differences are exact). 0 where invalid.
        valid: (F, W, P) bool: the ray reached the image and meets the sphere.
        towards: (F, W, P, 3) unit vectors from each ray's point on the sphere to P0 (Debye directions).
        center: (F, W, 3) the sphere centres P0, mm.
        radius: (F, W) the sphere radii R (CODE V's: through the real chief ray's exit-pupil point), mm.
        chief_opl: (F, W) ``opl`` of the chief ray (pupil origin), traced in the same bundle.
        chief_valid: (F, W) bool.
        bundle: the traced bundle; pupil point 0 is the chief ray, points 1… are the ones asked for.
    """

    opl: Tensor
    valid: Tensor
    towards: Tensor
    center: Tensor
    radius: Tensor
    chief_opl: Tensor
    chief_valid: Tensor
    bundle: Bundle


def trace_to_sphere(
    lens: Lens,
    system: System,
    pupil: Tensor,
    *,
    rel_field: Tensor | None = None,
    center: Tensor | None = None,
    fo: FirstOrder | None = None,
    aim: str | None = None,
    engine: Engine | None = None,
) -> SphereTrace:
    """Trace the chief ray and ``pupil`` ((P, 2) relative pupil points) for every field and wavelength to
    the reference sphere. Differentiable in the lens (fixed shapes, finite placeholders).

    Args:
        rel_field: (F,) relative fields; default: the system's.
        center: (F, 2) reference points P0 (x, y) on the image surface, mm; default: each field and
            wavelength's own chief-ray intercept.
        fo: first-order data (its exit-pupil position sets the sphere radius).
        aim: ``none``, ``chief`` or ``full``; default: the system's.
    """
    dt, dev = lens.dtype, lens.device
    fo = first_order(lens, system) if fo is None else fo
    pts = torch.cat([torch.zeros(1, 2, dtype=dt, device=dev), pupil.to(dtype=dt, device=dev)])
    b = trace_bundle(lens, system, pts, rel_field=rel_field, aim=aim, record=True, fo=fo, engine=engine)
    res = b.result
    opl = optical_path(lens, system, b)
    q, d = res.pos, res.dir  # (F, W, 1+P, 3) on the image surface
    qc, dc = q[:, :, 0], d[:, :, 0]  # chief rays (F, W, 3)
    z_img = lens.vertex_z()[-1]
    if center is None:
        p0 = qc
    else:
        c = center.to(dt)
        p0 = torch.cat([c, z_img.expand(c.shape[0], 1)], -1)[:, None, :].expand(qc.shape)
    tiny = torch.finfo(dt).tiny
    dcz = torch.where(dc[..., 2].abs() > tiny, dc[..., 2], torch.ones_like(dc[..., 2]))
    e = qc + dc * ((fo.exit_pupil_z - qc[..., 2]) / dcz).unsqueeze(-1)  # chief ray on the exit-pupil plane
    radius = torch.linalg.vector_norm(p0 - e, dim=-1)  # (F, W)
    sign = torch.where(fo.exit_pupil_z < z_img, 1.0, -1.0).to(dt)
    r = radius.unsqueeze(-1)
    rel = q - p0.unsqueeze(2)
    bb = (d * rel).sum(-1)
    cc = (rel * rel).sum(-1)
    disc = bb * bb - cc + r * r
    meets = disc > 0
    root = torch.sqrt(torch.where(meets, disc, r * r))
    # s − sign·R, with s the distance back along the ray to the sphere; stable for large R.
    s_extra = bb + sign * (bb * bb - cc) / (root + r)
    n_img = lens.index[-1][None, :, None]
    opl_sphere = opl - n_img * s_extra
    sphere_pt = q - (sign * r + s_extra).unsqueeze(-1) * d
    to_p0 = p0.unsqueeze(2) - sphere_pt
    norm = torch.linalg.vector_norm(to_p0, dim=-1, keepdim=True)
    to_p0 = to_p0 / torch.where(norm > tiny, norm, torch.ones_like(norm))
    ok = res.valid & meets
    opl_sphere = torch.where(ok, opl_sphere, torch.zeros_like(opl_sphere))
    return SphereTrace(opl=opl_sphere[:, :, 1:], valid=ok[:, :, 1:], towards=to_p0[:, :, 1:], center=p0,
                       radius=radius, chief_opl=opl_sphere[:, :, 0], chief_valid=ok[:, :, 0], bundle=b)


@dataclass(frozen=True)
class Wavefront:
    """Wavefront error W at pupil points, per field and wavelength (convention: module docstring).

    Attributes:
        pupil: (P, 2) relative pupil coordinates (px, py).
        opd: (F, W, P) W in waves of each wavelength (0 where invalid).
        valid: (F, W, P) bool: the ray and its field's chief ray reached the image.
        rel_field: (F,) relative fields.
        field_deg: (F,) object-space chief-ray angles, degrees.
        wavelength_um: (W,) wavelengths, µm.
        reference: index of the reference wavelength.
        radius_mm: (F, W) reference-sphere radii.
        chief: (F, W, 2) chief-ray intercepts (the sphere centres), mm.
        chief_valid: (F, W) bool.
    """

    pupil: Tensor
    opd: Tensor
    valid: Tensor
    rel_field: Tensor
    field_deg: Tensor
    wavelength_um: Tensor
    reference: int
    radius_mm: Tensor
    chief: Tensor
    chief_valid: Tensor


def wavefront(lens: Lens, system: System, pupil: Tensor, *, rel_field: Tensor | None = None,
              fo: FirstOrder | None = None, aim: str | None = None, engine: Engine | None = None) -> Wavefront:
    """W at the pupil points ``pupil`` ((P, 2)) of every field and wavelength, referenced to the real
    chief ray and its reference sphere (CODE V's). Differentiable in the lens."""
    st = trace_to_sphere(lens, system, pupil, rel_field=rel_field, fo=fo, aim=aim, engine=engine)
    lam_mm = lens.wavelength_um[None, :, None] * 1e-3
    ok = st.valid & st.chief_valid.unsqueeze(-1)
    w = (st.chief_opl.unsqueeze(-1) - st.opl) / lam_mm
    b = st.bundle
    return Wavefront(pupil=pupil.to(lens.dtype), opd=torch.where(ok, w, torch.zeros_like(w)), valid=ok,
                     rel_field=b.rel_field, field_deg=torch.rad2deg(torch.atan(b.tan_field)),
                     wavelength_um=lens.wavelength_um, reference=system.reference, radius_mm=st.radius,
                     chief=st.center[..., :2], chief_valid=st.chief_valid)


@dataclass(frozen=True)
class OpdFans:
    """OPD fans: W along the pupil's y axis (tangential) and x axis (sagittal), both over −1 … 1.

    Attributes:
        coord: (T,) relative pupil coordinate of the fan points.
        tangential: (F, W, T) W(0, py), waves; ``tangential_valid`` (F, W, T) bool.
        sagittal: (F, W, T) W(px, 0), waves; ``sagittal_valid`` (F, W, T) bool.
        rel_field, field_deg, wavelength_um, reference: as ``Wavefront``.
    """

    coord: Tensor
    tangential: Tensor
    tangential_valid: Tensor
    sagittal: Tensor
    sagittal_valid: Tensor
    rel_field: Tensor
    field_deg: Tensor
    wavelength_um: Tensor
    reference: int


def opd_fans(lens: Lens, system: System, *, points: int = 65, rel_field: Tensor | None = None,
             fo: FirstOrder | None = None, engine: Engine | None = None) -> OpdFans:
    """Tangential and sagittal OPD fans of every field and wavelength, ``points`` per fan (≥ 2)."""
    if points < 2:
        raise LensoptError("must be at least 2", path="points", got=points)
    v = torch.linspace(-1.0, 1.0, points, dtype=lens.dtype, device=lens.device)
    zero = torch.zeros_like(v)
    pupil = torch.cat([torch.stack([zero, v], -1), torch.stack([v, zero], -1)])
    wf = wavefront(lens, system, pupil, rel_field=fields_of(lens, system, rel_field), fo=fo, engine=engine)
    t, s = slice(0, points), slice(points, 2 * points)
    return OpdFans(coord=v, tangential=wf.opd[..., t], tangential_valid=wf.valid[..., t], sagittal=wf.opd[..., s],
                   sagittal_valid=wf.valid[..., s], rel_field=wf.rel_field, field_deg=wf.field_deg,
                   wavelength_um=wf.wavelength_um, reference=wf.reference)


def map_grid(n: int, *, dtype: torch.dtype, device: torch.device | None = None) -> tuple[Tensor, Tensor]:
    """(N², 2) cell-centred pupil points px, py = −1 + (2i + 1)/N (row-major in (py, px)) and the (N²,)
    mask of those inside the unit circle: every point stands for the same pupil area."""
    c = -1.0 + (2.0 * torch.arange(n, dtype=dtype, device=device) + 1.0) / n
    py, px = torch.meshgrid(c, c, indexing="ij")
    pts = torch.stack([px.reshape(-1), py.reshape(-1)], -1)
    return pts, (pts**2).sum(-1) <= 1.0


@dataclass(frozen=True)
class WavefrontMap:
    """W on an N×N pupil grid (row index grows with py, column with px).

    Attributes:
        wavefront: the samples, P = N² (points outside the unit circle are marked invalid).
        opd: (F, W, N, N) W in waves (0 outside the pupil or where rays failed).
        valid: (F, W, N, N) bool.
    """

    wavefront: Wavefront
    opd: Tensor
    valid: Tensor


def wavefront_map(lens: Lens, system: System, *, n: int = 64, rel_field: Tensor | None = None,
                  fo: FirstOrder | None = None, engine: Engine | None = None) -> WavefrontMap:
    """W of every field and wavelength on an N×N cell-centred grid of the pupil."""
    if n < 2:
        raise LensoptError("must be at least 2", path="grid", got=n)
    pts, inside = map_grid(n, dtype=lens.dtype, device=lens.device)
    wf = wavefront(lens, system, pts, rel_field=fields_of(lens, system, rel_field), fo=fo, engine=engine)
    ok = wf.valid & inside
    wf = Wavefront(**{**wf.__dict__, "valid": ok, "opd": torch.where(ok, wf.opd, torch.zeros_like(wf.opd))})
    shape = (*wf.opd.shape[:2], n, n)
    return WavefrontMap(wavefront=wf, opd=wf.opd.reshape(shape), valid=ok.reshape(shape))


def remove_tilt(pupil: Tensor, opd: Tensor, valid: Tensor, *, tilt: bool = True) -> Tensor:
    """W minus its masked least-squares piston (and tilt a + b px + c py when ``tilt``), 0 where invalid.

    Fixed shapes, masked sums, a 3×3 solve per field and wavelength: safe under ``torch.func.jacfwd``.

    Args:
        pupil: (P, 2) pupil points; opd, valid: (*, P).
    """
    m = valid.to(opd.dtype)
    one = torch.ones_like(pupil[:, 0])
    basis = torch.stack([one, pupil[:, 0], pupil[:, 1]], -1) if tilt else one[:, None]  # (P, K)
    k = basis.shape[-1]
    gram = torch.einsum("...p,pi,pj->...ij", m, basis, basis)
    rhs = torch.einsum("...p,pi,...p->...i", m, basis, opd)
    eye = torch.eye(k, dtype=opd.dtype, device=opd.device)
    empty = gram[..., 0, 0] <= 0
    gram = torch.where(empty[..., None, None], eye, gram)  # no valid ray: solve to 0, not NaN
    # A (near-)singular Gram matrix (rays only on a line) is regularized just enough to stay finite.
    gram = gram + eye * (1e-12 * gram.diagonal(dim1=-2, dim2=-1).sum(-1)[..., None, None])
    coef = torch.linalg.solve(gram, rhs.unsqueeze(-1)).squeeze(-1)
    resid = opd - coef @ basis.T
    return torch.where(valid, resid, torch.zeros_like(resid))


@dataclass(frozen=True)
class WavefrontStats:
    """RMS and peak-to-valley wavefront error per field and wavelength, waves.

    Attributes:
        rms_chief: (F, W) RMS of W about its mean (piston removed; reference: the chief ray's sphere).
        pv_chief: (F, W) max − min of W.
        rms: (F, W) RMS with piston and tilt removed (the sphere re-centred on the best image point,
            Zemax's "to centroid"); the number the Maréchal estimate uses.
        pv: (F, W) max − min with piston and tilt removed.
        count: (F, W) valid samples.
    """

    rms_chief: Tensor
    pv_chief: Tensor
    rms: Tensor
    pv: Tensor
    count: Tensor


def wavefront_stats(wf: Wavefront) -> WavefrontStats:
    """RMS and P-V of ``wf`` over its valid samples, every sample weighted alike (use an equal-area
    sampling such as ``map_grid``)."""
    m = wf.valid.to(wf.opd.dtype)
    count = m.sum(-1)
    denom = count.clamp_min(1.0)

    def rms_pv(w: Tensor) -> tuple[Tensor, Tensor]:
        rms = torch.sqrt(((w * w) * m).sum(-1) / denom)
        big = torch.finfo(w.dtype).max
        hi = torch.where(wf.valid, w, torch.full_like(w, -big)).amax(-1)
        lo = torch.where(wf.valid, w, torch.full_like(w, big)).amin(-1)
        return rms, torch.where(count > 0, hi - lo, torch.zeros_like(hi))

    rms_c, pv_c = rms_pv(remove_tilt(wf.pupil, wf.opd, wf.valid, tilt=False))
    rms_t, pv_t = rms_pv(remove_tilt(wf.pupil, wf.opd, wf.valid, tilt=True))
    return WavefrontStats(rms_chief=rms_c, pv_chief=pv_c, rms=rms_t, pv=pv_t, count=count)


def rms_wavefront_error(lens: Lens, system: System, pupil: Tensor, *, rel_field: Tensor | None = None,
                        fo: FirstOrder | None = None, tilt: bool = True, engine: Engine | None = None) -> Tensor:
    """(F, W) RMS wavefront error in waves, piston (and with ``tilt`` also tilt) removed, over the valid
    rays of ``pupil`` ((P, 2); use an equal-area sampling such as ``map_grid``'s points inside the circle).

    Pure tensor code with fixed shapes (failed rays are masked, never dropped), finite values and
    gradients everywhere (a perfect wavefront has RMS 0 with a zero, not NaN, gradient): safe under
    ``torch.func.jacfwd``/``vmap`` for use as an optimization residual.
    """
    wf = wavefront(lens, system, pupil, rel_field=rel_field, fo=fo, engine=engine)
    resid = remove_tilt(wf.pupil, wf.opd, wf.valid, tilt=tilt)
    m = wf.valid.to(resid.dtype)
    mean_sq = (resid * resid * m).sum(-1) / m.sum(-1).clamp_min(1.0)
    return safe_sqrt(mean_sq)
