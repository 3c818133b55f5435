"""Solves (S2.1.1, S2.1.3, Table S5), differentiable and applied inside the residual function.

The system's paraxial matrix is affine in the power of any single surface (M = M₂ R(K) M₁ with
R(K) = [[1, 0], [−K, 1]]), so a curvature solve is exact in closed form: evaluate the target
quantity with that curvature at 0 and at 1 and solve the linear equation. The derivative of the
solved curvature with respect to every other variable follows by ordinary autodiff.

Order: a TTL solve on the last airspace first (it does not depend on curvatures), then the curvature
solve, then a focus solve on the last airspace (it depends on the solved curvature).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch
from torch import Tensor

from lensopt.errors import SpecError
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import (
    chief_image_height,
    field_tangents,
    first_order,
    ray_transfer,
    trace_paraxial,
)
from lensopt.spec.models import LensSpec

__all__ = ["Solve", "resolve_solves", "solved_quantities", "apply_solves"]


@dataclass(frozen=True)
class Solve:
    """A resolved solve: kind, 0-based surface (curvature solves), target value (mm)."""

    kind: str
    surface: int | None
    value: float | None


def resolve_solves(spec: LensSpec) -> list[Solve]:
    """Check the spec's solves against its surfaces; return them in application order."""
    opt = spec.optimize
    if opt is None:
        return []
    S = len(spec.surfaces)
    out: list[Solve] = []
    for i, sol in enumerate(opt.solves):
        path = f"optimize.solves[{i}]"
        surface = None
        if sol.type in ("efl", "image_height"):
            surface = S - 1 if sol.surface is None else sol.surface
            if not -S <= surface < S:
                raise SpecError(f"no such surface (the lens has {S})", path=f"{path}.surface", got=sol.surface)
            surface %= S
            surf = spec.surfaces[surface]
            base = surf.base if surf.type == "diffractive" else surf
            if base.type == "plane":
                raise SpecError("a curvature solve needs a curved surface type (sphere, conic, asphere)",
                                path=f"{path}.surface", got=sol.surface)
            before = "air" if surface == 0 else spec.surfaces[surface - 1].material
            if before == surf.material:
                raise SpecError("a curvature solve needs a change of medium at the surface",
                                path=f"{path}.surface", got=sol.surface)
            if sol.type == "image_height":
                if surface <= spec.stop_index:
                    raise SpecError("an image_height solve must act on a surface after the aperture stop",
                                    path=f"{path}.surface", got=sol.surface)
                if spec.system.field.hfov_deg is None:
                    raise SpecError("an image_height solve needs an angular field (system.field.hfov_deg)",
                                    path=path)
        out.append(Solve(sol.type, surface, sol.value))
    rank = {"ttl": 0, "efl": 1, "image_height": 1, "focus": 2}
    return sorted(out, key=lambda s: rank[s.kind])


def solved_quantities(solves: list[Solve], num_surfaces: int) -> frozenset[tuple[str, int]]:
    """(kind, surface) pairs that solves set: they leave θ."""
    out = set()
    for s in solves:
        if s.kind in ("efl", "image_height"):
            out.add(("curvature", s.surface))
        else:
            out.add(("thickness", num_surfaces - 1))
    return frozenset(out)


def _with_curvature(lens: Lens, s: int, c: Tensor) -> Lens:
    curv = torch.cat([lens.curvature[:s], c.reshape(1), lens.curvature[s + 1 :]])
    return replace(lens, curvature=curv)


def _with_last_thickness(lens: Lens, t: Tensor) -> Lens:
    return replace(lens, thickness=torch.cat([lens.thickness[:-1], t.reshape(1)]))


def _linear_solve(f0: Tensor, f1: Tensor, target: Tensor) -> tuple[Tensor, Tensor]:
    """Root c of f0 + c (f1 − f0) = target, and whether the slope is usable."""
    slope = f1 - f0
    ok = slope.abs() > 1e-12 * (f0.abs() + f1.abs() + 1e-300)
    safe = torch.where(ok, slope, torch.ones_like(slope))
    return torch.where(ok, (target - f0) / safe, torch.zeros_like(f0)), ok


def apply_solves(lens: Lens, system: System, solves: list[Solve], *, defocus: float) -> tuple[Lens, Tensor]:
    """The lens with every solve applied, and a bool tensor: all solves well posed."""
    ok = torch.ones((), dtype=torch.bool, device=lens.device)
    w = system.reference
    last = lens.num_surfaces - 1
    for sol in solves:
        if sol.kind == "ttl":
            lens = _with_last_thickness(lens, sol.value - lens.thickness[:-1].sum())
        elif sol.kind == "efl":
            lo = _with_curvature(lens, sol.surface, lens.curvature[0] * 0)
            hi = _with_curvature(lens, sol.surface, lens.curvature[0] * 0 + 1)
            c0 = ray_transfer(lo, w, 0, last)[2]
            c1 = ray_transfer(hi, w, 0, last)[2]
            c, good = _linear_solve(c0, c1, torch.full_like(c0, -1.0 / sol.value))
            lens, ok = _with_curvature(lens, sol.surface, c), ok & good
        elif sol.kind == "image_height":
            one = torch.ones((), dtype=lens.dtype, device=lens.device)
            tan = field_tangents(lens, system, one)
            lo = _with_curvature(lens, sol.surface, lens.curvature[0] * 0)
            hi = _with_curvature(lens, sol.surface, lens.curvature[0] * 0 + 1)
            y0 = chief_image_height(lo, system, tan)
            y1 = chief_image_height(hi, system, tan)
            c, good = _linear_solve(y0, y1, torch.full_like(y0, sol.value))
            lens, ok = _with_curvature(lens, sol.surface, c), ok & good
        else:  # focus: marginal ray (linear, so any height) crosses the axis at the image + defocus
            n = lens.index[:, w]
            h = torch.ones((), dtype=lens.dtype, device=lens.device)
            if system.object_distance is None:
                y0, u0 = h, torch.zeros_like(h)
            else:
                ep_z = first_order(lens, system).entrance_pupil_z
                u0 = h / (ep_z + system.object_distance)
                y0 = h - u0 * ep_z
            ys, ws = trace_paraxial(lens, w, y0, n[0] * u0)
            y_last, w_last = ys[last], ws[last + 1]
            good = w_last.abs() > 1e-15
            t = -y_last * n[-1] / torch.where(good, w_last, torch.ones_like(w_last))
            lens, ok = _with_last_thickness(lens, t + defocus), ok & good
    return lens, ok
