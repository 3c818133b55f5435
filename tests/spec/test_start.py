"""``start = "other.json"`` in a spec file: the lens of the other file, this file's top-level keys
replacing its keys whole (a polishing run is a ``start`` plus a new ``[optimize]``)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lensopt.errors import SpecError
from lensopt.spec import load_spec

ROOT = Path(__file__).resolve().parents[2]
COOKE = ROOT / "specs" / "cooke_triplet_opt.toml"


def test_a_start_gives_the_other_lens_with_this_files_sections(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "start.toml").write_text(COOKE.read_text())
    (tmp_path / "polish.toml").write_text('start = "a/start.toml"\nname = "polished"\n\n[optimize]\nsteps = 7\n')
    base, spec = load_spec(COOKE), load_spec(tmp_path / "polish.toml")
    assert spec.name == "polished" and spec.optimize.steps == 7
    assert spec.surfaces == base.surfaces and spec.system == base.system and spec.spectrum == base.spectrum
    # whole tables are replaced: the start's solves are not merged into the new [optimize]
    assert base.optimize.solves and spec.optimize.solves == []


def test_a_chain_of_starts_and_a_json_start(tmp_path: Path) -> None:
    data = json.loads(load_spec(COOKE).model_dump_json())
    (tmp_path / "lens.json").write_text(json.dumps(data))
    (tmp_path / "b.toml").write_text('start = "lens.json"\nname = "b"\n')
    (tmp_path / "c.toml").write_text('start = "b.toml"\n[optimize]\nsteps = 3\n')
    spec = load_spec(tmp_path / "c.toml")
    assert spec.name == "b" and spec.optimize.steps == 3 and spec.surfaces == load_spec(COOKE).surfaces


def test_bad_starts_name_the_field(tmp_path: Path) -> None:
    (tmp_path / "missing.toml").write_text('start = "nowhere.json"\n')
    with pytest.raises(SpecError, match=r"missing.toml: start: no such file"):
        load_spec(tmp_path / "missing.toml")
    (tmp_path / "x.toml").write_text('start = "y.toml"\n')
    (tmp_path / "y.toml").write_text('start = "x.toml"\n')
    with pytest.raises(SpecError, match="cycle"):
        load_spec(tmp_path / "x.toml")
    (tmp_path / "num.toml").write_text("start = 3\n")
    with pytest.raises(SpecError, match=r"num.toml: start: must be the path"):
        load_spec(tmp_path / "num.toml")
