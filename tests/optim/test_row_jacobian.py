"""``optim.row_jacobian``: the Jacobian with inactive ramp rows skipped equals eager ``jacfwd``
(``Problem.jacobian``, itself checked against reverse mode and differences in test_jacobian.py) bit for
bit, including a row whose constraint sits exactly on its bound (value 0, non-zero derivative) and a θ
where rays fail."""

from __future__ import annotations

import torch

from lensopt.design import build_problem
from lensopt.optim import Problem
from lensopt.optim.residuals import gap_lengths
from lensopt.optim.row_jacobian import row_jacobian
from lensopt.spec import parse_spec


def _problem(make_cooke, **constraints) -> Problem:  # noqa: ANN001
    cons = {"ray_failure": {"penalty_mm": 2.0}, "ray_angle": {"max_deg": 12.0},
            "surface_normal": {"max_deg": 14.0}, **constraints}
    data = make_cooke(constraints=cons)
    for s in (0, 2, 4):
        data["surfaces"][s]["vary"] = ["radius", "thickness"]
    data["system"]["field"]["relative"] = [0.0, 1.0]
    return build_problem(parse_spec(data))


def _assert_same(p: Problem, theta: torch.Tensor) -> None:
    J0, r0 = p.jacobian(theta)
    J, r = row_jacobian(p, theta)
    assert torch.equal(r, r0)
    assert torch.equal(J, J0)


def test_equals_jacfwd_bit_for_bit(make_cooke) -> None:  # noqa: ANN001
    p = _problem(make_cooke, ray_path={"glass_min": 1.0, "glass_ratio": 2.0, "air_min": 4.0,
                                       "spans": [{"first": 1, "to": 3, "min": 6.0}]})
    J0, r0 = p.jacobian(p.theta0)
    for group in ("ray_path", "ray_angle", "surface_normal"):  # both kinds of rows are exercised
        rows = J0[p.slices[group]]
        live = (rows != 0).any(1)
        assert 0 < int(live.sum()) < rows.shape[0], group
    _assert_same(p, p.theta0)
    theta = p.theta0.clone()
    theta[0] *= 3.0  # marginal rays fail: their rows are masked, the failure rows come alive
    assert p.failure_summary(theta)[0] > 0
    _assert_same(p, theta)


def test_a_constraint_exactly_on_its_bound_keeps_its_derivative(make_cooke) -> None:  # noqa: ANN001
    p = _problem(make_cooke)
    with torch.no_grad():
        lens, _ = p.lens(p.theta0)
        tz = gap_lengths(p.bundle(lens))[1].reshape(-1)  # the air gap after the first element
    bound = float(tz[7])  # one ray travels exactly this far: ramp(bound − t_z) = 0 with slope −∂t_z/∂θ
    p = _problem(make_cooke, ray_path={"gaps": [{"gap": 1, "min": bound}]})
    J0, r0 = p.jacobian(p.theta0)
    n_r = tz.numel()
    row = p.slices["ray_path"].start + 1 * n_r + 7
    assert float(r0[row]) == 0.0 and bool((J0[row] != 0).any())
    _assert_same(p, p.theta0)
