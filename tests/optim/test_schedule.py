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


def test_full_weight_is_the_end_of_the_schedules_from_the_first_step(make_cooke) -> None:  # noqa: ANN001
    """``--full-weight`` (continuing a written lens): at step 0 every row carries the weight the scheduled run
    ends on. A schedule ending below 1 (here 0.5) keeps that factor; TRA's own schedule too."""
    import torch

    from lensopt.design import build_problem
    from lensopt.spec import parse_spec

    data = make_cooke(constraints={"ray_angle": {"weight": 2.0, "max_deg": 3.0,
                                                 "schedule": [[0.5, 0.01], [0.75, 0.5]]}})
    data["optimize"]["tra"] = {"weight": 1.0, "schedule": [[0.0, 0.1], [0.5, 3.0]]}
    data["surfaces"][0]["vary"] = ["radius"]
    spec = parse_spec(data)
    full = spec.model_copy(update={"optimize": spec.optimize.at_full_weight()})
    assert full.optimize.constraints.ray_angle.schedule is None and full.optimize.tra.schedule is None
    assert full.optimize.constraints.ray_angle.weight == pytest.approx(1.0)  # 2 × 0.5
    assert full.optimize.tra.weight == pytest.approx(3.0)
    assert spec.optimize.constraints.ray_angle.schedule is not None  # the original is untouched
    assert full.optimize.constraints.glass_catalog.schedule == spec.optimize.constraints.glass_catalog.schedule

    p, q = build_problem(spec), build_problem(full)
    theta = p.theta0
    rows = p.slices["ray_angle"]
    end = p.residuals(theta) * p.row_scale(1.0)
    start_full = q.residuals(theta) * q.row_scale(0.0)
    assert float(end[rows].abs().max()) > 0  # the angle limit is active: the rows are not trivially equal
    torch.testing.assert_close(start_full, end, rtol=1e-13, atol=0)
    assert q.schedules_settled(0.0)


def test_optimize_full_weight_starts_at_the_settled_merit_and_writes_the_schedules_back(make_cooke, tmp_path) -> None:  # noqa: ANN001, E501
    import json

    from typer.testing import CliRunner

    from lensopt.cli.app import app
    from lensopt.design import build_problem, optimize
    from lensopt.spec import load_spec, parse_spec, save_json

    data = make_cooke(constraints={"ray_angle": {"weight": 2.0, "max_deg": 3.0,
                                                 "schedule": [[0.5, 0.01], [0.75, 1.0]]}})
    data["surfaces"][0]["vary"] = ["radius"]
    spec = parse_spec(data)
    p = build_problem(spec)
    settled = 0.5 * float(((p.row_scale(1.0) * p.residuals(p.theta0)) ** 2).sum())
    gentle = 0.5 * float(((p.row_scale(0.0) * p.residuals(p.theta0)) ** 2).sum())
    assert settled > 1.5 * gentle  # the angle rows weigh: the two starts differ
    assert optimize(spec, steps=1, full_weight=True).start_merit == pytest.approx(settled, rel=1e-12)
    assert optimize(spec, steps=1).start_merit == pytest.approx(gentle, rel=1e-12)

    start, out = tmp_path / "start.json", tmp_path / "lens.json"
    save_json(spec, start)
    r = CliRunner().invoke(app, ["optimize", str(start), "-o", str(out), "--steps", "2", "--full-weight", "--json",
                                 "--allow-violations", "-q"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["steps"] == 2
    written = load_spec(out).optimize
    assert written.constraints.ray_angle.schedule == [(0.5, 0.01), (0.75, 1.0)]
    assert written.constraints.ray_angle.weight == 2.0


def test_full_weight_on_a_restored_spec_is_one_line_and_exit_2(tmp_path) -> None:  # noqa: ANN001
    from pathlib import Path

    from typer.testing import CliRunner

    from lensopt.cli.app import app

    out = tmp_path / "lens.json"
    spec = Path(__file__).resolve().parents[2] / "specs" / "cmount_4p_restored.toml"
    r = CliRunner().invoke(app, ["optimize", str(spec), "-o", str(out), "--full-weight", "-q"])
    assert r.exit_code == 2 and "--full-weight" in r.output and len(r.output.strip().splitlines()) == 1
    assert not out.exists()
