"""Helpers shared by the hard-case tests: small lenses built directly as tensors (so expected outcomes
can be derived by hand from the numbers given), rays, and the finiteness checks every case runs.

Every case checks the same contract (DESIGN.md rule 1): every value the trace returns is finite, the
gradient with respect to every lens tensor is finite — for a loss that reduces over *all* rays with
the ``valid`` mask (``torch.where``) and for the unmasked sum of every output (placeholders of failed
rays included) — and each failure is counted under its own ``Status`` reason.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor

from lensopt.optics.lens import Lens, SurfaceShape
from lensopt.optics.trace import Rays, RayTrace, failure_counts, trace

LENS_TENSORS = ("curvature", "conic", "asphere", "phase", "thickness", "index")


def make_lens(
    surfaces: Sequence[dict[str, Any]],
    *,
    index: Sequence[float],
    wavelength_um: float = 0.5876,
    stop: int = 0,
    dtype: torch.dtype = torch.float64,
) -> Lens:
    """A lens from plain numbers, one wavelength, constant indices (object space first).

    Each surface: ``kind`` (plane|sphere|conic|asphere), ``c`` (1/mm), ``t`` (gap after, mm), and
    optionally ``k`` (conic), ``a`` (asphere a4, a6, …), ``phase`` (d2, d4, …; makes it diffractive).
    """
    n_a = max((len(s.get("a", ())) for s in surfaces), default=0)
    n_p = max((len(s.get("phase", ())) for s in surfaces), default=0)

    def table(key: str, width: int) -> Tensor:
        rows = [list(s.get(key, ())) + [0.0] * (width - len(s.get(key, ()))) for s in surfaces]
        return torch.tensor(rows, dtype=dtype).reshape(len(surfaces), width)

    shapes = tuple(SurfaceShape(kind=s["kind"], diffractive="phase" in s) for s in surfaces)
    return Lens(
        shapes=shapes,
        curvature=torch.tensor([float(s.get("c", 0.0)) for s in surfaces], dtype=dtype),
        conic=torch.tensor([float(s.get("k", 0.0)) for s in surfaces], dtype=dtype),
        asphere=table("a", n_a),
        phase=table("phase", n_p),
        thickness=torch.tensor([float(s["t"]) for s in surfaces], dtype=dtype),
        index=torch.tensor(index, dtype=dtype).unsqueeze(-1),
        wavelength_um=torch.tensor([wavelength_um], dtype=dtype),
        semi_diameter=torch.zeros(len(surfaces), dtype=dtype),
        stop=stop,
    )


def make_rays(pos: Tensor, direction: Tensor) -> Rays:
    """Rays (single wavelength) from positions and (normalized here) directions, shape (N, 3)."""
    direction = direction / torch.linalg.vector_norm(direction, dim=-1, keepdim=True)
    pos, direction = torch.broadcast_tensors(pos, direction)
    return Rays(pos=pos, dir=direction, wavelength=torch.zeros((), dtype=torch.long))


def collimated(heights: Tensor, *, angle_deg: float = 0.0, z: float = -1.0) -> Rays:
    """Meridional rays at heights y on the plane ``z``, tilted by ``angle_deg`` in the y–z plane."""
    a = torch.deg2rad(torch.tensor(angle_deg, dtype=heights.dtype))
    pos = torch.stack([torch.zeros_like(heights), heights, torch.full_like(heights, z)], -1)
    d = torch.stack([torch.zeros_like(a), torch.sin(a), torch.cos(a)]).expand_as(pos)
    return make_rays(pos, d)


def counts(result: RayTrace) -> dict[str, int]:
    """Failure counts with the zero entries dropped (so expectations list only what happens)."""
    return {k: v for k, v in failure_counts(result).items() if v}


def _outputs(result: RayTrace) -> list[Tensor]:
    outs = [result.pos, result.dir]
    for h in result.hits:
        outs += [h.pos, h.dir_in, h.dir_out, h.normal, h.t, h.cos2_in, h.cos2_out]
    return outs


def trace_checked(lens: Lens, rays: Rays, **kwargs: Any) -> tuple[RayTrace, dict[str, Tensor]]:
    """Trace with every lens tensor as a leaf; assert all values and all gradients are finite.

    Returns the trace and the gradients of the masked loss Σ_valid |image xy|² w.r.t. each lens tensor.
    """
    leaves = {name: getattr(lens, name).detach().clone().requires_grad_(True) for name in LENS_TENSORS}
    lens = dataclasses.replace(lens, **leaves)
    result = trace(lens, rays, record=True, **kwargs)
    for out in _outputs(result):
        assert bool(torch.isfinite(out).all()), "non-finite value in the trace"
    valid = result.valid.unsqueeze(-1)
    masked = torch.where(valid, result.pos[..., :2], 0.0).pow(2).sum()
    masked = masked + torch.where(valid, result.dir, 0.0).sum()
    grads = torch.autograd.grad(masked, list(leaves.values()), retain_graph=True, allow_unused=True)
    unmasked = sum(out.sum() for out in _outputs(result) if out.requires_grad)
    grads_all = torch.autograd.grad(unmasked, list(leaves.values()), allow_unused=True)
    out: dict[str, Tensor] = {}
    for name, g, g_all in zip(leaves, grads, grads_all, strict=True):
        for what, grad in (("masked", g), ("unmasked", g_all)):
            if grad is not None:
                assert bool(torch.isfinite(grad).all()), f"non-finite {what} gradient w.r.t. {name}"
        out[name] = g if g is not None else torch.zeros_like(leaves[name])
    return result, out
