"""Levenberg–Marquardt (S2.3.2, Table S7): the damped step, the damping matrix, λ adaptation,
rejection, and convergence on a closed-form problem."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from lensopt.optim.lm import DampedSystem, LevenbergMarquardt, Trial, damped_step
from lensopt.optim.settings import LMSettings


def _rosenbrock(theta: torch.Tensor) -> torch.Tensor:
    return torch.stack([10.0 * (theta[1] - theta[0] ** 2), 1.0 - theta[0]])


def _lm(fun, theta0, **settings) -> LevenbergMarquardt:  # noqa: ANN001
    def jac(t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return torch.func.jacfwd(fun)(t), fun(t)

    return LevenbergMarquardt(torch.tensor(theta0, dtype=torch.float64), jac,
                              lambda t: Trial(fun(t), True), LMSettings(**settings))


def test_table_s7_defaults() -> None:
    s = LMSettings()
    assert (s.damping, s.epsilon, s.beta, s.increase, s.decrease, s.tolerance) == (1.0, 1e-6, 0.99, 2.0, 3.0, 1.0)


def test_damped_step_solves_s62() -> None:
    # Full-rank J: the augmented least-squares solution equals −(JᵀJ + λD²)⁻¹Jᵀr (S62).
    rng = np.random.default_rng(0)
    J = rng.normal(size=(7, 3))
    r = rng.normal(size=7)
    D = np.array([0.5, 2.0, 1.0])
    lam = 0.3
    expected = -np.linalg.solve(J.T @ J + lam * np.diag(D**2), J.T @ r)
    got = damped_step(torch.tensor(J), torch.tensor(r), torch.tensor(D), lam)
    np.testing.assert_allclose(got.numpy(), expected, rtol=1e-12)


def test_one_factorization_serves_every_damping() -> None:
    # ``DampedSystem`` factorizes J D⁻¹ once; each λ then gives S62's −(JᵀJ + λD²)⁻¹Jᵀr (closed form).
    rng = np.random.default_rng(1)
    J = rng.normal(size=(40, 5))
    J[:8] = 0.0  # inactive rows (ℓ = 0, zero gradient): left out, same solution
    r = rng.normal(size=40)
    r[:8] = 0.0
    D = np.array([0.5, 2.0, 1.0, 3.0, 0.7])
    system = DampedSystem(torch.tensor(J), torch.tensor(r), torch.tensor(D))
    for lam in (1e-8, 1e-3, 0.3, 10.0, 1e6):
        expected = -np.linalg.solve(J.T @ J + lam * np.diag(D**2), J.T @ r)
        np.testing.assert_allclose(system.step(lam).numpy(), expected, rtol=1e-10, atol=1e-300)


def test_a_rejected_step_reuses_the_factorization(monkeypatch: pytest.MonkeyPatch) -> None:
    # A rejected step keeps J (S7): its retry with a larger λ must not factorize again.
    import lensopt.optim.lm as lm_module

    calls = []
    svd = torch.linalg.svd
    monkeypatch.setattr(lm_module.torch.linalg, "svd", lambda *a, **k: calls.append(1) or svd(*a, **k))
    lm = _lm(_rosenbrock, [-1.2, 1.0], damping=1e-12)  # λ ≈ 0 from far away: the Gauss–Newton step overshoots
    one = torch.ones(2, dtype=torch.float64)
    infos = [lm.step(one) for _ in range(6)]
    assert not infos[0].accepted  # the premise: the first try is rejected
    jacobians = 1 + sum(i.accepted for i in infos[:-1])  # J at θ0, then after each accepted step but the last
    assert len(calls) == jacobians < len(infos)


def test_rank_deficient_jacobian_gives_a_finite_step() -> None:
    # Column 1 is zero, columns 2 and 3 are equal; D as LM builds it (column norms, floor ε) and λ
    # tiny: JᵀJ + λD² is singular to working precision, yet the step is finite, exactly 0 for the
    # unseen variable, and what the merit sees (δ0 and δ2 + δ3) equals the λ → 0 limit, the
    # least-squares solution of minimum ‖Dδ‖ (numpy's pinv of J D⁻¹). How the twins share δ2 + δ3
    # is not determined to better than cond² · eps in a least-squares problem with a residual.
    J = np.array([[1.0, 0.0, 2.0, 2.0], [0.0, 0.0, 1.0, 1.0], [1.0, 0.0, 0.0, 0.0], [0.5, 0.0, 3.0, 3.0]])
    r = np.array([1.0, -2.0, 0.5, 0.3])
    D = np.maximum(np.linalg.norm(J, axis=0), 1e-6)
    expected = -(np.linalg.pinv(J / D) @ r) / D
    for lam in (1e-15, 1e-6, 1.0):
        step = damped_step(torch.tensor(J), torch.tensor(r), torch.tensor(D), lam).numpy()
        assert np.isfinite(step).all()
        assert step[1] == 0.0
        if lam >= 1e-6:  # well conditioned: equal columns, equal damping, equal shares
            assert step[2] == pytest.approx(step[3], rel=1e-6)
        if lam == 1e-15:
            assert step[0] == pytest.approx(expected[0], rel=1e-9)
            assert step[2] + step[3] == pytest.approx(expected[2] + expected[3], rel=1e-9)
            np.testing.assert_allclose(J @ step, J @ expected, rtol=1e-9, atol=1e-12)


def test_converges_on_rosenbrock() -> None:
    # min ½‖(10(y − x²), 1 − x)‖² has its only minimum at (1, 1) with merit 0.
    lm = _lm(_rosenbrock, [-1.2, 1.0])
    one = torch.ones(2, dtype=torch.float64)
    for _ in range(100):
        lm.step(one)
    torch.testing.assert_close(lm.theta, torch.ones(2, dtype=torch.float64), rtol=0, atol=1e-10)
    assert lm.merit(one) < 1e-20
    # Accepted steps never raise the merit (TF = 1).
    accepted = [m for m in lm.history]
    assert all(b <= a for a, b in zip(accepted, accepted[1:], strict=False))


def test_damping_factor_and_running_max_damping_matrix() -> None:
    lm = _lm(_rosenbrock, [-1.2, 1.0])
    one = torch.ones(2, dtype=torch.float64)
    J0 = torch.func.jacfwd(_rosenbrock)(lm.theta)
    info = lm.step(one)
    # S65: D0 = max(‖J_n‖, ε).
    torch.testing.assert_close(lm.D, torch.linalg.vector_norm(J0, dim=0).clamp_min(1e-6))
    assert lm.damping == pytest.approx(1.0 / 3.0 if info.accepted else 2.0)
    D0 = lm.D.clone()
    J1 = torch.func.jacfwd(_rosenbrock)(lm.theta)
    lm.step(one)
    if info.accepted:  # a new Jacobian: S64 with β = 0.99
        d = torch.linalg.vector_norm(J1, dim=0)
        torch.testing.assert_close(lm.D, 0.99 * torch.maximum(D0, d) + 0.01 * d)


def test_non_physical_steps_are_rejected() -> None:
    # Minimum at θ = −1, but θ < 0 is declared non-physical: LM never accepts it, raises λ after each
    # refusal, and ends up close to the boundary from the physical side.
    def fun(t: torch.Tensor) -> torch.Tensor:
        return (t + 1.0) * torch.ones(3, dtype=t.dtype)

    def jac(t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return torch.func.jacfwd(fun)(t).reshape(3, 1), fun(t)

    def evaluate(t: torch.Tensor) -> Trial:
        return Trial(fun(t), bool(t[0] >= 0), "" if t[0] >= 0 else "θ < 0: non-physical")

    lm = LevenbergMarquardt(torch.tensor([2.0], dtype=torch.float64), jac, evaluate, LMSettings(damping=1e-6))
    one = torch.ones(3, dtype=torch.float64)
    first = lm.step(one)
    assert not first.accepted and first.reason == "θ < 0: non-physical"
    assert lm.damping == pytest.approx(2e-6)
    for _ in range(60):
        lm.step(one)
        assert float(lm.theta[0]) >= 0
    assert float(lm.theta[0]) < 0.05
    assert lm.rejected > 0 and lm.accepted > 0


def test_stopping_rules() -> None:
    lm = _lm(_rosenbrock, [-1.2, 1.0], patience=5, merit_tolerance=1e-3)
    one = torch.ones(2, dtype=torch.float64)
    reason = None
    for _ in range(200):
        lm.step(one)
        reason = lm.stop_reason()
        if reason:
            break
    assert reason is not None
    lm.damping = 1e13
    assert lm.stop_reason().startswith("damping")


def test_steps_past_convergence_stay_finite() -> None:
    # Run on after the stopping rules would end it (as a wall-time benchmark does): at the minimum
    # every step is refused and λ grows by IF each time. λ is capped instead of overflowing to inf
    # (√inf · I in the augmented system would make LAPACK refuse it), and θ stays at the minimum.
    lm = _lm(_rosenbrock, [-1.2, 1.0])
    one = torch.ones(2, dtype=torch.float64)
    for _ in range(1200):  # 2^1200 would overflow a float
        info = lm.step(one)
        assert math.isfinite(info.damping) and math.isfinite(info.merit)
    torch.testing.assert_close(lm.theta, torch.tensor([1.0, 1.0], dtype=torch.float64))


def test_a_non_finite_jacobian_column_does_not_move_its_variable() -> None:
    # A NaN derivative (e.g. from a lens on the edge of failing) is not solved with: its variable
    # stays put this step, the other one moves, and everything stays finite.
    def jac(t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        J = torch.func.jacfwd(_rosenbrock)(t)
        J[0, 0] = float("nan")
        return J, _rosenbrock(t)

    lm = LevenbergMarquardt(torch.tensor([-1.2, 1.0], dtype=torch.float64), jac,
                            lambda t: Trial(_rosenbrock(t), True), LMSettings())
    info = lm.step(torch.ones(2, dtype=torch.float64))
    assert info.accepted and math.isfinite(info.merit)
    assert float(lm.theta[0]) == -1.2 and float(lm.theta[1]) != 1.0


def test_steps_on_the_live_rows_equal_the_full_system_bit_for_bit() -> None:
    # LM keeps only the rows of J that are not (ℓ = 0, zero gradient) — inactive ramp constraints —
    # and the column norms of the whole J. Reference: the step written out on the whole (M, N) system
    # (the multipliers, the dead-column rule, ``damped_step``'s own row selection), as LM did before.
    rng = np.random.default_rng(3)
    A = torch.tensor(rng.normal(size=(60, 4)))
    b = torch.tensor(rng.normal(size=60))

    def fun(t: torch.Tensor) -> torch.Tensor:  # half of the rows are ramps that stay inactive near t0
        lin = A @ t + b
        return torch.cat([torch.tanh(lin[:30]), torch.clamp_min(lin[30:] - 50.0, 0.0)])

    lm = _lm(fun, [0.1, -0.2, 0.3, 0.05])
    scales = [torch.ones(60, dtype=torch.float64), torch.linspace(0.5, 2.0, 60, dtype=torch.float64)]
    for k in range(6):
        scale = scales[k % 2]
        theta, D, damping = lm.theta.clone(), None if lm.D is None else lm.D.clone(), lm.damping
        J, r = torch.func.jacfwd(fun)(theta), fun(theta)
        col = torch.linalg.vector_norm(scale[:, None] * J, dim=0)
        s = lm.settings
        D = col.clamp_min(s.epsilon) if D is None else (D if lm._J is not None else  # noqa: SLF001
                                                          s.beta * torch.maximum(D, col) + (1 - s.beta) * col)
        Js, rs = scale[:, None] * J, scale * r
        Js = torch.where(col > 1e-9 * col.max(), Js, torch.zeros_like(Js))
        expected = theta + damped_step(Js, rs, D, damping)
        info = lm.step(scale)
        assert torch.equal(lm.D, D)
        if info.accepted:
            assert torch.equal(lm.theta, expected)
    assert lm.accepted >= 2
