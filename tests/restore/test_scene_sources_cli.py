"""``train-irm --images NAME`` and ``evaluate --images photos|textured`` on the command line (issue 27): a
named source trains and is recorded in the checkpoint; a bad value is one line naming --images, exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from lensopt.cli.app import app

runner = CliRunner()
TINY = ["--steps", "1", "--fields", "3", "--sampling", "rings:4", "--psf-size", "9", "--val-patches", "1"]


def test_train_irm_on_a_mixture_records_its_source(tiny_lens: Path, tmp_path: Path) -> None:
    ck = tmp_path / "ck"
    r = runner.invoke(app, ["train-irm", str(tiny_lens), "-o", str(ck), "--images", "textured+photos", *TINY])
    assert r.exit_code == 0, r.output
    data = json.loads((ck / "meta.json").read_text())["meta"]["settings"]["data"]
    assert data.startswith("textured+photos (training: rocket.jpg")
    assert "astronaut" not in data and "chelsea" not in data and "coffee" not in data


@pytest.mark.parametrize("value", ["no_such_source", "textured+nope", "photos+photos"])
def test_bad_images_value_is_one_line_exit_2(tiny_lens: Path, tmp_path: Path, value: str) -> None:
    ck = tmp_path / "ck"
    r = runner.invoke(app, ["train-irm", str(tiny_lens), "-o", str(ck), "--images", value, *TINY])
    assert r.exit_code == 2
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --images:") and "Traceback" not in r.output
    assert not ck.exists()


def test_evaluate_scores_held_out_photograph_tiles(tiny_lens: Path) -> None:
    r = runner.invoke(app, ["evaluate", str(tiny_lens), "--images", "photos", "--count", "2", "--patch", "64",
                            "--rays", "rings:4", "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert [i["scene"] for i in out["items"]] == ["astronaut.png@0,0", "astronaut.png@0,1"]
    assert "held-out photographs" in out["images"]
