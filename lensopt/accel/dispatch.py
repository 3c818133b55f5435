"""Which trace runs: the eager ``trace``, an AOT-compiled package (``accel.aot``) or ``torch.compile``.

All give the same ``RayTrace`` (to ~1e-14 mm; tests hold them to 1e-12 mm). They differ in cost
(benchmarks/README.md, trace; measured on the loaded 2-core machine):

- eager: no start-up; every op writes a full array, and each call costs a fixed ≈ 5–20 ms of Python
  dispatch (large batches run in cache-sized chunks, ``trace.CHUNK_RAYS``);
- ``torch.compile`` (``accel.compiled``): ≈ 8× faster per ray, but *every process* pays Dynamo's
  tracing and Inductor's cache look-ups per lens structure — ≈ 20 s with a warm on-disk cache, 2 min
  cold — so it pays only for jobs tracing ~1e7 rays or more in one process;
- an AOT package: the same fused kernel, compiled once per machine and structure (``lensopt warmup``,
  or ``aot.build_package``), loaded in milliseconds by later processes. It is fed fixed chunks of
  ``aot.AOT_CHUNK`` rays (the last one padded with copies of the last ray and cut off), the one shape
  it was compiled for; inference only, CPU only.

``auto`` (the default) decides from the call alone — its ray count and the packages on disk —, never
from what the process traced before: it traces on the package when this structure has one on disk, the
call needs no gradients and it traces ``AOT_MIN_RAYS`` rays or more (the commands trace, plot psf,
simulate and evaluate, once ``lensopt warmup LENS`` ran); with ``torch.compile`` when one call traces
more than ``AUTO_MIN_RAYS`` rays (a compilation costs about what the eager trace of that many rays
does); otherwise eagerly. A call inside a forward-mode transform (``torch.func.jacfwd``, ``vmap``, dual
tensors: the LM Jacobian) always runs eagerly. ``compiled`` forces the compiled kernel: the package when
there is one (and no gradients are needed), else ``torch.compile``. The choice is made from ray counts
and the files on disk (not timings), so the same command on the same machine always takes the same path.

The backend comes with the ``Engine`` a call is given (``lensopt.engine``): ``trace_with`` is the
``tracer`` of the engines that ``lensopt.accel.engine`` makes (the CLI's). The first ``torch.compile`` of a
structure on this machine is timed, reported once through the engine's ``on_compile`` (the CLI prints
it) and remembered in ``lensopt_compiles.json`` in the Inductor cache directory; ``torch.compile`` is
also fed fixed chunks (``COMPILED_CHUNK``) so that it compiles one shape per structure.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
import torch.autograd.forward_ad as fwad
from torch import Tensor

from lensopt.accel import aot
from lensopt.engine import Engine
from lensopt.files import write_text_atomic
from lensopt.optics.intersect import NEWTON_ITERATIONS
from lensopt.optics.lens import Lens
from lensopt.optics.trace import Rays, RayTrace, SurfaceHit, trace

__all__ = ["AUTO_MIN_RAYS", "AOT_MIN_RAYS", "COMPILED_CHUNK", "choose_backend", "trace_with", "compile_log_path"]

logger = logging.getLogger(__name__)

AOT_MIN_RAYS = 5_000
"""Smallest call (rays) that ``auto`` sends to an AOT package: loading one costs 6–10 ms (measured, loaded
machine), about what the eager trace takes for 5,000 rays on the Cooke triplet (9,216 rays ≈ 12 ms; the
C-mount costs more per ray)."""
AUTO_MIN_RAYS = 10_000_000
"""Rays of one call above which ``auto`` compiles the trace with ``torch.compile`` (a structure without a
package): ≈ 5 s of float64 eager tracing here, about what a compilation costs with a warm on-disk cache."""

_compiled_keys: set[tuple] = set()
"""Structures compiled by ``torch.compile`` in this process (a cache: the first compilation is reported)."""


def _in_forward_transform() -> bool:
    return torch._C._functorch.peek_interpreter_stack() is not None or fwad._current_level >= 0


def _key(lens: Lens, upto: int | None, record: bool, newton_iterations: int) -> tuple:
    return (lens.shapes, lens.stop, upto, record, newton_iterations, lens.dtype, lens.device)


def choose_backend(lens: Lens, n_rays: int, *, backend: str = "auto", upto: int | None = None,
                   record: bool = False, newton_iterations: int = NEWTON_ITERATIONS, grad: bool = False) -> str:
    """``eager``, ``compiled`` (``torch.compile``) or ``aot`` (this structure's AOT package) for a call tracing
    ``n_rays`` rays with ``backend`` (``auto`` resolved as described above, from this call alone; ``grad``:
    the call needs autograd, which a package does not do)."""
    if backend == "eager":
        return backend
    forward = _in_forward_transform()
    packaged = (not grad and not forward
                and aot.has_package(lens, upto=upto, record=record, newton_iterations=newton_iterations))
    if backend == "compiled":
        return "aot" if packaged else "compiled"
    if forward:
        return "eager"
    if packaged and n_rays >= AOT_MIN_RAYS:
        return "aot"
    return "compiled" if n_rays > AUTO_MIN_RAYS else "eager"


def _needs_grad(lens: Lens, rays: Rays) -> bool:
    if not torch.is_grad_enabled():
        return False
    tensors = [rays.pos, rays.dir]
    tensors += [v for f in dataclasses.fields(lens) if isinstance(v := getattr(lens, f.name), Tensor)]
    return any(t.requires_grad for t in tensors)


def trace_with(lens: Lens, rays: Rays, *, engine: Engine | None = None, upto: int | None = None,
               record: bool = False, newton_iterations: int = NEWTON_ITERATIONS) -> RayTrace:
    """``trace(lens, rays, ...)`` on the backend of ``engine`` (None: ``Engine()``, auto)."""
    engine = engine or Engine()
    # math.prod of the broadcast shape (torch.broadcast_shapes would import sympy: 0.8 s on first use)
    n_rays = math.prod(np.broadcast_shapes(rays.pos.shape[:-1], rays.dir.shape[:-1], rays.wavelength.shape))
    name = choose_backend(lens, n_rays, backend=engine.backend, upto=upto, record=record,
                          newton_iterations=newton_iterations, grad=_needs_grad(lens, rays))
    if name == "eager":
        return trace(lens, rays, upto=upto, record=record, newton_iterations=newton_iterations)
    if name == "aot":
        try:
            return _compiled_in_chunks(aot.aot_trace, lens, rays, size=aot.AOT_CHUNK, upto=upto, record=record,
                                       newton_iterations=newton_iterations)
        except Exception as err:  # a package that does not load or run (damaged, foreign): eager from now on
            aot.mark_broken(lens, upto=upto, record=record, newton_iterations=newton_iterations)
            logger.warning("the compiled trace package %s failed (%s: %s); tracing eagerly",
                           aot.package_path(lens, upto=upto, record=record, newton_iterations=newton_iterations),
                           type(err).__name__, str(err).splitlines()[0] if str(err) else "")
            return trace(lens, rays, upto=upto, record=record, newton_iterations=newton_iterations)
    from lensopt.accel.compiled import compiled_trace  # imports torch._dynamo lazily

    key = _key(lens, upto, record, newton_iterations)
    first = key not in _compiled_keys
    start = time.perf_counter()
    out = _compiled_in_chunks(compiled_trace, lens, rays, size=COMPILED_CHUNK, upto=upto, record=record,
                              newton_iterations=newton_iterations)
    if first:
        _compiled_keys.add(key)
        _report_first(key, time.perf_counter() - start, engine.on_compile)
    return out


COMPILED_CHUNK = 1 << 16
"""Rays per call of the compiled kernel: every call gets exactly this many (the last chunk padded with
copies of the last ray, cut off again), so a lens structure is compiled for one shape only and every
later call and process finds it in Inductor's on-disk caches."""


def _compiled_in_chunks(fn: Callable[..., RayTrace], lens: Lens, rays: Rays, *, size: int,
                        **kwargs: object) -> RayTrace:
    """``fn(lens, rays, **kwargs)`` (a compiled trace) over fixed-size chunks of ``size`` rays, concatenated
    and cut back to the batch (same values: every ray is traced on its own)."""
    pos, dir = torch.broadcast_tensors(rays.pos, rays.dir)
    batch = pos.shape[:-1]
    n = batch.numel()
    if n == 0:
        return trace(lens, rays, **kwargs)  # type: ignore[arg-type]
    k = -(-n // size)
    pad = k * size - n
    wavelength = torch.broadcast_to(rays.wavelength, batch).reshape(-1)
    if pad:
        wavelength = torch.cat([wavelength, wavelength[-1:].expand(pad)])
    # One component-major copy of all chunks, (k, 3, size), the padding included (no padded copy first:
    # at 1e6 rays that second copy was 7 % of a packaged trace's call): chunk j is then a (size, 3) view
    # whose x, y, z planes are contiguous, the layout (and strides) the kernel is compiled for.
    pos_cm, dir_cm = (_chunk_planes(v.reshape(-1, 3), k, size) for v in (pos, dir))
    parts = [fn(lens, Rays(pos_cm[j].movedim(0, -1), dir_cm[j].movedim(0, -1), wavelength[j * size:(j + 1) * size]),
                **kwargs) for j in range(k)]

    def cat(values: list[Tensor]) -> Tensor:
        flat = values[0] if len(values) == 1 else torch.cat(values)
        return flat[:n].reshape(batch + flat.shape[1:])

    hits = tuple(SurfaceHit(*(cat([getattr(p.hits[i], f.name) for p in parts]) for f in dataclasses.fields(SurfaceHit)))
                 for i in range(len(parts[0].hits)))
    return RayTrace(pos=cat([p.pos for p in parts]), dir=cat([p.dir for p in parts]),
                    status=cat([p.status for p in parts]), backtrack=cat([p.backtrack for p in parts]), hits=hits,
                    failed_at=None if parts[0].failed_at is None else cat([p.failed_at for p in parts]))


def _chunk_planes(v: Tensor, k: int, size: int) -> Tensor:
    """(k, 3, size) component-major chunks of the (n, 3) rows ``v``, n ≤ k·size, the rows after the last
    filled with copies of the last one."""
    out = v.new_empty(k, 3, size)
    rows = out.transpose(1, 2)  # (k, size, 3) view of the planes
    n = v.shape[0]
    full, rest = divmod(n, size)
    if full:
        rows[:full].copy_(v[:full * size].reshape(full, size, 3))
    if rest:
        rows[full, :rest].copy_(v[full * size:])
        rows[full, rest:].copy_(v[-1:].expand(size - rest, 3))
    return out


def compile_log_path() -> Path:
    """Where the first compilation of each structure on this machine is remembered."""
    from torch._inductor.runtime.cache_dir_utils import cache_dir

    return Path(cache_dir()) / "lensopt_compiles.json"


def _report_first(key: tuple, seconds: float, listener: Callable[[str, float], None] | None) -> None:
    shapes, stop, upto, record, newton, dtype, device = key
    desc = (f"{len(shapes)} surfaces ({'/'.join(sorted({s.kind for s in shapes}))}), "
            f"{str(dtype).removeprefix('torch.')}, {device}{', recorded' if record else ''}"
            f"{'' if upto is None else f', up to surface {upto}'}")
    ident = repr(key)
    try:
        path = compile_log_path()
        log = json.loads(path.read_text()) if path.exists() else {}
    except (OSError, ValueError):
        return
    if ident in log:
        return
    log[ident] = {"structure": desc, "seconds": round(seconds, 3), "when": time.strftime("%Y-%m-%dT%H:%M:%SZ",
                                                                                        time.gmtime())}
    try:
        write_text_atomic(path, json.dumps(log, indent=1))
    except OSError:
        return
    logger.info("compiled the trace for %s in %.1f s (cached on disk in %s)", desc, seconds, path.parent)
    if listener is not None:
        listener(desc, seconds)
