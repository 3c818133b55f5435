"""Glass name lookup, listing and design catalogs."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import torch

from lensopt.errors import LensoptError, MaterialError
from lensopt.materials import DESIGN_CATALOGS, VENDORS, design_catalog, find_glass, list_glasses

SHARED_OHARA_CSV = (
    Path(__file__).resolve().parents[2] / "lensopt" / "materials" / "data" / "ohara_recommended.csv"
)


@pytest.mark.parametrize(
    "name", ["S-BSL7", "S-BSL 7", "s-bsl7", " s-BSL 7 ", "ohara:S-BSL7", "OHARA: s-bsl 7"]
)
def test_case_and_space_insensitive(name: str) -> None:
    g = find_glass(name)
    assert (g.vendor, g.name) == ("ohara", "S-BSL7")


def test_vendor_priority_for_bare_names() -> None:
    assert find_glass("F2").vendor == "schott"  # also in CDGM
    assert find_glass("cdgm:F2").vendor == "cdgm"
    assert find_glass("SK16").vendor == "hikari"  # the Cooke triplet's SK16 exists only there
    assert find_glass("N-SK16").vendor == "schott"
    assert find_glass("BSC7").vendor == "hoya"
    assert find_glass("K-BK7").vendor == "sumita"


def test_plastics_resolve_last_and_by_qualifier() -> None:
    plastics = list_glasses("plastics")
    assert len(plastics) == 12
    for p in plastics:
        assert find_glass(p.name) == p  # no plastic name is shadowed by a vendor glass
    assert find_glass("plastics:okp1").name == "OKP1"
    assert find_glass("pc(blk)").nd == 1.584


def test_unknown_glass_suggests_close_names() -> None:
    with pytest.raises(MaterialError) as info:
        find_glass("N-BK8")
    err = info.value
    assert isinstance(err, LensoptError) and err.got == "N-BK8"
    assert str(err).startswith("unknown glass 'N-BK8'; close matches: N-BK7 (schott)")
    assert "N-BK10 (schott)" in str(err) and str(err).endswith("(got 'N-BK8')")


def test_unknown_glass_in_vendor_and_unknown_vendor() -> None:
    with pytest.raises(MaterialError, match="in the ohara catalog; close matches: S-BSL7"):
        find_glass("ohara:S-BSL8")
    with pytest.raises(MaterialError, match="unknown glass vendor") as info:
        find_glass("zeiss:N-BK7")
    assert info.value.got == "zeiss"
    with pytest.raises(MaterialError, match="no close matches"):
        find_glass("qqqqqqqq")


def test_list_glasses() -> None:
    every = list_glasses()
    assert len(every) == sum(len(list_glasses(v)) for v in VENDORS)
    assert [g.vendor for g in every[:1]] == ["schott"]
    assert all(g.vendor == "hoya" for g in list_glasses("HOYA"))
    with pytest.raises(MaterialError):
        list_glasses("nope")


def test_ohara_recommended_is_the_seeds_104() -> None:
    cat = design_catalog("ohara-recommended")
    with SHARED_OHARA_CSV.open() as f:
        rows = [r for r in csv.DictReader(f) if r["ignore"] == "False"]
    assert len(cat) == 104 == len(rows)  # seed S5.1: 104 recommended Ohara glasses
    assert cat.names == tuple(r["name"] for r in rows)
    assert cat.values.shape == (104, 3) and cat.values.dtype == np.float64
    assert not cat.values.flags.writeable
    np.testing.assert_array_equal(cat.dpgf, [float(r["dpgf"]) for r in rows])
    assert cat.names[1] == "S-BSL 7" and cat.nd[1] == 1.51633


def test_ohara_recommended_agrees_with_vendor_catalog() -> None:
    # Two independent transcriptions of Ohara's data: the seed's csv and the 2017 Zemax catalog.
    # Eight of the 104 are newer than that catalog.
    newer = {"S-NBM52", "S-LAL 7Q", "S-LAL12Q", "S-LAL21", "S-NBH59", "S-NBH58", "S-LAH98", "S-LAH99"}
    cat = design_catalog("ohara-recommended")
    missing = set()
    for name, (nd, vd, dpgf) in zip(cat.names, cat.values, strict=True):
        try:
            g = find_glass("ohara:" + name)
        except MaterialError:
            missing.add(name)
            continue
        # the database's converter drops a zero dPgF (S-TIL 2, S-LAH93): None reads as 0
        assert abs(g.nd - nd) < 1e-5 and abs(g.vd - vd) < 1e-2, name
        assert abs((g.dpgf or 0.0) - dpgf) < 1e-4, name
    assert missing == newer


def test_schott_preferred_and_plastics() -> None:
    cat = design_catalog("schott-preferred")
    assert len(cat) > 50 and "N-BK7" in cat.names and "N-SF6" in cat.names
    assert all(find_glass("schott:" + n).status == "preferred" for n in cat.names)
    plastics = design_catalog("plastics")
    assert len(plastics) == 12 and (plastics.dpgf == 0).all()
    assert plastics.names[0] == "K26R" and tuple(plastics.values[0]) == (1.535, 56.0, 0.0)  # Table S10
    assert design_catalog("Plastics") is plastics  # cached
    t = plastics.as_tensor(dtype=torch.float32)
    assert t.shape == (12, 3) and t.dtype == torch.float32
    assert set(DESIGN_CATALOGS) == {"ohara-recommended", "schott-preferred", "plastics"}


def test_design_catalog_from_csv(tmp_path: Path) -> None:
    path = tmp_path / "mine.csv"
    path.write_text("name,nd,vd\nA,1.5,60\nB,1.7,30.5\n")
    cat = design_catalog(path)
    assert cat.names == ("A", "B") and cat.values.tolist() == [[1.5, 60.0, 0.0], [1.7, 30.5, 0.0]]
    path.write_text("name,nd,vd,dpgf,ignore\nA,1.5,60,0.01,False\nB,1.7,30,,True\nC,1.8,25,,\n")
    cat = design_catalog(str(path))
    assert cat.names == ("A", "C") and cat.dpgf.tolist() == [0.01, 0.0]


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("name,nd\nA,1.5\n", "missing column"),
        ("name,nd,vd\nA,1.5,sixty\n", "line 2: vd must be a finite number"),
        ("name,nd,vd\nA,nan,60\n", "line 2: nd must be a finite number"),
        ("name,nd,vd\n", "has no materials"),
        ("name,nd,vd,ignore\nA,1.5,60,maybe\n", "ignore must be True/False"),
    ],
)
def test_design_catalog_csv_errors(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(MaterialError, match=match):
        design_catalog(path)


def test_unknown_design_catalog(tmp_path: Path) -> None:
    with pytest.raises(MaterialError, match="unknown design catalog; known: ohara-recommended") as info:
        design_catalog("ohara-preferred")
    assert info.value.got == "ohara-preferred"
    with pytest.raises(MaterialError, match="unknown design catalog"):
        design_catalog(tmp_path / "absent.csv")
