"""Numbers in the lens files lensopt writes (CODE V and Zemax alike)."""

from __future__ import annotations

import math

__all__ = ["fmt_exact", "fmt_derived"]


def fmt_exact(x: float) -> str:
    """A number lensopt stores, written so that reading it back gives the same double (shortest
    round-trip form, ``repr``)."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot write {x} to a lens file")
    text = repr(x)
    return "0.0" if text == "-0.0" else text


def fmt_derived(x: float) -> str:
    """A number computed for the file (unit conversions, products such as relative field × maximum field):
    14 significant digits, so that the rounding of the computation does not show (0.7 × 3 is written
    2.1, not 2.0999999999999996).

    Reading it back and converting again reproduces it within a few ulp, far inside half a unit of
    the 14th digit, so export → import → export gives the same text; 14 digits keep the lens to
    5e-15 relative.
    """
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot write {x} to a lens file")
    text = format(x, ".14g")
    return "0" if text == "-0" else text
