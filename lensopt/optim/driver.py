"""The optimization driver: phases (glasses free, then bound to the catalog, S4.1.3), the glass
catalog weight schedule, stopping rules, progress reports, Ctrl-C. Library code: no printing; the
CLI renders the ``Progress`` records it receives. It runs a ``Problem``; binding the glasses rebuilds
the problem through a callback (``lensopt.design.optimize`` runs a spec: it builds the problem, binds
through the spec, and writes the result back as a spec)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import torch

from lensopt.accel.jacobian import CompiledJacobian
from lensopt.engine import retain_freed_memory
from lensopt.errors import LensoptError
from lensopt.imaging.metrics import psnr_of_mse
from lensopt.optim.adam import AdamOptimizer
from lensopt.optim.lm import LevenbergMarquardt, Trial
from lensopt.optim.problem import Problem

__all__ = ["Progress", "OptimizeResult", "OptimizeError", "Rebind", "run_problem", "make_optimizer",
           "JACOBIANS"]

JACOBIANS = ("eager", "compiled")


class OptimizeError(LensoptError):
    """The optimization cannot start or go on (e.g. no ray reaches the image)."""


@dataclass(frozen=True)
class Progress:
    """One step, as the live display shows it.

    Attributes:
        step, steps: step number (1-based) and the planned total.
        phase: ``glasses free``, ``glasses bound`` or ``fixed glasses``.
        merit: ½‖ℓ‖² after the step (current weights).
        damping: LM damping λ (NaN for Adam).
        esr_um: effective spot radius of the optimization rays, µm.
        accepted, rejected: step counts so far (this phase).
        last_accepted: whether this step was accepted.
        shares: each residual group's share of the merit.
        valid_fraction: share of optimization rays that reach the image.
        event: a note (binding, rejection reason), or "".
        elapsed_s: wall time since the start.
        image_loss: image loss L of this step's batch (image objectives; NaN otherwise).
        psnr_db: PSNR of this step's batch from L, dB (NaN for spot objectives).
    """

    step: int
    steps: int
    phase: str
    merit: float
    damping: float
    esr_um: float
    accepted: int
    rejected: int
    last_accepted: bool
    shares: dict[str, float]
    valid_fraction: float
    event: str
    elapsed_s: float
    image_loss: float = float("nan")
    psnr_db: float = float("nan")


@dataclass
class OptimizeResult:
    """What an optimization run produced.

    Attributes:
        spec: the optimized lens (values, solves and bound glasses written back) as a ``LensSpec``; set by
            ``lensopt.design.optimize`` (None from ``run_problem``).
        problem: the problem of the last phase; ``theta`` its final variables.
        steps: steps taken; stop_reason: why it stopped; interrupted: Ctrl-C.
        bound: glasses bound to the catalog (what the ``bind`` callback returned).
        history: (step, elapsed s, merit, ESR µm) per step.
        start_esr_um, start_merit: at the start point.
        warning: set when optimization rays still fail at the end (how many, why).
        start_psnr_db, final_psnr_db: held-out PSNR of the image objective before and after (NaN for spot).
        image_history: (step, image loss) per step of an image objective.
    """

    spec: Any
    problem: Problem
    theta: torch.Tensor
    steps: int
    stop_reason: str
    interrupted: bool
    bound: list[Any]
    history: list[tuple[int, float, float, float]] = field(default_factory=list)
    start_esr_um: float = float("nan")
    start_merit: float = float("nan")
    elapsed_s: float = 0.0
    warning: str = ""
    start_psnr_db: float = float("nan")
    final_psnr_db: float = float("nan")
    image_history: list[tuple[int, float]] = field(default_factory=list)


def make_optimizer(problem: Problem, theta: torch.Tensor, method: str,
                   jacobian: str = "eager") -> LevenbergMarquardt | AdamOptimizer:
    """An LM or Adam state machine on ``problem``'s residual function; ``jacobian``: ``eager``
    (``Problem.jacobian``) or ``compiled`` (``CompiledJacobian``, same values; LM only)."""
    if jacobian not in JACOBIANS:
        raise LensoptError(f"must be one of {', '.join(JACOBIANS)}", path="--jacobian", got=jacobian)
    if method == "lm":
        def evaluate(t: torch.Tensor) -> Trial:
            ev = problem.evaluate(t)
            return Trial(ev.residuals, ev.physical, ev.reason)

        jac = problem.jacobian if jacobian == "eager" else CompiledJacobian(problem)
        return LevenbergMarquardt(theta, jac, evaluate, problem.opt.lm)
    if method == "adam":
        return AdamOptimizer(theta, problem.residuals, problem.check, problem.opt.adam)
    raise LensoptError("must be lm or adam", path="--optimizer", got=method)


Rebind = Callable[[Problem, torch.Tensor], tuple[Problem, list[Any]]]
"""Bind the glass variables of θ to the catalog: the problem of the next phase (glasses fixed) and what
was bound."""


def run_problem(problem: Problem, *, optimizer: str | None = None, steps: int | None = None,
                callback: Callable[[Progress], None] | None = None, jacobian: str = "eager",
                bind: Rebind | None = None) -> OptimizeResult:
    """Optimize ``problem`` from its start θ0.

    Ctrl-C (KeyboardInterrupt) ends the run early; the result then holds the best lens so far.
    ``optimizer``: ``lm`` or ``adam`` (default: the settings'); ``steps``: default the settings';
    ``jacobian``: ``eager`` or ``compiled`` (see ``make_optimizer``); ``bind``: how the glasses are bound
    at ``bind_at`` of the run (None: they are not).

    Raises:
        OptimizeError: nothing varies, or the start lens is not usable (the message says why).
    """
    t0 = time.perf_counter()
    if problem.engine.retain_freed_memory:
        retain_freed_memory()  # a process setting, made once (lensopt.engine)
    if jacobian not in JACOBIANS:
        raise LensoptError(f"must be one of {', '.join(JACOBIANS)}", path="--jacobian", got=jacobian)
    opt = problem.opt
    method = optimizer or opt.optimizer
    total = steps if steps is not None else opt.steps
    result, start = _start(problem)
    bind_step = round(opt.bind_at * total) if bind is not None and problem.num_glasses and opt.bind_at < 1 else None
    state = make_optimizer(problem, problem.theta0, method, jacobian)
    phase = "glasses free" if problem.num_glasses else "fixed glasses"
    failing = 1.0 - start.valid_fraction
    event = f"{100 * failing:.1f} % of the rays fail at the start" if failing > 0 else ""
    k = 0
    try:
        while k < total:
            if bind_step is not None and k >= bind_step and not result.bound:
                problem, state, event = _bind(problem, state, result, method, bind, jacobian)
                phase = "glasses bound"
            frac = k / total
            scale = problem.row_scale(frac)
            image_loss = _next_batch(problem, state, k, method)
            info = state.step(scale)
            k += 1
            result.steps = k
            r = state.residuals
            if problem.image is not None:
                esr = 1e3 * problem.spot_esr_mm(state.theta)
                result.image_history.append((k, image_loss))
            else:
                esr = float("nan") if r is None else 1e3 * (problem.esr_mm(r) if "tra" in problem.slices
                                                              else problem.spot_esr_mm(state.theta))
            elapsed = time.perf_counter() - t0
            result.history.append((k, elapsed, info.merit, esr))
            if callback is not None:
                callback(_progress(problem, state, info, scale, k, total, phase, esr, event, elapsed, image_loss))
            event = ""
            flat = problem.schedules_settled(frac)
            reason = state.stop_reason()
            if reason and problem.image is not None and not reason.startswith("damping"):
                reason = None  # each step's merit is on another batch: a stalled merit means nothing
            if reason and (flat or reason.startswith("damping")):
                if bind_step is not None and not result.bound:
                    bind_step = k
                    continue
                result.stop_reason = reason
                break
        else:
            result.stop_reason = f"{total} steps"
        if bind_step is not None and not result.bound and bind_step <= k and not result.interrupted:
            problem, state, _ = _bind(problem, state, result, method, bind, jacobian)
    except KeyboardInterrupt:
        result.interrupted = True
        result.stop_reason = "interrupted"
    _finish(result, problem, state.theta)
    result.elapsed_s = time.perf_counter() - t0
    return result


def _start(problem: Problem) -> tuple[OptimizeResult, Any]:
    """The result of a run that has not stepped yet (start ESR, merit, held-out PSNR) and the start
    evaluation; refuses a problem with nothing to vary or an unusable start lens."""
    if problem.num_variables == 0:
        raise OptimizeError("nothing to optimize: no surface has a vary list", path="surfaces")
    start = problem.evaluate(problem.theta0)
    if not start.physical:
        raise OptimizeError(f"the start lens cannot be optimized: {start.reason}")
    scale0 = problem.row_scale(0.0)
    result = OptimizeResult(spec=None, problem=problem, theta=problem.theta0, steps=0, stop_reason="",
                            interrupted=False, bound=[],
                            start_esr_um=1e3 * (problem.esr_mm(start.residuals) if "tra" in problem.slices
                                                else problem.spot_esr_mm(problem.theta0)),
                            start_merit=0.5 * float(((scale0 * start.residuals) ** 2).sum()))
    if problem.image is not None:
        result.start_esr_um = 1e3 * problem.spot_esr_mm(problem.theta0)
        result.start_psnr_db = problem.image.held_out_psnr(problem.lens(problem.theta0)[0])
    return result, start


def _progress(problem: Problem, state, info, scale: torch.Tensor, k: int, total: int,  # noqa: ANN001
              phase: str, esr: float, event: str, elapsed: float, image_loss: float) -> Progress:
    """The ``Progress`` record of step ``k`` (each group's share of the merit, the valid rays)."""
    r = state.residuals
    merits = problem.merits(r, scale) if r is not None else {}
    tot = sum(merits.values()) or 1.0
    return Progress(k, total, phase, info.merit, state.damping, esr, state.accepted, state.rejected,
                    info.accepted, {n: m / tot for n, m in merits.items()}, _valid_fraction(problem, r),
                    event or info.reason, elapsed, image_loss,
                    psnr_of_mse(image_loss) if image_loss == image_loss else float("nan"))


def _finish(result: OptimizeResult, problem: Problem, theta: torch.Tensor) -> None:
    """The final problem and θ into ``result``, with the held-out PSNR and a warning when rays still fail."""
    result.problem = problem
    result.theta = theta
    if problem.image is not None:
        result.final_psnr_db = problem.image.held_out_psnr(problem.lens(result.theta)[0])
    failed, rays, reasons = problem.failure_summary(result.theta)
    if failed:
        why = ", ".join(f"{k}: {v}" for k, v in reasons.items())
        result.warning = (f"{failed} of {rays} optimization rays still fail ({why}); the start may be too "
                          "far from a working lens: change it, or run more steps")


def _next_batch(problem: Problem, state, k: int, method: str) -> float:  # noqa: ANN001
    """Image objectives: the batch of step ``k``; for LM the GTRA target at the current lens (the
    residual function changes, so the optimizer's cached ℓ and J are dropped). Returns the image loss
    of the batch at the current lens (NaN for spot objectives)."""
    img = problem.image
    if img is None:
        return float("nan")
    img.set_batch(k)
    with torch.no_grad():
        lens, _ = problem.lens(state.theta)
    if method == "lm":
        loss = float(img.update(lens).loss)
    else:
        with torch.no_grad():
            loss = float(img.loss(lens))
    state.invalidate()
    return loss


def _valid_fraction(problem: Problem, r: torch.Tensor | None) -> float:
    """Share of rays that reach the image, from the ray-failure rows (1 when that group is off)."""
    if r is None or "ray_failure" not in problem.slices:
        return float("nan")
    rows = r[problem.slices["ray_failure"]]
    return float((rows == 0).to(r.dtype).mean())


def _bind(problem: Problem, state, result: OptimizeResult, method: str, bind: Rebind,  # noqa: ANN001, ANN202
          jacobian: str = "eager"):
    """Bind glasses to the catalog (``bind`` rebuilds the problem without glass variables), reset the
    optimizer."""
    new, bound = bind(problem, state.theta)
    ev = new.evaluate(new.theta0)
    if not ev.physical:
        raise OptimizeError(f"binding the glasses to the catalog made the lens unusable: {ev.reason}")
    result.bound = bound
    names = ", ".join(b.name for b in bound)
    return new, make_optimizer(new, new.theta0, method, jacobian), f"bound glasses: {names}"
