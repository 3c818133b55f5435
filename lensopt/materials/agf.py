"""Zemax AGF glass catalogs: reading them and evaluating their dispersion formulas.

An AGF file lists glasses as records: ``NM name formula MIL nd vd ...`` (formula number, glass
code, catalog nd and vd), ``ED tce30-70 tce100-300 density dPgF ...``, ``CD c1 c2 ...`` (dispersion
coefficients, wavelengths in µm) and ``LD λmin λmax`` (the valid wavelength range in µm); other
records (thermal ``TD``, transmission ``IT``, ``OD``, ``CC`` comments) are not needed for the index.
Files are UTF-16 (OpticStudio) or ASCII/UTF-8 (older catalogs); both are read.

Zemax formula numbers (OpticStudio manual, "Glass dispersion formulas"), λ in µm:

====  =============  ==============================================================================
  1   Schott         n² = a0 + a1 λ² + a2 λ⁻² + a3 λ⁻⁴ + a4 λ⁻⁶ + a5 λ⁻⁸
  2   Sellmeier 1    n² − 1 = Σ_{i=1..3} K_i λ² / (λ² − L_i)            (CD: K1 L1 K2 L2 K3 L3)
  3   Herzberger     n = A + B L + C L² + D λ² + E λ⁴ + F λ⁶,  L = 1 / (λ² − 0.028)
  4   Sellmeier 2    n² − 1 = A + B1 λ² / (λ² − λ1²) + B2 / (λ² − λ2²)   (CD: A B1 λ1 B2 λ2)
  5   Conrady        n = n0 + A / λ + B / λ^3.5
  6   Sellmeier 3    n² − 1 = Σ_{i=1..4} K_i λ² / (λ² − L_i)
  7   Handbook 1     n² = A + B / (λ² − C) − D λ²
  8   Handbook 2     n² = A + B λ² / (λ² − C) − D λ²
  9   Sellmeier 4    n² = A + B λ² / (λ² − C) + D λ² / (λ² − E)
 10   Extended       n² = a0 + a1 λ² + a2 λ⁻² + a3 λ⁻⁴ + a4 λ⁻⁶ + a5 λ⁻⁸ + a6 λ⁻¹⁰ + a7 λ⁻¹²
 11   Sellmeier 5    n² − 1 = Σ_{i=1..5} K_i λ² / (λ² − L_i)
 12   Extended 2     n² = a0 + a1 λ² + a2 λ⁻² + a3 λ⁻⁴ + a4 λ⁻⁶ + a5 λ⁻⁸ + a6 λ⁴ + a7 λ⁶
 13   Extended 3     n² = a0 + a1 λ² + a2 λ⁴ + a3 λ⁻² + a4 λ⁻⁴ + a5 λ⁻⁶ + a6 λ⁻⁸ + a7 λ⁻¹⁰ + a8 λ⁻¹²
====  =============  ==============================================================================

Indices are relative to air, as lensopt's (and Zemax's catalog data at their reference
temperature); thermal coefficients are not applied. An AGF glass is evaluated outside its ``LD``
range too (the formulas extrapolate): whoever reads the catalog (``lensopt import-zemax``) warns.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import torch
from torch import Tensor

from lensopt.errors import MaterialError
from lensopt.materials.catalog import normalize_name
from lensopt.materials.material import Material, _check_wavelength_tensor

__all__ = ["AGF_FORMULAS", "AgfEntry", "AgfGlass", "agf_index", "read_agf", "agf_glass", "decode_text"]

#: Zemax formula number -> name (the formulas of the module doc).
AGF_FORMULAS: dict[int, str] = {
    1: "Schott", 2: "Sellmeier 1", 3: "Herzberger", 4: "Sellmeier 2", 5: "Conrady", 6: "Sellmeier 3",
    7: "Handbook of Optics 1", 8: "Handbook of Optics 2", 9: "Sellmeier 4", 10: "Extended", 11: "Sellmeier 5",
    12: "Extended 2", 13: "Extended 3",
}
_SIZES = {1: 6, 2: 6, 3: 6, 4: 5, 5: 3, 6: 8, 7: 4, 8: 4, 9: 5, 10: 8, 11: 10, 12: 8, 13: 9}


def _sellmeier(c: list[Tensor], w2: Tensor, terms: int) -> Tensor:
    n2 = 1.0 + torch.zeros_like(w2)
    for i in range(terms):
        n2 = n2 + c[2 * i] * w2 / (w2 - c[2 * i + 1])
    return torch.sqrt(n2)


def _powers(c: list[Tensor], w2: Tensor, exponents: tuple[int, ...]) -> Tensor:
    n2 = torch.zeros_like(w2)
    for a, p in zip(c, exponents, strict=True):
        n2 = n2 + a * w2 ** (p / 2)
    return torch.sqrt(n2)


def agf_index(formula: int, coefficients: Tensor, wavelength_um: Tensor) -> Tensor:
    """Index of a Zemax dispersion formula (module doc) at ``wavelength_um`` (µm).

    Args:
        formula: Zemax formula number 1…13.
        coefficients: ``(K,)`` the CD coefficients (missing trailing ones count as zero).
        wavelength_um: ``(*)`` wavelengths in µm.

    Returns:
        ``(*)`` refractive index (dtype/device from type promotion of the inputs).

    Raises:
        MaterialError: unknown formula number.
    """
    if formula not in _SIZES:
        raise MaterialError(f"unknown AGF dispersion formula; known: 1…13 ({', '.join(AGF_FORMULAS.values())})",
                            got=formula)
    size = _SIZES[formula]
    coefficients = coefficients.to(wavelength_um.dtype)
    if coefficients.shape[0] < size:
        coefficients = torch.nn.functional.pad(coefficients, (0, size - coefficients.shape[0]))
    c = [coefficients[i] for i in range(size)]
    wl = wavelength_um
    w2 = wl * wl
    if formula == 1:
        return _powers(c, w2, (0, 2, -2, -4, -6, -8))
    if formula in (2, 6, 11):
        return _sellmeier(c, w2, {2: 3, 6: 4, 11: 5}[formula])
    if formula == 3:
        q = 1.0 / (w2 - 0.028)
        return c[0] + c[1] * q + c[2] * q * q + c[3] * w2 + c[4] * w2 * w2 + c[5] * w2 * w2 * w2
    if formula == 4:
        return torch.sqrt(1.0 + c[0] + c[1] * w2 / (w2 - c[2] * c[2]) + c[3] / (w2 - c[4] * c[4]))
    if formula == 5:
        return c[0] + c[1] / wl + c[2] / wl ** 3.5
    if formula == 7:
        return torch.sqrt(c[0] + c[1] / (w2 - c[2]) - c[3] * w2)
    if formula == 8:
        return torch.sqrt(c[0] + c[1] * w2 / (w2 - c[2]) - c[3] * w2)
    if formula == 9:
        return torch.sqrt(c[0] + c[1] * w2 / (w2 - c[2]) + c[3] * w2 / (w2 - c[4]))
    if formula == 10:
        return _powers(c, w2, (0, 2, -2, -4, -6, -8, -10, -12))
    if formula == 12:
        return _powers(c, w2, (0, 2, -2, -4, -6, -8, 4, 6))
    return _powers(c, w2, (0, 2, 4, -2, -4, -6, -8, -10, -12))  # 13


@dataclass(frozen=True)
class AgfEntry:
    """One glass of an AGF catalog.

    Attributes:
        name: glass name as written in the catalog.
        catalog: catalog file stem (``SCHOTT``).
        formula: Zemax formula number (``AGF_FORMULAS``).
        coefficients: CD coefficients.
        nd, vd: catalog values from the NM line.
        dpgf: ΔPgF from the ED line (0 where absent).
        range_um: LD wavelength range in µm (``(0, inf)`` where the catalog gives none).
        line: line number of the NM record.
    """

    name: str
    catalog: str
    formula: int
    coefficients: tuple[float, ...]
    nd: float
    vd: float
    dpgf: float = 0.0
    range_um: tuple[float, float] = (0.0, math.inf)
    line: int = 0


@dataclass(frozen=True)
class AgfGlass(Material):
    """A glass from an AGF catalog (Zemax dispersion formula). Its wavelength range is informative:
    :meth:`check_wavelengths` accepts every wavelength, :meth:`outside_range` lists those outside it.
    """

    entry: AgfEntry
    name: str = field(init=False)
    nd: float = field(init=False)
    vd: float = field(init=False)
    valid_range_um: tuple[float, float] = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", self.entry.name)
        object.__setattr__(self, "nd", self.entry.nd)
        object.__setattr__(self, "vd", self.entry.vd)
        object.__setattr__(self, "valid_range_um", self.entry.range_um)

    @property
    def label(self) -> str:
        return f"{self.entry.name} ({self.entry.catalog}.agf)"

    def index(self, wavelength_um: Tensor) -> Tensor:
        _check_wavelength_tensor(wavelength_um)
        coefficients = torch.tensor(self.entry.coefficients, dtype=wavelength_um.dtype, device=wavelength_um.device)
        return agf_index(self.entry.formula, coefficients, wavelength_um)

    def check_wavelengths(self, wavelength_um: object, *, path: str) -> None:  # noqa: ARG002
        """Accept every wavelength (AGF ranges give warnings, not errors; see :meth:`outside_range`)."""

    def outside_range(self, wavelength_um: list[float]) -> list[float]:
        """The wavelengths (µm) outside the catalog's LD range."""
        lo, hi = self.entry.range_um
        return [w for w in wavelength_um if not lo <= w <= hi]


def decode_text(data: bytes, *, source: str) -> str:
    """Text of a Zemax file: UTF-16 (with a BOM, or little-endian ASCII), else UTF-8, else Latin-1.

    Raises:
        MaterialError: the bytes are not text (NUL bytes or control characters after decoding).
    """
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        text = data.decode("utf-16", errors="replace")
    elif len(data) >= 4 and data[1:2] == b"\x00" and data[3:4] == b"\x00" and data[0:1] != b"\x00":
        text = data.decode("utf-16-le", errors="replace")
    else:
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            text = data.decode("latin-1")
    bad = sum(1 for ch in text if (ord(ch) < 32 and ch not in "\r\n\t\f") or ch == "\ufffd")
    if "\x00" in text or bad > max(8, len(text) // 200):
        raise MaterialError("not a text file (binary content); expected a Zemax text file", path=source)
    return text.lstrip("\ufeff")


def _float(token: str) -> float:
    return float(token.replace(",", "."))


def parse_agf(text: str, *, catalog: str, source: str) -> dict[str, AgfEntry]:
    """Glasses of an AGF text by normalized name (see :func:`~lensopt.materials.catalog.normalize_name`).

    Raises:
        MaterialError: a malformed NM/CD/LD record or no glass at all.
    """
    out: dict[str, AgfEntry] = {}
    current: dict[str, object] | None = None

    def flush() -> None:
        if current is not None:
            entry = AgfEntry(**current)  # type: ignore[arg-type]
            out[normalize_name(entry.name)] = entry

    for number, raw in enumerate(text.splitlines(), start=1):
        tokens = raw.split()
        if not tokens:
            continue
        key = tokens[0].upper()
        try:
            if key == "NM":
                flush()
                formula = int(_float(tokens[2]))
                if formula not in AGF_FORMULAS:
                    raise MaterialError(f"line {number}: glass {tokens[1]!r} uses dispersion formula {formula}; "
                                        f"lensopt knows 1…13", path=source)
                nd = _float(tokens[4]) if len(tokens) > 4 else math.nan
                vd = _float(tokens[5]) if len(tokens) > 5 else math.nan
                current = {"name": tokens[1], "catalog": catalog, "formula": formula, "coefficients": (),
                           "nd": nd, "vd": vd, "line": number}
            elif current is None:
                continue
            elif key == "ED" and len(tokens) > 4:
                current["dpgf"] = _float(tokens[4])
            elif key == "CD":
                current["coefficients"] = tuple(_float(t) for t in tokens[1:])
            elif key == "LD" and len(tokens) >= 3:
                current["range_um"] = (_float(tokens[1]), _float(tokens[2]))
        except (IndexError, ValueError, OverflowError):
            raise MaterialError(f"line {number}: malformed {key} record: {raw.strip()[:60]!r}", path=source) from None
    flush()
    if not out:
        raise MaterialError("no glass (NM record) in this AGF catalog", path=source)
    return out


@functools.cache
def _read_cached(path: str, mtime_ns: int, size: int) -> dict[str, AgfEntry]:
    del mtime_ns, size  # part of the cache key only
    p = Path(path)
    return parse_agf(decode_text(p.read_bytes(), source=path), catalog=p.stem.upper(), source=path)


def read_agf(path: str | os.PathLike[str]) -> dict[str, AgfEntry]:
    """Glasses of the AGF file at ``path`` by normalized name (cached while the file is unchanged).

    Raises:
        MaterialError: missing/unreadable file or malformed catalog.
    """
    p = Path(path)
    if not p.is_file():
        raise MaterialError("no such AGF catalog file", path=str(path))
    try:
        st = p.stat()
        return _read_cached(str(p.resolve()), st.st_mtime_ns, st.st_size)
    except OSError as err:
        raise MaterialError(f"cannot read the AGF catalog: {err.strerror}", path=str(path)) from None


def agf_glass(path: str | os.PathLike[str], name: str) -> AgfGlass:
    """The glass ``name`` of the AGF catalog at ``path``.

    Raises:
        MaterialError: unknown glass (with close names) or unreadable catalog.
    """
    glasses = read_agf(path)
    entry = glasses.get(normalize_name(name))
    if entry is None:
        import difflib

        close = difflib.get_close_matches(normalize_name(name), list(glasses), n=4)
        hint = f"; close: {', '.join(glasses[c].name for c in close)}" if close else ""
        raise MaterialError(f"glass {name!r} is not in the AGF catalog {path}{hint}", path=str(path))
    return AgfGlass(entry)
