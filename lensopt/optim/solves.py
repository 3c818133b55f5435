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

from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import (
    chief_image_height,
    field_tangents,
    first_order,
    ray_transfer,
    trace_paraxial,
)

__all__ = ["Solve", "solved_quantities", "apply_solves"]


@dataclass(frozen=True)
class Solve:
    """A resolved solve: kind, 0-based surface (curvature solves), target value (mm). Solves are resolved
    from a spec (checked against its surfaces, in application order: ttl, then efl/image_height, then
    focus) by ``lensopt.design.setup.resolve_solves``."""

    kind: str
    surface: int | None
    value: float | None


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
