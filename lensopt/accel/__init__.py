"""The compile machinery: the same trace (and LM Jacobian) as the eager code, compiled for speed, and the
choice between them. Library code gets it through an ``Engine`` (``lensopt.engine``) whose ``tracer`` is
``dispatch.trace_with``: ``engine(...)`` makes one.

    dispatch.py  which trace runs for a call (eager, AOT package, torch.compile): ``choose_backend``, ``trace_with``
    compiled.py  the trace kernel under ``torch.compile`` (one compilation per structure and process)
    aot.py       ahead-of-time packages of the trace kernel on disk (``lensopt warmup``), loaded in milliseconds
    jacobian.py  the LM Jacobian captured once and compiled (AOTInductor package or Inductor in process)

Caches (plain memoization, never a switch): compiled kernels per structure (``compiled``), loaded and
broken packages (``aot``, ``jacobian``), structures compiled in this process (``dispatch``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from lensopt.engine import Engine

__all__ = ["engine", "on_backend"]


def engine(backend: str = "auto", *, max_memory: int | None = None,
           on_compile: Callable[[str, float], None] | None = None, retain_freed_memory: bool = False) -> Engine:
    """An ``Engine`` that traces on ``backend`` (``auto``, ``eager`` or ``compiled``) with the compiled
    traces available (``dispatch.trace_with``); the other arguments as ``Engine``'s."""
    from lensopt.accel.dispatch import trace_with

    return Engine(backend=backend, max_memory=max_memory, tracer=trace_with, on_compile=on_compile,
                  retain_freed_memory=retain_freed_memory)


def on_backend(base: Engine | None, backend: str) -> Engine:
    """``base`` (None: ``Engine()``) tracing on ``backend`` with the compiled traces available."""
    from lensopt.accel.dispatch import trace_with

    return dataclasses.replace(base or Engine(), backend=backend, tracer=trace_with)
