"""Weight schedules of the optimization run: the piecewise exponential schedule (S4.1.3) and the
per-group constraint weights built from it."""

from __future__ import annotations

import pytest

from lensopt.optim.schedule import schedule_weight


def test_piecewise_exponential_schedule() -> None:
    knots = [(0.0, 1e-4), (0.5, 1e-2), (0.8, 1.0)]
    assert schedule_weight(knots, 0.0) == pytest.approx(1e-4)
    assert schedule_weight(knots, 0.25) == pytest.approx(1e-3)  # geometric midpoint
    assert schedule_weight(knots, 0.65) == pytest.approx(1e-1)
    assert schedule_weight(knots, 1.0) == 1.0


def test_group_weight_schedules_scale_their_rows(make_cooke) -> None:  # noqa: ANN001
    from lensopt.design import build_problem
    from lensopt.spec import parse_spec

    data = make_cooke(constraints={"ray_angle": {"weight": 2.0, "schedule": [[0.5, 0.01], [0.75, 1.0]]}})
    data["surfaces"][0]["vary"] = ["radius"]
    p = build_problem(parse_spec(data))
    rows = p.slices["ray_angle"]
    assert float(p.row_scale(0.2)[rows][0]) == pytest.approx(0.01)
    assert float(p.row_scale(0.625)[rows][0]) == pytest.approx(0.1)  # geometric midpoint
    assert float(p.row_scale(0.9)[rows][0]) == 1.0
    assert float(p.row_scale(0.2)[p.slices["tra"]].max()) == 1.0
    assert not p.schedules_settled(0.6) and p.schedules_settled(0.8)
