"""``lensopt accuracy``: the converged spot reference, errors, Pareto front, recommendation, plot and
bad input.

Independent oracles:
- the quadrature reference is checked against a different scheme, a dense ``grid:N`` of equal-area
  cells (its own error ~1e-4 relative), and against ``spot_stats`` for equal weights (same definition);
- the quadrature itself on disc moments with closed forms (area π/2 of the half disc, mean r² = 1/2,
  mean y⁴ = 1/8);
- Pareto front and recommendation on hand-made points.
"""

from __future__ import annotations

import json
import math

import pytest
import torch
from typer.testing import CliRunner

from lensopt.analysis.spot import spot_stats
from lensopt.cli.app import app
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.qa.accuracy import (
    Point,
    _quadrature,
    pareto,
    recommend,
    spot_reference,
    weighted_spot,
)
from tests.helpers import COOKE

runner = CliRunner()


def test_quadrature_integrates_the_half_disc_exactly() -> None:
    pts, w = _quadrature(8, 16)
    assert float(w.sum()) == pytest.approx(math.pi / 2, rel=1e-14)  # area of the half disc
    r2 = (pts**2).sum(-1)
    assert float((w * r2).sum() / w.sum()) == pytest.approx(0.5, rel=1e-14)  # mean r² over the disc
    assert float((w * pts[:, 1] ** 4).sum() / w.sum()) == pytest.approx(1 / 8, rel=1e-13)  # mean y⁴ = 1/8
    assert bool((pts[:, 0] >= 0).all())


def test_weighted_spot_with_equal_weights_is_spot_stats(cooke) -> None:
    pts = PupilSampling.parse("rings:8").points(dtype=torch.float64)
    b = trace_bundle(cooke.lens, cooke.system, pts, half_pupil=True)
    esr, rms = weighted_spot(b, torch.ones(pts.shape[0], dtype=torch.float64), cooke.system.wavelength_weights)
    s = spot_stats(b, cooke.system.wavelength_weights)
    assert float(esr) == pytest.approx(float(s.effective_radius), rel=1e-13)
    assert torch.allclose(rms, s.rms_radius, rtol=1e-13)


def test_spot_reference_converges_to_1e9_and_agrees_with_a_dense_grid(cooke) -> None:
    ref = spot_reference(cooke)
    assert ref["converged"] and ref["agreement"] <= 1e-9 and ref["failed_rays"] == 0
    b = trace_bundle(cooke.lens, cooke.system, PupilSampling.parse("grid:160").points(dtype=torch.float64))
    grid_esr = 1e3 * float(spot_stats(b, cooke.system.wavelength_weights).effective_radius)
    assert grid_esr == pytest.approx(ref["esr_um"], rel=3e-4)


def test_pareto_and_recommendation_on_hand_made_points() -> None:
    pts = [Point("a", "a1", {"esr": 0.1}, 1.0), Point("a", "a2", {"esr": 0.005}, 3.0),
           Point("b", "b1", {"esr": 0.2}, 2.0), Point("b", "b2", {"esr": 0.008}, 2.5),
           Point("c", "c1", {"psf": 0.01}, 0.1)]
    assert [p.setting for p in pareto(pts, "esr")] == ["a1", "b2", "a2"]
    r = recommend(pts, "esr", 0.01, 2.2)
    assert r["cheapest"]["setting"] == "b2" and r["budget_buys"]["setting"] == "a1"
    r = recommend(pts, "esr", 0.001, None)
    assert r["cheapest"] is None and "a2" in r["why_not"]


def test_cli_json_table_plot(tmp_path) -> None:
    out = tmp_path / "acc.png"
    r = runner.invoke(app, ["accuracy", str(COOKE), "--knobs", "grid,aim_steps", "--repeats", "1", "--json",
                            "--target", "1%", "--budget", "0.05", "-o", str(out)])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    assert {p["knob"] for p in d["points"]} == {"grid", "aim_steps"}
    grid = {p["setting"]: p["errors"]["esr"] for p in d["points"] if p["knob"] == "grid"}
    assert grid["grid:96"] < 1e-3 < grid["grid:8"]  # the error falls with sampling
    aim = [p["errors"]["aim"] for p in d["points"] if p["knob"] == "aim_steps"]
    assert aim[-1] < 1e-10  # 4 Newton steps have converged to the 12-step answer
    rec = d["recommendation"]["esr"]
    assert rec["target"] == 0.01 and rec["cheapest"]["errors"]["esr"] <= 0.01
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("args", [["--knobs", "rings,bogus"], ["--target", "0"], ["--target", "-1%"],
                                  ["--target", "abc"], ["--budget", "0"]])
def test_bad_input_is_one_line_exit_2(args) -> None:
    r = runner.invoke(app, ["accuracy", str(COOKE), *args])
    assert r.exit_code == 2, r.output
    assert len(r.output.strip().splitlines()) == 1 and r.output.startswith("error:")
