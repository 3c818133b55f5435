"""Vendor glass catalogs: the :class:`Glass` record, name lookup and listing.

The data come from ``data/glasses.json`` (generated from the refractiveindex.info database, see
``data/README.md``) and ``data/plastics_table_s10.csv`` (seed Table S10). They are read lazily on
first use and cached for the life of the process.
"""

from __future__ import annotations

import csv
import difflib
import functools
import json
import logging
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lensopt.errors import MaterialError
from lensopt.materials.dispersion import HARTMANN_FORMULA, NORMAL_PGF_INTERCEPT, NORMAL_PGF_SLOPE

__all__ = [
    "Glass",
    "VENDORS",
    "PLASTICS_VENDOR",
    "HARTMANN_RANGE_UM",
    "find_glass",
    "resolve_glass",
    "list_glasses",
    "normalize_name",
    "catalog_info",
    "DesignCatalog",
    "DESIGN_CATALOGS",
    "design_catalog",
]

PLASTICS_VENDOR = "plastics"
#: Lookup order of bare names; qualified names (``"ohara:S-BSL7"``) pick the vendor directly. Schott and
#: Ohara first (the most used catalogs, formulas valid from the near UV to 2.3–2.5 µm), then Hoya, CDGM
#: and Sumita (valid to 1.0–2.3 µm), then Hikari, whose shipped data are valid from 0.4 to 0.7 µm only
#: for most glasses, then the Table S10 plastics. Of the vendors that have the name, the first whose
#: valid range covers the spectrum is taken (:func:`resolve_glass`).
VENDORS: tuple[str, ...] = ("schott", "ohara", "hoya", "cdgm", "sumita", "hikari", PLASTICS_VENDOR)

log = logging.getLogger(__name__)
_told: set[str] = set()


def notice(message: str) -> None:
    """Tell the user ``message`` once per process: a WARNING record on this module's logger (the CLI
    prints it as one ``warning: ...`` line); the library itself never prints."""
    if message not in _told:
        _told.add(message)
        log.warning("%s", message)

#: Valid wavelength range (µm) of Hartmann-model materials (ModelGlass, the Table S10 plastics).
#: For accepted inputs (10 <= vd <= 120, |dpgf| <= 0.1) the pole B of eq. S4 stays below
#: 0.29 µm, so 0.38 µm keeps >= 0.09 µm of margin. Inside this range the model stays within
#: 1.4e-3 (median 4e-4) of the catalog formulas of Schott's preferred glasses given their nd, vd,
#: dPgF; beyond ~1.3 µm it drifts by several 1e-3 (it has no infrared term).
HARTMANN_RANGE_UM: tuple[float, float] = (0.38, 1.0)

_PLASTICS_REFERENCE = "seed Table S10 (moldable optical plastics; nd and vd only, Hartmann model)"


@dataclass(frozen=True)
class Glass:
    """One catalog glass, as published by its vendor (via refractiveindex.info).

    Attributes:
        name: name as the vendor writes it (``N-BK7``, ``S-BSL7``).
        vendor: ``schott``, ``ohara``, ``hikari``, ``hoya``, ``cdgm``, ``sumita`` or ``plastics``.
        formula: refractiveindex.info formula number (see ``dispersion.catalog_index``); 0 for
            the Hartmann model (plastics), whose coefficients are ``(nd, vd, dpgf)``.
        coefficients: dispersion-formula coefficients (wavelengths in µm).
        range_um: ``(min, max)`` wavelength range (µm) in which the formula is valid.
        nd: catalog refractive index at the d line (587.5618 nm).
        vd: catalog Abbe number.
        pgf: partial dispersion PgF computed from the formula at g, F, C (the database does not
            carry PgF); None where those lines are outside ``range_um``.
        dpgf: catalog ΔPgF (deviation from the normal line), None where the database has none
            (its AGF converter drops zero values, so None often means 0).
        glass_code: six-digit glass code (plus density for Schott), None where not published.
        status: vendor status: preferred/standard/special/obsolete/melt (Zemax AGF meaning),
            ``recommended`` for Ohara's recommended glasses, None where the vendor gives none.
        comments: vendor comments ("inquiry glass", "Recommended - Lightweight", ...).
        reference: where the data come from (vendor catalog and its URL).
        temperature_k: reference temperature of the data (K), None where not given.
    """

    name: str
    vendor: str
    formula: int
    coefficients: tuple[float, ...]
    range_um: tuple[float, float]
    nd: float
    vd: float
    pgf: float | None
    dpgf: float | None
    glass_code: str | None
    status: str | None
    comments: str
    reference: str
    temperature_k: float | None = None

    @property
    def label(self) -> str:
        """``"N-BK7 (schott)"``: name and vendor, as used in messages."""
        return f"{self.name} ({self.vendor})"


def normalize_name(name: str) -> str:
    """Lookup key of a glass name: upper case, all whitespace removed (``"s-bsl 7"`` -> ``"S-BSL7"``)."""
    return "".join(name.split()).upper()


def _data_text(filename: str) -> str:
    return resources.files("lensopt.materials").joinpath("data", filename).read_text(encoding="utf-8")


@functools.cache
def catalog_info() -> dict[str, Any]:
    """Header of ``glasses.json``: source, database version/commit, vendors, references."""
    return {k: v for k, v in _raw_catalog().items() if k != "glasses"}


@functools.cache
def _raw_catalog() -> dict[str, Any]:
    return json.loads(_data_text("glasses.json"))


def _glass_from_record(rec: dict[str, Any], references: list[str]) -> Glass:
    return Glass(
        name=rec["name"],
        vendor=rec["vendor"],
        formula=int(rec["formula"]),
        coefficients=tuple(float(c) for c in rec["coefficients"]),
        range_um=(float(rec["range_um"][0]), float(rec["range_um"][1])),
        nd=float(rec["nd"]),
        vd=float(rec["vd"]),
        pgf=rec["pgf"],
        dpgf=rec["dpgf"],
        glass_code=rec["glass_code"],
        status=rec["status"],
        comments=rec["comments"],
        reference=references[rec["ref"]],
        temperature_k=rec["temperature_k"],
    )


def _plastic(name: str, nd: float, vd: float) -> Glass:
    return Glass(
        name=name,
        vendor=PLASTICS_VENDOR,
        formula=HARTMANN_FORMULA,
        coefficients=(nd, vd, 0.0),
        range_um=HARTMANN_RANGE_UM,
        nd=nd,
        vd=vd,
        pgf=round(NORMAL_PGF_INTERCEPT + NORMAL_PGF_SLOPE * vd, 6),
        dpgf=0.0,
        glass_code=f"{round((nd - 1.0) * 1000):03d}{round(vd * 10):03d}",
        status=None,
        comments="",
        reference=_PLASTICS_REFERENCE,
    )


@functools.cache
def _plastics() -> tuple[Glass, ...]:
    rows = csv.DictReader(_data_text("plastics_table_s10.csv").splitlines())
    return tuple(_plastic(r["name"].strip(), float(r["nd"]), float(r["vd"])) for r in rows)


@functools.cache
def _all_glasses() -> tuple[Glass, ...]:
    raw = _raw_catalog()
    refs = list(raw["references"])
    vendor_glasses = tuple(_glass_from_record(rec, refs) for rec in raw["glasses"])
    return vendor_glasses + _plastics()


@functools.cache
def _index() -> dict[str, dict[str, Glass]]:
    """vendor -> normalized name -> Glass."""
    out: dict[str, dict[str, Glass]] = {v: {} for v in VENDORS}
    for g in _all_glasses():
        key = normalize_name(g.name)
        if key in out[g.vendor]:
            raise MaterialError(f"glass catalog has two {g.vendor} glasses named alike", got=g.name)
        out[g.vendor][key] = g
    return out


def list_glasses(vendor: str | None = None) -> tuple[Glass, ...]:
    """All catalog glasses (vendor priority order, then data-file order), or one vendor's.

    Args:
        vendor: one of :data:`VENDORS` (case-insensitive), or None for all.

    Raises:
        MaterialError: unknown vendor.
    """
    if vendor is None:
        return tuple(g for v in VENDORS for g in _index()[v].values())
    return tuple(_index()[_vendor_key(vendor)].values())


def _vendor_key(vendor: str) -> str:
    key = vendor.strip().lower()
    if key not in VENDORS:
        raise MaterialError(f"unknown glass vendor; known: {', '.join(VENDORS)}", got=vendor)
    return key


def _close_matches(key: str, vendors: tuple[str, ...], n: int = 5) -> list[Glass]:
    """Up to ``n`` glasses whose normalized names are closest to ``key`` (best first)."""
    index = _index()
    keys = {k for v in vendors for k in index[v]}
    found: list[Glass] = []
    for k in difflib.get_close_matches(key, keys, n=n, cutoff=0.6):
        found.extend(index[v][k] for v in vendors if k in index[v])
    return found[:n]


def find_glass(name: str, wavelengths_um: Sequence[float] | None = None, *, path: str | None = None) -> Glass:
    """Look up a catalog glass by name (:func:`resolve_glass`); a vendor choice among several is told
    once as a notice (:func:`notice`), prefixed with ``path`` when given.

    Raises:
        MaterialError: unknown vendor or glass (the message lists close names), or a bare name none of
            whose vendors' data cover ``wavelengths_um``.
    """
    glass, told = resolve_glass(name, wavelengths_um)
    if told:
        notice(f"{path}: {told}" if path else told)
    return glass


def _covers(glass: Glass, wavelengths_um: Sequence[float]) -> bool:
    lo, hi = glass.range_um
    return all(lo <= float(w) <= hi for w in wavelengths_um)


def _span(wavelengths_um: Sequence[float]) -> str:
    lo, hi = min(wavelengths_um), max(wavelengths_um)
    return f"{lo * 1e3:g} nm" if lo == hi else f"{lo * 1e3:g}–{hi * 1e3:g} nm"


def _range(glass: Glass) -> str:
    return f"{glass.range_um[0]:g}–{glass.range_um[1]:g} µm"


def resolve_glass(name: str, wavelengths_um: Sequence[float] | None = None) -> tuple[Glass, str]:
    """The catalog glass a material name means, and the notice to give about the choice ("" if none).

    Matching ignores case and whitespace (``"S-BSL 7"``, ``"s-bsl7"`` and ``"S-BSL7"`` are the
    same). ``"vendor:NAME"`` picks a vendor (``"ohara:S-BSL7"``); its valid range is checked where the
    material is used (``Material.check_wavelengths``). A bare name is looked up in every vendor of
    :data:`VENDORS`, in that order (schott, ohara, hoya, cdgm, sumita, hikari, plastics); with
    ``wavelengths_um`` (the spec's spectrum, µm) the first whose valid range covers them all is taken.
    When more than one vendor has the name the notice says which was taken and why.

    Raises:
        MaterialError: unknown vendor or glass (the message lists close names); a bare name none of
            whose vendors' valid ranges covers ``wavelengths_um`` (the message gives the ranges, the
            spectrum and close names that cover it).
    """
    vendors = VENDORS
    bare = name
    if ":" in name:
        vendor, bare = name.split(":", 1)
        vendors = (_vendor_key(vendor),)
    key = normalize_name(bare)
    index = _index()
    found = [index[v][key] for v in vendors if key in index[v]]
    if not found:
        where = "" if len(vendors) > 1 else f" in the {vendors[0]} catalog"
        close = _close_matches(key, vendors)
        hint = "; close matches: " + ", ".join(g.label for g in close) if close else "; no close matches"
        raise MaterialError(f"unknown glass {bare.strip()!r}{where}{hint}", got=name)
    if len(vendors) == 1:
        return found[0], ""
    wl = [float(w) for w in wavelengths_um] if wavelengths_um else []
    fits = [g for g in found if _covers(g, wl)]
    if not fits:
        ranges = ", ".join(f"{_range(g)} of {g.label}" for g in found)
        others = [g for g in _close_matches(key, VENDORS, n=12) if _covers(g, wl) and g not in found][:3]
        hint = ("; close names that cover it: " + ", ".join(g.label for g in others)) if others else ""
        bad = [w for w in wl if not any(_covers(g, [w]) for g in found)]
        what = (f"wavelength {bad[0]:g} µm of the spectrum ({_span(wl)}) is outside" if bad else
                f"the spectrum {_span(wl)} is not inside")
        raise MaterialError(f"{what} the valid range {ranges}{hint}", got=name)
    pick = fits[0]
    if len(found) == 1:
        return pick, ""
    which = ", ".join(g.vendor for g in found)
    if pick is found[0]:
        why = "the first in the vendor order " + ", ".join(VENDORS)
    else:
        skipped = ", ".join(f"{g.label} is valid {_range(g)} only" for g in found[: found.index(pick)])
        why = f"the first in the vendor order whose data cover the spectrum ({_span(wl)}); {skipped}"
    told = (f"glass {bare.strip()!r} is in the {which} catalogs; using {pick.label}, {why}; "
            f"write '{pick.vendor}:{pick.name}' to make the choice explicit")
    return pick, told


# ---------------------------------------------------------------------------------------------
# Design catalogs: the (nd, vd, dpgf) point sets the optimizer snaps glass variables to (S2.1.2).

#: Names of the built-in design catalogs.
DESIGN_CATALOGS: tuple[str, ...] = ("ohara-recommended", "schott-preferred", "plastics")


@dataclass(frozen=True, eq=False)
class DesignCatalog:
    """A named set of real materials as points in glass-variable space.

    Attributes:
        name: catalog name (``"ohara-recommended"``) or the csv path it was read from.
        names: ``n`` material names.
        values: ``(n, 3)`` read-only float64 array of (nd, vd, dpgf); dpgf is 0 where unknown.
    """

    name: str
    names: tuple[str, ...]
    values: np.ndarray

    def __len__(self) -> int:
        return len(self.names)

    @property
    def nd(self) -> np.ndarray:
        """``(n,)`` refractive indices at the d line."""
        return self.values[:, 0]

    @property
    def vd(self) -> np.ndarray:
        """``(n,)`` Abbe numbers."""
        return self.values[:, 1]

    @property
    def dpgf(self) -> np.ndarray:
        """``(n,)`` deviations from normal partial dispersion."""
        return self.values[:, 2]

    def as_tensor(
        self, *, dtype: torch.dtype = torch.float64, device: torch.device | str | None = None
    ) -> torch.Tensor:
        """``(n, 3)`` tensor of (nd, vd, dpgf) (a fresh copy)."""
        return torch.tensor(self.values, dtype=dtype, device=device)


def _design(name: str, names: list[str], rows: list[tuple[float, float, float]]) -> DesignCatalog:
    values = np.array(rows, dtype=np.float64).reshape(len(rows), 3)
    values.flags.writeable = False
    return DesignCatalog(name=name, names=tuple(names), values=values)


_TRUE = {"true", "1", "yes", "y"}
_FALSE = {"false", "0", "no", "n", ""}


def _parse_design_csv(text: str, source: str) -> DesignCatalog:
    """Rows ``name,nd,vd[,dpgf][,ignore]`` -> DesignCatalog (rows with ignore=True are dropped)."""
    reader = csv.DictReader(text.splitlines())
    columns = {c.strip().lower() for c in reader.fieldnames or []}
    missing = [c for c in ("name", "nd", "vd") if c not in columns]
    if missing:
        raise MaterialError(
            f"design catalog {source}: missing column(s) {', '.join(missing)}; expected name,nd,vd[,dpgf]",
            got=sorted(columns),
        )
    names: list[str] = []
    rows: list[tuple[float, float, float]] = []
    for line, raw in enumerate(reader, start=2):
        row = {k.strip().lower(): (v or "").strip() for k, v in raw.items() if k is not None}
        flag = row.get("ignore", "").lower()
        if flag not in _TRUE | _FALSE:
            raise MaterialError(
                f"design catalog {source} line {line}: ignore must be True/False", got=row.get("ignore")
            )
        if flag in _TRUE:
            continue
        numbers = []
        for col in ("nd", "vd", "dpgf"):
            text_value = row.get(col, "") or ("0" if col == "dpgf" else "")
            try:
                value = float(text_value)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                raise MaterialError(
                    f"design catalog {source} line {line}: {col} must be a finite number", got=row.get(col)
                )
            numbers.append(value)
        if not row["name"]:
            raise MaterialError(f"design catalog {source} line {line}: name is empty", got=row["name"])
        names.append(row["name"])
        rows.append((numbers[0], numbers[1], numbers[2]))
    if not names:
        raise MaterialError(f"design catalog {source} has no materials", got=source)
    return _design(source, names, rows)


@functools.cache
def _builtin_design(name: str) -> DesignCatalog:
    if name == "ohara-recommended":
        cat = _parse_design_csv(_data_text("ohara_recommended.csv"), "ohara_recommended.csv")
        return _design(name, list(cat.names), [tuple(r) for r in cat.values.tolist()])
    if name == "schott-preferred":
        glasses = [g for g in list_glasses("schott") if g.status == "preferred"]
    else:
        glasses = list(_plastics())
    return _design(name, [g.name for g in glasses], [(g.nd, g.vd, g.dpgf or 0.0) for g in glasses])


def design_catalog(name: str | os.PathLike[str]) -> DesignCatalog:
    """A design catalog for glass-variable snapping/whitening (S2.1.2).

    Args:
        name: ``"ohara-recommended"`` (the seed's 104 recommended Ohara glasses, vendor values as
            tabulated by the seed's authors), ``"schott-preferred"`` (Schott glasses with status
            preferred), ``"plastics"`` (the 12 plastics of seed Table S10, dpgf 0), or a path to a
            csv file with columns ``name,nd,vd[,dpgf][,ignore]``.

    Raises:
        MaterialError: unknown name, unreadable file, or malformed csv.
    """
    key = os.fspath(name)
    if key.strip().lower() in DESIGN_CATALOGS:
        return _builtin_design(key.strip().lower())
    path = Path(key)
    if path.suffix.lower() != ".csv" or not path.is_file():
        raise MaterialError(
            f"unknown design catalog; known: {', '.join(DESIGN_CATALOGS)}, "
            "or a path to an existing .csv file with columns name,nd,vd[,dpgf]",
            got=key,
        )
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise MaterialError(f"cannot read design catalog: {exc}", got=key) from exc
    return _parse_design_csv(text, key)
