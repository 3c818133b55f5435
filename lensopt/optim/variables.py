"""Parameterization (S2.1, Table S4): one flat vector θ of scaled variables ↔ the lens tensors.

With α the scale factor (mm, default EPD/2)::

    thickness   s  = α s'                  curvature  c = c'/α
    conic       κ  = κ'                    asphere    a_2i = a'_2i / α^2i   (Bézier option below)
    phase       d_2i = d'_2i / α^2i        glass      [nd, vd(, ΔPgF)] = W⁻¹ (g − b)   (S30)

Bézier option (``asphere_basis = "bezier"``): the varied coefficients of a surface must be the
consecutive powers 4, 6, …, 4 + 2(K−1); writing the asphere as ρ⁴ q(ρ²) with ρ = r/α, θ holds the
Bernstein control points of q on [0, 1] instead of its monomial coefficients (a fixed invertible
linear map, converted back before tracing).

``lens(θ)`` is a pure function of θ: no in-place writes, every tensor rebuilt from θ and constants.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import torch
from torch import Tensor

from lensopt.errors import SpecError
from lensopt.materials import CatalogGlass, Material, ModelGlass, hartmann_index
from lensopt.materials.glass_space import GlassSpace
from lensopt.optics.lens import Lens

__all__ = ["Declared", "Variable", "Parameterization", "bernstein_to_monomial"]

Kind = Literal["thickness", "curvature", "conic", "asphere", "phase", "glass"]


@dataclass(frozen=True)
class Variable:
    """One entry (or, for glasses, ``size`` entries) of θ.

    Attributes:
        kind: what it sets.
        surface: 0-based surface index (glass: the medium after this surface).
        power: polynomial power for asphere/phase coefficients.
        index: position of the first entry in θ.
        size: number of entries (glass: 2 or 3; else 1).
    """

    kind: Kind
    surface: int
    power: int | None
    index: int
    size: int = 1

    @property
    def path(self) -> str:
        field = {"thickness": "thickness", "curvature": "radius", "conic": "conic", "glass": "material",
                 "asphere": f"coefficients.{self.power}", "phase": f"phase.{self.power}"}[self.kind]
        return f"surfaces[{self.surface}].{field}"


def bernstein_to_monomial(n: int, *, dtype: torch.dtype) -> Tensor:
    """(n, n) matrix M with monomial coefficients = M @ Bernstein control points (degree n − 1)."""
    deg = n - 1
    M = torch.zeros(n, n, dtype=dtype)
    for k in range(n):
        for j in range(k, n):
            M[j, k] = math.comb(deg, k) * math.comb(deg - k, j - k) * (-1) ** (j - k)
    return M


@dataclass(frozen=True)
class Declared:
    """A declared variable before scaling: what it sets, on which surface, at which power (asphere and
    phase coefficients). ``lensopt.design.setup.declare_variables`` reads them from a spec's ``vary``
    lists, in θ order."""

    kind: Kind
    surface: int
    power: int | None = None


class Parameterization:
    """Declared variables, their scaling, and the map θ → Lens (before solves).

    Args:
        lens: the lens at its start values, with a column for every varied coefficient power; its dtype
            and device are those of θ.
        media: (S+1) materials (object space, then the medium after every surface): the start values of
            glass variables.
        declared: the variables in θ order (asphere powers of a surface ascending).
        alpha: scale factor α in mm.
        glass: whitened glass space (needed when a material varies).
        asphere_basis: ``monomial`` or ``bezier``.
        skip: (kind, surface) pairs that are solved and so must not be in θ.
    """

    def __init__(self, lens: Lens, media: Sequence[Material], declared: Sequence[Declared], *, alpha: float,
                 glass: GlassSpace | None, asphere_basis: str = "monomial",
                 skip: frozenset[tuple[str, int]] = frozenset()) -> None:
        self.base = lens
        self.media = tuple(media)
        self.device = lens.device
        self.alpha = alpha
        self.glass = glass
        self.asphere_basis = asphere_basis
        self.dtype = lens.dtype
        self.variables: list[Variable] = []
        self._bezier: dict[int, Tensor] = {}
        n = 0
        for d in declared:
            if (d.kind, d.surface) in skip:
                name = "radius" if d.kind == "curvature" else d.kind
                raise SpecError(f"{name} is set by a solve (optimize.solves); remove it from vary",
                                path=f"surfaces[{d.surface}].vary")
            if d.kind == "glass" and glass is None:
                raise SpecError("glass variables need a design catalog", path="optimize.catalog")
            size = glass.dims if d.kind == "glass" and glass is not None else 1
            self.variables.append(Variable(d.kind, d.surface, d.power, n, size))
            n += size
        self.size = n
        if asphere_basis == "bezier":
            for s in sorted({v.surface for v in self.of_kind("asphere")}):
                asph = [v.power for v in self.of_kind("asphere") if v.surface == s]
                if asph != list(range(4, 4 + 2 * len(asph), 2)):
                    raise SpecError("the bezier basis needs the consecutive powers 4, 6, … varied",
                                    path=f"surfaces[{s}].vary", got=asph)
                self._bezier[s] = bernstein_to_monomial(len(asph), dtype=self.dtype).to(self.device)
        # θ → prescription values as two whole-vector operations, (θ · mul) / div: exactly t·α, t/α,
        # t/α^p or t for each variable (×1 and /1 are exact). One operation per variable costs ≈ 15×
        # more under forward-mode AD (a dual with a plain operand runs through Python meta kernels).
        self._mul, self._div = [1.0] * n, [1.0] * n
        for v in self.variables:
            if v.kind == "thickness":
                self._mul[v.index] = alpha
            elif v.kind == "curvature":
                self._div[v.index] = alpha
            elif v.kind in ("phase", "asphere"):
                self._div[v.index] = alpha**v.power

    # ---------------------------------------------------------------------------------- structure

    def of_kind(self, kind: Kind) -> list[Variable]:
        return [v for v in self.variables if v.kind == kind]

    # ------------------------------------------------------------------------------------ θ ↔ lens

    def initial(self) -> Tensor:
        """θ of the start lens's own values."""
        lens, a = self.base, self.alpha
        vals: list[Tensor] = []
        for v in self.variables:
            s = v.surface
            if v.kind == "thickness":
                vals.append(lens.thickness[s] / a)
            elif v.kind == "curvature":
                vals.append(lens.curvature[s] * a)
            elif v.kind == "conic":
                vals.append(lens.conic[s])
            elif v.kind == "phase":
                vals.append(lens.phase[s, (v.power - 2) // 2] * a**v.power)
            elif v.kind == "asphere":
                vals.append(lens.asphere[s, (v.power - 4) // 2] * a**v.power)
            else:
                vals.append(self.glass.to_g(self._glass_values(s)))
        for s, M in self._bezier.items():
            pos = [i for i, v in enumerate(self.variables) if v.kind == "asphere" and v.surface == s]
            control = torch.linalg.solve(M, torch.stack([vals[i] for i in pos]))
            for i, c in zip(pos, control.unbind(), strict=True):
                vals[i] = c
        if not vals:
            return torch.zeros(0, dtype=self.dtype, device=self.device)
        return torch.cat([x.reshape(-1) for x in vals])

    def _glass_values(self, s: int) -> Tensor:
        mat = self.media[s + 1]
        dpgf = 0.0
        if isinstance(mat, ModelGlass):
            dpgf = mat.dpgf
        elif isinstance(mat, CatalogGlass):
            dpgf = mat.glass.dpgf or 0.0
        vals = [mat.nd, mat.vd, dpgf][: self.glass.dims]
        return torch.tensor(vals, dtype=self.dtype, device=self.device)

    def glass_physical(self, theta: Tensor) -> Tensor:
        """(G, 3) (nd, vd, ΔPgF) of every glass variable (ΔPgF = 0 with 2 glass parameters)."""
        rows = []
        for v in self.of_kind("glass"):
            x = self.glass.from_g(theta[v.index : v.index + v.size])
            if v.size == 2:
                x = torch.cat([x, torch.zeros_like(x[:1])])
            rows.append(x)
        return torch.stack(rows) if rows else torch.zeros(0, 3, dtype=theta.dtype, device=theta.device)

    def glass_g(self, theta: Tensor) -> Tensor:
        """(G, d) whitened glass variables."""
        rows = [theta[v.index : v.index + v.size] for v in self.of_kind("glass")]
        d = self.glass.dims if self.glass is not None else 2
        return torch.stack(rows) if rows else torch.zeros(0, d, dtype=theta.dtype, device=theta.device)

    def lens(self, theta: Tensor) -> Lens:
        """The lens for θ (solved quantities still at their start values)."""
        base, a = self.base, self.alpha
        S = base.num_surfaces
        curv, thick, conic = list(base.curvature.unbind()), list(base.thickness.unbind()), list(base.conic.unbind())
        asph = [list(row.unbind()) for row in base.asphere] if base.asphere.shape[1] else [[] for _ in range(S)]
        phase = [list(row.unbind()) for row in base.phase] if base.phase.shape[1] else [[] for _ in range(S)]
        index = list(base.index.unbind())
        like = {"dtype": theta.dtype, "device": theta.device}
        scaled = theta * torch.tensor(self._mul, **like) / torch.tensor(self._div, **like)
        glass_rows = self.glass_physical(theta)
        if glass_rows.shape[0]:  # every glass at once (elementwise: the same numbers as one by one)
            glass_index = hartmann_index(glass_rows[:, 0, None], glass_rows[:, 1, None], glass_rows[:, 2, None],
                                         base.wavelength_um).unbind()
        g = 0
        for v in self.variables:
            s, t = v.surface, scaled[v.index]
            if v.kind == "thickness":
                thick[s] = t
            elif v.kind == "curvature":
                curv[s] = t
            elif v.kind == "conic":
                conic[s] = t
            elif v.kind == "phase":
                phase[s][(v.power - 2) // 2] = t
            elif v.kind == "asphere" and s not in self._bezier:
                asph[s][(v.power - 4) // 2] = t
            elif v.kind == "glass":
                index[s + 1] = glass_index[g]
                g += 1
        for s, M in self._bezier.items():
            vs = [v for v in self.variables if v.kind == "asphere" and v.surface == s]
            mono = M @ torch.stack([theta[v.index] for v in vs])
            for v, m in zip(vs, mono.unbind(), strict=True):
                asph[s][(v.power - 4) // 2] = m / a**v.power

        def table(rows: list[list[Tensor]], like: Tensor) -> Tensor:
            return torch.stack([torch.stack(r) for r in rows]) if like.shape[1] else like

        return dataclasses.replace(
            base,
            curvature=torch.stack(curv),
            thickness=torch.stack(thick),
            conic=torch.stack(conic),
            asphere=table(asph, base.asphere),
            phase=table(phase, base.phase),
            index=torch.stack(index),
        )
