"""`lensopt export-codev` and `lensopt import-codev`: files written atomically, one-line errors, exit 2."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from lensopt.cli.app import app
from lensopt.spec import load_spec

ROOT = Path(__file__).resolve().parents[2]
DATA = Path(__file__).parent / "data"
runner = CliRunner()


def test_export_then_import_on_the_command_line(tmp_path: Path) -> None:
    seq, lens = tmp_path / "cooke.seq", tmp_path / "cooke.json"
    result = runner.invoke(app, ["export-codev", str(ROOT / "specs" / "cooke_triplet.toml"), "-o", str(seq)])
    assert result.exit_code == 0, result.output
    assert seq.read_text().splitlines()[-1] == "GO"
    result = runner.invoke(app, ["import-codev", str(seq), "-o", str(lens)])
    assert result.exit_code == 0, result.output
    assert load_spec(lens) == load_spec(ROOT / "specs" / "cooke_triplet.toml")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cooke.json", "cooke.seq"]  # no temp files left


def test_private_catalog_flag(tmp_path: Path) -> None:
    seq = tmp_path / "cooke.seq"
    result = runner.invoke(app, ["export-codev", str(ROOT / "specs" / "cooke_triplet.toml"), "-o", str(seq),
                                 "--private-catalog"])
    assert result.exit_code == 0, result.output
    assert "PRV" in seq.read_text().splitlines()


def test_import_prints_warnings_for_ignored_codes(tmp_path: Path) -> None:
    lens = tmp_path / "dg.json"
    result = runner.invoke(app, ["import-codev", str(DATA / "codev" / "ag_dblgauss.seq"), "-o", str(lens)])
    assert result.exit_code == 0, result.output
    assert "ignored CODE V solves and variable codes: CCY, THC, PIM" in result.output
    assert json.loads(lens.read_text())["name"] == "Double Gauss F/2 -  Available Glasses"


def test_mirror_file_exits_2_with_one_line_and_no_output(tmp_path: Path) -> None:
    lens = tmp_path / "mirror.json"
    result = runner.invoke(app, ["import-codev", str(DATA / "codev" / "CODV_35571.seq"), "-o", str(lens)])
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "mirrors (REFL) are not supported yet" in lines[0]
    assert "Traceback" not in result.output
    assert not lens.exists()


def test_unknown_glass_exits_2_listing_close_matches(tmp_path: Path) -> None:
    text = (DATA / "codev" / "CODV_32327.seq").read_text().replace("NBK7_SCHOTT", "NBK8_SCHOTT")
    seq = tmp_path / "bad.seq"
    seq.write_text(text)
    result = runner.invoke(app, ["import-codev", str(seq), "-o", str(tmp_path / "bad.json")])
    assert result.exit_code == 2
    assert "CODE V glass 'NBK8_SCHOTT'" in result.output and "close matches:" in result.output
    assert "N-BK7 (schott)" in result.output


def test_import_needs_a_json_output(tmp_path: Path) -> None:
    result = runner.invoke(app, ["import-codev", str(DATA / "codev" / "CODV_32327.seq"), "-o",
                                 str(tmp_path / "lens.toml")])
    assert result.exit_code == 2 and "--output: the imported lens is written as JSON" in result.output
