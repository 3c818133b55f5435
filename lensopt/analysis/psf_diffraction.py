"""The diffraction heuristic of S1.4.3: each ray spreads an Airy *field* pattern; the fields interfere.

``heuristic = |sqrt(K_geo) ⊛ U_Airy|²`` renormalized to the energy of ``K_geo``, with
``U_Airy(r) = 2 J1(v)/v``, ``v = k NA r``, ``k = 2π/λ``, ``NA = 1/(2 N_w)`` from the working f-number
(S25). A Dirac geometric PSF gives the Airy intensity pattern. ``incoherent`` is the naive variant of
S7.1 (geometric PSF convolved with the Airy *intensity*), kept for comparison.

Gradients flow through the geometric PSF; the Airy kernel is built from detached values (it depends
on the lens only through the working f-number, which barely changes between optimization steps).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from lensopt.analysis.fft_size import next_fast_len

__all__ = ["airy_radius_mm", "airy_field", "fft_convolve_same", "diffraction_heuristic", "incoherent_airy"]


def airy_radius_mm(wavelength_um: Tensor | float, working_fnumber: Tensor | float) -> Tensor:
    """Radius of the first dark ring r1 = 0.61 λ / NA = 1.22 λ N_w, mm."""
    lam = torch.as_tensor(wavelength_um, dtype=torch.float64) * 1e-3
    return 1.22 * lam * torch.as_tensor(working_fnumber, dtype=torch.float64).abs()


def airy_field(
    wavelength_um: Tensor,
    working_fnumber: float,
    pitch_mm: float,
    *,
    dark_rings: float = 3.0,
    image_index: float = 1.0,
    dtype: torch.dtype = torch.float64,
) -> Tensor:
    """Airy field kernels sampled at bin centres, one per wavelength, all the same odd size K.

    K covers ``2·dark_rings·r1`` of the longest wavelength (the seed asks S_Airy ≥ 6 r1) and is at
    least 3 bins. Each kernel is scaled so that its squared values sum to 1.

    Args:
        wavelength_um: (W,) wavelengths, µm.
        working_fnumber: image-space working f-number N_w.
        pitch_mm: bin size, mm.
        image_index: refractive index of image space n' (NA = n'/(2 N_w) with the paraxial N_w).

    Returns:
        (W, K, K) real field kernels (positive centre lobe, negative first ring).
    """
    lam_mm = wavelength_um.detach().to(torch.float64) * 1e-3
    na = image_index / (2.0 * abs(float(working_fnumber)))
    r1 = 0.61 * float(lam_mm.max()) / na
    half = max(1, math.ceil(dark_rings * r1 / pitch_mm))
    c = torch.arange(-half, half + 1, dtype=torch.float64) * pitch_mm
    r = torch.sqrt(c[None, :] ** 2 + c[:, None] ** 2)  # (K, K)
    v = (2.0 * math.pi / lam_mm)[:, None, None] * na * r  # (W, K, K)
    safe = torch.where(v > 1e-8, v, torch.ones_like(v))
    u = torch.where(v > 1e-8, 2.0 * torch.special.bessel_j1(safe) / safe, torch.ones_like(v))
    u = u / torch.sqrt((u * u).sum((-1, -2), keepdim=True))
    return u.to(dtype=dtype, device=wavelength_um.device)


def fft_convolve_same(x: Tensor, k: Tensor) -> Tensor:
    """Linear 2D convolution of ``x`` (*B, H, W) with odd-sized kernels ``k`` (*B', Kh, Kw)
    (broadcast over the batch), cropped to the input size ("same", centred), via real FFTs."""
    h, w = x.shape[-2:]
    kh, kw = k.shape[-2:]
    fh, fw = next_fast_len(h + kh - 1), next_fast_len(w + kw - 1)
    spec = torch.fft.rfft2(x, s=(fh, fw)) * torch.fft.rfft2(k.to(x.dtype), s=(fh, fw))
    full = torch.fft.irfft2(spec, s=(fh, fw))
    oy, ox = (kh - 1) // 2, (kw - 1) // 2
    return full[..., oy:oy + h, ox:ox + w]


def diffraction_heuristic(psf: Tensor, field: Tensor) -> Tensor:
    """S1.4.3: |sqrt(psf) ⊛ field|², renormalized to the energy of ``psf`` per grid.

    Args:
        psf: (*B, W, S, S) geometric PSFs (non-negative).
        field: (W, K, K) Airy field kernels (``airy_field``) on the same bin pitch.

    Returns:
        (*B, W, S, S) diffraction-compensated PSFs.
    """
    tiny = torch.finfo(psf.dtype).tiny
    amp = torch.sqrt(psf.clamp_min(torch.finfo(psf.dtype).eps ** 2))  # finite gradient at empty bins
    out = fft_convolve_same(amp, field) ** 2
    total = psf.sum((-1, -2), keepdim=True)
    return out * total / out.sum((-1, -2), keepdim=True).clamp_min(tiny)


def incoherent_airy(psf: Tensor, field: Tensor) -> Tensor:
    """Naive variant (S7.1): psf ⊛ |field|², renormalized to the energy of ``psf``."""
    tiny = torch.finfo(psf.dtype).tiny
    inten = field**2
    out = fft_convolve_same(psf, inten / inten.sum((-1, -2), keepdim=True)).clamp_min(0.0)
    total = psf.sum((-1, -2), keepdim=True)
    return out * total / out.sum((-1, -2), keepdim=True).clamp_min(tiny)
