"""Seidel (third-order) aberration sums per surface and in total, from the paraxial marginal and chief rays.

Welford's formulation (*Aberrations of Optical Systems*, 1986, ch. 8), at the reference wavelength, with
the paraxial marginal ray (axial object point through the edge of the entrance pupil) and chief ray
(full field, through the centre of the entrance pupil) of ``optics.paraxial``. At each surface, with n,
u, y, c the index, the ray slope before refraction, the ray height and the curvature (barred: chief ray)::

    A = n (u + y c),   Ā = n (ū + ȳ c),   Δ(u/n) = u'/n' − u/n,   H = n (ū y − u ȳ)  (Lagrange invariant)
    S_I   = −A² y Δ(u/n)              S_II = −A Ā y Δ(u/n)       S_III = −Ā² y Δ(u/n)
    S_IV  = −H² c Δ(1/n)              S_V  = (Ā/A)(S_III + S_IV) (computed in a form without 1/A)
    C_I   = A y Δ(δn/n)               C_II = Ā y Δ(δn/n)          δn = n(λ_short) − n(λ_long)

A conic κ or a fourth-order asphere coefficient a4 adds, with a = κ c³/8 + a4 the r⁴ sag term beyond
the sphere: δS_I = 8 a (n' − n) y⁴, δS_II = 8 a (n' − n) y³ ȳ, δS_III = 8 a (n' − n) y² ȳ²,
δS_V = 8 a (n' − n) y ȳ³ (higher asphere terms have no third-order effect). The colour terms use the
shortest and longest wavelengths of the spec (as optiland does; F and C for a visible F-d-C spec).

Units: the sums S and C are lengths (mm). The wavefront aberration coefficients (Welford eq. 8.23) are
``W040 = S_I/8``, ``W131 = S_II/2``, ``W222 = S_III/2``, ``W220P = S_IV/4`` (Petzval),
``W311 = S_V/2``, ``W020 = C_I/2``, ``W111 = C_II``; ``waves`` divides them by the reference
wavelength. Their sign is that of ``analysis.wavefront`` (ahead-positive): an under-corrected positive
singlet has S_I > 0 and W040 > 0. The transverse ray aberrations (mm, the "TSC, CC, TAC, TPC, DC, TAchC,
TchC" of Smith and optiland) are S/(2 n'u') and C/(n'u') with u' the image-space marginal slope.
optiland's ``SeidelAberrations.seidels()`` returns −S (its sums are −2 n'u' × the transverse ones).

Diffractive surfaces and decentered lenses are not supported (one-line error).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.errors import LensoptError
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import field_tangents, first_order, trace_paraxial

__all__ = ["SeidelSums", "seidel_sums", "SEIDEL_NAMES", "WAVE_NAMES"]

SEIDEL_NAMES = ("S_I", "S_II", "S_III", "S_IV", "S_V", "C_I", "C_II")
WAVE_NAMES = ("W040", "W131", "W222", "W220P", "W311", "W020", "W111")
_WAVE_FACTORS = (1 / 8, 1 / 2, 1 / 2, 1 / 4, 1 / 2, 1 / 2, 1.0)
_TRANSVERSE_NAMES = ("TSC", "CC", "TAC", "TPC", "DC", "TAchC", "TchC")


@dataclass(frozen=True)
class SeidelSums:
    """Seidel sums of a lens.

    Attributes:
        surfaces: (7, S) per-surface S_I … S_V, C_I, C_II (``SEIDEL_NAMES``), mm.
        total: (7,) their sums over the surfaces, mm.
        wavelength_um: reference wavelength, µm.
        color_wavelengths_um: (short, long) wavelengths of δn, µm.
        image_nu: n'u' of the marginal ray in image space (converts S to transverse aberrations).
        invariant: Lagrange invariant H, mm.
    """

    surfaces: Tensor
    total: Tensor
    wavelength_um: float
    color_wavelengths_um: tuple[float, float]
    image_nu: Tensor
    invariant: Tensor

    def waves(self, which: str = "total") -> Tensor:
        """Wavefront coefficients (``WAVE_NAMES``) in waves of the reference wavelength: (7,) for
        ``total``, (7, S) for ``surfaces``."""
        s = self.total if which == "total" else self.surfaces
        f = torch.tensor(_WAVE_FACTORS, dtype=s.dtype, device=s.device).reshape(-1, *[1] * (s.dim() - 1))
        return s * f / (self.wavelength_um * 1e-3)

    def transverse(self, which: str = "total") -> Tensor:
        """Transverse ray aberrations (TSC, CC, TAC, TPC, DC, TAchC, TchC), mm."""
        s = self.total if which == "total" else self.surfaces
        f = torch.tensor([2, 2, 2, 2, 2, 1, 1], dtype=s.dtype, device=s.device).reshape(-1, *[1] * (s.dim() - 1))
        return s / f / self.image_nu

    def as_dict(self) -> dict[str, object]:
        """Plain data (what ``lensopt trace --seidel --json`` prints)."""
        waves_t, waves_s = self.waves("total"), self.waves("surfaces")
        trans_t = self.transverse("total")
        return {
            "wavelength_nm": round(self.wavelength_um * 1e3, 9),
            "color_wavelengths_nm": [round(w * 1e3, 9) for w in self.color_wavelengths_um],
            "lagrange_invariant_mm": float(self.invariant),
            "total_mm": {k: float(v) for k, v in zip(SEIDEL_NAMES, self.total, strict=True)},
            "total_waves": {k: float(v) for k, v in zip(WAVE_NAMES, waves_t, strict=True)},
            "total_transverse_mm": {k: float(v) for k, v in zip(_TRANSVERSE_NAMES, trans_t, strict=True)},
            "surfaces_mm": [{k: float(self.surfaces[i, s]) for i, k in enumerate(SEIDEL_NAMES)}
                            for s in range(self.surfaces.shape[1])],
            "surfaces_waves": [{k: float(waves_s[i, s]) for i, k in enumerate(WAVE_NAMES)}
                               for s in range(waves_s.shape[1])],
        }


def seidel_sums(lens: Lens, system: System) -> SeidelSums:
    """Per-surface and total Seidel sums S_I … S_V and colour sums C_I, C_II (see the module docstring).
    Differentiable in the lens tensors."""
    if any(s.diffractive for s in lens.shapes):
        raise LensoptError("Seidel sums of diffractive surfaces are not supported", path="seidel")
    if lens.placement is not None:
        raise LensoptError("Seidel sums need a lens on its axis (this one is decentered or tilted)", path="seidel")
    w = system.reference
    fo = first_order(lens, system)
    n = lens.index[:, w]  # (S+1,)
    one = torch.ones((), dtype=lens.dtype, device=lens.device)

    h = fo.epd / 2
    if system.object_distance is None:
        y0, u0 = h, 0.0 * h
    else:
        u0 = h / (fo.entrance_pupil_z + system.object_distance)
        y0 = h - u0 * fo.entrance_pupil_z
    tan = field_tangents(lens, system, one)
    y, om = trace_paraxial(lens, w, y0, n[0] * u0)
    yb, omb = trace_paraxial(lens, w, -tan * fo.entrance_pupil_z, n[0] * tan)
    num = lens.num_surfaces
    y, yb = y[:num], yb[:num]  # heights at the surfaces
    n1, n2 = n[:-1], n[1:]
    om1, om2 = om[:num], om[1:]  # reduced angles before / after each surface
    omb1, omb2 = omb[:num], omb[1:]
    c = lens.curvature
    a_m = om1 + n1 * y * c  # A = n i
    a_c = omb1 + n1 * yb * c
    d_un = om2 / n2**2 - om1 / n1**2  # Δ(u/n)
    d_ubn = omb2 / n2**2 - omb1 / n1**2
    inv = omb[0] * y0 - om[0] * (-tan * fo.entrance_pupil_z)  # H = n(ū y − u ȳ) on surface 1's plane
    d_inv_n = 1.0 / n2 - 1.0 / n1

    s1 = -a_m**2 * y * d_un
    s2 = -a_m * a_c * y * d_un
    s3 = -a_c**2 * y * d_un
    s4 = -inv**2 * c * d_inv_n
    # S_V = (Ā/A)(S_III + S_IV) per surface, rewritten without 1/A (finite where A = 0):
    # S_V = −A Ā ȳ Δ(ū/n) − H (ū'² − ū²)  (the two agree wherever A ≠ 0; tests/analysis/test_seidel.py).
    s5 = -a_m * a_c * yb * d_ubn - inv * ((omb2 / n2) ** 2 - (omb1 / n1) ** 2)

    a4 = lens.asphere[:, 0] if lens.asphere.shape[-1] > 0 else torch.zeros_like(c)
    kinds = torch.tensor([s.kind in ("conic", "asphere") for s in lens.shapes], device=lens.device)
    a = torch.where(kinds, lens.conic * c**3 / 8.0, torch.zeros_like(c)) + a4
    dn = n2 - n1
    s1 = s1 + 8.0 * a * dn * y**4
    s2 = s2 + 8.0 * a * dn * y**3 * yb
    s3 = s3 + 8.0 * a * dn * y**2 * yb**2
    s5 = s5 + 8.0 * a * dn * y * yb**3

    lam = lens.wavelength_um
    short, long_ = int(torch.argmin(lam)), int(torch.argmax(lam))
    dnn = (lens.index[:, short] - lens.index[:, long_]) / n  # δn/n per medium
    d_dnn = dnn[1:] - dnn[:-1]
    c1 = a_m * y * d_dnn
    c2 = a_c * y * d_dnn
    per = torch.stack([s1, s2, s3, s4, s5, c1, c2])
    return SeidelSums(surfaces=per, total=per.sum(-1), wavelength_um=float(lam[w]),
                      color_wavelengths_um=(float(lam[short]), float(lam[long_])), image_nu=om[-1], invariant=inv)
