"""Work skipped because it cannot contribute: the failure-margin walk when no ray failed, and the
inactive constraint rows before the LM solve. Oracles: the full computation (the walk forced on)
and the closed-form damped step (S62)."""

from __future__ import annotations

import numpy as np
import torch

from lensopt.design import build_problem
from lensopt.optim import residuals as terms
from lensopt.optim.lm import damped_step
from lensopt.spec import parse_spec


def test_failure_rows_without_the_walk_equal_the_walk(make_cooke, monkeypatch) -> None:  # noqa: ANN001
    data = make_cooke(constraints={"ray_failure": {"penalty_mm": 2.0}})
    data["surfaces"][0]["vary"] = ["radius"]
    data["surfaces"][2]["vary"] = ["radius"]
    p = build_problem(parse_spec(data))
    assert p.failure_summary(p.theta0)[0] == 0  # the Cooke triplet passes every ray
    calls = []
    real_margin = terms.failure_margin
    monkeypatch.setattr(terms, "failure_margin", lambda *a: calls.append(1) or real_margin(*a))
    J_skip, r_skip = p.jacobian(p.theta0)
    assert not calls  # skipped
    monkeypatch.setattr(terms, "_tracing", lambda: True)  # as in a captured graph: the walk runs
    J_walk, r_walk = p.jacobian(p.theta0)
    assert calls
    assert torch.equal(r_skip, r_walk) and torch.equal(J_skip, J_walk)


def test_inactive_rows_do_not_change_the_damped_step() -> None:
    # J with 5 active rows and 40 inactive ones (ℓ = 0, zero gradient): the step equals the closed
    # form −(JᵀJ + λD²)⁻¹Jᵀr of the active rows (S62), which is also that of all rows.
    rng = np.random.default_rng(1)
    J = np.zeros((45, 3))
    r = np.zeros(45)
    rows = rng.choice(45, 5, replace=False)
    J[rows] = rng.normal(size=(5, 3))
    r[rows] = rng.normal(size=5)
    J[rows[0]] = 0.0  # an active row with a zero gradient (a constant residual) stays
    D, lam = np.array([1.0, 0.5, 2.0]), 0.2
    expected = -np.linalg.solve(J.T @ J + lam * np.diag(D**2), J.T @ r)
    got = damped_step(torch.tensor(J), torch.tensor(r), torch.tensor(D), lam)
    np.testing.assert_allclose(got.numpy(), expected, rtol=1e-12)
