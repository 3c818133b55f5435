"""The reporting default ``gauss:16`` (issue 29) on every shipped lens: the effective spot radius that
``lensopt trace`` reports is within 0.1 % of the converged pupil integral, and closer to it than the old
default ``rings:24`` (the table in benchmarks/README.md, "Reporting default on every shipped lens").

Reference: ``qa.accuracy.spot_reference``, a Gauss–Legendre × midpoint quadrature doubled until two
successive ESRs agree to 1e-9; tests/analysis/test_spot_weights.py checks that quadrature against an
independent dense equal-weight grid (grid:151).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from lensopt.analysis.report import trace_report
from lensopt.engine import Engine
from lensopt.optics.sampling import PupilSampling
from lensopt.qa.accuracy import spot_reference
from lensopt.spec import build, load_spec

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = sorted(p for p in (ROOT / "lenses").glob("*.json") if p.name != "check_baseline.json")


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_gauss16_esr_within_0p1_percent_of_the_converged_integral(path: Path) -> None:
    model = build(load_spec(path))
    engine = Engine()  # eager
    ref = spot_reference(model, engine=engine)
    assert ref["converged"], ref
    esr = {s: trace_report(model, PupilSampling.parse(s, weighted=True), engine=engine)["effective_spot_radius_um"]
           for s in ("gauss:16", "rings:24")}
    err = {s: abs(v - ref["esr_um"]) / ref["esr_um"] for s, v in esr.items()}
    assert err["gauss:16"] <= 1e-3, err
    assert err["gauss:16"] < err["rings:24"], err
