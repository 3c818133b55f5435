"""Argument checks shared by the analyses: one-line ``LensoptError``s naming the argument.

The analyses take relative fields (the spec's field scale: 1 = the full field), wavelengths as indices
into the lens's wavelengths, and spatial frequencies in cycles/mm. These helpers turn what a person
typed (a field past the field of view, a wavelength the spec does not list, a frequency ≤ 0) into
errors that say which argument and what is allowed, instead of silently extrapolating.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from lensopt.errors import LensoptError
from lensopt.optics.lens import Lens, System

__all__ = ["relative_fields", "fields_of", "wavelength_indices", "frequencies", "positive_int"]

_FIELD_SLACK = 1e-9


def relative_fields(system: System, values: Sequence[float] | Tensor | None, *, path: str = "field",
                    dtype: torch.dtype = torch.float64, device: torch.device | None = None) -> Tensor:
    """(F,) relative fields in [0, 1] (1 = the spec's largest field); the system's when ``values`` is None."""
    if values is None:
        return torch.tensor(system.rel_field, dtype=dtype, device=device)
    vals = [float(v) for v in (values.tolist() if isinstance(values, Tensor) else values)]
    if not vals:
        raise LensoptError("needs at least one field", path=path, got=vals)
    for v in vals:
        if not math.isfinite(v) or v < -_FIELD_SLACK or v > 1.0 + _FIELD_SLACK:
            unit = "°" if system.field_type == "angle" else " mm"
            raise LensoptError(f"relative field must lie in [0, 1] (1 = the full field, {system.field_max:g}{unit})",
                               path=path, got=v)
    return torch.tensor(vals, dtype=dtype, device=device)


def fields_of(lens: Lens, system: System, rel_field: Tensor | Sequence[float] | None, *, path: str = "field") -> Tensor:
    """``relative_fields`` on the lens's dtype and device (the analyses' entry check)."""
    return relative_fields(system, rel_field, path=path, dtype=lens.dtype, device=lens.device)


def wavelength_indices(lens: Lens, values_nm: Sequence[float] | None, *, path: str = "wavelength") -> list[int]:
    """Indices of the spec's wavelengths named in nm (all of them when ``values_nm`` is None)."""
    listed = [1e3 * float(w) for w in lens.wavelength_um]
    if values_nm is None:
        return list(range(len(listed)))
    out = []
    for v in values_nm:
        hit = [i for i, w in enumerate(listed) if abs(w - float(v)) <= 1e-6 * max(1.0, abs(w))]
        if not hit:
            raise LensoptError(f"not a wavelength of the spec; one of {', '.join(f'{w:g}' for w in listed)} nm",
                               path=path, got=v)
        out.append(hit[0])
    return out


def frequencies(values: Sequence[float] | Tensor, *, path: str = "frequency",
                dtype: torch.dtype = torch.float64, device: torch.device | None = None) -> Tensor:
    """(K,) spatial frequencies in cycles/mm, each finite and > 0."""
    vals = [float(v) for v in (values.tolist() if isinstance(values, Tensor) else values)]
    if not vals:
        raise LensoptError("needs at least one frequency", path=path, got=vals)
    for v in vals:
        if not (math.isfinite(v) and v > 0):
            raise LensoptError("spatial frequency must be > 0 cycles/mm", path=path, got=v)
    return torch.tensor(vals, dtype=dtype, device=device)


def positive_int(value: int, *, path: str, minimum: int = 1) -> int:
    """``value`` as an int ≥ ``minimum``."""
    if int(value) != value or value < minimum:
        raise LensoptError(f"must be an integer ≥ {minimum}", path=path, got=value)
    return int(value)
