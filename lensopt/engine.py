"""How a command's work runs, never what it computes: one frozen ``Engine`` value (trace backend, memory
budget, the compiled-trace dispatcher, the allocator setting of long optimizations).

The CLI builds it once per command from its options and the environment (``--backend`` /
``LENSOPT_BACKEND``, ``--max-memory`` / ``LENSOPT_MAX_MEMORY``) and passes it down; library functions
take ``engine=`` (None: ``Engine()``, the eager trace and the default budget). Nothing in the library
reads the environment or a process-wide switch for these.

The memory budget is checked before large allocations (rays, images, PSF grids): work that would need
more than the budget is refused with one ``LensoptError`` that says what to lower, instead of exhausting
the machine's memory. The default budget is a fraction of the machine's memory (or of the cgroup limit,
whichever is smaller). The estimates are deliberately coarse upper bounds of the peak working set
(bytes per ray and surface, copies of an image through the simulation pipeline).

A leaf: it imports nothing from lensopt but the errors.
"""

from __future__ import annotations

import functools
import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from lensopt.errors import LensoptError

__all__ = ["BACKENDS", "BYTES_PER_RAY_SURFACE", "DEFAULT_FRACTION", "Engine", "Tracer", "check_backend",
           "format_bytes", "machine_memory", "parse_size", "retain_freed_memory"]

BACKENDS = ("auto", "eager", "compiled")
#: Share of the machine's memory that one command may plan to use.
DEFAULT_FRACTION = 0.5
#: Bytes per ray and surface of a traced bundle (positions, directions, masks, path lengths and
#: intermediates): ``trace --sampling rings:300`` on the Cooke triplet grows the peak RSS by ~66 bytes per
#: ray-surface over rings:24; 160 leaves room for the analyses built on the bundle.
BYTES_PER_RAY_SURFACE = 160


class Tracer(Protocol):
    """A trace on the engine's backend: ``tracer(lens, rays, engine=, upto=, record=, newton_iterations=)``
    returns what ``optics.trace.trace`` returns (``lensopt.accel.dispatch.trace_with`` is the one)."""

    def __call__(self, lens: Any, rays: Any, *, engine: Engine, upto: int | None, record: bool,
                 newton_iterations: int) -> Any: ...


def check_backend(name: str, *, path: str = "--backend") -> str:
    """``name`` if it is a backend, else a ``LensoptError`` naming ``path``."""
    if name not in BACKENDS:
        raise LensoptError(f"must be one of {', '.join(BACKENDS)}", path=path, got=name)
    return name


@dataclass(frozen=True)
class Engine:
    """How work runs.

    Attributes:
        backend: ``auto``, ``eager`` or ``compiled`` (``lensopt.accel.dispatch``); it takes effect through
            ``tracer``: without one every trace is eager.
        max_memory: the memory budget in bytes; None: ``DEFAULT_FRACTION`` of the machine's memory.
        tracer: the trace dispatcher of the compiled backends (``lensopt.accel.engine`` sets it).
        on_compile: called as ``on_compile(description, seconds)`` when a lens structure is compiled for
            the first time on this machine (the CLI prints it), or None.
        retain_freed_memory: keep freed memory in the process during an optimization
            (``retain_freed_memory``; the ``optimize`` and ``sweep`` commands set it).
    """

    backend: str = "auto"
    max_memory: int | None = None
    tracer: Tracer | None = field(default=None, repr=False)
    on_compile: Callable[[str, float], None] | None = field(default=None, repr=False, compare=False)
    retain_freed_memory: bool = False

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        # A listener belongs to the process that set it: another process (a Dask worker) gets the engine
        # without it (and a lambda would not pickle).
        return (Engine, (self.backend, self.max_memory, self.tracer, None, self.retain_freed_memory))

    def __post_init__(self) -> None:
        check_backend(self.backend, path="backend")
        if self.max_memory is not None and self.max_memory < 1:
            raise LensoptError("must be at least 1 byte", path="max_memory", got=self.max_memory)

    @property
    def trace_backend(self) -> str:
        """The backend traces really run on: ``backend``, or ``eager`` without a ``tracer``."""
        return self.backend if self.tracer is not None else "eager"

    @property
    def budget(self) -> int:
        """The memory budget in bytes."""
        return self.max_memory if self.max_memory is not None else int(DEFAULT_FRACTION * machine_memory())

    def require(self, nbytes: float, what: str, *, lower: str, path: str | None = None) -> None:
        """Raise one ``LensoptError`` when ``nbytes`` (an estimate of ``what``) is over the budget."""
        limit = self.budget
        if nbytes > limit:
            raise LensoptError(f"{what} needs about {format_bytes(nbytes)}, over the memory budget of "
                               f"{format_bytes(limit)}; lower {lower} (or raise --max-memory)", path=path)


def machine_memory() -> int:
    """Physical memory in bytes, capped by a cgroup (v2 or v1) limit when one is set."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        total = 8 << 30
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            with open(path, encoding="ascii") as fh:
                text = fh.read().strip()
        except OSError:
            continue
        if text.isdigit() and 0 < int(text) < total:
            total = int(text)
    return total


def parse_size(text: str, *, path: str = "--max-memory") -> int:
    """``512M``, ``4G``, ``1.5GB``, ``2e9`` → bytes (K/M/G/T are powers of 1024)."""
    m = re.fullmatch(r"\s*(\d+(?:\.\d*)?(?:[eE]\d{1,3})?)\s*([kKmMgGtT]?)(?:i?[bB])?\s*", text)
    if not m:
        raise LensoptError("expected a size such as 512M, 4G or 1.5GB", path=path, got=text)
    value = float(m.group(1)) * 1024 ** " KMGT".index(m.group(2).upper() or " ")
    if not 1 <= value < 2**63:
        raise LensoptError("must be at least 1 byte and below 8 EiB", path=path, got=text)
    return int(value)


def format_bytes(n: float) -> str:
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n / 1e3:.3g} kB"


@functools.cache
def retain_freed_memory() -> bool:
    """Keep freed memory in the process (glibc ``mallopt``) instead of returning it to the OS at once.

    Every step of the optimizer allocates and frees the same few hundred arrays of 0.1–15 MB (the
    Jacobian's tangents, ray bundles). With glibc's defaults, arrays above the mmap threshold are mapped
    and unmapped on every call and the top of the heap is trimmed after each free, so each step
    touches fresh pages: the C-mount design spent 18 % of its CPU time in the kernel (8.7 M page
    faults). Raising the mmap and trim thresholds keeps those pages for the next step (peak memory is
    unchanged: the same arrays are live at once). The setting belongs to the process, so it is made once
    (the answer is cached); a no-op where glibc is absent. Returns whether the thresholds were set.
    """
    try:
        import ctypes
        import ctypes.util

        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        m_trim_threshold, m_top_pad, m_mmap_threshold = -1, -2, -3
        # Older glibc refuses an mmap threshold above 32 MB (HEAP_MAX_SIZE / 2): then 32 MB.
        mapped = bool(libc.mallopt(m_mmap_threshold, 256 << 20)) or bool(libc.mallopt(m_mmap_threshold, 32 << 20))
        return mapped and bool(libc.mallopt(m_trim_threshold, 1 << 30)) and bool(libc.mallopt(m_top_pad, 16 << 20))
    except (OSError, AttributeError):  # not glibc (macOS, Windows, musl without mallopt)
        return False
