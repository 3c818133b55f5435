"""``lensopt tolerance``, ``lensopt plot mtf`` and ``trace --mtf``: JSON carries the library's numbers,
files are complete, bad input is one line and exit code 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch
from typer.testing import CliRunner

from lensopt.analysis.mtf import lens_mtf
from lensopt.cli.app import app
from lensopt.design.tolerance import tolerance_job
from lensopt.spec import build, load_spec
from lensopt.spec.tolerance import ToleranceSpec
from lensopt.tolerance.monte_carlo import monte_carlo
from tests.helpers import CMOUNT, COOKE

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
runner = CliRunner()


def test_tolerance_json_equals_library_and_writes_files(tmp_path: Path) -> None:
    tol = tmp_path / "tol.toml"
    tol.write_text('[tolerance]\nprofile = "s6.2"\nsampling = "rings:4"\ntrials = 12\nseed = 4\n'
                   '[[tolerance.items]]\nkind = "element_tilt_x"\nlimit = 1.0\n')
    out = tmp_path / "out"
    r = runner.invoke(app, ["tolerance", str(CMOUNT), "--tolerances", str(tol), "--scheduler", "serial", "--json",
                            "-o", str(out), "--worst", "2"])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.stdout)
    model = build(load_spec(CMOUNT))
    settings = ToleranceSpec.model_validate({"profile": "s6.2", "sampling": "rings:4", "trials": 12, "seed": 4,
                                             "items": [{"kind": "element_tilt_x", "limit": 1.0}]})
    mc = monte_carlo(tolerance_job(model, settings), 12, seed=4)
    assert [y["value"] for y in rep["monte_carlo"]["yields"]] == [y["value"] for y in mc.yields]
    assert len(rep["tolerances"]) == 24 + 4  # S6.2 + one tilt per element
    assert {s["name"] for s in rep["sensitivity"]} == {t["name"] for t in rep["tolerances"]}
    for name in ("cdf.png", "histogram.png", "sensitivity.png"):
        assert (out / name).read_bytes()[:8] == PNG_MAGIC
    assert len(rep["worst"]) == 2
    worst = build(load_spec(rep["worst"][0]["path"]))
    assert worst.lens.placement is not None  # the element tilt is in the written lens


def test_tolerance_errors_are_one_line() -> None:
    r = runner.invoke(app, ["tolerance", str(CMOUNT), "--profile", "s6.2", "--metric", "sharpness"])
    assert r.exit_code == 2 and "--metric" in r.output and len(r.output.strip().splitlines()) == 1
    r = runner.invoke(app, ["tolerance", str(CMOUNT)])
    assert r.exit_code == 2 and "--tolerances" in r.output


def test_trace_json_mtf_and_plot_mtf(cooke, tmp_path: Path) -> None:
    r = runner.invoke(app, ["trace", str(COOKE), "--json", "--sampling", "rings:6", "--mtf", "10,40"])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.stdout)["mtf"]
    model = cooke
    ref = lens_mtf(model.lens, model.system, torch.tensor([10.0, 40.0], dtype=torch.float64))
    assert np.allclose(rep["tangential"], ref.tangential.numpy(), rtol=0, atol=1e-12)
    assert np.allclose(rep["sagittal"], ref.sagittal.numpy(), rtol=0, atol=1e-12)
    png = tmp_path / "mtf.png"
    r = runner.invoke(app, ["plot", "mtf", str(COOKE), "-o", str(png), "--points", "9", "--sampling", "rings:8"])
    assert r.exit_code == 0, r.output
    assert png.read_bytes()[:8] == PNG_MAGIC
    r = runner.invoke(app, ["trace", str(COOKE), "--mtf", "ten"])
    assert r.exit_code == 2 and "--mtf" in r.output


def test_tolerance_table_shows_every_sensitivity_row(tmp_path: Path) -> None:
    # Issue 29: the table showed 15 of the 24 rows of S6.2 without a word. Every tolerance has its row,
    # and the title says how many there are.
    r = runner.invoke(app, ["tolerance", str(CMOUNT), "--profile", "s6.2", "--sampling", "rings:3", "--trials", "0"])
    assert r.exit_code == 0, r.output
    rep = json.loads(runner.invoke(app, ["tolerance", str(CMOUNT), "--profile", "s6.2", "--sampling", "rings:3",
                                         "--trials", "0", "--json"]).stdout)
    names = [s["name"] for s in rep["sensitivity"]]
    assert len(names) == 24
    lines = r.stdout.splitlines()
    assert any("all 24 tolerances" in line for line in lines)
    for name in names:  # one row each, in the order of the report (most harmful first)
        assert sum(line.startswith(name + " ") for line in lines) == 1, name
    rows = [line.split()[0] + " " + line.split()[1] for line in lines if line.split()[:2] and
            " ".join(line.split()[:2]) in names]
    assert rows == names
