"""The LM Jacobian without the work of inactive constraint rows (S2.2.2 "efficient pruning"), exact.

A ramp constraint row ramp(x) = max(x, 0) of a ray that reached the image has the tangent
``where(x >= 0, ẋ, 0)`` (``clamp_min``'s forward-mode rule), and a row of a failed ray is masked to
0 with its tangent: so a row with x < 0 (an inactive constraint) or a failed ray has an exactly zero
Jacobian row. At a C-mount start 95 % of the rows (ray path per gap, angles per interface) are such
rows, and eager ``jacfwd`` spends a quarter of its time carrying their tangents through the ramp,
mask, stack and concatenation (N tangents per row).

``row_jacobian(problem, θ)`` first evaluates ℓ(θ) without tangents (no autograd), which also gives x
of every ramp row; then runs ``jacfwd`` of the residual function in which the ramp groups keep only
the rows with x ≥ 0 of valid rays (the same elementwise operations on the same values, so those rows
are bit for bit the eager ones), and scatters them into an (M, N) Jacobian of zeros. The other
groups (TRA, distortion, glass terms, failures, any registered term) go through their own residual
functions unchanged. ``Problem.jacobian`` stays the reference (``tests/optim/test_row_jacobian.py``
checks equality with it, rows with x = 0 exactly included).

The selection depends on θ, so this is an eager path: it never runs inside a captured graph.

**Not used by the optimizer**: measured, it does not pay (``benchmarks/optimize/jacobian_cost.py --rows --clock
cpu``: 1.07× the CPU time of eager ``jacfwd`` on the C-mount start, 1.10× on the Cooke): the extra
tangent-free evaluation of ℓ and the gathers cost as much as the skipped rows' tangent work, which is a
small part of the Jacobian (the trace's tangents are the bulk). Kept as the measured, tested
alternative (the benchmark diary in git history: ``git log -- benchmarks/RESULTS.md``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import torch
from torch import Tensor

from lensopt.analysis.spot import spot_stats
from lensopt.optics.bundle import Bundle
from lensopt.optics.lens import Lens
from lensopt.optim import residuals as res
from lensopt.optim.rays import head
from lensopt.optim.terms import TERMS, TermContext

if TYPE_CHECKING:
    from lensopt.optim.problem import Problem

__all__ = ["row_jacobian", "ramp_inputs", "RAMP_GROUPS"]

# A ramp group's pre-ramp values: context ↦ (rows, F, W, P) x, whose residual rows are
# ramp(x) masked to valid rays, flattened, / √n_r (residuals.ray_path, ray_angle, surface_normal).
_RESIDUAL_OF: dict[str, Callable] = {name: TERMS[name].residual for name in ("ray_path", "ray_angle", "surface_normal")}


def _path_x(c: TermContext, rows: Tensor | None = None) -> list[Tensor]:
    """Pre-ramp values of ``ray_path``: per gap max(t_z − upper, lower − t_z), then per span."""
    r = c.bundle.result
    lo, hi = c.problem.gap_bounds(c.lens)
    z = [h.pos[..., 2] for h in r.hits] + [r.pos[..., 2]]
    out = [torch.maximum((z[s + 1] - z[s]) - hi[s], lo[s] - (z[s + 1] - z[s])) for s in range(len(z) - 1)]
    for a, b, low, high in c.problem.path_spans:
        t = torch.stack([z[s + 1] - z[s] for s in range(a, b)]).sum(0)
        out.append(torch.maximum(t - high, low - t))
    return out


def _angle_x(c: TermContext) -> list[Tensor]:
    hits = c.bundle.result.hits
    c2 = math.cos(math.radians(c.problem.opt.constraints.ray_angle.max_deg)) ** 2
    out = []
    for s in c.problem.interfaces:
        out += [c2 - hits[s].cos2_in, c2 - hits[s].cos2_out]
    return out


def _normal_x(c: TermContext) -> list[Tensor]:
    hits = c.bundle.result.hits
    c2 = math.cos(math.radians(c.problem.opt.constraints.surface_normal.max_deg)) ** 2
    refracting = [s for s in c.problem.interfaces if not c.problem.surfaces[s].plane]
    return [c2 - hits[s].normal[..., 2] ** 2 for s in refracting]


RAMP_GROUPS: dict[str, Callable[[TermContext], list[Tensor]]] = {
    "ray_path": _path_x, "ray_angle": _angle_x, "surface_normal": _normal_x}
"""The ramp groups whose inactive rows are skipped, each with its pre-ramp values (one (F, W, P)
tensor per block of rows, in row order)."""


def ramp_inputs(c: TermContext, name: str) -> list[Tensor]:
    """The pre-ramp values x of group ``name``, one (F, W, P) tensor per block of its rows."""
    return RAMP_GROUPS[name](c)


def _context(problem: Problem, theta: Tensor, lens: Lens, bundle: Bundle) -> TermContext:
    spot = head(bundle, problem.num_spot)
    stats = spot_stats(spot, problem.system.wavelength_weights, problem.field_weights)
    return TermContext(problem, theta, lens, bundle, spot, stats)


def _skippable(problem: Problem) -> list[str]:
    """The active ramp groups whose residual function is still the built-in one (a replaced term is
    differentiated in full)."""
    return [n for n in RAMP_GROUPS if n in problem.slices and TERMS[n].residual is _RESIDUAL_OF[n]]


def row_jacobian(problem: Problem, theta: Tensor) -> tuple[Tensor, Tensor]:
    """(M, N) Jacobian and ℓ(θ) (M,) of ``problem``, equal to ``problem.jacobian(θ)``; the rows of
    inactive ramp constraints and failed rays are written as zeros without carrying their tangents."""
    groups = _skippable(problem)
    if not groups:
        return problem.jacobian(theta)
    with torch.no_grad():
        lens, _ = problem.lens(theta)
        bundle = problem.bundle(lens)
        ctx = _context(problem, theta, lens, bundle)
        r = torch.cat([TERMS[n].residual(ctx) * TERMS[n].weight(problem) for n in problem.slices])
        valid = bundle.result.valid.reshape(-1)
        keep = {}  # group ↦ per block, the flat ray indices whose row can be non-zero
        for n in groups:
            keep[n] = [torch.nonzero((x.reshape(-1) >= 0) & valid).squeeze(-1) for x in ramp_inputs(ctx, n)]
    n_r = valid.numel()

    def selected(t: Tensor) -> Tensor:
        lens, _ = problem.lens(t)
        c = _context(problem, t, lens, problem.bundle(lens))
        out = []
        for name in problem.slices:
            term = TERMS[name]
            w = term.weight(problem)
            if name in keep:
                xs = ramp_inputs(c, name)
                d = torch.cat([res._ramp(x.reshape(-1)[i]) for x, i in zip(xs, keep[name], strict=True)])
                out.append(d / math.sqrt(n_r) * w)
            else:
                out.append(term.residual(c) * w)
        return torch.cat(out)

    Js = torch.func.jacfwd(selected)(theta)
    rows = []
    for name, sl in problem.slices.items():
        if name in keep:
            rows += [sl.start + k * n_r + i for k, i in enumerate(keep[name])]
        else:
            rows.append(torch.arange(sl.start, sl.stop, device=r.device))
    J = torch.zeros(problem.size, theta.shape[0], dtype=Js.dtype, device=Js.device)
    J[torch.cat(rows)] = Js
    return J, r
