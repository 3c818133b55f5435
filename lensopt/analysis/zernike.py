"""Zernike polynomials on the unit pupil and least-squares fits of wavefronts to them.

Each term is ``Z(ρ, θ) = N · R_n^|m|(ρ) · cos(m θ)`` for m ≥ 0 and ``N · R_n^|m|(ρ) · sin(|m| θ)`` for
m < 0, with θ measured from the +x axis of the pupil (px) towards +y (py), ρ = sqrt(px² + py²).
Three orderings, numbered as their users number them:

- ``fringe``: the University of Arizona "Fringe" set (Zemax "Zernike Fringe", CODE V "ZFR"), terms
  1 … 37: j = (1 + (n + |m|)/2)² − 2|m| + (1 − sign m)/2 for j ≤ 36, and Z37 = 12th-order spherical
  (n = 12, m = 0), the set's one exception to the pattern (which would put (6, 6) there; optiland 0.6.3
  follows the pattern); **not normalized** (N = 1), so Z4 = 2ρ² − 1 and a coefficient is the term's
  amplitude at the pupil edge. At most 37 terms.
- ``noll``: Noll's ordering (J. Opt. Soc. Am. 66, 207 (1976); Zemax "Zernike Standard"), terms 1, 2, …,
  even j the cosine term, odd j the sine term; **RMS-normalized**, N = sqrt(2(n + 1)) (m ≠ 0) or
  sqrt(n + 1) (m = 0), so a coefficient is the term's RMS over the pupil.
- ``ansi``: OSA/ANSI Z80.28 single index, terms 0, 1, …: j = (n(n + 2) + m)/2; RMS-normalized as
  ``noll`` (optiland calls this ordering "standard").

The fit is a masked linear least-squares fit over the valid samples (fixed shapes; invalid samples
get zero weight), in the units of the data (waves for ``analysis.wavefront``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import torch
from torch import Tensor

from lensopt.errors import LensoptError

__all__ = ["ORDERINGS", "zernike_indices", "zernike_basis", "ZernikeFit", "fit_zernike", "first_index"]

ORDERINGS = ("fringe", "noll", "ansi")


def first_index(ordering: str) -> int:
    """The number of the first term: 0 for ``ansi``, 1 otherwise."""
    return 0 if ordering == "ansi" else 1


def _number(ordering: str, n: int, m: int) -> int:
    if ordering == "fringe":
        return int((1 + (n + abs(m)) // 2) ** 2 - 2 * abs(m) + (1 if m < 0 else 0))
    if ordering == "ansi":
        return (n * (n + 2) + m) // 2
    # Noll: j = n(n+1)/2 + |m| + c, with c ∈ {0, 1} chosen so that even j carries cos (m > 0) and odd j sin.
    mod = n % 4
    c = 0 if (m > 0 and mod <= 1) or (m < 0 and mod >= 2) else 1
    return n * (n + 1) // 2 + abs(m) + c


@cache
def zernike_indices(ordering: str, terms: int) -> tuple[tuple[int, int], ...]:
    """The (n, m) of the first ``terms`` terms of ``ordering`` (signed m: cos for m ≥ 0, sin for m < 0)."""
    if ordering not in ORDERINGS:
        raise LensoptError(f"must be one of {', '.join(ORDERINGS)}", path="zernike.ordering", got=ordering)
    if terms < 1:
        raise LensoptError("must be ≥ 1", path="zernike.terms", got=terms)
    if ordering == "fringe" and terms > 37:
        raise LensoptError("the Fringe set has 37 terms (use noll or ansi for more)", path="zernike.terms", got=terms)
    found: dict[int, tuple[int, int]] = {}
    first = first_index(ordering)
    n = 0
    while len([j for j in found if j < first + terms]) < terms:
        for m in range(-n, n + 1, 2):
            found[_number(ordering, n, m)] = (n, m)
        n += 1
        if n > 200:  # pragma: no cover - the numbering functions are bijections
            raise RuntimeError("Zernike numbering did not close")
    if ordering == "fringe":
        found[37] = (12, 0)
    return tuple(found[j] for j in range(first, first + terms))


def _radial(n: int, m: int, rho: Tensor) -> Tensor:
    m = abs(m)
    out = torch.zeros_like(rho)
    for k in range((n - m) // 2 + 1):
        c = (-1) ** k * math.factorial(n - k) / (
            math.factorial(k) * math.factorial((n + m) // 2 - k) * math.factorial((n - m) // 2 - k))
        out = out + c * rho ** (n - 2 * k)
    return out


def zernike_basis(pupil: Tensor, indices: tuple[tuple[int, int], ...], *, normalized: bool) -> Tensor:
    """(P, J) values of the terms ``indices`` at pupil points ``pupil`` ((P, 2): px, py)."""
    x, y = pupil[..., 0], pupil[..., 1]
    rho = torch.sqrt(x * x + y * y)
    theta = torch.atan2(y, x)
    cols = []
    for n, m in indices:
        z = _radial(n, m, rho)
        if m > 0:
            z = z * torch.cos(m * theta)
        elif m < 0:
            z = z * torch.sin(-m * theta)
        if normalized:
            z = z * math.sqrt((2.0 if m != 0 else 1.0) * (n + 1))
        cols.append(z)
    return torch.stack(cols, -1)


@dataclass(frozen=True)
class ZernikeFit:
    """A least-squares Zernike fit.

    Attributes:
        ordering: ``fringe``, ``noll`` or ``ansi``.
        numbers: (J,) the term numbers (``fringe``/``noll`` from 1, ``ansi`` from 0).
        indices: the (n, m) of each term.
        coefficients: (*, J) in the data's units.
        residual_rms: (*) RMS of data − fit over the valid samples.
    """

    ordering: str
    numbers: tuple[int, ...]
    indices: tuple[tuple[int, int], ...]
    coefficients: Tensor
    residual_rms: Tensor


def fit_zernike(pupil: Tensor, values: Tensor, valid: Tensor, *, ordering: str = "fringe",
                terms: int = 37) -> ZernikeFit:
    """Fit ``values`` ((*, P) at ``pupil`` points (P, 2) in the unit circle) with the first ``terms``
    terms of ``ordering``, each batch row over its own valid samples (``valid`` (*, P) bool)."""
    idx = zernike_indices(ordering, terms)
    basis = zernike_basis(pupil.to(values.dtype), idx, normalized=ordering != "fringe")  # (P, J)
    w = valid.to(values.dtype)
    a = basis * w.unsqueeze(-1)  # (*, P, J): rows of invalid samples are zero
    b = (values * w).unsqueeze(-1)
    coef = torch.linalg.lstsq(a, b, driver="gelsd" if a.device.type == "cpu" else None).solution.squeeze(-1)
    resid = (values - coef @ basis.T) * w
    rms = torch.sqrt((resid * resid).sum(-1) / w.sum(-1).clamp_min(1.0))
    first = first_index(ordering)
    return ZernikeFit(ordering=ordering, numbers=tuple(range(first, first + terms)), indices=idx,
                      coefficients=coef, residual_rms=rms)
