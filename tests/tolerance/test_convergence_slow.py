"""Monte-Carlo convergence on the C-mount with the S6.2 tolerances and the back-focus compensator
(issue 12): the 1000-trial yields lie inside the 100-trial 95 % confidence intervals (order
statistics), and the 1000-trial mean inside the 100-trial mean ± 3 standard errors. Slow (1100
trials); ``make test-slow``. The full study at rings:12 is ``benchmarks/tolerance_cmount.py``."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from lensopt.spec import build, load_spec
from lensopt.spec.tolerance import ToleranceSpec
from lensopt.tolerance.run import monte_carlo
from lensopt.tolerance.setup import make_job

CMOUNT = Path(__file__).resolve().parents[2] / "lenses" / "cmount_4p.json"


@pytest.mark.slow
def test_cmount_s62_monte_carlo_converges() -> None:
    model = build(load_spec(CMOUNT))
    job = make_job(model, ToleranceSpec(profile="s6.2", sampling="rings:6", chunk=50))
    small = monte_carlo(job, 100, seed=1)
    large = monte_carlo(job, 1000, seed=2)  # a different seed: independent draws
    for a, b in zip(small.yields, large.yields, strict=True):
        assert a["ci_low"] <= b["value"] <= a["ci_high"], (a, b)
    se = small.stats["std"] / math.sqrt(100)
    assert abs(large.stats["mean"] - small.stats["mean"]) <= 3 * se
    assert small.stats["compensator_failures"] == 0 and large.stats["trials_with_failed_rays"] == 0
