"""``lensopt optimize``: the written lens re-traces to the same numbers, glasses are bound by name,
bad input gives one line and exit 2, Ctrl-C still writes the best lens atomically."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from lensopt.cli.app import app
from lensopt.design import build_problem, optimize
from lensopt.materials import CatalogGlass
from lensopt.spec import build, load_spec, parse_spec, save_json

runner = CliRunner()


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "start.json"
    save_json(parse_spec(data), path)
    return path


def test_written_lens_traces_to_the_optimizers_numbers(tmp_path: Path, make_cooke) -> None:  # noqa: ANN001
    data = make_cooke(solves=[{"type": "efl", "surface": -1, "value": 50.0}])
    for i in (0, 2, 4):
        data["surfaces"][i]["vary"] = ["radius"]
    data["surfaces"][3]["vary"] = ["thickness"]
    start = _write(tmp_path, data)
    out = tmp_path / "lens.json"
    r = runner.invoke(app, ["optimize", str(start), "-o", str(out), "--steps", "6", "--json", "-q"])
    assert r.exit_code == 0, r.output
    summary = json.loads(r.stdout)
    t = runner.invoke(app, ["trace", str(out), "--json"])
    assert t.exit_code == 0, t.output
    traced = json.loads(t.stdout)
    assert traced["effective_spot_radius_um"] == summary["final"]["effective_spot_radius_um"]
    assert traced["first_order"] == summary["final"]["first_order"]
    assert traced["fields"] == summary["final"]["fields"]
    assert summary["final"]["first_order"]["efl"] == pytest.approx(50.0, rel=1e-12)  # the solve
    assert not list(tmp_path.glob(".*part*"))  # nothing half-written left behind


def test_summary_reports_the_seeds_measure_of_both_lenses(tmp_path: Path) -> None:
    # The ESR on the seed's measure (11 fields, grid:61) beside the spec's own, for the start and the written
    # lens, each equal to ``analysis.spot.seed_esr`` of that lens computed here; the shipped C-mount start
    # is issue 25's 13.438 µm.
    from rich.console import Console

    from lensopt.analysis.spot import seed_esr
    from lensopt.cli.optimize import render_summary

    start = Path(__file__).resolve().parents[2] / "lenses" / "cmount_4p.json"
    out = tmp_path / "lens.json"
    r = runner.invoke(app, ["optimize", str(start), "-o", str(out), "--steps", "1", "--json", "-q",
                            "--allow-violations"])
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    assert s["seed_measure"] == {"fields": 11, "sampling": "grid:61"}
    with torch.no_grad():
        for key, path in (("start", start), ("final", out)):
            model = build(load_spec(path))
            assert s[key]["seed_esr_um"] == pytest.approx(1e3 * float(seed_esr(model.lens, model.system)), rel=1e-12)
    assert abs(s["start"]["seed_esr_um"] - 13.438) <= 1e-3
    assert s["final"]["seed_esr_um"] != s["start"]["seed_esr_um"]  # one step moved the lens
    console = Console(record=True, width=80)
    render_summary(console, s)
    text = console.export_text()
    assert (f"ESR, seed's measure (11 fields, grid:61): {s['start']['seed_esr_um']:.4f} µm → "
            f"{s['final']['seed_esr_um']:.4f} µm") in text


def test_written_values_reproduce_the_final_residuals(make_cooke) -> None:  # noqa: ANN001
    # The lens file holds the optimizer's lens: rebuilt from it, the residual function gives the same
    # vector (to the last few ulps: radii are written as 1/c).
    data = make_cooke(solves=[{"type": "efl", "surface": -1, "value": 50.0}])
    for i in (0, 2):
        data["surfaces"][i]["vary"] = ["radius"]
    data["surfaces"][1]["vary"] = ["thickness"]
    result = optimize(parse_spec(data), steps=4)
    again = build_problem(result.spec)
    torch.testing.assert_close(again.residuals(again.theta0), result.problem.residuals(result.theta),
                               rtol=1e-11, atol=1e-15)


def test_glasses_are_bound_to_catalog_glasses_by_name(make_cooke) -> None:  # noqa: ANN001
    # The flint varies freely for half the run, is then bound to the nearest Schott preferred glass,
    # frozen, and the rest of the run (and the written lens) uses that glass's catalog formula.
    data = make_cooke(catalog="schott-preferred", bind_at=0.5, steps=20)
    data["surfaces"][2]["vary"] = ["material", "radius"]
    data["surfaces"][0]["vary"] = ["radius"]
    result = optimize(parse_spec(data))
    assert len(result.bound) == 1 and result.bound[0].surface == 2
    material = result.spec.surfaces[2].material
    assert isinstance(material, str) and material.startswith("schott:")
    assert "material" not in result.spec.surfaces[2].vary
    medium = build(result.spec).media[3]
    assert isinstance(medium, CatalogGlass) and medium.name == result.bound[0].name
    assert result.problem.num_glasses == 0


def test_bad_input_is_one_line_and_exit_2(tmp_path: Path, make_cooke) -> None:  # noqa: ANN001
    data = make_cooke()
    start = _write(tmp_path, data)
    r = runner.invoke(app, ["optimize", str(start), "-o", str(tmp_path / "x.json"), "-q"])
    assert r.exit_code == 2
    assert "surfaces: nothing to optimize: no surface has a vary list" in r.output
    data["surfaces"][0]["vary"] = ["radius"]
    start = _write(tmp_path, data)
    r = runner.invoke(app, ["optimize", str(start), "-o", str(tmp_path / "x.json"), "--optimizer", "bfgs", "-q"])
    assert r.exit_code == 2 and "--optimizer: must be lm or adam (got 'bfgs')" in r.output
    r = runner.invoke(app, ["optimize", str(start), "-o", str(tmp_path / "x.toml"), "-q"])
    assert r.exit_code == 2 and "--output: the optimized lens is written as .json" in r.output
    data["optimize"]["sampling"] = "rings:0"
    (tmp_path / "bad.json").write_text(json.dumps(data))
    r = runner.invoke(app, ["optimize", str(tmp_path / "bad.json"), "-o", str(tmp_path / "x.json"), "-q"])
    assert r.exit_code == 2 and r.output.count("\n") == 1 and "optimize.sampling" in r.output
    assert not (tmp_path / "x.json").exists()


def test_ctrl_c_writes_the_best_lens_so_far(tmp_path: Path, make_cooke) -> None:  # noqa: ANN001
    data = make_cooke()
    data["surfaces"][0]["vary"] = ["radius"]
    data["surfaces"][4]["vary"] = ["radius"]
    start = _write(tmp_path, data)
    out = tmp_path / "lens.json"
    exe = Path(sys.executable).parent / "lensopt"
    proc = subprocess.Popen([str(exe), "optimize", str(start), "-o", str(out), "--steps", "100000", "-q"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "OMP_NUM_THREADS": "1", "COLUMNS": "200"})
    assert proc.stderr is not None
    line = proc.stderr.readline()  # printed once the first step is done
    assert "Ctrl-C keeps the best lens" in line
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    out_text, err_text = proc.communicate(timeout=120)
    assert proc.returncode == 130, err_text
    assert "interrupted — best lens so far" in out_text
    lens = load_spec(out)  # complete and valid
    assert lens.surfaces[0].radius != 22.01359 or lens.surfaces[4].radius != 79.68360
    assert not list(tmp_path.glob(".*part*"))
