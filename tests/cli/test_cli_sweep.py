"""``lensopt sweep``: the JSON table is the one written to disk, a re-run resumes, bad keys and a folder of
another sweep are one line and exit 2, before any work."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from typer.testing import CliRunner

from lensopt.cli.app import app

ROOT = Path(__file__).resolve().parents[2]
COOKE = ROOT / "specs" / "cooke_triplet_opt.toml"
runner = CliRunner()


def _tiny(tmp: Path) -> Path:
    p = tmp / "tiny.toml"
    p.write_text(COOKE.read_text().replace('sampling = "rings:8"', 'sampling = "rings:3"'))
    return p


def _args(spec: Path, out: Path, *extra: str) -> list[str]:
    return ["sweep", str(spec), "--vary", "optimize.solves[0].value=48.0:52.0:4.0", "--starts", "2", "--steps", "3",
            "--scheduler", "serial", "--esr-sampling", "rings:3", "-o", str(out), "--quiet", *extra]


def test_sweep_json_resume_and_mismatch(tmp_path: Path) -> None:
    spec, out = _tiny(tmp_path), tmp_path / "out"
    r = runner.invoke(app, _args(spec, out, "--json"))
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["complete"] and doc["computed"] == 4 and doc["skipped"] == 0
    disk = json.loads((out / "sweep.json").read_text())
    assert doc["points"] == disk["points"]
    assert [p["optimize.solves[0].value"] for p in doc["points"]] == [48.0, 52.0]
    for name in ("sweep.csv", "sweep.png", "best_0.json", "best_1.json", "manifest.json"):
        assert (out / name).is_file()
    assert (out / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    again = json.loads(runner.invoke(app, _args(spec, out, "--json")).stdout)
    assert again["computed"] == 0 and again["skipped"] == 4
    # The table (80 columns in a pipe) shows the seed's measure beside the ESR, as in the JSON.
    shown = runner.invoke(app, _args(spec, out), env={"COLUMNS": ""})
    assert shown.exit_code == 0, shown.output
    lines = shown.stdout.split(" task(s) run, ")[0].splitlines()[:-1]  # the table, not the list of files
    assert max(map(len, lines)) <= 80 and "seed's" in lines[2]
    for p in doc["points"]:
        first = [str(p["point"]), f"{p['optimize.solves[0].value']:g}"]
        row = next(ln.split() for ln in lines if ln.split()[:2] == first)
        assert row[2:4] == [f"{p['best_esr_um']:.4g}", f"{p['best_seed_esr_um']:.4g}"]
    bad = runner.invoke(app, _args(spec, out, "--perturb", "0.1"))
    assert bad.exit_code == 2
    assert bad.stderr.strip().splitlines() == [bad.stderr.strip()]
    assert bad.stderr.startswith("error: --output: holds a sweep made with another spec or other arguments")


def test_bad_key_is_one_line_exit_2(tmp_path: Path) -> None:
    spec = _tiny(tmp_path)
    for vary, words in [("optimize.solve[0].value=1,2", "--vary: optimize has no 'solve'"),
                        ("surfaces[7].thickness=1,2", "--vary: surfaces has 6 entries"),
                        ("surfaces[0].thickness=1,-1", "--vary: surfaces[0].thickness=-1 is rejected by the spec"),
                        ("surfaces[0].thickness", "--vary: expected KEY=V1,V2")]:
        r = runner.invoke(app, ["sweep", str(spec), "--vary", vary, "-o", str(tmp_path / "o")])
        assert r.exit_code == 2, r.output
        line = r.stderr.strip()
        assert "\n" not in line and line.startswith("error: " + words), line
    assert not (tmp_path / "o").exists()
    r = runner.invoke(app, ["sweep", str(spec), "--vary", "optimize.steps=3", "-o", str(tmp_path / "o"),
                            "--scheduler", "nowhere"])
    assert r.exit_code == 2 and r.stderr.startswith("error: --scheduler:")
    r = runner.invoke(app, ["sweep", str(spec), "--vary", "optimize.steps=3,4", "--vary", "optimize.solves[0].value=50",
                            "--continuation", "-o", str(tmp_path / "o")])
    assert r.exit_code == 2 and r.stderr.strip() == ("error: --continuation: a continuation walks along one key: give "
                                                     "one --vary (got ['optimize.steps', 'optimize.solves[0].value'])")
    assert not (tmp_path / "o").exists()


def test_sigterm_keeps_finished_starts_and_the_run_resumes(tmp_path: Path) -> None:
    spec, out = _tiny(tmp_path), tmp_path / "out"
    args = ["sweep", str(spec), "--vary", "optimize.solves[0].value=47,49", "--starts", "2", "--steps", "12",
            "--scheduler", "serial", "--esr-sampling", "rings:3", "-o", str(out), "--json"]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "lensopt", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)
    seen = ""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and "sweep 1/4 tasks" not in seen:  # the plain progress line (no TTY)
        line = proc.stderr.readline()
        seen += line
        if not line and proc.poll() is not None:
            break
    assert "sweep 1/4 tasks" in seen, seen
    proc.send_signal(signal.SIGTERM)
    stdout, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert "Traceback" not in err and "terminated:" in err
    doc = json.loads(stdout)
    assert doc["interrupted"] and not doc["complete"]
    done = doc["computed"]
    assert 1 <= done < 4 and len(list((out / "points").glob("*_*.json"))) == 2 * done  # record + lens each
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []  # no temp files left
    assert json.loads((out / "sweep.json").read_text())["complete"] is False
    r = runner.invoke(app, [*args, "--quiet"])
    assert r.exit_code == 0, r.output
    again = json.loads(r.stdout)
    assert again["complete"] and again["skipped"] == done and again["computed"] == 4 - done


def test_full_weight_reaches_every_start_and_the_manifest(tmp_path: Path, monkeypatch) -> None:  # noqa: ANN001
    import lensopt.study.sweep as sw

    seen: list[bool] = []
    real = sw.optimize

    def capturing(spec, **kw):  # noqa: ANN001, ANN202
        seen.append(kw["full_weight"])
        return real(spec, **kw)

    monkeypatch.setattr(sw, "optimize", capturing)
    spec, out = _tiny(tmp_path), tmp_path / "out"
    r = runner.invoke(app, _args(spec, out, "--full-weight", "--steps", "1"))
    assert r.exit_code == 0, r.output
    assert seen == [True] * 4
    assert json.loads((out / "manifest.json").read_text())["settings"]["full_weight"] is True
