"""Strehl ratio per field and wavelength: from the diffraction PSF, and the Maréchal estimate.

**From the PSF**: the peak of the Debye PSF (``analysis.psf_reference``: the sum over pupil rays of
``a_p exp(i k [W_p + α_p x + β_p y])``) divided by the peak of the same pupil with W = 0, ``(Σ a)²``.
The peak is searched on the image surface about the chief ray (four nested 21 × 21 grids, the finest
spacing about 1/1000 of the Airy radius), so a lateral shift (tilt) costs nothing, as in Zemax's Huygens PSF
Strehl; there is no refocusing.

**Maréchal**: ``exp(−(2π σ)²)`` with σ the RMS wavefront error in waves with piston and tilt removed
(``WavefrontStats.rms``); good to a few per cent above a Strehl of about 0.5.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.analysis.checks import fields_of
from lensopt.analysis.psf_reference import debye_intensity
from lensopt.analysis.wavefront import Wavefront, map_grid, trace_to_sphere, wavefront_stats
from lensopt.engine import Engine
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import first_order

__all__ = ["StrehlResult", "strehl", "marechal", "peak_strehl"]


def marechal(rms_waves: Tensor) -> Tensor:
    """Maréchal's estimate ``exp(−(2π σ)²)`` of the Strehl ratio from the RMS wavefront error σ (waves)."""
    return torch.exp(-((2.0 * math.pi * rms_waves) ** 2))


def peak_strehl(opd_mm: Tensor, alpha: Tensor, beta: Tensor, amp: Tensor, wavelength_um: float,
                airy_mm: float, *, levels: int = 4, points: int = 21) -> tuple[float, tuple[float, float]]:
    """Strehl ratio of one pupil (``opd_mm`` path, ``alpha``/``beta`` direction cosines × n', ``amp``;
    each (P,)), and the (x, y) offset of the peak from P0, mm. ``airy_mm`` sets the search span (±3)."""
    k = 2.0 * math.pi / (wavelength_um * 1e-3)
    perfect = float(amp.double().sum()) ** 2
    if perfect <= 0:
        return 0.0, (0.0, 0.0)
    cx = cy = 0.0
    span = 3.0 * airy_mm
    best = 0.0
    for _ in range(levels):
        g = torch.linspace(-span, span, points, dtype=torch.float64, device=opd_mm.device)
        inten = debye_intensity(opd_mm, alpha, beta, amp, k, g + cx, g + cy)
        i = int(torch.argmax(inten))
        best = float(inten.reshape(-1)[i])
        cy, cx = cy + float(g[i // points]), cx + float(g[i % points])
        span = span * 2.0 / (points - 1) * 1.5
    return best / perfect, (cx, cy)


@dataclass(frozen=True)
class StrehlResult:
    """Strehl ratios per field and wavelength.

    Attributes:
        psf: (F, W) peak of the diffraction PSF over the perfect peak.
        marechal: (F, W) exp(−(2π σ)²) of the same pupil sampling's tilt-removed RMS σ.
        rms_waves: (F, W) that σ.
        peak_offset_mm: (F, W, 2) where the peak lies, relative to the chief ray.
        wavefront: the sampled wavefront (an N×N grid).
    """

    psf: Tensor
    marechal: Tensor
    rms_waves: Tensor
    peak_offset_mm: Tensor
    wavefront: Wavefront


@torch.no_grad()
def strehl(lens: Lens, system: System, *, rel_field: Tensor, pupil_samples: int = 64,
           engine: Engine | None = None) -> StrehlResult:
    """Strehl ratio (PSF peak and Maréchal) of every field and wavelength, from an N×N pupil grid."""
    dt = lens.dtype
    fo = first_order(lens, system)
    pupil, inside = map_grid(pupil_samples, dtype=dt, device=lens.device)
    st = trace_to_sphere(lens, system, pupil, rel_field=fields_of(lens, system, rel_field), fo=fo, engine=engine)
    ok = st.valid & inside & st.chief_valid.unsqueeze(-1)
    lam_mm = lens.wavelength_um[None, :, None] * 1e-3
    w = torch.where(ok, (st.chief_opl.unsqueeze(-1) - st.opl) / lam_mm, torch.zeros_like(st.opl))
    b = st.bundle
    wf = Wavefront(pupil=pupil, opd=w, valid=ok, rel_field=b.rel_field,
                   field_deg=torch.rad2deg(torch.atan(b.tan_field)), wavelength_um=lens.wavelength_um,
                   reference=system.reference, radius_mm=st.radius, chief=st.center[..., :2],
                   chief_valid=st.chief_valid)
    rms = wavefront_stats(wf).rms
    n_img = lens.index[-1]
    wn = abs(float(fo.working_fnumber))
    num_f, num_w = w.shape[:2]
    psf = torch.zeros(num_f, num_w, dtype=dt, device=lens.device)
    offset = torch.zeros(num_f, num_w, 2, dtype=dt, device=lens.device)
    path = torch.where(ok, st.opl - st.chief_opl.unsqueeze(-1), torch.zeros_like(st.opl))
    for f in range(num_f):
        for j in range(num_w):
            lam = float(lens.wavelength_um[j])
            airy = 1.22 * lam * 1e-3 * wn / float(n_img[j])
            s, (x, y) = peak_strehl(path[f, j], st.towards[f, j, :, 0] * n_img[j], st.towards[f, j, :, 1] * n_img[j],
                                    ok[f, j].to(dt), lam, airy)
            psf[f, j] = s
            offset[f, j, 0], offset[f, j, 1] = x, y
    return StrehlResult(psf=psf, marechal=marechal(rms), rms_waves=rms, peak_offset_mm=offset, wavefront=wf)
