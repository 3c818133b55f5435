"""Modulation transfer function from PSFs: sagittal and tangential MTF per field at chosen frequencies.

The OTF is the Fourier transform of the PSF; along one direction it is the transform of the line
spread function, ``OTF(ν) = Σ_{x,y} K(x, y) exp(−2πi ν x) / Σ K``. Fields lie along +y, so the
**tangential** (meridional) MTF has its frequency along y and the **sagittal** one along x. The
transform is a direct sum at the requested frequencies (no FFT grid, no interpolation).

PSFs estimated on bins carry the bins' own transfer: box integration over a pitch p (``count``
deposits, the reference PSF's averaged sub-samples) multiplies the MTF by sinc(ν p), a triangular
kernel (``triangular`` KDE, support 2) by sinc²(ν p). ``mtf_from_psf(..., bin_transfer=...)`` divides
that back out, so the result is the lens's MTF, not the lens's and the grid's.

The PSFs come from ``analysis.psf_stack`` (geometric with the diffraction heuristic of S1.4.3) or from
``analysis.psf_reference`` (the FFT/Debye reference). The closed form of a perfect lens with a circular
pupil, ``(2/π)(acos s − s sqrt(1 − s²))`` with ``s = ν λ N_w``, is ``diffraction_limited_mtf``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.analysis.psf import mirror_half_pupil
from lensopt.analysis.psf_reference import diffraction_psf
from lensopt.analysis.psf_stack import PsfSettings, compute_psfs
from lensopt.analysis.spot import spot_stats
from lensopt.engine import Engine
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import PupilSampling

__all__ = ["MtfResult", "otf_from_psf", "mtf_from_psf", "diffraction_limited_mtf", "lens_mtf", "MTF_METHODS",
           "bin_transfer"]

MTF_METHODS = ("heuristic", "geometric", "reference")


@dataclass(frozen=True)
class MtfResult:
    """MTF of a lens per field (polychromatic, weighted by the spectral weights).

    Attributes:
        frequency: (K,) spatial frequencies, cycles/mm.
        sagittal: (F, K) MTF with the frequency along x.
        tangential: (F, K) MTF with the frequency along y (the field direction).
        rel_field: (F,) relative fields.
        method: ``heuristic``, ``geometric`` or ``reference``.
        cutoff: () incoherent cutoff 1/(λ_min N_w), cycles/mm.
    """

    frequency: Tensor
    sagittal: Tensor
    tangential: Tensor
    rel_field: Tensor
    method: str
    cutoff: float


def bin_transfer(kernel: str) -> int:
    """Power of sinc(ν p) that a PSF estimated with ``kernel`` carries (0: not corrected)."""
    return {"count": 1, "triangular": 2, "box": 1}.get(kernel, 0)


def otf_from_psf(psf: Tensor, pitch_mm: float, frequency: Tensor, *, bin_power: int = 0
                 ) -> tuple[tuple[Tensor, Tensor], tuple[Tensor, Tensor]]:
    """Complex OTF of PSF grids along x (sagittal) and y (tangential), as (real, imaginary) pairs.

    Args:
        psf: (*, S, S) PSFs, row index growing with +y, column with +x, bin centres every ``pitch_mm``,
            centred on the grid centre (the phase is relative to it).
        pitch_mm: bin size, mm.
        frequency: (K,) cycles/mm.
        bin_power: divide by sinc(ν p)^bin_power (the grid's own transfer, see the module docstring).

    Returns:
        ((re, im) sagittal, (re, im) tangential), each (*, K), normalized to 1 at ν = 0.
    """
    size = psf.shape[-1]
    dt = psf.dtype if psf.dtype.is_floating_point else torch.float64
    coord = (torch.arange(size, dtype=dt, device=psf.device) - (size - 1) / 2) * pitch_mm
    nu = frequency.to(dt)
    phase = -2.0 * math.pi * nu[:, None] * coord[None, :]  # (K, S)
    cos, sin = torch.cos(phase), torch.sin(phase)
    total = psf.sum((-2, -1)).clamp_min(torch.finfo(dt).tiny)[..., None]
    scale = torch.ones_like(nu)
    if bin_power:
        s = torch.sinc(nu * pitch_mm) ** bin_power  # torch.sinc is sin(πx)/(πx)
        scale = torch.where(s.abs() > 1e-3, s, torch.ones_like(s))

    def transform(lsf: Tensor) -> tuple[Tensor, Tensor]:
        return (lsf @ cos.T) / total / scale, (lsf @ sin.T) / total / scale

    return transform(psf.sum(-2)), transform(psf.sum(-1))  # LSF along x (sum over y), along y


def mtf_from_psf(psf: Tensor, pitch_mm: float, frequency: Tensor, *, bin_power: int = 0) -> tuple[Tensor, Tensor]:
    """Sagittal and tangential MTF ((*, K) each) of PSF grids; arguments as ``otf_from_psf``."""
    (sr, si), (tr, ti) = otf_from_psf(psf, pitch_mm, frequency, bin_power=bin_power)
    return torch.sqrt(sr * sr + si * si), torch.sqrt(tr * tr + ti * ti)


def ray_otf(lens: Lens, system: System, rel_field: Tensor, frequency: Tensor, *, sampling: str = "rings:32",
            engine: Engine | None = None) -> tuple[tuple[Tensor, Tensor], tuple[Tensor, Tensor]]:
    """Geometric OTF per field and wavelength from the ray intercepts themselves (every ray the same
    pupil area): ``Σ_r exp(−2πi ν (x_r − x̄)) / n`` along x (sagittal) and y (tangential), about the
    field's polychromatic centroid; failed rays carry no weight. Returns (re, im) pairs of (F, W, K)."""
    scheme = PupilSampling.parse(sampling, path="mtf.sampling")
    bundle = trace_bundle(lens, system, scheme.points(dtype=lens.dtype, device=lens.device, engine=engine),
                          half_pupil=scheme.half, rel_field=rel_field, engine=engine)
    center = spot_stats(bundle, system.wavelength_weights).centroid  # (F, 2)
    xy, valid = bundle.result.pos[..., :2], bundle.result.valid
    if bundle.half_pupil:
        xy, valid = mirror_half_pupil(xy, valid, 0.0)
    d = xy - center[:, None, None, :]
    m = valid.to(lens.dtype)
    count = m.sum(-1).clamp_min(1.0)[..., None]  # (F, W, 1)

    def transform(u: Tensor) -> tuple[Tensor, Tensor]:
        phase = -2.0 * math.pi * u[..., None] * frequency  # (F, W, P, K)
        return ((m[..., None] * torch.cos(phase)).sum(-2) / count,
                (m[..., None] * torch.sin(phase)).sum(-2) / count)

    return transform(d[..., 0]), transform(d[..., 1])


def diffraction_limited_mtf(frequency: Tensor, wavelength_um: float, working_fnumber: float) -> Tensor:
    """Closed-form MTF of an aberration-free lens with a uniformly filled circular pupil (cycles/mm)."""
    s = (frequency * wavelength_um * 1e-3 * abs(working_fnumber)).clamp(0.0, 1.0)
    return 2.0 / math.pi * (torch.acos(s) - s * torch.sqrt(1.0 - s * s))


def lens_mtf(
    lens: Lens,
    system: System,
    frequency: Tensor,
    *,
    rel_field: Tensor | None = None,
    method: str = "heuristic",
    pitch_mm: float | None = None,
    sampling: str = "rings:32",
    size: int | None = None,
    pupil_samples: int | None = None,
    engine: Engine | None = None,
) -> MtfResult:
    """Polychromatic sagittal/tangential MTF per field.

    Args:
        frequency: (K,) cycles/mm.
        rel_field: (F,) relative fields; default: the system's.
        method: ``heuristic`` (geometric PSF convolved with the Airy intensity per wavelength — the
            incoherent heuristic of S7.1, done in the frequency domain with the closed-form pupil MTF,
            so the Airy pattern is not truncated), ``geometric`` (no diffraction) or ``reference``
            (the Debye/FFT reference PSF of ``analysis.psf_reference``, slow).
        pitch_mm: PSF bin size of ``reference``; default λ_min N_w / 4.
        sampling: pupil sampling of the geometric PSF (the rays).
        size: PSF grid bins per side (odd); default automatic (``reference``: 8 Airy radii + spot).
        pupil_samples: pupil samples across the diameter for ``reference``.
    """
    if method not in MTF_METHODS:
        raise ValueError(f"method must be one of {MTF_METHODS}, got {method!r}")
    if rel_field is None:
        rel_field = torch.tensor(system.rel_field, dtype=lens.dtype, device=lens.device)
    fo = first_order(lens, system)
    wn = float(fo.working_fnumber.detach())
    lam_min = float(lens.wavelength_um.min())
    cutoff = 1.0 / (lam_min * 1e-3 * abs(wn))
    pitch = pitch_mm or lam_min * 1e-3 * abs(wn) / 4.0
    weights = system.wavelength_weights.to(lens.dtype)
    weights = weights / weights.sum()
    if method == "reference":
        settings = PsfSettings(sampling=sampling, kernel="count", pitch_mm=pitch, diffraction="none")
        geo = compute_psfs(lens, system, rel_field, settings, fo=fo, engine=engine)
        if size is None:
            airy = 8 * 1.22 * float(lens.wavelength_um.max()) * 1e-3 * abs(wn)
            size = 2 * math.ceil((geo.psf.shape[-1] // 2 * pitch + airy) / pitch) + 1
        psf = diffraction_psf(lens, system, rel_field, geo.center, pitch_mm=pitch, size=size,
                              pupil_samples=pupil_samples, engine=engine)
        poly = torch.einsum("fwij,w->fij", psf.to(lens.dtype), weights)
        sag, tan = mtf_from_psf(poly, pitch, frequency.to(lens.dtype), bin_power=1)
    else:
        # The geometric PSF is the set of ray intercepts: its OTF is their exact transform (no bins),
        # taken about the polychromatic centroid. The heuristic multiplies each wavelength's OTF by the
        # closed-form MTF of the diffraction-limited pupil (= the geometric PSF convolved with the
        # full, untruncated Airy intensity), then sums over wavelengths.
        nu = frequency.to(lens.dtype)
        (sr, si), (tr, ti) = ray_otf(lens, system, rel_field, nu, sampling=sampling, engine=engine)  # (F, W, K)
        w = weights[None, :, None]
        if method == "heuristic":
            dl = torch.stack([diffraction_limited_mtf(nu, float(lam), wn) for lam in lens.wavelength_um])
            w = w * dl[None]
        sag = torch.sqrt((w * sr).sum(1) ** 2 + (w * si).sum(1) ** 2)
        tan = torch.sqrt((w * tr).sum(1) ** 2 + (w * ti).sum(1) ** 2)
    return MtfResult(frequency=frequency, sagittal=sag, tangential=tan, rel_field=rel_field, method=method,
                     cutoff=cutoff)
