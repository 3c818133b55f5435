"""Numbers in the lens files lensopt writes (CODE V and Zemax alike)."""

from __future__ import annotations

import math

__all__ = ["fmt_exact"]


def fmt_exact(x: float) -> str:
    """A number lensopt stores, written so that reading it back gives the same double (shortest
    round-trip form, ``repr``)."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot write {x} to a lens file")
    text = repr(x)
    return "0.0" if text == "-0.0" else text
