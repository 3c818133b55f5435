"""θ → spec: write optimized (and solved) values back into the ``LensSpec`` a problem was built from
(``SpecProblem.spec``), and bind glass variables to their nearest catalog glasses (S4.1.3), by name."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.design.setup import VENDOR_CATALOGS, SpecProblem
from lensopt.errors import LensoptError
from lensopt.materials import find_glass, notice
from lensopt.materials.glass_space import nearest_glass
from lensopt.spec.models import DiffractiveSurface, LensSpec, ModelGlassSpec

__all__ = ["BoundGlass", "to_spec", "bind_glasses"]

_VENDOR = {c: v for v, c in VENDOR_CATALOGS.items()}


@dataclass(frozen=True)
class BoundGlass:
    """A glass variable bound to a catalog glass.

    Attributes:
        surface: the element's first surface (the medium after it).
        name: catalog name.
        material: what the spec now says: ``"vendor:NAME"`` when the vendor catalog has the glass (its
            dispersion formula is used from now on), else a Hartmann model glass with the catalog's
            nd, vd, ΔPgF and the name.
        distance: whitened distance from the variable to the glass at binding.
    """

    surface: int
    name: str
    material: str | ModelGlassSpec
    distance: float


def to_spec(problem: SpecProblem, theta: Tensor, materials: dict[int, str | ModelGlassSpec] | None = None,
            *, freeze_glass: bool = False) -> LensSpec:
    """The spec with every varied or solved quantity set from θ.

    Args:
        materials: replacement materials per surface (bound glasses); other glass variables are
            written as Hartmann model glasses {nd, vd, dpgf}.
        freeze_glass: remove ``material`` from the ``vary`` lists of the replaced materials.
    """
    materials = materials or {}
    with torch.no_grad():
        lens, _ = problem.lens(theta)
        glass = problem.param.glass_physical(theta).tolist()
    spec = problem.spec.model_copy(deep=True)
    last = len(spec.surfaces) - 1
    written: set[tuple[str, int, int | None]] = {(v.kind, v.surface, v.power) for v in problem.param.variables}
    for sol in problem.solves:
        written.add(("curvature", sol.surface, None) if sol.kind in ("efl", "image_height")
                    else ("thickness", last, None))
    glass_vars = problem.param.of_kind("glass")
    for kind, s, power in sorted(written, key=lambda x: (x[1], x[0], x[2] or 0)):
        surf = spec.surfaces[s]
        base = surf.base if isinstance(surf, DiffractiveSurface) else surf
        if kind == "curvature":
            c = float(lens.curvature[s])
            base.radius = math.inf if c == 0.0 else 1.0 / c
        elif kind == "thickness":
            t = float(lens.thickness[s])
            surf.thickness = t - problem.defocus if s == last else t
        elif kind == "conic":
            base.conic = float(lens.conic[s])
        elif kind == "asphere":
            base.coefficients = {**base.coefficients, power: float(lens.asphere[s, (power - 4) // 2])}
        elif kind == "phase":
            surf.phase = {**surf.phase, power: float(lens.phase[s, (power - 2) // 2])}
        elif kind == "glass":
            if s in materials:
                surf.material = materials[s]
                if freeze_glass:
                    surf.vary = [v for v in surf.vary if v != "material"]
            else:
                nd, vd, dpgf = glass[[v.surface for v in glass_vars].index(s)]
                surf.material = ModelGlassSpec(nd=nd, vd=vd, dpgf=dpgf)
    return spec


def bind_glasses(problem: SpecProblem, theta: Tensor) -> tuple[LensSpec, list[BoundGlass]]:
    """Bind every glass variable to its nearest catalog glass (whitened distance) and freeze it.

    The catalog is the problem's design catalog (``setup.binding_catalog``: the spec's ``[optimize]
    catalog``, else the start glasses' vendor's). A bound glass is written as ``"vendor:NAME"`` when the
    vendor data lensopt ships have it, else as a model glass with the catalog's nd, vd, ΔPgF; that
    substitution is told as a notice.

    Returns the spec for the next phase (materials by name, ``material`` out of ``vary``) and what
    was bound.
    """
    space = problem.space
    if space is None or problem.num_glasses == 0:
        return to_spec(problem, theta), []
    g = problem.param.glass_g(theta.detach())
    picks = nearest_glass(g, space)
    cat = space.catalog
    vendor = _VENDOR.get(cat.name)
    materials: dict[int, str | ModelGlassSpec] = {}
    bound: list[BoundGlass] = []
    for v, i, gi in zip(problem.param.of_kind("glass"), picks, g, strict=True):
        name = cat.names[i]
        nd, vd, dpgf = (float(x) for x in cat.values[i])
        mat: str | ModelGlassSpec = ModelGlassSpec(nd=nd, vd=vd, dpgf=dpgf, name=name)
        if vendor is not None:
            try:
                found = find_glass(f"{vendor}:{name}")
                mat = f"{vendor}:{found.name}"
            except LensoptError:  # not in the vendor data lensopt ships: keep the catalog's nd, vd, ΔPgF
                notice(f"surfaces[{v.surface}].material: {name} of {cat.name} is not in lensopt's {vendor} "
                       f"data; written as a model glass (nd={nd:.5f}, vd={vd:.2f}, dpgf={dpgf:.4f})")
        materials[v.surface] = mat
        dist = float(torch.linalg.vector_norm(gi - torch.as_tensor(space.points[i], dtype=gi.dtype)))
        bound.append(BoundGlass(v.surface, name, mat, dist))
    return to_spec(problem, theta, materials, freeze_glass=True), bound
