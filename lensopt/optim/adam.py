"""Adam (S2.3.1; ``torch.optim.Adam``) on L = ½‖s ⊙ ℓ(θ)‖² from the same residual function as LM,
with its gradient Jᵀℓ (S59) by reverse-mode autodiff. For comparison with LM.

A step that makes the lens non-physical (or the merit non-finite) is undone and counted as rejected;
the moments are kept and the learning rate halved. The merit reported for a step is that of the point
where the gradient was taken.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from torch import Tensor

from lensopt.optim.lm import StepInfo
from lensopt.optim.settings import AdamSettings

__all__ = ["AdamOptimizer"]


class AdamOptimizer:
    """Adam state machine with the same interface as ``LevenbergMarquardt``.

    One step costs one forward and one backward pass: the physical check of the new point happens
    at the start of the next step, which undoes the update when it fails.

    Args:
        theta: (N,) starting point.
        residuals: θ ↦ ℓ(θ) (M,), differentiable.
        check: θ ↦ "" when the lens is physical, else the reason (no ray trace needed).
    """

    def __init__(self, theta: Tensor, residuals: Callable[[Tensor], Tensor],
                 check: Callable[[Tensor], str], settings: AdamSettings | None = None) -> None:
        self.settings = settings or AdamSettings()
        self._residuals = residuals
        self._check = check
        self._param = theta.detach().clone().requires_grad_(True)
        self._previous: Tensor | None = None
        self._make()
        self.history: list[float] = []
        self.accepted = 0
        self.rejected = 0
        self.damping = float("nan")
        self._r: Tensor | None = None
        self._best: tuple[float, Tensor] | None = None

    def _make(self) -> None:
        s = self.settings
        self._opt = torch.optim.Adam([self._param], lr=s.lr, betas=(s.beta1, s.beta2))

    @property
    def theta(self) -> Tensor:
        """The last point whose merit was evaluated (the newest update is checked at the next step)."""
        if self._previous is not None:
            return self._previous.clone()
        return self._param.detach().clone()

    @property
    def residuals(self) -> Tensor | None:
        return self._r

    def merit(self, scale: Tensor) -> float:
        with torch.no_grad():
            r = self._residuals(self.theta)
        self._r = r
        return 0.5 * float(((scale * r) ** 2).sum())

    def step(self, scale: Tensor) -> StepInfo:
        reason = self._check(self._param.detach())
        if not reason:
            self._opt.zero_grad(set_to_none=True)
            r = self._residuals(self._param)
            loss = 0.5 * ((scale * r) ** 2).sum()
            if not bool(torch.isfinite(loss)):
                reason = "non-finite merit"
        if reason:
            if self._previous is not None:
                with torch.no_grad():
                    self._param.copy_(self._previous)
            for group in self._opt.param_groups:
                group["lr"] *= 0.5  # the same update would come back
            self.rejected += 1
            merit = self.history[-1] if self.history else float("nan")
            return StepInfo(False, merit, self.damping, reason)
        loss.backward()
        merit = float(loss.detach())
        self._r = r.detach()
        self._previous = self._param.detach().clone()
        if self._param.grad is not None:
            self._param.grad = torch.nan_to_num(self._param.grad, nan=0.0, posinf=0.0, neginf=0.0)
        self._opt.step()
        self.accepted += 1
        self.history.append(merit)
        return StepInfo(True, merit, self.damping, "")

    def snapshot(self) -> tuple[dict[str, Tensor], dict[str, Any]]:
        """The state that decides the next steps, as (tensors, JSON values), for a checkpoint: the point,
        the last checked point, Adam's moments and step counts, the learning rate (halved by rejections),
        the merit history and counts."""
        tensors = {"param": self._param.detach().clone()}
        if self._previous is not None:
            tensors["previous"] = self._previous.clone()
        moments: dict[str, Any] = {}
        for k, v in self._opt.state_dict()["state"].get(0, {}).items():
            if isinstance(v, Tensor):
                tensors[f"adam.{k}"] = v.clone()
            else:
                moments[k] = v
        return tensors, {"lr": [g["lr"] for g in self._opt.param_groups], "scalars": moments,
                         "history": list(self.history), "accepted": self.accepted, "rejected": self.rejected}

    def restore(self, tensors: dict[str, Tensor], values: dict[str, Any]) -> None:
        """Continue from ``snapshot``'s state."""
        like = self._param.detach()
        with torch.no_grad():
            self._param.copy_(tensors["param"].to(like))
        self._previous = tensors["previous"].to(like).clone() if "previous" in tensors else None
        state = {k[5:]: v.to(like.device) for k, v in tensors.items() if k.startswith("adam.")}
        state.update(values["scalars"])
        sd = self._opt.state_dict()
        sd["state"] = {0: state} if state else {}
        for group, lr in zip(sd["param_groups"], values["lr"], strict=True):
            group["lr"] = lr
        self._opt.load_state_dict(sd)
        self.history = [float(h) for h in values["history"]]
        self.accepted, self.rejected = int(values["accepted"]), int(values["rejected"])

    def stop_reason(self) -> str | None:
        return None

    def invalidate(self) -> None:
        """Nothing cached: every step evaluates ℓ afresh."""

    def reset(self) -> None:
        self._make()
        self.history.clear()
