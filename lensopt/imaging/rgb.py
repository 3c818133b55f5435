"""Wavelength → RGB weights from a spectrum (seed S4.1.2, Table S9; the matrix W_w of S1.5.1).

The seed's rule: split the spectrum evenly into R, G and B so that the three channels sum to the
spectrum (row i of W_w sums to 3·s_i for normalized spectral weights s, each column sums to 1), give
all of the shortest wavelength to B and all of the longest to R, and minimize the average extent of the
channels.

Here the extent of a channel is its spectral standard deviation, √(Σ_i W_ic (λ_i − λ̄_c)²) with
λ̄_c = Σ_i W_ic λ_i. That is a concave function of W on the feasible polytope (the variance is linear
minus a square), so its minimum lies at a vertex; the minimizing vertex is the contiguous split: sort
the wavelengths, B takes the first third of the cumulative spectrum, G the second, R the last, with the
boundary wavelengths shared between neighbouring channels. The shortest and longest wavelengths then go
entirely to B and R unless one of them alone carries more than a third of the spectrum (then it fills
its channel and the rest spills into G). Zero-weight wavelengths get zero rows.

Table S9's digits are not reproduced: its channels overlap (G reaches from 475 to 625 nm), which this
extent measure never prefers — the contiguous split has a smaller average standard deviation (21.5 nm
against the table's 25.5 nm on Table S9's spectrum); the seed does not say which extent it minimized or
how. ``tests/imaging/test_rgb.py`` checks the defining properties and the optimality against a linear-
programming oracle; README "RGB weights" documents the difference.
"""

from __future__ import annotations

import numpy as np

from lensopt.errors import LensoptError

__all__ = ["rgb_weights_from_spectrum", "channel_extent_nm", "RULE"]

RULE = ("derived from the spectrum by the seed's rule: contiguous thirds of the spectrum, "
        "shortest wavelengths → B, longest → R")


def rgb_weights_from_spectrum(wavelengths_nm: list[float] | np.ndarray, weights: list[float] | np.ndarray | None,
                              *, path: str = "spectrum") -> np.ndarray:
    """W_w ``[n_w, 3]`` (columns R, G, B, each summing to 1; rows summing to 3× the normalized spectrum).

    Args:
        wavelengths_nm: ``[n_w]`` in any order (rows of the result follow this order).
        weights: ``[n_w]`` non-negative spectral weights (None: uniform).
    """
    wl = np.asarray(wavelengths_nm, dtype=np.float64).ravel()
    n = wl.size
    s = np.ones(n) if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    if n == 0 or s.size != n:
        raise LensoptError("need one weight per wavelength", path=f"{path}.weights", got=(n, s.size))
    if (s < 0).any() or not np.isfinite(s).all() or s.sum() <= 0:
        raise LensoptError("spectral weights must be non-negative with a positive sum", path=f"{path}.weights",
                           got=s.tolist())
    s = s / s.sum()
    order = np.argsort(wl, kind="stable")
    c1 = np.cumsum(s[order])
    c1[-1] = 1.0
    c0 = np.concatenate([[0.0], c1[:-1]])
    w_sorted = np.zeros((n, 3))
    for k, (lo, hi) in enumerate(((0.0, 1 / 3), (1 / 3, 2 / 3), (2 / 3, 1.0))):  # B, G, R
        w_sorted[:, 2 - k] = 3.0 * np.clip(np.minimum(c1, hi) - np.maximum(c0, lo), 0.0, None)
    w = np.empty_like(w_sorted)
    w[order] = w_sorted
    return w / w.sum(axis=0, keepdims=True)


def channel_extent_nm(wavelengths_nm: list[float] | np.ndarray, w: np.ndarray) -> np.ndarray:
    """Spectral standard deviation (nm) of each column of ``w`` ``[n_w, C]`` — the extent minimized above."""
    wl = np.asarray(wavelengths_nm, dtype=np.float64)[:, None]
    w = np.asarray(w, dtype=np.float64)
    w = w / w.sum(axis=0, keepdims=True)
    mean = (w * wl).sum(axis=0)
    return np.sqrt(np.maximum((w * (wl - mean) ** 2).sum(axis=0), 0.0))
