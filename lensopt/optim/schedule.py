"""Weight schedules of the optimization run (S4.1.3: glass catalog weight; per-group constraint weights)."""

from __future__ import annotations

__all__ = ["schedule_weight"]


def schedule_weight(schedule: list[tuple[float, float]], fraction: float) -> float:
    """Piecewise exponential schedule: log-linear between knots (fraction, weight), flat outside."""
    if fraction <= schedule[0][0]:
        return schedule[0][1]
    for (f0, w0), (f1, w1) in zip(schedule, schedule[1:], strict=False):
        if fraction <= f1:
            if f1 == f0:
                return w1
            u = (fraction - f0) / (f1 - f0)
            return float(w0 * (w1 / w0) ** u)
    return schedule[-1][1]
