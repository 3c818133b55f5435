"""Runtime material objects: what a lens gap is filled with.

Thin frozen objects over the pure functions of :mod:`lensopt.materials.dispersion`. A material
answers ``index(wavelength_um)`` for a tensor of wavelengths, following its dtype and device, and
``check_wavelengths`` at build time. Glass *variables* of the optimizer do not go through these
objects: they call :func:`~lensopt.materials.dispersion.hartmann_index` with tensors directly.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field

import torch
from torch import Tensor

from lensopt.errors import MaterialError
from lensopt.materials.catalog import HARTMANN_RANGE_UM, PLASTICS_VENDOR, Glass, find_glass
from lensopt.materials.dispersion import catalog_index, hartmann_coefficients

__all__ = [
    "Material",
    "Air",
    "CatalogGlass",
    "ModelGlass",
    "TabulatedGlass",
    "MODEL_ND_RANGE",
    "MODEL_VD_RANGE",
    "MODEL_DPGF_RANGE",
    "material_from_name",
]

#: Accepted glass variables of :class:`ModelGlass` (open interval for nd, closed for the others).
MODEL_ND_RANGE: tuple[float, float] = (1.0, 3.0)
MODEL_VD_RANGE: tuple[float, float] = (10.0, 120.0)
MODEL_DPGF_RANGE: tuple[float, float] = (-0.1, 0.1)


def _check_wavelength_tensor(wavelength_um: Tensor) -> None:
    if not isinstance(wavelength_um, Tensor) or not wavelength_um.is_floating_point():
        raise MaterialError(
            "wavelength_um must be a floating-point tensor",
            got=getattr(wavelength_um, "dtype", type(wavelength_um).__name__),
        )


class Material(ABC):
    """Base of all materials.

    Attributes:
        name: display name (``"N-BK7"``, ``"air"``).
        nd: refractive index at the d line.
        vd: Abbe number (``inf`` for air).
        valid_range_um: ``(min, max)`` wavelengths (µm) the dispersion model is valid for.
    """

    name: str
    nd: float
    vd: float
    valid_range_um: tuple[float, float]

    @property
    def label(self) -> str:
        """How messages name this material (``"N-BK7 (schott)"``)."""
        return self.name

    @abstractmethod
    def index(self, wavelength_um: Tensor) -> Tensor:
        """Refractive index relative to air.

        Args:
            wavelength_um: ``(*)`` floating-point tensor of wavelengths in µm.

        Returns:
            ``(*)`` refractive index, same dtype and device as ``wavelength_um``.
        """

    def check_wavelengths(self, wavelength_um: Sequence[float], *, path: str) -> None:
        """Raise if any wavelength (µm) is outside :attr:`valid_range_um`.

        Args:
            wavelength_um: wavelengths in µm (plain floats, e.g. the spec's spectrum).
            path: spec field path for the error (``"surfaces[2].material"``).

        Raises:
            MaterialError: ``path: wavelength 0.25 µm is outside the valid range 0.3–2.5 µm of ...``.
        """
        lo, hi = self.valid_range_um
        for w in wavelength_um:
            w = float(w)
            if not (math.isfinite(w) and w > 0.0 and lo <= w <= hi):
                raise MaterialError(
                    f"wavelength {w:g} µm is outside the valid range {lo:g}–{hi:g} µm of {self.label}",
                    path=path,
                )


@dataclass(frozen=True)
class Air(Material):
    """Air: index exactly 1 at every wavelength (lensopt works relative to air, like CODE V)."""

    name: str = field(default="air", init=False)
    nd: float = field(default=1.0, init=False)
    vd: float = field(default=math.inf, init=False)
    valid_range_um: tuple[float, float] = field(default=(0.0, math.inf), init=False)

    def index(self, wavelength_um: Tensor) -> Tensor:
        """``(*)`` ones like ``wavelength_um``."""
        _check_wavelength_tensor(wavelength_um)
        return torch.ones_like(wavelength_um)


@dataclass(frozen=True)
class CatalogGlass(Material):
    """A vendor glass evaluated with its catalog dispersion formula.

    Attributes:
        glass: the catalog record (from :func:`~lensopt.materials.catalog.find_glass`).
    """

    glass: Glass
    name: str = field(init=False)
    nd: float = field(init=False)
    vd: float = field(init=False)
    valid_range_um: tuple[float, float] = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", self.glass.name)
        object.__setattr__(self, "nd", self.glass.nd)
        object.__setattr__(self, "vd", self.glass.vd)
        object.__setattr__(self, "valid_range_um", self.glass.range_um)

    @property
    def label(self) -> str:
        return self.glass.label

    def index(self, wavelength_um: Tensor) -> Tensor:
        """``(*)`` catalog-formula index at ``wavelength_um`` (µm), dtype/device of the input."""
        _check_wavelength_tensor(wavelength_um)
        coefficients = torch.tensor(
            self.glass.coefficients, dtype=wavelength_um.dtype, device=wavelength_um.device
        )
        return catalog_index(self.glass.formula, coefficients, wavelength_um)


def _check_range(what: str, value: float, lo: float, hi: float, *, open_interval: bool) -> None:
    ok = lo < value < hi if open_interval else lo <= value <= hi
    if not (math.isfinite(value) and ok):
        brackets = ("(", ")") if open_interval else ("[", "]")
        raise MaterialError(
            f"model glass {what} must be in {brackets[0]}{lo:g}, {hi:g}{brackets[1]}", path=what, got=value
        )


@dataclass(frozen=True)
class ModelGlass(Material):
    """A fictitious glass from (nd, vd, ΔPgF) through the Hartmann model (seed S1.1, eqs. S3–S7).

    Valid for wavelengths in :data:`~lensopt.materials.catalog.HARTMANN_RANGE_UM` (0.38–1.0 µm):
    with nd in (1, 3), vd in [10, 120] and dpgf in [−0.1, 0.1] the Hartmann pole B (eq. S5) stays
    below 0.29 µm, at least 0.09 µm under the range. There the model stays within 1.4e-3
    (median 4e-4) of real glasses with the same nd, vd, dPgF (Schott's preferred glasses); beyond
    ~1.3 µm it drifts by several 1e-3 (it has no infrared term).

    Attributes:
        nd: refractive index at the d line, in (1, 3).
        vd: Abbe number, in [10, 120].
        dpgf: deviation from normal partial dispersion, in [−0.1, 0.1] (default 0).
        name: display name; default ``"model(nd=1.62, vd=60.3, dpgf=0)"``.
    """

    nd: float
    vd: float
    dpgf: float = 0.0
    name: str = ""
    valid_range_um: tuple[float, float] = field(default=HARTMANN_RANGE_UM, init=False)
    _abc: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for attr in ("nd", "vd", "dpgf"):
            value = getattr(self, attr)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise MaterialError(f"model glass {attr} must be a number", path=attr, got=value)
            object.__setattr__(self, attr, float(value))
        _check_range("nd", self.nd, *MODEL_ND_RANGE, open_interval=True)
        _check_range("vd", self.vd, *MODEL_VD_RANGE, open_interval=False)
        _check_range("dpgf", self.dpgf, *MODEL_DPGF_RANGE, open_interval=False)
        if not self.name:
            object.__setattr__(self, "name", f"model(nd={self.nd:g}, vd={self.vd:g}, dpgf={self.dpgf:g})")
        t = torch.tensor([self.nd, self.vd, self.dpgf], dtype=torch.float64)
        a, b, c = hartmann_coefficients(t[0], t[1], t[2])
        object.__setattr__(self, "_abc", (float(a), float(b), float(c)))

    @property
    def label(self) -> str:
        return f"{self.name} (Hartmann model)"

    @property
    def hartmann_abc(self) -> tuple[float, float, float]:
        """Hartmann coefficients (A, B µm, C µm), computed once in float64."""
        return self._abc

    def index(self, wavelength_um: Tensor) -> Tensor:
        """``(*)`` Hartmann index A + C/(λ − B) at ``wavelength_um`` (µm), dtype/device of the input."""
        _check_wavelength_tensor(wavelength_um)
        a, b, c = self._abc
        return a + c / (wavelength_um - b)


@dataclass(frozen=True)
class TabulatedGlass(Material):
    """A glass given by indices at a few wavelengths (e.g. a CODE V private catalog entry).

    The index is exact at the tabulated wavelengths and a not-a-knot cubic spline in λ between them
    (linear for two points, constant for one; the scheme scipy's ``interp1d(kind="cubic")`` and
    rayoptics use for such data). Valid only inside the tabulated range.

    Attributes:
        name: display name (``"E48"``).
        wavelengths_um: strictly increasing wavelengths, µm.
        indices: refractive index at each wavelength.
    """

    name: str
    wavelengths_um: tuple[float, ...]
    indices: tuple[float, ...]
    nd: float = field(default=math.nan, init=False)
    vd: float = field(default=math.nan, init=False)
    valid_range_um: tuple[float, float] = field(default=(0.0, 0.0), init=False)
    _poly: tuple[tuple[float, ...], ...] = field(default=(), init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        wl = tuple(float(w) for w in self.wavelengths_um)
        n = tuple(float(x) for x in self.indices)
        if not wl or len(wl) != len(n):
            raise MaterialError(f"tabulated glass {self.name}: needs as many indices as wavelengths",
                                got=(len(wl), len(n)))
        if any(not (math.isfinite(w) and w > 0) for w in wl) or any(b <= a for a, b in zip(wl, wl[1:], strict=False)):
            raise MaterialError(f"tabulated glass {self.name}: wavelengths must be positive and increasing",
                                got=wl)
        if any(not (math.isfinite(x) and x > 0) for x in n):
            raise MaterialError(f"tabulated glass {self.name}: indices must be positive", got=n)
        object.__setattr__(self, "wavelengths_um", wl)
        object.__setattr__(self, "indices", n)
        object.__setattr__(self, "valid_range_um", (wl[0], wl[-1]))
        object.__setattr__(self, "_poly", _spline_pieces(wl, n))
        if wl[0] <= 0.4861327 and wl[-1] >= 0.6562725:
            nd, nf, nc = (float(self.index(torch.tensor(w, dtype=torch.float64)))
                          for w in (0.5875618, 0.4861327, 0.6562725))
            object.__setattr__(self, "nd", nd)
            object.__setattr__(self, "vd", (nd - 1.0) / (nf - nc) if nf != nc else math.inf)

    @property
    def label(self) -> str:
        return f"{self.name} (tabulated)"

    def index(self, wavelength_um: Tensor) -> Tensor:
        """``(*)`` spline index at ``wavelength_um`` (µm); exactly the tabulated value at a node."""
        _check_wavelength_tensor(wavelength_um)
        opts = {"dtype": wavelength_um.dtype, "device": wavelength_um.device}
        nodes = torch.tensor(self.wavelengths_um, **opts)
        coef = torch.tensor(self._poly, **opts)  # (K, 4): c0 + c1 t + c2 t² + c3 t³, t = λ − λ_k
        k = (torch.searchsorted(nodes, wavelength_um.detach().contiguous(), right=True) - 1)
        k = k.clamp(0, coef.shape[0] - 1)
        t = wavelength_um - nodes[k]
        c = coef[k]
        value = c[..., 0] + t * (c[..., 1] + t * (c[..., 2] + t * c[..., 3]))
        for w, n in zip(self.wavelengths_um, self.indices, strict=True):
            value = torch.where(wavelength_um == w, torch.full_like(value, n), value)
        return value


def _spline_pieces(wl: tuple[float, ...], n: tuple[float, ...]) -> tuple[tuple[float, ...], ...]:
    """Polynomial pieces (c0, c1, c2, c3) in t = λ − λ_k of the interpolant of (wl, n)."""
    if len(wl) == 1:
        return ((n[0], 0.0, 0.0, 0.0),)
    if len(wl) == 2:
        return ((n[0], (n[1] - n[0]) / (wl[1] - wl[0]), 0.0, 0.0),)
    from scipy.interpolate import CubicSpline

    spline = CubicSpline(wl, n, bc_type="not-a-knot")
    # scipy stores c[m, k] for (λ − λ_k)^(3 − m); reorder to ascending powers.
    return tuple(tuple(float(spline.c[3 - p, k]) for p in range(4)) for k in range(len(wl) - 1))


def material_from_name(name: str, wavelengths_um: Sequence[float] | None = None, *,
                       path: str | None = None) -> Material:
    """The material a spec names: ``"air"`` -> :class:`Air`, a Table S10 plastic -> :class:`ModelGlass`,
    anything else -> :class:`CatalogGlass` via :func:`~lensopt.materials.catalog.find_glass`
    (case/space-insensitive, optional ``"vendor:"`` prefix; a bare name takes the first vendor in
    :data:`~lensopt.materials.catalog.VENDORS` whose valid range covers ``wavelengths_um``, and a choice
    among several vendors is told once as a notice naming ``path``).

    Raises:
        MaterialError: unknown glass (with close matches), or a bare name whose vendors' data do not
            cover ``wavelengths_um``.
    """
    if name.strip().lower() == "air":
        return Air()
    glass = find_glass(name, wavelengths_um, path=path)
    if glass.vendor == PLASTICS_VENDOR:
        return ModelGlass(nd=glass.nd, vd=glass.vd, dpgf=0.0, name=glass.name)
    return CatalogGlass(glass)
