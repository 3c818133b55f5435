"""CODE V export: file layout, glass names, private catalogs, HCO conversion, refusals."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from lensopt.errors import SpecError
from lensopt.interchange.codev.names import codev_glass_name, find_codev_glass
from lensopt.interchange.codev.syntax import split_commands
from lensopt.interchange.codev.write import MIN_PRIVATE_WAVELENGTHS, export_codev, write_codev
from lensopt.materials import find_glass, list_glasses
from lensopt.optics.paraxial import first_order
from lensopt.spec import build, load_spec, parse_spec
from tests.helpers import cooke_data

ROOT = Path(__file__).resolve().parents[2]
DATA = Path(__file__).parent / "data"


def _cooke() -> dict:
    return cooke_data()


def test_one_command_per_line_and_no_qualified_forms() -> None:
    # Several readers reject "RDY S1 …" and ";"-joined modifiers: every modifier has its own line,
    # directly after its surface line.
    for name in ("asphere_plastic.toml", "hybrid_diffractive.toml", "finite_relay.toml"):
        text = export_codev(load_spec(DATA / name))
        body = [line for line in text.splitlines() if not line.startswith("!")]
        assert not any(";" in line for line in body)
        for cmd in split_commands(text).commands:
            assert not any(t[:1] == "S" and t[1:].isdigit() for t in cmd.args), cmd


def test_cooke_triplet_file() -> None:
    text = export_codev(load_spec(ROOT / "specs" / "cooke_triplet.toml"))
    lines = [line for line in text.splitlines() if not line.startswith("!")]
    assert lines[:6] == ["RDM Y", "LEN", "TITLE 'Cooke triplet'", "DIM M", "EPD 10.0", "YAN 0 14 20"]
    assert "WL 480.0 550.0 650.0" in lines and "REF 2" in lines and "SO 0 1e10" in lines
    assert "S 22.01359 3.25896 SK16_HIKARI" in lines
    assert lines[lines.index("S -22.21328 0.99997 F2_SCHOTT") + 1] == "  STO"
    assert lines[-2:] == ["SI 0 0.0", "GO"]


def test_model_glasses_become_a_private_catalog_of_lensopt_indices() -> None:
    data = _cooke()
    data["spectrum"] = {"wavelengths_nm": [550.0]}  # one wavelength: the catalog still needs ≥ 4
    data["surfaces"][0]["material"] = {"nd": 1.62, "vd": 60.3, "dpgf": 0.0}
    spec = parse_spec(data)
    seq = split_commands(export_codev(spec))
    names = [c.name for c in seq.commands]
    pwl = next(c for c in seq.commands if c.name == "PWL")
    wavelengths = [float(t) for t in pwl.args]
    assert len(wavelengths) >= MIN_PRIVATE_WAVELENGTHS and 550.0 in wavelengths
    entry = seq.commands[names.index("PWL") + 1]
    assert entry.tokens[0] == "LOMODEL"
    model = build(spec)
    at_550 = float(entry.args[wavelengths.index(550.0)])
    assert at_550 == float(model.lens.index[1, 0])  # exactly the index lensopt traces with
    assert "S 22.01359 3.25896 LOMODEL" in export_codev(spec)


def test_private_catalog_option_writes_every_glass_privately() -> None:
    spec = load_spec(ROOT / "specs" / "cooke_triplet.toml")
    text = export_codev(spec, private_catalog=True)
    assert "SK16_HIKARI" not in text and "S 22.01359 3.25896 LOSK16" in text
    seq = split_commands(text)
    pwl = [float(t) for t in next(c for c in seq.commands if c.name == "PWL").args]
    entry = next(c for c in seq.commands if c.tokens[0] == "LOF2")
    got = dict(zip(pwl, (float(t) for t in entry.args), strict=True))
    model = build(spec)
    for w, nm in enumerate(spec.spectrum.wavelengths_nm):
        assert got[nm] == float(model.lens.index[3, w])


def test_hco_is_the_phase_as_optical_path_at_the_construction_wavelength() -> None:
    # φ = 2π/λ0 · OPD (CODE V DOE, see interchange/codev/write.py): d2 = −9.5 rad/mm² at λ0 = 587.5618 nm gives
    # C1 = −9.5 · 587.5618e-6 / (2π) = −8.8837696599873e-4 mm⁻¹ (hand computed).
    text = export_codev(load_spec(DATA / "hybrid_diffractive.toml"))
    assert "  HCO C1 -0.00088837696599873" in text.splitlines()
    assert -9.5 * 587.5618e-6 / (2 * math.pi) == pytest.approx(-8.8837696599873e-4, rel=1e-13)
    assert "  HOR 1" in text and "  HWL 587.5618" in text and "  HCT R" in text


def test_apertures_and_fields() -> None:
    finite = export_codev(load_spec(DATA / "finite_relay.toml"))
    assert "YIM 0 2.1 3" in finite.splitlines()
    # A finite-conjugate f-number (EFL/EPD in lensopt) is written as the EPD it implies, because
    # CODE V's FNO would then mean the working f-number.
    epd = next(line for line in finite.splitlines() if line.startswith("EPD"))
    model = build(load_spec(DATA / "finite_relay.toml"))
    efl = float(first_order(model.lens, model.system).efl)
    assert float(epd.split()[1]) == pytest.approx(efl / 6.0, rel=1e-13)
    plastic = export_codev(load_spec(DATA / "asphere_plastic.toml"))
    assert "FNO 10.0" in plastic.splitlines() and "WTF 1.0 2.0 2.0 1.0" in plastic.splitlines()
    hybrid = export_codev(load_spec(DATA / "hybrid_diffractive.toml")).splitlines()
    assert {"VUY 0.0 0.1 0.2", "VLY 0.0 0.05 0.12", "VUX 0.0 0.02 0.05", "VLX 0.0 0.02 0.05"} <= set(hybrid)
    assert "SO 0 400.0" in hybrid


def test_asphere_terms_beyond_r20_are_refused_and_no_file_is_left(tmp_path: Path) -> None:
    data = _cooke()
    data["surfaces"][0] = {"type": "asphere", "radius": 22.01359, "coefficients": {"22": 1e-20},
                           "thickness": 3.25896, "material": "SK16"}
    out = tmp_path / "lens.seq"
    with pytest.raises(SpecError, match=r"surfaces\[0\]\.coefficients: CODE V's ASP surface stops at r\^20"):
        write_codev(parse_spec(data), out)
    assert list(tmp_path.iterdir()) == []


def test_every_catalog_glass_has_a_codev_name_that_reads_back() -> None:
    for glass in list_glasses():
        if glass.vendor == "plastics":
            continue
        assert find_codev_glass(codev_glass_name(glass)) is glass, glass.label


def test_codev_names_of_known_glasses() -> None:
    # Spellings as in CODE V files written by CODE V (tests/interchange/data/codev: NBK7_SCHOTT, NSF5_SCHOTT,
    # SLAL8_OHARA, STIH53_OHARA, NPSK53A_SCHOTT, NLASF9_SCHOTT).
    for vendor_name, cv in [("schott:N-BK7", "NBK7_SCHOTT"), ("schott:N-SF5", "NSF5_SCHOTT"),
                            ("ohara:S-LAL8", "SLAL8_OHARA"), ("ohara:S-TIH53", "STIH53_OHARA"),
                            ("schott:N-PSK53A", "NPSK53A_SCHOTT"), ("schott:N-LASF9", "NLASF9_SCHOTT")]:
        assert codev_glass_name(find_glass(vendor_name)) == cv


def test_export_is_deterministic_and_numbers_read_back_exactly() -> None:
    spec = load_spec(DATA / "asphere_plastic.toml")
    text = export_codev(spec)
    assert text == export_codev(spec)
    asp = [c for c in split_commands(text).commands if c.name in ("A", "B", "C", "D", "E", "F", "G", "H", "J")]
    assert [float(c.args[0]) for c in asp[:9]] == list(spec.surfaces[1].coefficients.values())
