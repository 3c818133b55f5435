"""``torch.compile``-d sequential trace for large ray counts (PSFs, image simulation, benchmarks).

``trace`` is written with fixed shapes, masks instead of branches on tensor values and no
``.item()``, so that TorchDynamo captures it as one graph and Inductor fuses the whole surface loop
into one C++ kernel (DESIGN.md "Speed": eager torch is memory-bound, every op writes a full array).
``compiled_trace`` is a drop-in for ``trace``: same arguments, same ``RayTrace``, same numbers (to
rounding: Inductor may contract ``a*b + c`` and reorder sums), differentiable: reverse mode runs
through the compiled graph (AOTAutograd compiles the backward too); forward mode (``torch.func.jvp``,
``jacfwd``, ``forward_ad`` duals) runs the eager ``trace`` for that call, because a compiled graph
called from inside a forward-mode transform either raises or silently drops the tangents
(tests/optics/test_compiled_gradients.py).

What it buys on CPU today (benchmarks/RESULTS.md issue 14, Cooke triplet, 1e6 rays, one thread):
≈ 10× optiland's tracer in float64 (≈ 9× the chunked eager trace), within ≈ 2.6× of a bare
sphere-and-Snell sketch, with peak memory only that of the outputs. The whole surface loop is one
fused SIMD loop over the rays: the trace internals are component-wise, rays are read
component-major, Inductor's fusion-size limit is raised so that it does not split the loop into
several kernels joined by ray-sized buffers, and inside the graph the trace avoids what Inductor's
C++ code does badly: boolean mask algebra (masks are float flags combined by selects) and gathers
(per-wavelength tables are looked up by selects).

One compiled function is cached per lens *structure* (surface kinds, stop, ``upto``, ``record``,
Newton cap, dtype, device). Changing tensor values (an optimizer step) reuses it; changing the
number of rays recompiles once, after which the ray count is a dynamic dimension. Each structure
gets its own code object, so many structures in one process never hit Dynamo's per-code-object
recompile limit (which would silently fall back to eager).

If compilation is unavailable (no C++ compiler, unsupported Python, a backend error), the eager
``trace`` runs instead and a warning is logged once per structure; ``fallback=False`` raises
instead (for tests that must know they measured the compiled path).
"""

from __future__ import annotations

import logging
import types
from collections.abc import Callable
from typing import Any

import torch
from torch import Tensor

from lensopt.optics.intersect import NEWTON_ITERATIONS
from lensopt.optics.lens import Lens, SurfaceShape
from lensopt.optics.trace import Rays, RayTrace, SurfaceHit, trace

__all__ = ["compiled_trace", "component_major_rays", "clear_compiled_cache"]

logger = logging.getLogger(__name__)

_LENS_TENSORS = ("curvature", "conic", "asphere", "phase", "thickness", "index", "wavelength_um", "semi_diameter")

_Key = tuple[tuple[SurfaceShape, ...], int, int | None, bool, int, torch.dtype, torch.device, int]
_EAGER = "eager"
_cache: dict[_Key, Callable[..., Any] | str] = {}
_MAX_FUSION_SIZE = 4096


def compiled_trace(
    lens: Lens,
    rays: Rays,
    *,
    upto: int | None = None,
    record: bool = False,
    newton_iterations: int = NEWTON_ITERATIONS,
    fallback: bool = True,
) -> RayTrace:
    """``trace(lens, rays, ...)`` through a cached ``torch.compile``-d function.

    Args:
        lens: the lens (any tensor values; the structure selects the cached function).
        rays: object-space rays, batch (*B).
        upto, record, newton_iterations: as in ``trace``.
        fallback: run the eager ``trace`` when compilation fails (logged once per structure);
            False re-raises the compilation error.

    Returns:
        The same ``RayTrace`` as ``trace``: pos/dir (*B, 3), status/backtrack (*B), hits.

    Compilation takes tens of seconds the first time per structure (Inductor caches kernels on
    disk, so later processes are faster); use it when the trace is called on ≳1e5 rays or many times.
    """
    if lens.placement is not None:  # decentered/tilted lenses: the eager trace (not compiled yet)
        return trace(lens, rays, upto=upto, record=record, newton_iterations=newton_iterations)
    args = [getattr(lens, name) for name in _LENS_TENSORS]
    if _forward_mode(args + [rays.pos, rays.dir]):
        # torch.compile drops forward-mode tangents of a graph called from outside it (measured:
        # a ``forward_ad`` dual comes back with tangent None; ``torch.func.jvp`` raises), so forward
        # mode runs the eager trace, without marking the structure as failed. The optimizer's
        # compiled Jacobian (``optim.compiled_jacobian``) compiles the jvp itself instead.
        return trace(lens, rays, upto=upto, record=record, newton_iterations=newton_iterations)
    # The number of wavelengths is part of the structure: the trace looks the index table up by
    # selects over the wavelengths when it is compiled (``trace._per_ray``).
    key: _Key = (lens.shapes, lens.stop, upto, record, newton_iterations, lens.dtype, lens.device,
                 lens.index.shape[-1])
    fn = _cache.get(key)
    if fn is None:
        fn = _cache[key] = _make_compiled(key)
    # Component-major copies (x of every ray, then y, then z): the fused kernel then loads each
    # component contiguously and vectorizes over rays; from the interleaved (*B, 3) layout Inductor
    # falls back to scalar loops (about 2× slower). Rays made component-major by the caller
    # (``component_major_rays``) skip the copy, ~20 % of a call at 1e6 rays.
    pos, dir = torch.broadcast_tensors(rays.pos, rays.dir)
    args += [_component_major(pos), _component_major(dir), rays.wavelength]
    if isinstance(fn, str):
        return trace(lens, rays, upto=upto, record=record, newton_iterations=newton_iterations)
    try:
        out = fn(*args)
    except Exception as err:
        if not fallback:
            raise
        result = trace(lens, rays, upto=upto, record=record, newton_iterations=newton_iterations)
        # Eager worked on the same input, so compilation itself is what failed: remember that.
        _cache[key] = _EAGER
        logger.warning("torch.compile of the trace failed (%s: %s); using the eager trace",
                       type(err).__name__, str(err).splitlines()[0] if str(err) else "")
        return result
    pos, dir, status, backtrack, hits, failed_at = out
    return RayTrace(pos=pos, dir=dir, status=status, backtrack=backtrack,
                    hits=tuple(SurfaceHit(*h) for h in hits), failed_at=failed_at)


def _forward_mode(tensors: list[Tensor]) -> bool:
    """Whether a forward-mode transform is active (``torch.func.jvp``/``jacfwd``/``vmap``) or any
    input carries a ``torch.autograd.forward_ad`` tangent."""
    from torch._C._functorch import is_functorch_wrapped_tensor
    from torch.autograd.forward_ad import unpack_dual

    return any(is_functorch_wrapped_tensor(t) or unpack_dual(t).tangent is not None for t in tensors)


def _component_major(v: Tensor) -> Tensor:
    """The same (*B, 3) values stored as three contiguous (*B) planes (no copy when they already are)."""
    planes = v.movedim(-1, 0)
    return v if planes.is_contiguous() else planes.contiguous().movedim(0, -1)


def component_major_rays(rays: Rays) -> Rays:
    """The same rays with positions and directions stored component-major (x of every ray, then y,
    then z; still (*B, 3) tensors): the layout ``compiled_trace`` (and the eager trace) read fastest."""
    pos, dir = torch.broadcast_tensors(rays.pos, rays.dir)
    return Rays(_component_major(pos), _component_major(dir), rays.wavelength)


def clear_compiled_cache() -> None:
    """Forget every compiled trace (and every remembered compilation failure)."""
    _cache.clear()


def _make_compiled(key: _Key) -> Callable[..., Any]:
    """A fresh ``torch.compile``-d flat-tensor trace for one lens structure."""
    shapes, stop, upto, record, newton_iterations = key[:5]

    def flat_trace(
        curvature: Tensor, conic: Tensor, asphere: Tensor, phase: Tensor, thickness: Tensor,
        index: Tensor, wavelength_um: Tensor, semi_diameter: Tensor,
        pos: Tensor, dir: Tensor, wavelength: Tensor,
    ) -> tuple[Tensor, Tensor, Tensor, Tensor, tuple[tuple[Tensor, ...], ...], Tensor | None]:
        lens = Lens(shapes=shapes, curvature=curvature, conic=conic, asphere=asphere, phase=phase,
                    thickness=thickness, index=index, wavelength_um=wavelength_um,
                    semi_diameter=semi_diameter, stop=stop)
        r = trace(lens, Rays(pos, dir, wavelength), upto=upto, record=record,
                  newton_iterations=newton_iterations)
        hits = tuple((h.pos, h.dir_in, h.dir_out, h.normal, h.t, h.cos2_in, h.cos2_out) for h in r.hits)
        return r.pos, r.dir, r.status, r.backtrack, hits, r.failed_at

    # Dynamo keeps its compiled-code cache (and recompile limit) per code object; a copy of the
    # code per structure keeps structures from evicting each other.
    code = flat_trace.__code__.replace(co_name=f"flat_trace_{len(_cache)}")
    fresh = types.FunctionType(code, flat_trace.__globals__, code.co_name, None, flat_trace.__closure__)
    # fullgraph: a graph break (an ``.item()``, a branch on a tensor value) is an error here, which
    # the caller turns into the eager fallback (or raises with ``fallback=False``, as the tests do).
    # max_fusion_size: Inductor's default (64 nodes per fused kernel) cuts the surface loop into a
    # few kernels joined by ~100 ray-sized buffers; one kernel over the whole loop keeps the rays in
    # registers (2.5× faster at 1e6 rays on the Cooke triplet, benchmarks/RESULTS.md).
    return torch.compile(fresh, fullgraph=True, options={"max_fusion_size": _MAX_FUSION_SIZE})
