"""``torch.compile``-d sequential trace for large ray counts (PSFs, image simulation, benchmarks).

``trace`` is written with fixed shapes, masks instead of branches on tensor values and no
``.item()``, so that TorchDynamo captures it as one graph and Inductor fuses the whole surface loop
into one C++ kernel (DESIGN.md "Speed": eager torch is memory-bound, every op writes a full array).
``compiled_trace`` is a drop-in for ``trace``: same arguments, same ``RayTrace``, same statuses and
the same numbers to rounding, differentiable: reverse mode runs through the compiled graph
(AOTAutograd compiles the backward too); forward mode (``torch.func.jvp``, ``jacfwd``,
``forward_ad`` duals) runs the eager ``trace`` for that call, because a compiled graph called from
inside a forward-mode transform either raises or silently drops the tangents
(tests/optics/test_compiled_gradients.py).

What it compiles is ``trace.trace_kernel``: the same trace in a formulation with less work per ray
(``trace.KernelOptions``), which differs from the eager reference only in rounding (and Inductor may
contract ``a*b + c`` and reorder sums): refraction from one per-wavelength table of n/n', no far
root on spheres, ellipsoids and paraboloids (1 + κ ≥ 0, read from the prescription outside the
kernel; ``near_only_surfaces``), outputs written component-major (``pos``/``dir`` are (*B, 3) views
of (3, *B) planes, like rays from ``component_major_rays``). tests/optics/test_trace_kernel.py runs
that formulation eagerly against ``trace`` on hard cases.

What it buys on CPU today (benchmarks/README.md, trace; Cooke triplet, 1e6 rays, one thread):
≈ 10× optiland's tracer in float64 (≈ 9× the chunked eager trace), within ≈ 2× of a bare
sphere-and-Snell sketch, with peak memory only that of the outputs. The whole surface loop is one
fused SIMD loop over the rays: the trace internals are component-wise, rays are read
component-major, Inductor's fusion-size limit is raised so that it does not split the loop into
several kernels joined by ray-sized buffers, and inside the graph the trace avoids what Inductor's
C++ code does badly: boolean mask algebra (masks are float flags combined by selects), float32
flags in a float64 kernel, strided stores, and gathers (per-wavelength tables are looked up by
selects).

One compiled function is cached per lens *structure* (surface kinds, stop, ``upto``, ``record``,
Newton cap, dtype, device, number of wavelengths, which quadrics skip the far root). Changing
tensor values (an optimizer step) reuses it (a conic crossing κ = −1 selects another one);
changing the number of rays recompiles once, after which the ray count is a dynamic dimension.
Each structure gets its own code object, so many structures in one process never hit Dynamo's
per-code-object recompile limit (which would silently fall back to eager).

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
from lensopt.optics.trace import KernelOptions, Rays, RayTrace, SurfaceHit, index_ratio, trace, trace_kernel

__all__ = ["compiled_trace", "component_major_rays", "clear_compiled_cache", "near_only_surfaces"]

logger = logging.getLogger(__name__)

_LENS_TENSORS = ("curvature", "conic", "asphere", "phase", "thickness", "index", "wavelength_um", "semi_diameter")

_Key = tuple[tuple[SurfaceShape, ...], int, int | None, bool, int, torch.dtype, torch.device, int, tuple[bool, ...]]
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
        The same ``RayTrace`` as ``trace``: pos/dir (*B, 3), status/backtrack (*B), hits; pos, dir
        and the hits' vectors stored component-major ((*B, 3) views of (3, *B) planes).

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
        # compiled Jacobian (``accel.jacobian``) compiles the jvp itself instead.
        return trace(lens, rays, upto=upto, record=record, newton_iterations=newton_iterations)
    # Component-major copies (x of every ray, then y, then z): the fused kernel then loads each
    # component contiguously and vectorizes over rays; from the interleaved (*B, 3) layout Inductor
    # falls back to scalar loops (about 2× slower). Rays made component-major by the caller
    # (``component_major_rays``) skip the copy, ~20 % of a call at 1e6 rays.
    pos, dir = torch.broadcast_tensors(rays.pos, rays.dir)
    # The n/n' table computed here, outside the kernel (which would redo it per block of rays).
    args += [_component_major(pos), _component_major(dir), rays.wavelength, index_ratio(lens)]
    # The structure: the number of wavelengths (the kernel looks the index tables up by selects over
    # the wavelengths, ``trace._per_ray``) and which quadrics can skip the far root (1 + κ ≥ 0, read
    # from the prescription here, outside the kernel: no branch on values inside it).
    key: _Key = (lens.shapes, lens.stop, upto, record, newton_iterations, lens.dtype, lens.device,
                 lens.index.shape[-1], near_only_surfaces(lens))
    out = _call(key, args, lens, rays, upto, record, newton_iterations, fallback)
    if isinstance(out, RayTrace):
        return out
    pos, dir, status, backtrack, hits, failed_at = out
    return RayTrace(pos=pos, dir=dir, status=status, backtrack=backtrack,
                    hits=tuple(SurfaceHit(*h) for h in hits), failed_at=failed_at)


def near_only_surfaces(lens: Lens) -> tuple[bool, ...]:
    """Per surface, whether a closed-form quadric there can skip the far root: 1 + κ ≥ 0 (a plane,
    sphere, ellipsoid or paraboloid; ``intersect.quadric_near_xyz``). A decision on the prescription's
    values, made outside the kernel: a conic that crosses κ = −1 selects another compiled kernel."""
    return tuple(bool(v) for v in (lens.conic.detach() >= -1.0).tolist())


def _call(key: _Key, args: list[Tensor], lens: Lens, rays: Rays, upto: int | None, record: bool,
          newton_iterations: int, fallback: bool) -> RayTrace | tuple[Any, ...]:
    """The compiled function of ``key`` on ``args`` (its flat outputs), or the eager trace's
    ``RayTrace`` where compilation is unavailable or fails (with ``fallback``)."""
    fn = _cache.get(key)
    if fn is None:
        fn = _cache[key] = _make_compiled(key)
    if isinstance(fn, str):
        return trace(lens, rays, upto=upto, record=record, newton_iterations=newton_iterations)
    try:
        return fn(*args)
    except Exception as err:
        if not fallback:
            raise
        result = trace(lens, rays, upto=upto, record=record, newton_iterations=newton_iterations)
        # Eager worked on the same input, so compilation itself is what failed: remember that.
        _cache[key] = _EAGER
        logger.warning("torch.compile of the trace failed (%s: %s); using the eager trace",
                       type(err).__name__, str(err).splitlines()[0] if str(err) else "")
        return result


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
    options = KernelOptions(near_only=key[-1])

    def flat_trace(
        curvature: Tensor, conic: Tensor, asphere: Tensor, phase: Tensor, thickness: Tensor,
        index: Tensor, wavelength_um: Tensor, semi_diameter: Tensor,
        pos: Tensor, dir: Tensor, wavelength: Tensor, ratio: Tensor,
    ) -> tuple[Tensor, Tensor, Tensor, Tensor, tuple[tuple[Tensor, ...], ...], Tensor | None]:
        lens = Lens(shapes=shapes, curvature=curvature, conic=conic, asphere=asphere, phase=phase,
                    thickness=thickness, index=index, wavelength_um=wavelength_um,
                    semi_diameter=semi_diameter, stop=stop)
        r = trace_kernel(lens, Rays(pos, dir, wavelength), options, upto=upto, record=record,
                         newton_iterations=newton_iterations, ratio=ratio)
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
    # registers (2.5× faster at 1e6 rays on the Cooke triplet, git history of benchmarks/RESULTS.md).
    return torch.compile(fresh, fullgraph=True, options={"max_fusion_size": _MAX_FUSION_SIZE})
