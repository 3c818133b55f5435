"""Levenberg–Marquardt (S2.3.2, Table S7) on a residual function ℓ(θ) with a forward-mode Jacobian.

Each step solves the damped linear least-squares problem (S63)

    min_δ ‖ℓ + J δ‖² + λ ‖D δ‖²

as an augmented least-squares system through one SVD of the scaled J per Jacobian (``DampedSystem``;
never the normal equations; a rejected step's next λ reuses it), so a rank-deficient J (variables the
merit does not see, or that act alike) gives a finite step instead of NaN. D is the running maximum of
the column norms of J (S64), started from
max(‖J_n‖, ε) (S65). λ is divided by DF after a step that lowers the merit and multiplied by IF
otherwise; a step whose merit exceeds TF times the current one, or that makes the lens non-physical,
is rejected (the Jacobian is reused for the next try).

Parameter evaporation (S2.3.2): besides the running-max D, columns of J whose norm is below
``DEAD_COLUMN`` times the largest one are treated as exactly zero (their step is then exactly 0). Such
columns carry only round-off (a variable the merit does not see, e.g. the radius of a surface between
two identical media); with D at its floor ε even that noise would otherwise drive long random steps.
A column with a non-finite entry is treated the same way; non-finite residuals are refused. λ is
capped at ``MAX_DAMPING`` so that running on past the stopping rules never overflows it.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from lensopt.optim.settings import LMSettings

__all__ = ["Trial", "StepInfo", "LevenbergMarquardt", "DampedSystem", "damped_step"]

MIN_DAMPING = 1e-15
MAX_DAMPING = 1e100
DEAD_COLUMN = 1e-9


@dataclass(frozen=True)
class Trial:
    """What the optimizer needs from one evaluation of ℓ at a trial point."""

    residuals: Tensor
    physical: bool
    reason: str = ""


@dataclass(frozen=True)
class StepInfo:
    """Outcome of one LM iteration."""

    accepted: bool
    merit: float
    damping: float
    reason: str


@contextlib.contextmanager
def threads(n: int) -> Iterator[int]:
    """Run the block on ``n`` intra-op threads (``torch.set_num_threads``); yields the caller's count and
    restores it after."""
    old = torch.get_num_threads()
    if n != old:
        torch.set_num_threads(n)
    try:
        yield old
    finally:
        if n != old:
            torch.set_num_threads(old)


def one_thread() -> contextlib.AbstractContextManager[int]:
    """Run the reductions and the least-squares solve that decide the optimizer's path on one thread;
    yields the caller's thread count (the residual evaluations inside run on it again: ``threads``).

    Multi-threaded BLAS/LAPACK and torch's parallel reductions split sums by thread count, so the same
    problem took different paths with 1 and 2 threads (README, "Determinism"). These are small
    (M × N with N variables), so one thread costs little; the residual evaluations keep all threads.
    """
    return threads(1)


class DampedSystem:
    """The damped least-squares problem (S63) of one (J, ℓ, D), solved for any λ from one SVD.

    In the scaled variables y = D δ the step solves ``[J D⁻¹; √λ I] y = [−ℓ; 0]``. With the thin SVD
    J D⁻¹ = U S Vᵀ (computed once) its solution is y = −V diag(s / (s² + λ)) Uᵀ ℓ for every λ (Moré's
    LM: one factorization per Jacobian, each λ then costs O(N²)), never the normal equations: a
    rank-deficient J (two equal columns) has s = 0 there and gives a finite step (that component 0).
    Zero columns (variables the merit does not see) are left out: their step is exactly 0; so are rows
    with ℓ = 0 and a zero gradient (inactive constraints), which do not change the solution.
    """

    def __init__(self, J: Tensor, r: Tensor, D: Tensor) -> None:
        self.n = J.shape[1]
        # Rows that are 0 with a zero gradient (inactive constraints: a ramp at 0) add nothing to the
        # system; dropping them first makes the factorization cheaper (on the C-mount, 95 % of rows).
        active = (r != 0) | (J != 0).any(1)
        J, r = J[active], r[active]
        self.live = torch.linalg.vector_norm(J, dim=0) > 0
        self.Dl = D[self.live]
        U, self.s, Vh = torch.linalg.svd(J[:, self.live] / self.Dl, full_matrices=False)
        self.V = Vh.mT
        self.u_r = U.mT @ (-r)  # Uᵀ(−ℓ), shared by every λ

    def step(self, damping: float) -> Tensor:
        """(N,) δ minimising ‖ℓ + J δ‖² + λ‖D δ‖² for λ = ``damping``."""
        s = self.s
        f = torch.where(s > 0, s / (s * s + damping), torch.zeros_like(s))
        step = torch.zeros(self.n, dtype=s.dtype, device=s.device)
        step[self.live] = (self.V @ (f * self.u_r)) / self.Dl
        return step


def damped_step(J: Tensor, r: Tensor, D: Tensor, damping: float) -> Tensor:
    """(N,) δ minimising ‖r + J δ‖² + λ‖D δ‖² (S63): ``DampedSystem(J, r, D).step(damping)``."""
    return DampedSystem(J, r, D).step(damping)


class LevenbergMarquardt:
    """LM state machine.

    Args:
        theta: (N,) starting point.
        jacobian: θ ↦ (J (M, N), ℓ (M,)) — the forward-mode Jacobian of the residual function.
        evaluate: θ ↦ Trial — ℓ at a trial point plus the physical check.
        settings: Table S7 parameters and stopping rules.
    """

    def __init__(self, theta: Tensor, jacobian: Callable[[Tensor], tuple[Tensor, Tensor]],
                 evaluate: Callable[[Tensor], Trial], settings: LMSettings | None = None) -> None:
        self.settings = settings or LMSettings()
        self.theta = theta.detach().clone()
        self._jacobian = jacobian
        self._evaluate = evaluate
        self.damping = self.settings.damping
        self.D: Tensor | None = None
        self._J: Tensor | None = None
        self._r: Tensor | None = None
        self._scale_for_D: Tensor | None = None
        self._rows: Tensor | None = None  # rows of J that are not all zero where ℓ is 0 (``_ensure_jacobian``)
        self._J_rows: Tensor | None = None
        self._col: tuple[Tensor, Tensor] | None = None  # (scale, column norms of scale ⊙ J) of this J
        self._system: tuple[Tensor, Tensor, DampedSystem] | None = None  # (scale, D, its system) of this J
        self.history: list[float] = []
        self.accepted = 0
        self.rejected = 0
        self._keep_D = False  # restored with J held: the next J is the one D already saw (``restore``)

    @property
    def residuals(self) -> Tensor | None:
        """ℓ at the current θ (without row multipliers), once computed."""
        return self._r

    def snapshot(self) -> tuple[dict[str, Tensor], dict[str, Any]]:
        """The state that decides the next steps, as (tensors, JSON values), for a checkpoint: θ, λ, D, the
        merit history of the stopping rules, the counts, and whether J at θ is held (after a rejected
        step the next try reuses it, and D has already seen it). ℓ and J are not stored: they are
        functions of θ, evaluated again on ``restore`` to the same bits."""
        tensors = {"theta": self.theta.clone()}
        if self.D is not None:
            tensors["D"] = self.D.clone()
        return tensors, {"damping": self.damping, "history": list(self.history), "accepted": self.accepted,
                         "rejected": self.rejected, "jacobian_held": self._J is not None}

    def restore(self, tensors: dict[str, Tensor], values: dict[str, Any]) -> None:
        """Continue from ``snapshot``'s state: the next step is the one the snapshotted run took next."""
        self.theta = tensors["theta"].to(self.theta).clone()
        self.D = tensors["D"].to(self.theta).clone() if "D" in tensors else None
        self.damping = float(values["damping"])
        self.history = [float(h) for h in values["history"]]
        self.accepted, self.rejected = int(values["accepted"]), int(values["rejected"])
        self._forget_jacobian()
        self._r = None
        self._keep_D = bool(values["jacobian_held"]) and self.D is not None

    def merit(self, scale: Tensor) -> float:
        """½‖s ⊙ ℓ(θ)‖² at the current θ."""
        self._ensure_jacobian(scale)
        with one_thread():
            return 0.5 * float(((scale * self._r) ** 2).sum())

    def _ensure_jacobian(self, scale: Tensor) -> None:
        if self._J is None:
            J, r = self._jacobian(self.theta)
            self._J, self._r = J.detach(), r.detach()
            with one_thread():
                col = torch.linalg.vector_norm(scale[:, None] * self._J, dim=0)
                # The rows ``damped_step`` can use: a row that is 0 with a zero gradient (an inactive
                # constraint) stays so under any row multiplier. The steps work on these rows only
                # (on the aimed studies ≤ 10 % of M), which ``damped_step`` would select anyway.
                self._rows = ((self._r != 0) | (self._J != 0).any(1)).nonzero().squeeze(1)
                self._J_rows = self._J.index_select(0, self._rows)
            col = torch.where(torch.isfinite(col), col, torch.zeros_like(col))
            self._col = (scale.clone(), col)
            s = self.settings
            if self._keep_D:  # this J was held when the run was snapshotted: D has seen it
                self._keep_D = False
            elif self.D is None:
                self.D = col.clamp_min(s.epsilon)
            else:
                self.D = s.beta * torch.maximum(self.D, col) + (1 - s.beta) * col

    def step(self, scale: Tensor) -> StepInfo:
        """One iteration with row multipliers ``scale`` (M,) (1 everywhere for a fixed merit)."""
        self._ensure_jacobian(scale)
        with one_thread() as caller:
            return self._step(scale, caller)

    def _step(self, scale: Tensor, caller_threads: int) -> StepInfo:
        s = self.settings
        r = scale * self._r
        if not bool(torch.isfinite(r).all()):
            return self._reject(float("inf"), "non-finite residuals")
        # A column with a non-finite entry (a derivative that could not be evaluated) counts as dead:
        # that variable does not move in this step. The norms are those of the whole J (all rows, in
        # their order: the same rounding), kept from ``_ensure_jacobian`` while the multipliers hold.
        if self._col is not None and torch.equal(self._col[0], scale):
            col = self._col[1]
        else:
            col = torch.linalg.vector_norm(scale[:, None] * self._J, dim=0)
            col = torch.where(torch.isfinite(col), col, torch.zeros_like(col))
            self._col = (scale.clone(), col)
        merit = 0.5 * float((r**2).sum())
        # One factorization per J, multipliers and D: a rejected step's retry only changes λ.
        if self._system is None or not (torch.equal(self._system[0], scale) and torch.equal(self._system[1], self.D)):
            rows = self._rows
            J = scale.index_select(0, rows)[:, None] * self._J_rows
            J = torch.where(col > DEAD_COLUMN * col.max(), J, torch.zeros_like(J))
            self._system = (scale.clone(), self.D.clone(), DampedSystem(J, r.index_select(0, rows), self.D))
        delta = self._system[2].step(self.damping)
        if not bool(torch.isfinite(delta).all()):
            return self._reject(merit, "non-finite step")
        with threads(caller_threads):
            trial = self._evaluate(self.theta + delta)
        if not trial.physical:
            return self._reject(merit, trial.reason)
        new = 0.5 * float(((scale * trial.residuals) ** 2).sum())
        accept = new < merit if s.tolerance == 1.0 else new <= s.tolerance * merit
        if new < merit:
            self.damping = max(self.damping / s.decrease, MIN_DAMPING)
        else:
            self.damping = min(self.damping * s.increase, MAX_DAMPING)
        if not accept:
            self.rejected += 1
            self.history.append(merit)
            return StepInfo(False, merit, self.damping, "merit rose")
        self.theta = self.theta + delta
        self._forget_jacobian()
        self._r = trial.residuals.detach()
        self.accepted += 1
        self.history.append(new)
        return StepInfo(True, new, self.damping, "")

    def _reject(self, merit: float, reason: str) -> StepInfo:
        self.damping = min(self.damping * self.settings.increase, MAX_DAMPING)
        self.rejected += 1
        self.history.append(merit)
        return StepInfo(False, merit, self.damping, reason)

    def stop_reason(self) -> str | None:
        """Why to stop now (λ ceiling, merit stalled), or None."""
        s = self.settings
        if self.damping > s.max_damping:
            return f"damping λ above {s.max_damping:g}"
        h = self.history
        if len(h) > s.patience and h[-1 - s.patience] > 0:
            if (h[-1 - s.patience] - h[-1]) / h[-1 - s.patience] < s.merit_tolerance:
                return f"merit changed by less than {s.merit_tolerance:g} over {s.patience} steps"
        return None

    def invalidate(self) -> None:
        """Forget ℓ and J at the current θ (the residual function changed, e.g. a new image batch and
        GTRA target): the next step evaluates them again. λ and D are kept."""
        self._forget_jacobian()
        self._r = None
        self._keep_D = False  # a new J: D sees it

    def reset(self) -> None:
        """Back to the initial damping and damping matrix (after binding glasses, S4.1.3)."""
        self.damping = self.settings.damping
        self.D = None
        self._forget_jacobian()
        self.history.clear()

    def _forget_jacobian(self) -> None:
        self._J = self._J_rows = self._rows = self._col = self._system = None
