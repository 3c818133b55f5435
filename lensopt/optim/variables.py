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
from dataclasses import dataclass
from typing import Literal

import torch
from torch import Tensor

from lensopt.errors import SpecError
from lensopt.materials import CatalogGlass, ModelGlass, hartmann_index
from lensopt.materials.glass_space import GlassSpace
from lensopt.optics.lens import Lens
from lensopt.spec.build import Model, build
from lensopt.spec.models import DiffractiveSurface, LensSpec

__all__ = ["Variable", "Parameterization", "bernstein_to_monomial"]

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


def _base_of(surf):  # noqa: ANN001, ANN202 - spec surface → its shape part
    return surf.base if isinstance(surf, DiffractiveSurface) else surf


def prepare_spec(spec: LensSpec) -> LensSpec:
    """Copy of ``spec`` where every varied coefficient power exists (0 where the spec has none)."""
    spec = spec.model_copy(deep=True)
    for surf in spec.surfaces:
        for item in surf.vary:
            name, _, power = item.partition(".")
            if not power:
                continue
            if name == "coefficients":
                base = _base_of(surf)
                if int(power) not in base.coefficients:
                    base.coefficients = {**base.coefficients, int(power): 0.0}
            elif name == "phase" and int(power) not in surf.phase:
                surf.phase = {**surf.phase, int(power): 0.0}
    return spec


class Parameterization:
    """Variables of a spec, their scaling, and the map θ → Lens (before solves).

    Args:
        spec: the lens spec (``vary`` lists say what varies).
        alpha: scale factor α in mm.
        glass: whitened glass space (needed when a material varies).
        asphere_basis: ``monomial`` or ``bezier``.
        skip: (kind, surface) pairs that are solved and so must not be in θ.
        dtype, device: of the lens tensors and θ (default device: the CPU).
    """

    def __init__(self, spec: LensSpec, *, alpha: float, glass: GlassSpace | None,
                 asphere_basis: str = "monomial", skip: frozenset[tuple[str, int]] = frozenset(),
                 dtype: torch.dtype = torch.float64, device: torch.device | str | None = None) -> None:
        self.spec = prepare_spec(spec)
        self.model: Model = build(self.spec, dtype=dtype, device=device)
        self.device = self.model.lens.device
        self.alpha = alpha
        self.glass = glass
        self.asphere_basis = asphere_basis
        self.dtype = dtype
        self.variables: list[Variable] = []
        self._bezier: dict[int, Tensor] = {}
        n = 0
        for s, surf in enumerate(self.spec.surfaces):
            for kind, power in self._surface_variables(s, surf):
                if (kind, s) in skip:
                    name = "radius" if kind == "curvature" else kind
                    raise SpecError(f"{name} is set by a solve (optimize.solves); remove it from vary",
                                    path=f"surfaces[{s}].vary")
                size = glass.dims if kind == "glass" and glass is not None else 1
                self.variables.append(Variable(kind, s, power, n, size))
                n += size
        self.size = n

    # ---------------------------------------------------------------------------------- structure

    def _surface_variables(self, s: int, surf) -> list[tuple[Kind, int | None]]:  # noqa: ANN001
        out: list[tuple[Kind, int | None]] = []
        base = _base_of(surf)
        names = list(dict.fromkeys(surf.vary))
        for item in names:
            name, _, power = item.partition(".")
            if name == "thickness":
                out.append(("thickness", None))
            elif name == "radius":
                out.append(("curvature", None))
            elif name == "conic":
                out.append(("conic", None))
            elif name == "material":
                if surf.is_air:
                    raise SpecError("air cannot vary; give the element a glass to start from",
                                    path=f"surfaces[{s}].vary")
                if self.glass is None:
                    raise SpecError("glass variables need a design catalog", path="optimize.catalog")
                out.append(("glass", None))
            elif name in ("coefficients", "phase"):
                table = base.coefficients if name == "coefficients" else surf.phase
                powers = [int(power)] if power else sorted(table)
                if not powers:
                    raise SpecError(f"no {name} to vary; name the powers, e.g. {name}.{4 if name[0] == 'c' else 2}",
                                    path=f"surfaces[{s}].vary")
                kind: Kind = "asphere" if name == "coefficients" else "phase"
                out.extend((kind, p) for p in powers)
        asph = sorted(p for k, p in out if k == "asphere")
        if asph and self.asphere_basis == "bezier":
            if asph != list(range(4, 4 + 2 * len(asph), 2)):
                raise SpecError("the bezier basis needs the consecutive powers 4, 6, … varied",
                                path=f"surfaces[{s}].vary", got=asph)
            self._bezier[s] = bernstein_to_monomial(len(asph), dtype=self.dtype).to(self.device)
        # θ order within a surface: as declared, with the asphere powers ascending (Bézier points).
        rest = [(k, p) for k, p in out if k != "asphere"]
        return rest + [("asphere", p) for p in asph]

    def of_kind(self, kind: Kind) -> list[Variable]:
        return [v for v in self.variables if v.kind == kind]

    # ------------------------------------------------------------------------------------ θ ↔ lens

    def initial(self) -> Tensor:
        """θ of the spec's own values."""
        lens, a = self.model.lens, self.alpha
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
        mat = self.model.media[s + 1]
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
        """The lens for θ (solved quantities still at their spec values)."""
        base, a = self.model.lens, self.alpha
        S = base.num_surfaces
        curv, thick, conic = list(base.curvature.unbind()), list(base.thickness.unbind()), list(base.conic.unbind())
        asph = [list(row.unbind()) for row in base.asphere] if base.asphere.shape[1] else [[] for _ in range(S)]
        phase = [list(row.unbind()) for row in base.phase] if base.phase.shape[1] else [[] for _ in range(S)]
        index = list(base.index.unbind())
        glass_rows = self.glass_physical(theta)
        g = 0
        for v in self.variables:
            s, t = v.surface, theta[v.index]
            if v.kind == "thickness":
                thick[s] = t * a
            elif v.kind == "curvature":
                curv[s] = t / a
            elif v.kind == "conic":
                conic[s] = t
            elif v.kind == "phase":
                phase[s][(v.power - 2) // 2] = t / a**v.power
            elif v.kind == "asphere" and s not in self._bezier:
                asph[s][(v.power - 4) // 2] = t / a**v.power
            elif v.kind == "glass":
                x = glass_rows[g]
                index[s + 1] = hartmann_index(x[0], x[1], x[2], base.wavelength_um)
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
