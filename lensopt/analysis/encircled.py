"""Encircled and ensquared energy per field: geometric (from spot rays) and diffraction (from the
Debye/FFT reference PSF of ``analysis.psf_reference``).

Both are fractions of the energy that reaches the image (vignetted and failed rays carry none),
polychromatic curves weighted by the spectral weights, against the radius of a circle (encircled) or
the half-width of a square (ensquared, sides along x and y), both centred on ``center``:
``centroid`` (the field's polychromatic spot centroid, default) or ``chief`` (the reference
wavelength's chief ray, optiland's default).

**Geometric**: every ray of the pupil sampling stands for the same pupil area; the curve is the
weighted fraction of rays inside. (A ``rings`` sampling holds the half pupil x ≥ 0; both centres lie on
x = 0, where the mirror images give the same distances.)

**Diffraction**: the Debye field ``E(x) = Σ_p a_p exp(i k [W_p + α_p x + β_p y])`` is evaluated on a
square grid of points about the centre (pitch ``pitch_mm``), each standing for a pixel; a pixel counts
with its overlap with the circle or square (a linear ramp one pitch wide, exact for squares). The total
energy is not the grid's sum (which would cut the Airy tails off) but Parseval's theorem in the pupil:
``∫|E|² = λ² Σ_p a_p² / J_p``, with J_p the area each pupil sample covers in direction-cosine space
(α, β), from finite differences of the traced directions over the pupil grid. A perfect lens therefore
gives the Airy pattern's closed form ``1 − J0²(v) − J1²(v)``, ``v = k NA r`` (tests check it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.analysis.checks import fields_of
from lensopt.analysis.psf_reference import debye_intensity, wavefront_error
from lensopt.analysis.spot import spot_stats
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import PupilSampling

__all__ = ["EnergyCurves", "geometric_energy", "diffraction_energy", "CENTERS", "pupil_cell_area"]

CENTERS = ("centroid", "chief")


@dataclass(frozen=True)
class EnergyCurves:
    """Encircled and ensquared energy curves.

    Attributes:
        radius_mm: (R,) circle radii, and square half-widths, mm.
        encircled: (F, R) polychromatic encircled energy, 0 … 1.
        ensquared: (F, R) polychromatic ensquared energy.
        encircled_w: (F, W, R) per wavelength; ensquared_w: (F, W, R).
        center: (F, 2) the centres, mm.
        rel_field: (F,); field_deg: (F,); wavelength_um: (W,).
        method: ``geometric`` or ``diffraction``.
        airy_radius_mm: first dark ring 1.22 λ N_w / n' at the reference wavelength (for plots).
    """

    radius_mm: Tensor
    encircled: Tensor
    ensquared: Tensor
    encircled_w: Tensor
    ensquared_w: Tensor
    center: Tensor
    rel_field: Tensor
    field_deg: Tensor
    wavelength_um: Tensor
    method: str
    airy_radius_mm: float


def _centers(lens: Lens, system: System, rel_field: Tensor, center: str, bundle_stats: Tensor, *,
             engine: Engine | None = None) -> Tensor:
    if center == "centroid":
        return bundle_stats
    if center != "chief":
        raise ValueError(f"center must be one of {CENTERS}, got {center!r}")
    chief = trace_bundle(lens, system, torch.zeros(1, 2, dtype=lens.dtype, device=lens.device), rel_field=rel_field,
                         engine=engine)
    return chief.result.pos[:, system.reference, 0, :2]


def _weighted(curves_w: Tensor, system: System) -> Tensor:
    w = system.wavelength_weights.to(curves_w.dtype)
    return torch.einsum("fwr,w->fr", curves_w, w / w.sum())


def _airy(lens: Lens, system: System) -> float:
    wn = float(first_order(lens, system).working_fnumber)
    n_img = float(lens.index[-1, system.reference])
    return 1.22 * float(lens.wavelength_um[system.reference]) * 1e-3 * abs(wn) / n_img


@torch.no_grad()
def geometric_energy(lens: Lens, system: System, *, rel_field: Tensor, radii: Tensor | None = None,
                     sampling: str = "rings:32", center: str = "centroid", pupil: Tensor | None = None,
                     engine: Engine | None = None
                     ) -> EnergyCurves:
    """Geometric encircled/ensquared energy from the rays of ``sampling`` (see the module docstring), or
    of the full-pupil points ``pupil`` ((P, 2)) when given; ``radii`` default: 101 radii up to 1.1 × the
    largest ray distance (201 radii)."""
    if pupil is None:
        scheme = PupilSampling.parse(sampling, path="encircled.sampling")
        pupil, half = scheme.points(dtype=lens.dtype, device=lens.device, engine=engine), scheme.half
    else:
        half = False
    rel_field = fields_of(lens, system, rel_field)
    b = trace_bundle(lens, system, pupil.to(lens.dtype), half_pupil=half, rel_field=rel_field, engine=engine)
    c = _centers(lens, system, rel_field, center, spot_stats(b, system.wavelength_weights).centroid, engine=engine)
    xy, valid = b.result.pos[..., :2], b.result.valid
    d = xy - c[:, None, None, :]
    r = torch.linalg.vector_norm(d, dim=-1)
    s = d.abs().amax(-1)
    if radii is None:
        top = float(torch.where(valid, r, torch.zeros_like(r)).max())
        radii = torch.linspace(0.0, 1.1 * max(top, 1e-9), 201, dtype=lens.dtype, device=lens.device)
    radii = radii.to(lens.dtype)
    m = valid.to(lens.dtype)
    count = m.sum(-1).clamp_min(1.0)  # (F, W)
    enc = ((r[..., None] <= radii) * m[..., None]).sum(-2) / count[..., None]
    ens = ((s[..., None] <= radii) * m[..., None]).sum(-2) / count[..., None]
    return EnergyCurves(radius_mm=radii, encircled=_weighted(enc, system), ensquared=_weighted(ens, system),
                        encircled_w=enc, ensquared_w=ens, center=c, rel_field=b.rel_field,
                        field_deg=torch.rad2deg(torch.atan(b.tan_field)), wavelength_um=lens.wavelength_um,
                        method="geometric", airy_radius_mm=_airy(lens, system))


def pupil_cell_area(alpha: Tensor, beta: Tensor, amp: Tensor, n: int) -> Tensor:
    """(…, N²) area J_p of direction-cosine space each sample of an N×N pupil grid covers: the
    determinant of the central-difference Jacobian ∂(α, β)/∂(column, row). Samples whose four
    neighbours are not all in the pupil (its rim, failed rays) get the median of the others."""
    shape = (*alpha.shape[:-1], n, n)
    a, b = alpha.reshape(shape), beta.reshape(shape)
    a_r, a_c = torch.gradient(a, dim=(-2, -1))
    b_r, b_c = torch.gradient(b, dim=(-2, -1))
    jac = (a_c * b_r - a_r * b_c).abs().reshape(alpha.shape)
    inside = amp.reshape(shape) > 0
    ok = inside.clone()
    for dim in (-2, -1):
        for shift in (1, -1):
            ok = ok & torch.roll(inside, shift, dim)  # the grid's outer rows lie outside the pupil circle
    ok = ok.reshape(alpha.shape)
    med = torch.nanmedian(torch.where(ok, jac, torch.full_like(jac, math.nan)), dim=-1, keepdim=True).values
    return torch.where(ok, jac, med)


@torch.no_grad()
def diffraction_energy(lens: Lens, system: System, *, rel_field: Tensor, radii: Tensor | None = None,
                       pupil_samples: int | None = None, pitch_mm: float | None = None, center: str = "centroid",
                       sampling: str = "rings:16", engine: Engine | None = None) -> EnergyCurves:
    """Diffraction encircled/ensquared energy (see the module docstring).

    Args:
        radii: (R,) radii; default 201 radii up to the geometric extent plus 6 Airy radii.
        pupil_samples: pupil grid N (N×N rays). The PSF of a sampled pupil repeats with period λ/Δα,
            Δα = 2 NA/N, so the largest radius must stay below half of it; default: enough for ``radii``
            (at least 64, at most 512).
        pitch_mm: grid pitch; default the Airy radius / 12.
        sampling: rays of the geometric spot that sets the centroid and the default extent.
    """
    fo = first_order(lens, system)
    wn = abs(float(fo.working_fnumber))
    airy = _airy(lens, system)
    rel_field = fields_of(lens, system, rel_field)
    geo = geometric_energy(lens, system, rel_field=rel_field, sampling=sampling, center=center, engine=engine)
    if radii is None:
        extent = float(geo.radius_mm[-1]) / 1.1
        radii = torch.linspace(0.0, extent + 6.0 * airy, 201, dtype=lens.dtype, device=lens.device)
    radii = radii.to(lens.dtype)
    r_max = float(radii.max())
    lam_min, n_img = float(lens.wavelength_um.min()) * 1e-3, float(lens.index[-1].max())
    need = math.ceil(2.2 * r_max * n_img / (lam_min * wn))  # the PSF repeats every λ/Δα, Δα = 2 NA/N
    n = pupil_samples if pupil_samples is not None else min(max(64, need), 512)
    if n < need:
        raise LensoptError(f"too few for radii up to {1e3 * r_max:.4g} µm: the PSF repeats every "
                           f"{1e3 * lam_min * wn * n / n_img:.4g} µm; use at least {need}",
                           path="pupil_samples", got=n)
    pitch = pitch_mm or airy / 12.0
    half = math.ceil(r_max / pitch) + 1
    coord = torch.arange(-half, half + 1, dtype=torch.float64, device=lens.device) * pitch
    opd, alpha, beta, amp = wavefront_error(lens, system, rel_field, geo.center, n, engine=engine)
    area = pupil_cell_area(alpha, beta, amp, n)
    rr = torch.sqrt(coord[None, :] ** 2 + coord[:, None] ** 2)  # (Y, X)
    sq = coord.abs()
    rad = radii.double()
    ring = ((rad[:, None, None] - rr) / pitch + 0.5).clamp(0.0, 1.0)  # (R, Y, X) pixel-in-circle weights
    box = ((rad[:, None] - sq) / pitch + 0.5).clamp(0.0, 1.0)  # (R, X)
    num_f, num_w = opd.shape[:2]
    enc = torch.zeros(num_f, num_w, rad.shape[0], dtype=torch.float64, device=lens.device)
    ens = torch.zeros_like(enc)
    for f in range(num_f):
        for w in range(num_w):
            lam_mm = float(lens.wavelength_um[w]) * 1e-3
            inten = debye_intensity(opd[f, w], alpha[f, w], beta[f, w], amp[f, w], 2.0 * math.pi / lam_mm,
                                    coord, coord)
            total = lam_mm**2 * (amp[f, w].double() / area[f, w].double()).sum()
            e = inten * pitch**2 / total
            enc[f, w] = (ring * e).sum((-2, -1))
            ens[f, w] = torch.einsum("ry,yx,rx->r", box, e, box)
    enc, ens = enc.to(lens.dtype), ens.to(lens.dtype)
    return EnergyCurves(radius_mm=radii, encircled=_weighted(enc, system), ensquared=_weighted(ens, system),
                        encircled_w=enc, ensquared_w=ens, center=geo.center, rel_field=geo.rel_field,
                        field_deg=geo.field_deg, wavelength_um=lens.wavelength_um, method="diffraction",
                        airy_radius_mm=airy)
