"""``lensopt warmup``: which structures it compiles, that it skips what is on disk, its JSON and its
bad input. The compilation itself (``aot.build_package``) is replaced by a stand-in that records the
call and writes a file: that the packages give the eager trace's numbers is tested in
tests/optics/test_backend.py."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from lensopt.cli import app
from lensopt.optics import aot

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()


def test_warmup_builds_plain_recorded_and_rgb_structures_once(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("TORCHINDUCTOR_CACHE_DIR", str(tmp_path))
    built: list[tuple[int, int, bool]] = []

    def fake_build(lens, *, record=False, upto=None, newton_iterations=12):  # type: ignore[no-untyped-def]
        built.append((lens.num_surfaces, lens.index.shape[-1], record))
        path = aot.package_path(lens, record=record)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"stand-in")
        return 1.5

    monkeypatch.setattr(aot, "build_package", fake_build)
    cmount = str(ROOT / "lenses" / "cmount_4p.json")  # 12 wavelengths, no rgb_weights: RGB uses 11 (S4.1.2)
    r = runner.invoke(app, ["warmup", cmount, "--json"])
    assert r.exit_code == 0, r.output
    # plain and recorded with all 12 wavelengths, and the 11 with a non-zero RGB channel weight
    assert built == [(9, 12, False), (9, 12, True), (9, 11, False)]
    rows = json.loads(r.stdout)["packages"]
    assert [row["built_s"] for row in rows] == [1.5, 1.5, 1.5]
    assert all(Path(row["package"]).parent == tmp_path / "lensopt_aot" for row in rows)
    # Again: everything is on disk, nothing is compiled; --no-recorded leaves the recorded one out.
    r = runner.invoke(app, ["warmup", cmount, "--no-recorded"])
    assert r.exit_code == 0 and len(built) == 3
    assert r.output.count("already compiled") == 2
    # A 3-wavelength lens: its RGB simulation traces all of them, so no third structure.
    built.clear()
    r = runner.invoke(app, ["warmup", str(ROOT / "specs" / "cooke_triplet.toml")])
    assert r.exit_code == 0 and built == [(6, 3, False), (6, 3, True)]


def test_warmup_of_a_decentered_lens_is_one_line_exit_2(tmp_path) -> None:
    spec = (ROOT / "specs" / "achromat_f10.toml").read_text()
    spec = spec.replace('[[surfaces]]', '[[surfaces]]\ndecenter = [0.1, 0.0]', 1)
    path = tmp_path / "decentered.toml"
    path.write_text(spec)
    r = runner.invoke(app, ["warmup", str(path)])
    assert r.exit_code == 2, r.output
    assert len(r.output.strip().splitlines()) == 1 and "decentered" in r.output
