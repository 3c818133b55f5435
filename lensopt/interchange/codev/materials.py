"""Materials of an imported CODE V file: catalog names, fictitious codes, private catalogs."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch

from lensopt.errors import LensoptError, SpecError
from lensopt.interchange.codev.names import fictitious_glass, find_codev_glass
from lensopt.materials import CatalogGlass, material_from_name
from lensopt.spec.build import resolve_material
from lensopt.spec.models import ModelGlassSpec, TabulatedGlassSpec

__all__ = ["PrivateGlass", "resolve_glass", "EXTRAS_INDEX_TOLERANCE"]

#: A lensopt definition in the file's comments replaces a private glass only if it reproduces every
#: tabulated index to this (absolute) tolerance.
EXTRAS_INDEX_TOLERANCE = 1e-12


@dataclass(frozen=True)
class PrivateGlass:
    """A private catalog entry: its name, line, the ``PWL`` wavelengths (nm) and its data tokens."""

    name: str
    line: int
    wavelengths_nm: list[float] | None
    data: list[str]

    def table(self, source: str) -> tuple[list[float], list[float]]:
        """(wavelengths_nm, indices) in increasing wavelength."""
        try:
            values = [float(t) for t in self.data]
        except ValueError:
            raise SpecError(f"line {self.line}: private glass {self.name!r} is given by a formula "
                            f"({self.data[0] if self.data else '?'}); lensopt reads only index tables",
                            path=source) from None
        wl = self.wavelengths_nm or []
        if not values or len(values) != len(wl):
            raise SpecError(f"line {self.line}: private glass {self.name!r} has {len(values)} indices for "
                            f"{len(wl)} PWL wavelengths", path=source)
        pairs = sorted(zip(wl, values, strict=True))
        return [p[0] for p in pairs], [p[1] for p in pairs]


def resolve_glass(token: str | None, private: dict[str, PrivateGlass], extra_name: Any, extra_glasses: Any,
                  *, path: str, line: int, source: str) -> Any:
    """The spec ``material`` value for a CODE V glass token.

    Args:
        token: the third field of the S line (None: air).
        private: private catalog entries by upper-case name.
        extra_name: lensopt's original material name for this surface, from the file's comments.
        extra_glasses: lensopt definitions of private glasses, from the file's comments.
        path: spec path of the surface (``surfaces[2]``), for errors.

    Raises:
        SpecError: unknown glass (with close catalog matches), formula-only private glass.
    """
    if token is None or token.upper() == "AIR":
        return "air"
    entry = private.get(token.upper())
    if entry is not None:
        wl, index = entry.table(source)
        exact = _extras_definition(entry.name, extra_glasses, wl, index)
        if exact is not None:
            return exact
        return {"name": entry.name, "wavelengths_nm": wl, "index": index}
    code = fictitious_glass(token)
    if code is not None:
        return {"nd": code[0], "vd": code[1], "dpgf": 0.0, "name": token}
    try:
        glass = find_codev_glass(token)
    except LensoptError as err:
        raise SpecError(f"line {line}: {err.message}", path=f"{source}: {path}.material") from None
    if isinstance(extra_name, str):
        try:
            mat = material_from_name(extra_name)
        except LensoptError:
            mat = None
        if isinstance(mat, CatalogGlass) and mat.glass == glass:
            return extra_name
    return f"{glass.vendor}:{glass.name}"


def _extras_definition(name: str, extra_glasses: Any, wl: list[float], index: list[float]) -> Any:
    """lensopt's own definition of a private glass if the comments give one that reproduces the table."""
    if not isinstance(extra_glasses, dict) or name not in extra_glasses:
        return None
    raw = extra_glasses[name]
    try:
        if isinstance(raw, str):
            value: Any = raw
        elif isinstance(raw, dict) and raw.get("type") == "model":
            value = ModelGlassSpec(**{k: v for k, v in raw.items() if k != "type"})
        elif isinstance(raw, dict) and raw.get("type") == "tabulated":
            value = TabulatedGlassSpec(**{k: v for k, v in raw.items() if k != "type"})
        else:
            return None
        mat = resolve_material(value, path="material", wavelengths_um=[w * 1e-3 for w in wl])
        mat.check_wavelengths([w * 1e-3 for w in wl], path="material")
        got = mat.index(torch.tensor([w * 1e-3 for w in wl], dtype=torch.float64)).tolist()
    except (LensoptError, ValueError, TypeError):
        return None
    if any(abs(a - b) > EXTRAS_INDEX_TOLERANCE for a, b in zip(got, index, strict=True)):
        return None
    if isinstance(value, str):
        return value
    return value.model_dump(mode="json", exclude_none=True)
