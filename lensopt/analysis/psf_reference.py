"""Reference diffraction PSF: Fourier transform of the exit-pupil field (for validation, S4.4.3/S7.1).

For each field and wavelength, a full N×N grid of rays is traced through the entrance pupil (points
outside the unit circle get zero amplitude). The optical path length of every ray is accumulated from
a plane wavefront in object space (or from the object point) to the reference sphere centred on the
PSF grid centre P0 and passing through the exit pupil centre (where the chief ray crosses the paraxial
exit-pupil plane; ``analysis.wavefront.trace_to_sphere``, the one home of this computation), which
gives the path W. In the Debye approximation the image field is

    E(x, y) = Σ_p a_p exp(i k [W_p + α_p x + β_p y]),       k = 2π/λ,

with (α_p, β_p) the direction cosines from ray p's point on the reference sphere towards P0 and
(x, y) the image-plane offsets from P0. The sum is evaluated directly on sub-pixel points of the PSF
grid (a non-uniform DFT done as two matrix products), so no pupil resampling or zero padding is
needed and pupil distortion is kept. Intensities are averaged over each bin and normalized to sum 1
on the grid (as the seed post-processes CODE V PSFs). Uniform pupil amplitude (no apodization).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from lensopt.analysis.wavefront import map_grid, trace_to_sphere
from lensopt.engine import Engine
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import first_order

__all__ = ["diffraction_psf", "debye_intensity", "pupil_samples_for", "wavefront_error"]


def pupil_samples_for(half_width_mm: float, wavelength_um: float, working_fnumber: float) -> int:
    """Pupil samples across the diameter so that the DFT's replicas (period λ/Δα, Δα = 2 NA/N) lie
    beyond twice the grid half-width."""
    na = 1.0 / (2.0 * abs(working_fnumber))
    n = math.ceil(4.0 * na * half_width_mm / (wavelength_um * 1e-3)) + 16
    return int(min(max(n, 64), 512))


def wavefront_error(
    lens: Lens, system: System, rel_field: Tensor, center: Tensor, n: int, *, engine: Engine | None = None
) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Optical path and Debye direction cosines on an N×N entrance-pupil grid, from
    ``analysis.wavefront.trace_to_sphere`` (the reference sphere about P0, CODE V's radius).

    Args:
        rel_field: (F,) relative fields.
        center: (F, 2) reference points P0 on the image surface, mm.
        n: pupil samples per diameter.

    Returns:
        opd: (F, W, N²) optical path to the sphere about P0 minus its mean, mm (the phase of the
            Debye sum; the opposite sign of ``analysis.wavefront``'s W, which is ahead-positive).
        alpha, beta: (F, W, N²) direction cosines towards P0, times n'.
        amp: (F, W, N²) 1 for rays inside the pupil that reached the image, else 0.
    """
    dt = lens.dtype
    pupil, inside = map_grid(n, dtype=dt, device=lens.device)
    st = trace_to_sphere(lens, system, pupil, rel_field=rel_field, center=center, engine=engine)
    ok = st.valid & inside
    amp = ok.to(dt)
    mean = (st.opl * amp).sum(-1, keepdim=True) / amp.sum(-1, keepdim=True).clamp_min(1.0)
    opd = torch.where(ok, st.opl - mean, torch.zeros_like(st.opl))
    n_img = lens.index[-1][None, :, None]
    return opd, st.towards[..., 0] * n_img, st.towards[..., 1] * n_img, amp


@torch.no_grad()
def diffraction_psf(
    lens: Lens,
    system: System,
    rel_field: Tensor,
    center: Tensor,
    *,
    pitch_mm: float,
    size: int,
    pupil_samples: int | None = None,
    subsamples: int = 3,
    chunk: int = 16384,
    engine: Engine | None = None,
) -> Tensor:
    """(F, W, S, S) diffraction PSFs on grids centred on ``center`` ((F, 2) mm), each summing to 1,
    in the orientation of ``lensopt.analysis.psf`` (row index grows with +y)."""
    wn = float(first_order(lens, system).working_fnumber)
    half = (size // 2 + 0.5) * pitch_mm
    n = pupil_samples or pupil_samples_for(half, float(lens.wavelength_um.min()), wn)
    opd, alpha, beta, amp = wavefront_error(lens, system, rel_field, center.to(lens.dtype), n, engine=engine)
    o = subsamples
    j = torch.arange(size * o, dtype=torch.float64, device=lens.device)
    coord = (j - (size * o - 1) / 2) * (pitch_mm / o)  # sub-pixel sample positions, mm
    num_f, num_w = opd.shape[:2]
    out = torch.zeros(num_f, num_w, size, size, dtype=torch.float64, device=lens.device)
    for f in range(num_f):
        for w in range(num_w):
            k = 2.0 * math.pi / (float(lens.wavelength_um[w]) * 1e-3)
            inten = debye_intensity(opd[f, w], alpha[f, w], beta[f, w], amp[f, w], k, coord, coord, chunk=chunk)
            inten = inten.reshape(size, o, size, o).sum((1, 3))
            out[f, w] = inten / inten.sum().clamp_min(torch.finfo(torch.float64).tiny)
    return out


def debye_intensity(opd: Tensor, alpha: Tensor, beta: Tensor, amp: Tensor, k: float, xs: Tensor, ys: Tensor,
                    *, chunk: int = 16384) -> Tensor:
    """(Y, X) intensity |E|² of the Debye sum at the image offsets ``xs`` (X,) and ``ys`` (Y,) from P0, mm,
    unnormalized: a perfect wavefront (opd = 0) gives (Σ a)² at P0.

    Args:
        opd, alpha, beta, amp: (P,) one field and wavelength of ``wavefront_error``.
        k: wavenumber 2π/λ, 1/mm.
    """
    xs, ys = xs.double(), ys.double()
    field = torch.zeros(ys.shape[0], xs.shape[0], dtype=torch.complex128, device=opd.device)
    for start in range(0, opd.shape[-1], chunk):
        sl = slice(start, start + chunk)
        keep = amp[sl] > 0
        if not bool(keep.any()):
            continue
        a = alpha[sl][keep].double()
        b_ = beta[sl][keep].double()
        ph = opd[sl][keep].double()
        w = amp[sl][keep].double()
        cx = torch.polar(torch.ones(a.shape[0], xs.shape[0], dtype=torch.float64, device=opd.device),
                         k * a[:, None] * xs[None, :])  # (P, X)
        by = torch.polar(torch.ones(ys.shape[0], a.shape[0], dtype=torch.float64, device=opd.device),
                         k * ys[:, None] * b_[None, :])  # (Y, P)
        cp = torch.polar(w, k * ph)
        field = field + by @ (cp[:, None] * cx)
    return field.abs() ** 2
