"""PSNR before and after restoration as a tolerance metric (issue 12, ``metric = "psnr"``, ``--irm``).

- The nominal trial's PSNR (pre- and post-restoration) equals ``lensopt evaluate`` (``--irm``) on the same
  scenes: the compensators act relative to the nominal lens, so the nominal is imaged as designed.
- A defocus (the back focal distance changed, no compensator) lowers the PSNR, more for a larger error.
- Higher is better: the yield table, the worst trials and the CDF plot turn around.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from lensopt.cli.app import app
from lensopt.design.tolerance import tolerance_job
from lensopt.errors import LensoptError
from lensopt.spec.tolerance import ToleranceSpec
from lensopt.tolerance.job import run_trials
from lensopt.tolerance.monte_carlo import monte_carlo, yield_table
from tests.helpers import cooke_data

runner = CliRunner()
TINY_RESTORE = {"width": 4, "encoder_blocks": [1, 1], "middle_blocks": 1, "decoder_blocks": [1, 1],
                "train": {"batch": 2, "patch": 32, "steps": 1, "checkpoint_every": 1, "validate_every": 1,
                          "validation_patches": 2}}
IMAGING = {"psnr_count": 2, "psnr_patch": 32, "psnr_sampling": "rings:4", "seed": 3}


@pytest.fixture
def tiny_lens(tmp_path: Path) -> Path:
    """The Cooke triplet on a 640 × 480 sensor with a tiny restoration network section."""
    data = cooke_data()
    data["sensor"]["resolution"] = [640, 480]
    data["restore"] = TINY_RESTORE
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(data), encoding="utf-8")
    return path


def test_nominal_psnr_equals_evaluate_and_yield_is_higher_better(tiny_lens: Path, tmp_path: Path) -> None:
    ck = tmp_path / "ck"
    r = runner.invoke(app, ["train-irm", str(tiny_lens), "-o", str(ck), "--fields", "3", "--psf-size", "9",
                            "--sampling", "rings:4", "--steps", "1", "--json"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["evaluate", str(tiny_lens), "--count", "2", "--patch", "32", "--rays", "rings:4",
                            "--seed", "3", "--irm", str(ck), "--json"])
    assert r.exit_code == 0, r.output
    ev = json.loads(r.stdout)
    tol = tmp_path / "tol.toml"
    tol.write_text("[tolerance]\nprofile = \"s6.2\"\ntrials = 5\nsampling = \"rings:4\"\ncompensator = \"focus\"\n"
                   + "".join(f"{k} = {json.dumps(v)}\n" for k, v in IMAGING.items()))
    out = tmp_path / "out"
    r = runner.invoke(app, ["tolerance", str(tiny_lens), "--tolerances", str(tol), "--irm", str(ck),
                            "--scheduler", "serial", "--no-sensitivity", "--json", "-o", str(out), "--worst", "1"])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.stdout)
    assert rep["metric"] == "psnr" and rep["unit"] == "dB" and rep["higher_is_better"] is True
    assert rep["nominal"]["focus_shift_mm"] != 0.0  # the compensator moved the nominal plane for the ESR...
    # ...but the nominal is imaged as designed: the same numbers as lensopt evaluate.
    assert rep["nominal"]["psnr_pre_db"] == pytest.approx(ev["psnr_db"], abs=1e-9)
    assert rep["nominal"]["psnr_post_db"] == pytest.approx(ev["after_restoration"]["psnr_db"], abs=1e-9)
    assert rep["nominal"]["value"] == rep["nominal"]["psnr_post_db"]
    assert ev["after_restoration"]["psnr_db"] != ev["psnr_db"]  # the network really ran
    mc = rep["monte_carlo"]
    assert set(mc["metrics"]) >= {"psnr_pre", "psnr_post"}
    values = [y["value"] for y in mc["yields"]]  # levels 50, 80, 90, 95, 99 %: lower PSNR for more lenses
    assert values == sorted(values, reverse=True)
    assert rep["worst"][0]["value"] == pytest.approx(mc["stats"]["min"])
    assert (out / "cdf.png").exists()


def _with(settings: ToleranceSpec, **kw) -> ToleranceSpec:
    return ToleranceSpec.model_validate({**settings.model_dump(), **kw})


def test_defocus_lowers_psnr_and_errors(cooke) -> None:
    model = cooke
    last = len(model.spec.surfaces) - 1
    settings = ToleranceSpec.model_validate({"items": [{"kind": "thickness", "limit": 0.2, "surfaces": [last]}],
                                             "compensator": "none", "metric": "psnr", **IMAGING})
    job = tolerance_job(model, settings)
    out = run_trials(job, torch.tensor([[0.0], [0.1], [0.3]], dtype=torch.float64))
    pre = out["psnr_pre"]
    assert "psnr_post" not in out
    assert pre[0] > pre[1] > pre[2], pre
    # With the focus compensator the same error is focused away: back to (nearly) the nominal PSNR.
    job_f = tolerance_job(model, _with(settings, compensator="focus"))
    refocused = run_trials(job_f, torch.tensor([[0.3]], dtype=torch.float64))["psnr_pre"][0]
    assert abs(refocused - pre[0]) < 0.1 * (pre[0] - pre[2])
    # Higher is better: the worst trials are the lowest PSNRs, the yield levels go down.
    mc = monte_carlo(job, 4, 0)
    assert mc.worst(1) == [int(np.argmin(mc.scalar))]
    rows = yield_table(mc.scalar, higher_is_better=True)
    assert rows[0]["value"] >= rows[-1]["value"]
    with pytest.raises(LensoptError, match="tolerance.metric"):
        tolerance_job(model, _with(settings, items=[{"kind": "decenter_y", "limit": 0.01}]))
    with pytest.raises(LensoptError, match="tolerance.psnr_patch"):  # larger than the 4000 × 3000 sensor
        tolerance_job(model, _with(settings, psnr_patch=4096))
    with pytest.raises(LensoptError, match="tolerance.psnr_sampling"):
        tolerance_job(model, _with(settings, psnr_sampling="rings:x"))
    with pytest.raises(LensoptError, match="--irm"):
        tolerance_job(model, _with(settings, metric="esr"), restore=lambda c, i: c)


def test_rss_prediction_turns_around_for_higher_is_better() -> None:
    from lensopt.tolerance.model import Tolerance
    from lensopt.tolerance.sensitivity import SensitivityRow, rss_prediction

    # One uniform tolerance on [−1, 1] with Δ(x) = 0.5 x: σ = 0.5 / √3; worst |Δ| = 0.5.
    row = SensitivityRow("t", "thickness", 1.0, -0.5, 0.5, 0.0, 0.0, 0.5, 0.0, 1.0, 0)
    tols = (Tolerance("thickness", 0, 1.0, "uniform", "t"),)
    z90 = 1.2815515655446004  # Φ⁻¹(0.9)
    low = rss_prediction([row], tols, 10.0)
    high = rss_prediction([row], tols, 10.0, higher_is_better=True)
    assert low["std"] == pytest.approx(0.5 / 3**0.5) and high["std"] == low["std"]
    assert low["p90"] == pytest.approx(10.0 + z90 * 0.5 / 3**0.5)
    assert high["p90"] == pytest.approx(10.0 - z90 * 0.5 / 3**0.5)
    assert (low["rss_worst"], high["rss_worst"]) == pytest.approx((10.5, 9.5))
