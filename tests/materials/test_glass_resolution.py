"""Bare glass names: the documented vendor order, the valid-range check against the spectrum, and the one
notice line a choice among vendors gives (issue 29, item 5).

Independent oracles: the vendors and valid ranges are read from the catalog records themselves
(``list_glasses(vendor)``), not from the resolver; the expected choice follows from the rule written in
docs/spec.md (first vendor in the order whose range covers every wavelength of the spectrum).
"""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from typer.testing import CliRunner

from lensopt.cli.app import app
from lensopt.errors import MaterialError
from lensopt.materials import VENDORS, find_glass, list_glasses, material_from_name, resolve_glass
from lensopt.materials import catalog as cat_mod
from lensopt.materials.catalog import normalize_name

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def _fresh_notices(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(cat_mod, "_told", set())  # notices are once per process: start each test afresh


def _vendors_of(name: str) -> list[str]:
    key = normalize_name(name)
    return [v for v in VENDORS if any(normalize_name(g.name) == key for g in list_glasses(v))]


def test_documented_vendor_order() -> None:
    assert VENDORS == ("schott", "ohara", "hoya", "cdgm", "sumita", "hikari", "plastics")
    doc = (ROOT / "docs" / "spec.md").read_text(encoding="utf-8")
    assert "schott, ohara, hoya, cdgm, sumita, hikari, plastics" in doc


def test_first_vendor_of_a_shared_name_covers_the_others() -> None:
    """Why Hikari comes late: for every name several vendors ship, the first in the order is valid over
    at least the range of every later one, so the order never prefers narrower data."""
    shared = {normalize_name(g.name) for g in list_glasses()}
    n_shared = 0
    for key in sorted(shared):
        vendors = _vendors_of(key)
        if len(vendors) < 2:
            continue
        n_shared += 1
        ranges = [find_glass(f"{v}:{key}").range_um for v in vendors]
        assert all(ranges[0][0] <= lo and hi <= ranges[0][1] for lo, hi in ranges[1:]), (key, vendors, ranges)
        assert find_glass(key).vendor == vendors[0]
    assert n_shared >= 20  # F2, SF1 ... in Schott and Hikari; BAF10 ... in Hoya and Hikari


def test_bare_names_follow_the_order() -> None:
    assert _vendors_of("BAF10") == ["hoya", "hikari"]
    assert find_glass("BAF10").vendor == "hoya"
    assert find_glass("hikari:BAF10").vendor == "hikari"
    assert _vendors_of("F1") == ["cdgm", "hikari"]
    assert find_glass("F1").vendor == "cdgm"


def test_range_check_falls_through_to_a_vendor_that_covers(monkeypatch: pytest.MonkeyPatch,
                                                            caplog: pytest.LogCaptureFixture) -> None:
    """With Hikari put first (the old order), BAF10 at 380 nm is outside Hikari's 0.4–0.7 µm: Hoya's is
    taken, and the notice says why; inside 0.4–0.7 µm Hikari's is taken."""
    monkeypatch.setattr(cat_mod, "VENDORS", ("schott", "ohara", "hikari", "hoya", "cdgm", "sumita", "plastics"))
    assert find_glass("hikari:BAF10").range_um == (0.4, 0.7)
    g, told = resolve_glass("BAF10", [0.38, 0.55, 0.65])
    assert g.vendor == "hoya"
    assert "BAF10 (hikari) is valid 0.4–0.7 µm only" in told and "380–650 nm" in told
    g, told = resolve_glass("BAF10", [0.45, 0.55, 0.65])
    assert g.vendor == "hikari"
    assert "the first in the vendor order" in told


def test_no_vendor_covers_the_spectrum_is_an_error() -> None:
    assert _vendors_of("SK16") == ["hikari"]
    assert find_glass("SK16", [0.486, 0.588, 0.656]).vendor == "hikari"  # the Cooke triplet's: inside
    with pytest.raises(MaterialError) as info:
        material_from_name("SK16", [0.38, 0.55, 0.65], path="surfaces[0].material")
    msg = str(info.value)
    assert msg.startswith("wavelength 0.38 µm of the spectrum (380–650 nm) is outside the valid range 0.4–0.7 µm of "
                          "SK16 (hikari)")
    assert "N-SK16 (schott)" in msg  # a close name whose data cover the spectrum
    with pytest.raises(MaterialError, match=r"0\.39–2\.5 µm of SF11 \(schott\), 0\.4–0\.7 µm of SF11 \(hikari\)"):
        find_glass("SF11", [0.38, 0.55])


def test_one_notice_line_for_a_choice_among_vendors(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING):
        for _ in range(3):  # built many times in a run: told once
            g = find_glass("F2", [0.48, 0.55, 0.65], path="surfaces[2].material")
        find_glass("schott:F2", [0.48, 0.55, 0.65])  # qualified: no choice, no notice
        find_glass("N-BK7", [0.48, 0.55, 0.65])  # one vendor only: no notice
    assert g.vendor == "schott"
    assert _vendors_of("F2") == ["schott", "cdgm", "hikari"]
    assert [r.getMessage() for r in caplog.records] == [
        "surfaces[2].material: glass 'F2' is in the schott, cdgm, hikari catalogs; using F2 (schott), the first "
        "in the vendor order schott, ohara, hoya, cdgm, sumita, hikari, plastics; write 'schott:F2' to make "
        "the choice explicit"]


def _spec(tmp_path: Path, material: str, wavelengths: str) -> Path:
    text = (ROOT / "specs" / "cooke_triplet.toml").read_text(encoding="utf-8")
    text = text.replace('material = "schott:F2"', f'material = "{material}"')
    text = text.replace("wavelengths_nm = [480.0, 550.0, 650.0]", f"wavelengths_nm = {wavelengths}")
    assert f"wavelengths_nm = {wavelengths}" in text
    path = tmp_path / "lens.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_cli_range_error_names_the_field(tmp_path: Path) -> None:
    spec = _spec(tmp_path, "schott:F2", "[380.0, 550.0, 650.0]")
    result = CliRunner().invoke(app, ["trace", str(spec)])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, result.output
    assert lines[0].startswith("error: ") and "surfaces[0].material: wavelength 0.38 µm of the spectrum " \
        "(380–650 nm) is outside the valid range 0.4–0.7 µm of SK16 (hikari)" in lines[0]


def test_cli_prints_the_notice_as_a_warning_line(tmp_path: Path) -> None:
    spec = _spec(tmp_path, "F2", "[480.0, 550.0, 650.0]")
    result = CliRunner().invoke(app, ["trace", str(spec)])
    assert result.exit_code == 0, result.output
    told = [line for line in result.output.splitlines() if line.startswith("warning:")]
    assert told == ["warning: surfaces[2].material: glass 'F2' is in the schott, cdgm, hikari catalogs; using "
                    "F2 (schott), the first in the vendor order schott, ohara, hoya, cdgm, sumita, hikari, "
                    "plastics; write 'schott:F2' to make the choice explicit"]
