"""``lensopt warmup``: which structures it compiles, that it skips what is on disk, its JSON and its
bad input. The compilation itself (``aot.build_package``) is replaced by a stand-in that records the
call and writes a file: that the packages give the eager trace's numbers is tested in
tests/optics/test_backend.py."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from lensopt.accel import aot
from lensopt.cli.app import app

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


def test_warmup_jacobian_builds_the_package_optimize_looks_for(tmp_path, monkeypatch) -> None:
    """``--jacobian`` keys the package like ``optimize`` builds its problem (the same spec and seed), so that
    ``optimize --jacobian compiled`` finds it; the build itself is a stand-in here (the slow test in
    tests/accel/test_compiled_jacobian.py builds and loads a real one)."""
    import torch

    from lensopt.accel import jacobian as cj
    from lensopt.design import build_problem
    from lensopt.spec import load_spec

    monkeypatch.setenv("TORCHINDUCTOR_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(aot, "build_package", lambda lens, **kw: 0.0)  # the trace packages are not the point
    built: list[str] = []

    def fake_build(problem, theta, key=None):  # type: ignore[no-untyped-def]
        path = cj.package_path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"stand-in")
        built.append(key)
        return path, 2.5

    monkeypatch.setattr(cj, "build_package", fake_build)
    spec = ROOT / "specs" / "cooke_triplet_opt.toml"
    r = runner.invoke(app, ["warmup", str(spec), "--jacobian", "--seed", "3", "--json"])
    assert r.exit_code == 0, r.output
    row = json.loads(r.stdout)["packages"][-1]
    # the problem as lensopt.design.optimize builds it for `optimize --seed 3`
    problem = build_problem(load_spec(spec), seed=3, method="lm", device=torch.device("cpu"))
    assert built == [cj.problem_key(problem)] and row["built_s"] == 2.5
    assert Path(row["package"]) == cj.package_path(cj.problem_key(problem))
    r = runner.invoke(app, ["warmup", str(spec), "--jacobian", "--seed", "3"])
    assert r.exit_code == 0 and len(built) == 1 and "LM Jacobian" in r.output and "already compiled" in r.output
    # A lens with nothing to vary has no optimization problem: one line, exit 2.
    r = runner.invoke(app, ["warmup", str(ROOT / "specs" / "cooke_triplet.toml"), "--jacobian"])
    assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1 and "nothing to optimize" in r.output
