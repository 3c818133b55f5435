"""Which trace runs: the eager ``trace``, an AOT-compiled package (``optics.aot``) or ``torch.compile``.

All give the same ``RayTrace`` (to ~1e-14 mm; tests hold them to 1e-12 mm). They differ in cost
(benchmarks/README.md, trace; measured on the loaded 2-core machine):

- eager: no start-up; every op writes a full array, and each call costs a fixed ≈ 5–20 ms of Python
  dispatch (large batches run in cache-sized chunks, ``trace.CHUNK_RAYS``);
- ``torch.compile`` (``optics.compiled``): ≈ 8× faster per ray, but *every process* pays Dynamo's
  tracing and Inductor's cache look-ups per lens structure — ≈ 20 s with a warm on-disk cache, 2 min
  cold — so it pays only for jobs tracing ~1e7 rays or more in one process;
- an AOT package: the same fused kernel, compiled once per machine and structure (``lensopt warmup``,
  or ``aot.build_package``), loaded in milliseconds by later processes. It is fed fixed chunks of
  ``aot.AOT_CHUNK`` rays (the last one padded with copies of the last ray and cut off), the one shape
  it was compiled for; inference only, CPU only.

``auto`` (the default) traces on the package when this structure has one on disk, the call needs no
gradients and it traces ``AOT_MIN_RAYS`` rays or more (or the package is loaded already): the commands
trace, plot psf, simulate and evaluate, once ``lensopt warmup LENS`` ran. Otherwise it traces eagerly,
until the rays traced for one structure in this process (``AUTO_MIN_RAYS``, ≈ 5 s of eager work) would
have paid for an in-process ``torch.compile``, which it then uses. A call inside a
forward-mode transform (``torch.func.jacfwd``, ``vmap``, dual tensors: the LM Jacobian) always runs
eagerly. ``compiled`` forces the compiled kernel: the package when there is one (and no gradients are
needed), else ``torch.compile``. The choice is made from ray counts and the files on disk (not
timings), so the same command on the same machine always takes the same path.

The backend is chosen per call (``backend=``) or for a block of code with ``use_backend`` (the CLI's
``--backend`` option), so the analysis functions need no extra argument. The first ``torch.compile`` of a
structure on this machine is timed and reported once through ``on_compile`` listeners (the CLI prints
it) and remembered in ``lensopt_compiles.json`` in the Inductor cache directory; ``torch.compile`` is
also fed fixed chunks (``COMPILED_CHUNK``) so that it compiles one shape per structure.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import json
import logging
import math
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import torch
import torch.autograd.forward_ad as fwad
from torch import Tensor

from lensopt.errors import LensoptError
from lensopt.files import write_text_atomic
from lensopt.optics import aot
from lensopt.optics.intersect import NEWTON_ITERATIONS
from lensopt.optics.lens import Lens
from lensopt.optics.trace import Rays, RayTrace, SurfaceHit, trace

__all__ = ["BACKENDS", "AUTO_MIN_RAYS", "AOT_MIN_RAYS", "COMPILED_CHUNK",
           "check_backend", "use_backend", "set_backend", "current_backend",
           "choose_backend",
           "trace_with", "on_compile", "compile_log_path", "reset_auto_counts"]

logger = logging.getLogger(__name__)

BACKENDS = ("auto", "eager", "compiled")
AOT_MIN_RAYS = 5_000
"""Smallest call (rays) that ``auto`` sends to an AOT package not loaded yet in this process: loading one
costs 6–10 ms (measured, loaded machine), about what the eager trace takes for 5,000 rays on the Cooke
triplet (9,216 rays ≈ 12 ms; the C-mount costs more per ray); once loaded, a package takes calls of any
size (one padded chunk costs about a millisecond, less than an eager call's fixed cost)."""
AUTO_MIN_RAYS = 10_000_000
"""Rays (summed over calls) one lens structure is traced eagerly under ``auto`` before it is compiled:
≈ 5 s of float64 eager tracing here, about what a compilation costs with a warm on-disk cache."""

_current: contextvars.ContextVar[str | None] = contextvars.ContextVar("lensopt_trace_backend", default=None)
_rays_seen: dict[tuple, int] = {}
_compiled_keys: set[tuple] = set()
_listeners: list[Callable[[str, float], None]] = []


def check_backend(name: str, *, path: str = "--backend") -> str:
    """``name`` if it is a backend, else a ``LensoptError`` naming ``path``."""
    if name not in BACKENDS:
        raise LensoptError(f"must be one of {', '.join(BACKENDS)}", path=path, got=name)
    return name


@contextlib.contextmanager
def use_backend(name: str) -> Iterator[None]:
    """Trace with backend ``name`` (auto | eager | compiled) inside the block."""
    token = _current.set(check_backend(name))
    try:
        yield
    finally:
        _current.reset(token)


def current_backend() -> str:
    """The backend set by the innermost ``use_backend`` or ``set_backend`` (default: ``$LENSOPT_BACKEND``,
    else auto)."""
    name = _current.get()
    return name if name is not None else check_backend(os.environ.get("LENSOPT_BACKEND", "auto"),
                                                       path="LENSOPT_BACKEND")


def set_backend(name: str) -> None:
    """Trace with backend ``name`` from now on in this context (the CLI: one command per process)."""
    _current.set(check_backend(name))


def reset_auto_counts() -> None:
    """Forget the rays counted per structure by ``auto`` (tests)."""
    _rays_seen.clear()


def on_compile(listener: Callable[[str, float], None]) -> Callable[[], None]:
    """Call ``listener(description, seconds)`` when a structure is compiled for the first time on this
    machine; returns a function that removes the listener."""
    _listeners.append(listener)
    return lambda: _listeners.remove(listener) if listener in _listeners else None


def _in_forward_transform() -> bool:
    return torch._C._functorch.peek_interpreter_stack() is not None or fwad._current_level >= 0


def _key(lens: Lens, upto: int | None, record: bool, newton_iterations: int) -> tuple:
    return (lens.shapes, lens.stop, upto, record, newton_iterations, lens.dtype, lens.device)


def choose_backend(lens: Lens, n_rays: int, *, backend: str | None = None, upto: int | None = None,
                   record: bool = False, newton_iterations: int = NEWTON_ITERATIONS, count: bool = True,
                   grad: bool = False) -> str:
    """``eager``, ``compiled`` (``torch.compile``) or ``aot`` (this structure's AOT package) for a call tracing
    ``n_rays`` rays (``auto`` resolved as described above; ``grad``: the call needs autograd, which a package
    does not do; ``count`` adds the rays to the structure's running total)."""
    name = current_backend() if backend is None else check_backend(backend, path="backend")
    if name == "eager":
        return name
    forward = _in_forward_transform()
    packaged = (not grad and not forward
                and aot.has_package(lens, upto=upto, record=record, newton_iterations=newton_iterations))
    if name == "compiled":
        return "aot" if packaged else "compiled"
    if forward:
        return "eager"
    if packaged and (n_rays >= AOT_MIN_RAYS
                     or aot.is_loaded(lens, upto=upto, record=record, newton_iterations=newton_iterations)):
        return "aot"
    key = _key(lens, upto, record, newton_iterations)
    if key in _compiled_keys:
        return "compiled"
    seen = _rays_seen.get(key, 0) + n_rays
    if count:
        _rays_seen[key] = seen
    return "compiled" if seen > AUTO_MIN_RAYS else "eager"


def _needs_grad(lens: Lens, rays: Rays) -> bool:
    if not torch.is_grad_enabled():
        return False
    tensors = [rays.pos, rays.dir]
    tensors += [v for f in dataclasses.fields(lens) if isinstance(v := getattr(lens, f.name), Tensor)]
    return any(t.requires_grad for t in tensors)


def trace_with(lens: Lens, rays: Rays, *, backend: str | None = None, upto: int | None = None,
               record: bool = False, newton_iterations: int = NEWTON_ITERATIONS) -> RayTrace:
    """``trace(lens, rays, ...)`` on the chosen backend (default: ``current_backend()``)."""
    if backend is not None:
        check_backend(backend, path="backend")
    # math.prod of the broadcast shape (torch.broadcast_shapes would import sympy: 0.8 s on first use)
    n_rays = math.prod(np.broadcast_shapes(rays.pos.shape[:-1], rays.dir.shape[:-1], rays.wavelength.shape))
    name = choose_backend(lens, n_rays, backend=backend, upto=upto, record=record,
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
    from lensopt.optics.compiled import compiled_trace  # imports torch._dynamo lazily

    key = _key(lens, upto, record, newton_iterations)
    first = key not in _compiled_keys
    start = time.perf_counter()
    out = _compiled_in_chunks(compiled_trace, lens, rays, size=COMPILED_CHUNK, upto=upto, record=record,
                              newton_iterations=newton_iterations)
    if first:
        _compiled_keys.add(key)
        _report_first(key, time.perf_counter() - start)
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
    pos, dir = pos.reshape(-1, 3), dir.reshape(-1, 3)
    if pad:
        pos = torch.cat([pos, pos[-1:].expand(pad, 3)])
        dir = torch.cat([dir, dir[-1:].expand(pad, 3)])
        wavelength = torch.cat([wavelength, wavelength[-1:].expand(pad)])
    # One component-major copy of all chunks, (k, 3, size): chunk j is then a (size, 3) view whose x, y, z
    # planes are contiguous, the layout (and strides) the kernel is compiled for.
    pos_cm = pos.reshape(k, size, 3).transpose(1, 2).contiguous()
    dir_cm = dir.reshape(k, size, 3).transpose(1, 2).contiguous()
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


def compile_log_path() -> Path:
    """Where the first compilation of each structure on this machine is remembered."""
    from torch._inductor.runtime.cache_dir_utils import cache_dir

    return Path(cache_dir()) / "lensopt_compiles.json"


def _report_first(key: tuple, seconds: float) -> None:
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
    for listener in list(_listeners):
        listener(desc, seconds)
