"""A memory budget checked before large allocations (rays, images, PSF grids).

Work that would need more than the budget is refused with one ``LensoptError`` that says what to lower,
instead of exhausting the machine's memory. The budget is a fraction of the machine's memory (or of the
cgroup limit, whichever is smaller) unless set with ``set_budget`` (the CLI's ``--max-memory`` and the
``LENSOPT_MAX_MEMORY`` environment variable). The estimates are deliberately coarse upper bounds of the
peak working set (bytes per ray and surface, copies of an image through the simulation pipeline).
"""

from __future__ import annotations

import os
import re

from lensopt.errors import LensoptError

__all__ = ["DEFAULT_FRACTION", "budget", "format_bytes", "machine_memory", "parse_size", "require", "set_budget"]

#: Share of the machine's memory that one command may plan to use.
DEFAULT_FRACTION = 0.5
#: Bytes per ray and surface of a traced bundle (positions, directions, masks, path lengths and
#: intermediates): ``trace --sampling rings:300`` on the Cooke triplet grows the peak RSS by ~66 bytes per
#: ray-surface over rings:24; 160 leaves room for the analyses built on the bundle.
BYTES_PER_RAY_SURFACE = 160

_budget: int | None = None


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


def set_budget(nbytes: int | None) -> None:
    """Set the budget in bytes (None: the default fraction of the machine's memory)."""
    global _budget
    _budget = nbytes


def budget() -> int:
    """The memory budget in bytes: ``set_budget``'s, else ``LENSOPT_MAX_MEMORY``, else the default."""
    if _budget is not None:
        return _budget
    env = os.environ.get("LENSOPT_MAX_MEMORY")
    if env:
        return parse_size(env, path="LENSOPT_MAX_MEMORY")
    return int(DEFAULT_FRACTION * machine_memory())


def format_bytes(n: float) -> str:
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n / 1e3:.3g} kB"


def require(nbytes: float, what: str, *, lower: str, path: str | None = None) -> None:
    """Raise one ``LensoptError`` when ``nbytes`` (an estimate of ``what``) is over the budget."""
    limit = budget()
    if nbytes > limit:
        raise LensoptError(f"{what} needs about {format_bytes(nbytes)}, over the memory budget of "
                           f"{format_bytes(limit)}; lower {lower} (or raise --max-memory)", path=path)
