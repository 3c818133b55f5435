"""Tolerances, their random draws, and perturbed lenses with a leading trial dimension (S6.2).

A ``Tolerance`` is one manufacturing error: a kind, where it acts (a surface, a medium or an element),
its limit ``±limit`` in the kind's unit, and a distribution. ``draw`` samples a (K, T) table of values
from a seed; ``perturb`` turns the nominal lens and such a table into a ``TrialParams`` whose tensors
have a leading trial dimension K (so K perturbed lenses are traced in one vmapped call).

Kinds and units (the tolerance values of CODE V's TOR/Zemax's tolerance data editor):

===================  =============================  ================================================
kind                 limit unit                     effect on trial value v
===================  =============================  ================================================
``curvature``        % of the curvature              c → c (1 + v/100)
``radius``           % of the radius                 c → c / (1 + v/100)
``fringes``          fringes of power at λ_test      c → c + v λ_test / a² (a: the surface's semi-aperture)
``thickness``        mm                              gap after surface s → t + v
``index``            absolute                        n(λ) → n(λ) + v for the medium after surface s
``abbe``             % of V_d                        n(λ) → n_d + (n(λ) − n_d) / (1 + v/100)
``decenter_x/_y``    mm                              surface s decentered (decenter-and-return)
``tilt_x/_y``        arcmin                          surface s tilted about x / y (decenter-and-return)
``element_decenter_x/_y``  mm                        element (first..last) moved rigidly
``element_tilt_x/_y``      arcmin                    element tilted about its first vertex
===================  =============================  ================================================

Distributions: ``uniform`` on [−limit, limit]; ``normal`` with σ = limit/2 (±limit is 2σ);
``truncnormal``: that normal truncated to [−limit, limit].
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

import torch
from torch import Tensor

from lensopt.optics.lens import Lens
from lensopt.optics.placement import Placement, no_placement

__all__ = ["Tolerance", "KINDS", "DISTRIBUTIONS", "TrialParams", "elements_of", "s62_profile", "draw", "perturb",
           "nominal_params", "params_lens", "FRINGE_WAVELENGTH_UM", "UNITS", "glass_gaps"]

Kind = Literal["curvature", "radius", "fringes", "thickness", "index", "abbe", "decenter_x", "decenter_y",
               "tilt_x", "tilt_y", "element_decenter_x", "element_decenter_y", "element_tilt_x", "element_tilt_y"]
KINDS: tuple[str, ...] = Kind.__args__  # type: ignore[attr-defined]
DISTRIBUTIONS = ("uniform", "normal", "truncnormal")
UNITS = {"curvature": "%", "radius": "%", "fringes": "fr", "thickness": "mm", "index": "", "abbe": "%",
         "decenter_x": "mm", "decenter_y": "mm", "tilt_x": "arcmin", "tilt_y": "arcmin",
         "element_decenter_x": "mm", "element_decenter_y": "mm", "element_tilt_x": "arcmin",
         "element_tilt_y": "arcmin"}
FRINGE_WAVELENGTH_UM = 0.6328
"""Test wavelength of power fringes (HeNe), µm."""
ARCMIN = math.pi / (180.0 * 60.0)


@dataclass(frozen=True)
class Tolerance:
    """One tolerance.

    Attributes:
        kind: see the module table.
        target: surface index (surface kinds, ``thickness``: the gap after it; ``index``/``abbe``: the
            medium after it), or the element's (first, last) surfaces for ``element_*``.
        limit: ± limit in the kind's unit (> 0).
        distribution: ``uniform``, ``normal`` (σ = limit/2) or ``truncnormal``.
        label: short name for tables (e.g. ``TTH s3``).
    """

    kind: str
    target: int | tuple[int, int]
    limit: float
    distribution: str = "uniform"
    label: str = ""

    @property
    def name(self) -> str:
        if self.label:
            return self.label
        where = f"e{self.target[0]}-{self.target[1]}" if isinstance(self.target, tuple) else f"s{self.target}"
        return f"{self.kind} {where}"


@dataclass(frozen=True)
class TrialParams:
    """The perturbable tensors of K lenses (leading dimension K on every field).

    Attributes:
        curvature: (K, S); thickness: (K, S); index: (K, S+1, W);
        decenter, tilt: (K, S, 2) (mm, radians); group_decenter, group_tilt: (K, G, 2).
    """

    curvature: Tensor
    thickness: Tensor
    index: Tensor
    decenter: Tensor
    tilt: Tensor
    group_decenter: Tensor
    group_tilt: Tensor

    def select(self, idx: Tensor | slice) -> TrialParams:
        return TrialParams(*(getattr(self, f.name)[idx] for f in dataclasses.fields(self)))

    @property
    def num_trials(self) -> int:
        return self.curvature.shape[0]


def glass_gaps(lens: Lens) -> list[bool]:
    """(S,) whether the medium after each surface is not air (index ≠ 1 at every wavelength)."""
    n = lens.index[1:]
    return [bool((row - 1.0).abs().max() > 1e-9) for row in n]


def elements_of(lens: Lens) -> list[tuple[int, int]]:
    """Elements as (first, last) surface ranges: a run of glass gaps and the surface that ends it
    (a cemented doublet is one element of three surfaces)."""
    glass = glass_gaps(lens)
    out, start = [], None
    for s, g in enumerate(glass):
        if g and start is None:
            start = s
        if not g and start is not None:
            out.append((start, s))
            start = None
    return out


def s62_profile(lens: Lens, *, distribution: str = "uniform") -> list[Tolerance]:
    """The seed's S6.2 C-mount set: ±0.02 mm airspaces, ±0.01 mm element thicknesses, ±0.1 % curvatures,
    ±0.0005 refractive index, ±0.5 % Abbe number, uniform. The last gap (back focus) is the
    compensator and gets no tolerance; flat surfaces have no curvature to perturb."""
    glass = glass_gaps(lens)
    tols: list[Tolerance] = []
    last = lens.num_surfaces - 1
    for s in range(lens.num_surfaces):
        if float(lens.curvature[s]) != 0.0:
            tols.append(Tolerance("curvature", s, 0.1, distribution, f"CUR s{s}"))
    for s in range(last):
        if glass[s]:
            tols.append(Tolerance("thickness", s, 0.01, distribution, f"THI s{s}"))
        else:
            tols.append(Tolerance("thickness", s, 0.02, distribution, f"AIR s{s}"))
    for s in range(lens.num_surfaces):
        if glass[s]:
            tols.append(Tolerance("index", s, 0.0005, distribution, f"IND s{s}"))
            tols.append(Tolerance("abbe", s, 0.5, distribution, f"ABB s{s}"))
    return tols


def draw(tols: list[Tolerance], num_trials: int, seed: int, *, dtype: torch.dtype = torch.float64) -> Tensor:
    """(K, T) values drawn from each tolerance's distribution, reproducibly from ``seed``.

    Every tolerance draws from its own stream (seeded by ``seed`` and its position), so adding trials
    keeps the first ones unchanged.
    """
    cols = []
    for t, tol in enumerate(tols):
        if tol.distribution not in DISTRIBUTIONS:
            raise ValueError(f"distribution must be one of {DISTRIBUTIONS}, got {tol.distribution!r}")
        gen = torch.Generator().manual_seed(int(seed) * 1_000_003 + t)
        if tol.distribution == "uniform":
            v = (2.0 * torch.rand(num_trials, generator=gen, dtype=torch.float64) - 1.0) * tol.limit
        elif tol.distribution == "normal":
            v = torch.randn(num_trials, generator=gen, dtype=torch.float64) * (tol.limit / 2.0)
        else:  # truncated normal by inverse CDF of the uniform on [Φ(−2), Φ(2)]
            lo = 0.5 * (1.0 + math.erf(-2.0 / math.sqrt(2.0)))
            u = lo + (1.0 - 2.0 * lo) * torch.rand(num_trials, generator=gen, dtype=torch.float64)
            v = torch.special.ndtri(u) * (tol.limit / 2.0)
        cols.append(v)
    if not cols:
        return torch.zeros(num_trials, 0, dtype=dtype)
    return torch.stack(cols, -1).to(dtype)


def nominal_params(lens: Lens) -> tuple[TrialParams, Placement]:
    """The nominal lens's perturbable tensors (K = 1) and the placement structure trials use
    (every surface decenter-and-return, one group per element)."""
    groups = tuple(elements_of(lens))
    base = lens.placement or no_placement(lens.num_surfaces, dtype=lens.dtype, device=lens.device)
    base_groups = tuple(base.groups)
    g_dec = base.group_decenter if base.group_decenter is not None else torch.zeros(0, 2, dtype=lens.dtype)
    g_tilt = base.group_tilt if base.group_tilt is not None else torch.zeros(0, 2, dtype=lens.dtype)
    extra = torch.zeros(len(groups), 2, dtype=lens.dtype, device=lens.device)
    placement = dataclasses.replace(base, groups=base_groups + groups,
                                    group_decenter=torch.cat([g_dec, extra]), group_tilt=torch.cat([g_tilt, extra]))
    p = TrialParams(lens.curvature[None], lens.thickness[None], lens.index[None], placement.decenter[None],
                    placement.tilt[None], placement.group_decenter[None], placement.group_tilt[None])
    return p, placement


def perturb(
    lens: Lens,
    tols: list[Tolerance],
    values: Tensor,
    *,
    nd: Tensor,
    semi_aperture: Tensor,
) -> TrialParams:
    """K perturbed lenses from the (K, T) table ``values`` (batched tensor operations, no trial loop).

    Args:
        lens: the nominal lens.
        tols: the T tolerances.
        values: (K, T) drawn values in each tolerance's unit.
        nd: (S+1,) d-line index of every medium (for Abbe-number changes).
        semi_aperture: (S,) semi-aperture of every surface, mm (for fringes).
    """
    base, placement = nominal_params(lens)
    k = values.shape[0]
    curv = base.curvature.expand(k, -1).clone()
    thick = base.thickness.expand(k, -1).clone()
    index = base.index.expand(k, -1, -1).clone()
    dec = base.decenter.expand(k, -1, -1).clone()
    tilt = base.tilt.expand(k, -1, -1).clone()
    gdec = base.group_decenter.expand(k, -1, -1).clone()
    gtilt = base.group_tilt.expand(k, -1, -1).clone()
    elements = list(placement.groups)
    shift = torch.zeros(k, index.shape[1], dtype=lens.dtype, device=lens.device)  # Δn_d per medium
    spread = torch.ones_like(shift)  # V_d factor per medium
    for t, tol in enumerate(tols):
        v = values[:, t].to(lens.dtype)
        kind, s = tol.kind, tol.target
        if kind == "curvature":
            curv[:, s] = curv[:, s] * (1.0 + v / 100.0)
        elif kind == "radius":
            curv[:, s] = curv[:, s] / (1.0 + v / 100.0)
        elif kind == "fringes":
            curv[:, s] = curv[:, s] + v * FRINGE_WAVELENGTH_UM * 1e-3 / semi_aperture[s] ** 2
        elif kind == "thickness":
            thick[:, s] = thick[:, s] + v
        elif kind == "index":
            shift[:, s + 1] = shift[:, s + 1] + v
        elif kind == "abbe":
            spread[:, s + 1] = spread[:, s + 1] * (1.0 + v / 100.0)
        elif kind in ("decenter_x", "decenter_y"):
            dec[:, s, 0 if kind.endswith("x") else 1] += v
        elif kind in ("tilt_x", "tilt_y"):
            tilt[:, s, 0 if kind.endswith("x") else 1] += v * ARCMIN
        elif kind.startswith("element_"):
            g = elements.index(tuple(s), len(placement.groups) - len(elements_of(lens)))
            axis = 0 if kind.endswith("x") else 1
            if "decenter" in kind:
                gdec[:, g, axis] += v
            else:
                gtilt[:, g, axis] += v * ARCMIN
        else:
            raise ValueError(f"unknown tolerance kind {kind!r}")
    # n(λ) = n_d + Δn + (n0(λ) − n_d) / f: the index moves as a whole, the dispersion n_F − n_C scales
    # by 1/f so that V_d = (n_d − 1)/(n_F − n_C) scales by f (n_d + Δn − 1 over that: Δn/(n_d − 1) is
    # the index tolerance's own, tiny, effect on V_d).
    ndv = nd.to(lens.dtype)[None, :, None]
    index = ndv + shift[..., None] + (index - ndv) / spread[..., None]
    return TrialParams(curv, thick, index, dec, tilt, gdec, gtilt)


def params_lens(lens: Lens, placement: Placement | None, p: TrialParams | dict) -> Lens:
    """The lens of one trial (fields of ``p`` without the trial dimension, e.g. inside ``vmap``)."""
    get = p.__getitem__ if isinstance(p, dict) else lambda n: getattr(p, n)
    new_placement = None
    if placement is not None:
        new_placement = dataclasses.replace(placement, decenter=get("decenter"), tilt=get("tilt"),
                                            group_decenter=get("group_decenter"), group_tilt=get("group_tilt"))
    return dataclasses.replace(lens, curvature=get("curvature"), thickness=get("thickness"), index=get("index"),
                               placement=new_placement)
