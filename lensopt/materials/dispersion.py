"""Dispersion formulas: catalog (refractiveindex.info numbering) and the Hartmann model of S1.1.

Pure torch functions. Wavelengths are in µm, indices are relative to vacuum for catalog formulas
(lensopt treats them as relative to air, like CODE V's default). Every function broadcasts over
leading dimensions, returns a tensor whose dtype/device follow its inputs (torch type promotion),
and is differentiable (reverse and forward mode) with respect to every tensor argument.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from lensopt.errors import MaterialError

__all__ = [
    "LINE_D_UM",
    "LINE_F_UM",
    "LINE_C_UM",
    "LINE_G_UM",
    "HARTMANN_FORMULA",
    "CATALOG_FORMULAS",
    "NORMAL_PGF_INTERCEPT",
    "NORMAL_PGF_SLOPE",
    "catalog_index",
    "normal_pgf",
    "hartmann_coefficients",
    "hartmann_index",
]

# Fraunhofer lines (µm), as used for nd, vd and PgF (S1.1).
LINE_D_UM = 0.5875618  # helium d line
LINE_F_UM = 0.4861327  # hydrogen F line
LINE_C_UM = 0.6562725  # hydrogen C line
LINE_G_UM = 0.4358343  # mercury g line

# Normal partial dispersion line, seed eq. S3: PgF = 0.6438 - 0.001682 vd + dPgF.
NORMAL_PGF_INTERCEPT = 0.6438
NORMAL_PGF_SLOPE = -0.001682

# lensopt-specific formula id (not a refractiveindex.info number): Hartmann model with
# coefficients (nd, vd, dpgf). Used for materials whose vendors publish only nd/vd (Table S10).
HARTMANN_FORMULA = 0


def _series(c: Tensor, start: int) -> list[tuple[Tensor, Tensor]]:
    """Pairs (c[i], c[i+1]) for i = start, start+2, ... (the coefficient list is padded to fit)."""
    return [(c[i], c[i + 1]) for i in range(start, c.shape[0] - 1, 2)]


def _sellmeier(c: Tensor, wl: Tensor) -> Tensor:
    """Formula 1: n² − 1 = C1 + Σ C_i λ² / (λ² − C_{i+1}²)."""
    w2 = wl * wl
    n2 = 1.0 + c[0] + torch.zeros_like(w2)
    for b, l in _series(c, 1):
        n2 = n2 + b * w2 / (w2 - l * l)
    return torch.sqrt(n2)


def _sellmeier2(c: Tensor, wl: Tensor) -> Tensor:
    """Formula 2: n² − 1 = C1 + Σ C_i λ² / (λ² − C_{i+1})."""
    w2 = wl * wl
    n2 = 1.0 + c[0] + torch.zeros_like(w2)
    for b, l in _series(c, 1):
        n2 = n2 + b * w2 / (w2 - l)
    return torch.sqrt(n2)


def _polynomial(c: Tensor, wl: Tensor) -> Tensor:
    """Formula 3: n² = C1 + Σ C_i λ^C_{i+1}."""
    n2 = c[0] + torch.zeros_like(wl)
    for a, p in _series(c, 1):
        n2 = n2 + a * torch.pow(wl, p)
    return torch.sqrt(n2)


def _rii(c: Tensor, wl: Tensor) -> Tensor:
    """Formula 4: n² = C1 + Σ_{i=2,6} C_i λ^C_{i+1} / (λ² − C_{i+2}^C_{i+3}) + Σ_{i≥10} C_i λ^C_{i+1}."""
    w2 = wl * wl
    n2 = c[0] + torch.zeros_like(wl)
    for i in (1, 5):
        n2 = n2 + c[i] * torch.pow(wl, c[i + 1]) / (w2 - torch.pow(c[i + 2], c[i + 3]))
    for a, p in _series(c, 9):
        n2 = n2 + a * torch.pow(wl, p)
    return torch.sqrt(n2)


def _cauchy(c: Tensor, wl: Tensor) -> Tensor:
    """Formula 5: n = C1 + Σ C_i λ^C_{i+1}."""
    n = c[0] + torch.zeros_like(wl)
    for a, p in _series(c, 1):
        n = n + a * torch.pow(wl, p)
    return n


def _gases(c: Tensor, wl: Tensor) -> Tensor:
    """Formula 6: n − 1 = C1 + Σ C_i / (C_{i+1} − λ⁻²)."""
    inv2 = 1.0 / (wl * wl)
    n = 1.0 + c[0] + torch.zeros_like(wl)
    for b, l in _series(c, 1):
        n = n + b / (l - inv2)
    return n


def _herzberger(c: Tensor, wl: Tensor) -> Tensor:
    """Formula 7: n = C1 + C2/(λ²−0.028) + C3/(λ²−0.028)² + C4 λ² + C5 λ⁴ + C6 λ⁶."""
    w2 = wl * wl
    q = 1.0 / (w2 - 0.028)
    return c[0] + c[1] * q + c[2] * q * q + c[3] * w2 + c[4] * w2 * w2 + c[5] * w2 * w2 * w2


def _retro(c: Tensor, wl: Tensor) -> Tensor:
    """Formula 8: (n²−1)/(n²+2) = C1 + C2 λ²/(λ²−C3) + C4 λ²."""
    w2 = wl * wl
    t = c[0] + c[1] * w2 / (w2 - c[2]) + c[3] * w2
    return torch.sqrt((2.0 * t + 1.0) / (1.0 - t))


def _exotic(c: Tensor, wl: Tensor) -> Tensor:
    """Formula 9: n² = C1 + C2/(λ²−C3) + C4 (λ−C5) / ((λ−C5)² + C6)."""
    u = wl - c[4]
    return torch.sqrt(c[0] + c[1] / (wl * wl - c[2]) + c[3] * u / (u * u + c[5]))


def _hartmann_formula(c: Tensor, wl: Tensor) -> Tensor:
    """Formula 0 (lensopt): Hartmann model from coefficients (nd, vd, dpgf), eqs. S3–S7."""
    return hartmann_index(c[0], c[1], c[2], wl)


# formula id -> (function, padded length rule): ("odd", k) pads to an odd length >= k,
# ("fixed", k) pads to exactly k coefficients (more is an error).
_FORMULAS: dict[int, tuple[Callable[[Tensor, Tensor], Tensor], str, int]] = {
    0: (_hartmann_formula, "fixed", 3),
    1: (_sellmeier, "odd", 1),
    2: (_sellmeier2, "odd", 1),
    3: (_polynomial, "odd", 1),
    4: (_rii, "odd", 9),
    5: (_cauchy, "odd", 1),
    6: (_gases, "odd", 1),
    7: (_herzberger, "fixed", 6),
    8: (_retro, "fixed", 4),
    9: (_exotic, "fixed", 6),
}

#: refractiveindex.info formula numbers that :func:`catalog_index` evaluates (plus 0 = Hartmann).
CATALOG_FORMULAS: tuple[int, ...] = tuple(sorted(k for k in _FORMULAS if k != HARTMANN_FORMULA))


def catalog_index(formula: int, coefficients: Tensor, wavelength_um: Tensor) -> Tensor:
    """Refractive index from a refractiveindex.info dispersion formula.

    Formulas follow refractiveindex.info's "formula N" numbering (1 Sellmeier, 2 Sellmeier-2,
    3 polynomial, 4 RefractiveIndex.INFO, 5 Cauchy, 6 gases, 7 Herzberger, 8 retro, 9 exotic);
    ``formula=0`` is lensopt's Hartmann model with coefficients ``(nd, vd, dpgf)``. Missing
    trailing coefficients count as zero, as on refractiveindex.info.

    Args:
        formula: formula id, one of ``CATALOG_FORMULAS`` or ``HARTMANN_FORMULA``.
        coefficients: ``(K,)`` formula coefficients C1..CK (wavelength terms in µm).
        wavelength_um: ``(*)`` vacuum wavelengths in µm (> 0).

    Returns:
        ``(*)`` refractive index; dtype/device from promoting ``coefficients`` and ``wavelength_um``.

    Raises:
        MaterialError: unknown formula id, or a coefficient tensor of the wrong shape.
    """
    if formula not in _FORMULAS:
        raise MaterialError(f"unknown dispersion formula; known: {sorted(_FORMULAS)}", got=formula)
    if coefficients.ndim != 1:
        raise MaterialError("dispersion coefficients must be a 1-D tensor", got=tuple(coefficients.shape))
    fn, rule, k = _FORMULAS[formula]
    n = coefficients.shape[0]
    if rule == "fixed":
        if n > k:
            raise MaterialError(f"formula {formula} takes at most {k} coefficients", got=n)
        size = k
    else:
        size = max(n, k)
        size += 1 - size % 2
    if size > n:
        coefficients = torch.nn.functional.pad(coefficients, (0, size - n))
    return fn(coefficients, wavelength_um)


def normal_pgf(vd: Tensor) -> Tensor:
    """Partial dispersion PgF of a "normal" glass with Abbe number ``vd`` (seed eq. S3, dPgF = 0).

    Args:
        vd: ``(*)`` Abbe numbers.

    Returns:
        ``(*)`` 0.6438 − 0.001682 vd, same dtype/device as ``vd``.
    """
    return NORMAL_PGF_INTERCEPT + NORMAL_PGF_SLOPE * vd


def hartmann_coefficients(nd: Tensor, vd: Tensor, dpgf: Tensor | float) -> tuple[Tensor, Tensor, Tensor]:
    """Hartmann coefficients (A, B, C) of n(λ) = A + C / (λ − B) from glass variables (eqs. S3, S5–S7).

    The model reproduces nd at λd exactly, vd from the F and C lines, and PgF = 0.6438 − 0.001682 vd
    + dpgf from the g, F and C lines. B (µm) is the model's pole; it lies below λg whenever
    PgF > (λF − λg)/(λC − λF) ≈ 0.2955 (see :class:`lensopt.materials.material.ModelGlass`).

    Args:
        nd: ``(*)`` refractive index at the d line (dimensionless).
        vd: ``(*)`` Abbe number (dimensionless, > 0).
        dpgf: ``(*)`` deviation from normal partial dispersion ΔPgF; a float is taken as a tensor
            like ``nd``.

    Returns:
        ``(A, B, C)``, each of the broadcast shape of the inputs: A (dimensionless), B (µm),
        C (µm).
    """
    dpgf = torch.as_tensor(dpgf, dtype=nd.dtype, device=nd.device)
    lc, lf, lg, ld = LINE_C_UM, LINE_F_UM, LINE_G_UM, LINE_D_UM
    pgf = normal_pgf(vd) + dpgf  # eq. S3
    b = (-lc * lf + lc * lg + pgf * (lc * lg - lf * lg)) / (-lf + lg + pgf * (lc - lf))  # eq. S5
    c = (b - lc) * (b - lf) * (nd - 1.0) / (vd * (lc - lf))  # eq. S6
    a = (b * nd + c - ld * nd) / (b - ld)  # eq. S7
    return a, b, c


def hartmann_index(nd: Tensor, vd: Tensor, dpgf: Tensor | float, wavelength_um: Tensor) -> Tensor:
    """Refractive index of the Hartmann model n(λ) = A + C / (λ − B) (eq. S4).

    Args:
        nd: ``(*)`` refractive index at the d line.
        vd: ``(*)`` Abbe number.
        dpgf: ``(*)`` deviation from normal partial dispersion (a float is taken as a tensor).
        wavelength_um: ``(*)`` wavelengths in µm; should lie above the pole B.

    Returns:
        Refractive index with the broadcast shape of all inputs; dtype/device by type promotion.
    """
    a, b, c = hartmann_coefficients(nd, vd, dpgf)
    return a + c / (wavelength_um - b)
