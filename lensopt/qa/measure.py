"""A measured setting of ``lensopt accuracy`` and how its time is taken (shared by ``qa.accuracy`` and
``qa.accuracy_analyses``)."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["Point", "timed"]


@dataclass(frozen=True)
class Point:
    """One measured setting: ``errors`` by metric (relative/absolute as in ``qa.accuracy.METRICS``),
    median seconds."""

    knob: str
    setting: str
    errors: dict[str, float]
    time_s: float
    note: str = ""


def timed(fn: Callable[[], Any], repeats: int) -> tuple[Any, float]:
    """``fn()``'s result and the median of ``repeats`` wall times, s."""
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times)
