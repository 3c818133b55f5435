"""``lensopt accuracy`` rows of the designer's analyses (``qa.accuracy_analyses``): every knob is known,
errors fall as the sampling grows (the reference is the same analysis, converged), Seidel has no
sampling error, and the rows come out of ``run_accuracy`` like the others."""

from __future__ import annotations

from lensopt.qa.accuracy import ANALYSES, DEFAULT_KNOBS, KNOBS, METRICS, run_accuracy
from lensopt.qa.accuracy_analyses import ANALYSIS_KNOBS, analysis_points


def test_every_analysis_has_a_knob_and_a_metric() -> None:
    assert set(ANALYSES) == set(ANALYSIS_KNOBS) and set(ANALYSES) <= set(DEFAULT_KNOBS)
    for k, m in ANALYSIS_KNOBS.items():
        assert KNOBS[k] == m and m in METRICS


def test_errors_fall_with_sampling(cooke) -> None:
    # the cheap knobs (the grid knobs trace their reference on 160² pupil points: minutes on a busy machine)
    pts, info = analysis_points(cooke, ["field_curves", "focal_shift", "seidel"], 1, lambda s: None)
    by = {}
    for p in pts:
        by.setdefault(p.knob, []).append(next(iter(p.errors.values())))
        assert p.time_s > 0
    assert by["field_curves"] == sorted(by["field_curves"], reverse=True) and by["field_curves"][-1] < 1e-6
    assert by["focal_shift"] == sorted(by["focal_shift"], reverse=True)
    assert by["seidel"] == [0.0]
    assert info["field_curves"]["reference"] == "1e-05"


def test_rows_come_out_of_run_accuracy(cooke) -> None:
    res = run_accuracy(cooke, knobs=("seidel", "field_curves"), repeats=1)
    d = res.as_json(0.01, None)
    assert {p["knob"] for p in d["points"]} == {"seidel", "field_curves"}
    assert "field" in d["recommendation"] and "analyses" in d["reference"]
