"""Zemax AGF catalogs: formulas against the catalog data they come from and hand-evaluated formulas,
UTF-16 and ASCII files, the spec's material form, and wavelength-range warnings."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from lensopt.errors import MaterialError
from lensopt.interchange.zemax.read import import_zemax
from lensopt.materials import find_glass, material_from_name
from lensopt.materials.agf import AGF_FORMULAS, agf_glass, agf_index, read_agf
from lensopt.spec import build, load_spec

ROOT = Path(__file__).resolve().parents[2]
NBK7 = find_glass("schott:N-BK7")  # refractiveindex.info record: formula 2 with B1 C1 B2 C2 B3 C3

AGF_TEXT = f"""CC test catalog
NM N-BK7 2 517642.251 1.5168 64.17 0 1 0
ED 7.1 8.3 2.51 -0.0009 0
CD {NBK7.coefficients[1]} {NBK7.coefficients[2]} {NBK7.coefficients[3]} {NBK7.coefficients[4]} {NBK7.coefficients[5]} \
{NBK7.coefficients[6]} 0 0 0 0
TD 0 0 0 0 0 0 20
LD 0.3 2.5
NM BK7OLD 1 517642 1.5168 64.17 0 1 0
CD 2.2718929 -1.0108077E-2 1.0592509E-2 2.0816965E-4 -7.6472538E-6 4.9240991E-7 0 0 0 0
LD 0.365 1.014
"""


@pytest.fixture
def agf(tmp_path: Path) -> Path:
    p = tmp_path / "TEST.agf"
    p.write_text(AGF_TEXT)
    return p


def test_sellmeier_1_equals_the_catalog_glass(agf: Path) -> None:
    wl = torch.linspace(0.35, 2.4, 50, dtype=torch.float64)
    got = agf_glass(agf, "n-bk7").index(wl)
    ref = material_from_name("schott:N-BK7").index(wl)
    assert float((got - ref).abs().max()) <= 1e-15


def test_schott_formula_gives_the_catalog_nd(agf: Path) -> None:
    # Schott's pre-2000 catalog BK7 (formula 1 coefficients): catalog nd = 1.51680, vd = 64.17.
    g = agf_glass(agf, "BK7OLD")
    n = g.index(torch.tensor([0.5875618, 0.4861327, 0.6562725], dtype=torch.float64)).tolist()
    assert n[0] == pytest.approx(1.51680, abs=1e-5)
    assert (n[0] - 1) / (n[1] - n[2]) == pytest.approx(64.17, abs=0.05)


def _hand(formula: int, c: list[float], x: float) -> float:
    """The formulas of the OpticStudio manual, written out again with the math module."""
    c = c + [0.0] * (12 - len(c))
    L = x * x
    if formula == 1:
        return math.sqrt(c[0] + c[1] * L + c[2] / L + c[3] / L**2 + c[4] / L**3 + c[5] / L**4)
    if formula in (2, 6, 11):
        k = {2: 3, 6: 4, 11: 5}[formula]
        return math.sqrt(1 + sum(c[2 * i] * L / (L - c[2 * i + 1]) for i in range(k)))
    if formula == 3:
        q = 1 / (L - 0.028)
        return c[0] + c[1] * q + c[2] * q * q + c[3] * L + c[4] * L**2 + c[5] * L**3
    if formula == 4:
        return math.sqrt(1 + c[0] + c[1] * L / (L - c[2] ** 2) + c[3] / (L - c[4] ** 2))
    if formula == 5:
        return c[0] + c[1] / x + c[2] / x**3.5
    if formula == 7:
        return math.sqrt(c[0] + c[1] / (L - c[2]) - c[3] * L)
    if formula == 8:
        return math.sqrt(c[0] + c[1] * L / (L - c[2]) - c[3] * L)
    if formula == 9:
        return math.sqrt(c[0] + c[1] * L / (L - c[2]) + c[3] * L / (L - c[4]))
    if formula == 10:
        return math.sqrt(c[0] + c[1] * L + sum(c[i] / L ** (i - 1) for i in range(2, 8)))
    if formula == 12:
        return math.sqrt(c[0] + c[1] * L + sum(c[i] / L ** (i - 1) for i in range(2, 6)) + c[6] * L**2 + c[7] * L**3)
    return math.sqrt(c[0] + c[1] * L + c[2] * L**2 + sum(c[i] / L ** (i - 2) for i in range(3, 9)))


COEFFS = {1: [2.27, -0.0101, 0.0106, 2.08e-4, -7.6e-6, 4.9e-7], 2: [1.04, 0.006, 0.23, 0.02, 1.01, 103.5],
          3: [1.5, 0.004, 1e-4, -0.002, 1e-5, -1e-7], 4: [0.1, 1.1, 0.08, 0.002, 0.1], 5: [1.5, 0.004, 1e-4],
          6: [1.0, 0.006, 0.2, 0.02, 0.9, 100.0, 0.01, 0.03], 7: [2.3, 0.01, 0.015, 0.01],
          8: [1.3, 1.0, 0.01, 0.01], 9: [1.2, 1.0, 0.006, 0.9, 100.0],
          10: [2.27, -0.0101, 0.0106, 2.08e-4, -7.6e-6, 4.9e-7, 1e-8, -1e-9],
          11: [1.0, 0.006, 0.2, 0.02, 0.9, 100.0, 0.01, 0.03, 0.001, 0.05],
          12: [2.27, -0.0101, 0.0106, 2.08e-4, -7.6e-6, 4.9e-7, 1e-4, -1e-5],
          13: [2.27, -0.0101, 1e-4, 0.0106, 2.08e-4, -7.6e-6, 4.9e-7, 1e-8, -1e-9]}


@pytest.mark.parametrize("formula", sorted(AGF_FORMULAS))
def test_every_formula_matches_the_manual(formula: int) -> None:
    for x in (0.4, 0.55, 0.7, 1.0):
        got = float(agf_index(formula, torch.tensor(COEFFS[formula], dtype=torch.float64),
                              torch.tensor(x, dtype=torch.float64)))
        assert got == pytest.approx(_hand(formula, list(COEFFS[formula]), x), rel=1e-14)


def test_utf16_catalog_and_unknown_names(tmp_path: Path) -> None:
    p = tmp_path / "U16.agf"
    p.write_bytes(AGF_TEXT.encode("utf-16"))
    glasses = read_agf(p)
    assert set(glasses) == {"N-BK7", "BK7OLD"}
    assert glasses["N-BK7"].range_um == (0.3, 2.5) and glasses["N-BK7"].dpgf == -0.0009
    with pytest.raises(MaterialError, match="close: N-BK7"):
        agf_glass(p, "N-BK8")
    bad = tmp_path / "bad.agf"
    bad.write_text("NM FOO 42 0 1.5 50\nCD 1\n")
    with pytest.raises(MaterialError, match="formula 42"):
        read_agf(bad)


def test_agf_material_form_in_a_spec(tmp_path: Path, agf: Path) -> None:
    text = (ROOT / "specs" / "achromat_f10.toml").read_text()
    spec = load_spec(ROOT / "specs" / "achromat_f10.toml")
    first = spec.surfaces[0].material
    assert isinstance(first, str)
    quoted = f'"{first}"'
    assert quoted in text
    toml = tmp_path / "agf_lens.toml"
    toml.write_text(text.replace(quoted, f'{{ catalog = "{agf.as_posix()}", glass = "N-BK7" }}', 1))
    model = build(load_spec(toml))
    wl = model.lens.wavelength_um
    assert float((model.lens.index[1] - material_from_name("schott:N-BK7").index(wl)).abs().max()) <= 1e-15


def test_import_with_catalog_uses_it_and_warns_out_of_range(tmp_path: Path) -> None:
    agf = tmp_path / "MY.agf"
    agf.write_text(AGF_TEXT.replace("NM N-BK7", "NM N-SK16X").replace("LD 0.3 2.5", "LD 0.5 2.5", 1))
    zmx = (ROOT / "tests" / "data" / "zemax" / "optiland_lens1.zmx").read_text().replace("GLAS N-SK16", "GLAS N-SK16X")
    with pytest.raises(Exception, match="N-SK16X"):
        import_zemax(zmx)
    result = import_zemax(zmx, catalogs=[agf])
    assert result.spec.surfaces[0].material.glass == "N-SK16X"
    lines = [w for w in result.warnings if "N-SK16X" in w]
    assert len(lines) == 1 and "486.133 nm outside" in lines[0]
