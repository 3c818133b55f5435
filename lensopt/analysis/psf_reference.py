"""Reference diffraction PSF: Fourier transform of the exit-pupil field (for validation, S4.4.3/S7.1).

For each field and wavelength, a full N×N grid of rays is traced through the entrance pupil (points
outside the unit circle get zero amplitude). The optical path length of every ray is accumulated from
a plane wavefront in object space (or from the object point) to the reference sphere centred on the
PSF grid centre P0 and passing through the exit pupil centre (where the chief ray crosses the paraxial
exit-pupil plane), which gives the wavefront error W. In the Debye approximation the image field is

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

from lensopt.optics.bundle import trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import first_order

__all__ = ["diffraction_psf", "pupil_samples_for", "wavefront_error"]


def pupil_samples_for(half_width_mm: float, wavelength_um: float, working_fnumber: float) -> int:
    """Pupil samples across the diameter so that the DFT's replicas (period λ/Δα, Δα = 2 NA/N) lie
    beyond twice the grid half-width."""
    na = 1.0 / (2.0 * abs(working_fnumber))
    n = math.ceil(4.0 * na * half_width_mm / (wavelength_um * 1e-3)) + 16
    return int(min(max(n, 64), 512))


def wavefront_error(
    lens: Lens, system: System, rel_field: Tensor, center: Tensor, n: int
) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Wavefront error and Debye direction cosines on an N×N entrance-pupil grid.

    Args:
        rel_field: (F,) relative fields.
        center: (F, 2) reference points P0 on the image surface, mm.
        n: pupil samples per diameter.

    Returns:
        opd: (F, W, N²) wavefront error relative to the sphere about P0, mm (mean removed).
        alpha, beta: (F, W, N²) direction cosines towards P0.
        amp: (F, W, N²) 1 for rays inside the pupil that reached the image, else 0.
    """
    dt = lens.dtype
    c = -1.0 + (2.0 * torch.arange(n, dtype=dt, device=lens.device) + 1.0) / n
    py, px = torch.meshgrid(c, c, indexing="ij")
    pupil = torch.stack([px.reshape(-1), py.reshape(-1)], -1)
    inside = (pupil**2).sum(-1) <= 1.0
    fo = first_order(lens, system)
    b = trace_bundle(lens, system, pupil, rel_field=rel_field, record=True, fo=fo)
    chief = trace_bundle(lens, system, torch.zeros(1, 2, dtype=dt, device=lens.device), rel_field=rel_field, fo=fo)
    res = b.result
    nidx = lens.index  # (S+1, W)
    if system.object_distance is None:
        opl = nidx[0][None, :, None] * (b.rays.pos * b.rays.dir).sum(-1)
    else:
        opl = torch.zeros(res.pos.shape[:-1], dtype=dt, device=lens.device)
    for s, hit in enumerate(res.hits):
        opl = opl + nidx[s][None, :, None] * hit.t
    last = res.hits[-1].pos
    n_img = nidx[-1][None, :, None]
    opl = opl + n_img * torch.linalg.vector_norm(res.pos - last, dim=-1)
    q, d = res.pos, res.dir  # on the image surface
    z_img = lens.vertex_z()[-1]
    p0 = torch.cat([center, z_img.expand(center.shape[0], 1)], -1)[:, None, None, :]  # (F,1,1,3)
    qc, dc = chief.result.pos, chief.result.dir  # (F, W, 1, 3)
    e = qc + dc * ((fo.exit_pupil_z - qc[..., 2]) / dc[..., 2]).unsqueeze(-1)
    radius = torch.linalg.vector_norm(p0 - e, dim=-1)  # (F, W, 1)
    sign = torch.where(fo.exit_pupil_z < z_img, 1.0, -1.0)
    rel = q - p0
    bb = (d * rel).sum(-1)
    cc = (rel * rel).sum(-1)
    disc = (bb * bb - cc + radius**2).clamp_min(0.0)
    s_extra = bb + sign * (bb * bb - cc) / (torch.sqrt(disc) + radius)  # s − sign·R, stable for large R
    opl_sphere = opl - n_img * s_extra
    sphere_pt = q - (sign * radius + s_extra).unsqueeze(-1) * d
    to_p0 = p0 - sphere_pt
    to_p0 = to_p0 / torch.linalg.vector_norm(to_p0, dim=-1, keepdim=True)
    ok = res.valid & inside
    amp = ok.to(dt)
    mean = (opl_sphere * amp).sum(-1, keepdim=True) / amp.sum(-1, keepdim=True).clamp_min(1.0)
    opd = torch.where(ok, opl_sphere - mean, torch.zeros_like(opl_sphere))
    return opd, to_p0[..., 0] * n_img, to_p0[..., 1] * n_img, amp


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
) -> Tensor:
    """(F, W, S, S) diffraction PSFs on grids centred on ``center`` ((F, 2) mm), each summing to 1,
    in the orientation of ``lensopt.analysis.psf`` (row index grows with +y)."""
    wn = float(first_order(lens, system).working_fnumber)
    half = (size // 2 + 0.5) * pitch_mm
    n = pupil_samples or pupil_samples_for(half, float(lens.wavelength_um.min()), wn)
    opd, alpha, beta, amp = wavefront_error(lens, system, rel_field, center.to(lens.dtype), n)
    o = subsamples
    j = torch.arange(size * o, dtype=torch.float64, device=lens.device)
    coord = (j - (size * o - 1) / 2) * (pitch_mm / o)  # sub-pixel sample positions, mm
    num_f, num_w = opd.shape[:2]
    out = torch.zeros(num_f, num_w, size, size, dtype=torch.float64, device=lens.device)
    for f in range(num_f):
        for w in range(num_w):
            k = 2.0 * math.pi / (float(lens.wavelength_um[w]) * 1e-3)
            field = torch.zeros(size * o, size * o, dtype=torch.complex128, device=lens.device)
            for start in range(0, opd.shape[-1], chunk):
                sl = slice(start, start + chunk)
                keep = amp[f, w, sl] > 0
                if not bool(keep.any()):
                    continue
                a = alpha[f, w, sl][keep].double()
                b_ = beta[f, w, sl][keep].double()
                ph = opd[f, w, sl][keep].double()
                cx = torch.polar(torch.ones(a.shape[0], coord.shape[0], dtype=torch.float64),
                                 k * a[:, None] * coord[None, :])  # (P, X)
                by = torch.polar(torch.ones(coord.shape[0], a.shape[0], dtype=torch.float64),
                                 k * coord[:, None] * b_[None, :])  # (Y, P)
                cp = torch.polar(torch.ones_like(ph), k * ph)
                field = field + by @ (cp[:, None] * cx)
            inten = field.abs() ** 2
            inten = inten.reshape(size, o, size, o).sum((1, 3))
            out[f, w] = inten / inten.sum().clamp_min(torch.finfo(torch.float64).tiny)
    return out
