"""Process memory for the benchmarks (Linux /proc), shared by scripts that run in different venvs
(lensopt's and the DeepLens peer's): import it from the benchmarks folder."""

from __future__ import annotations

from pathlib import Path


def vm_kb(field: str) -> int:
    """A ``VmRSS``/``VmHWM`` line of /proc/self/status, kB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise RuntimeError(f"{field} not in /proc/self/status")


def peak_rss_mb() -> float:
    """Peak resident set of this process (VmHWM; unlike ru_maxrss it does not inherit the parent's peak)."""
    return vm_kb("VmHWM") / 1024
