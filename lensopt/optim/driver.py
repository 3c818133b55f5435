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

__all__ = ["Progress", "OptimizeResult", "OptimizeError", "Rebind", "RunState", "run_problem", "make_optimizer",
           "JACOBIANS"]

JACOBIANS = ("eager", "compiled")

MIN_PHASE_STEPS = 10
"""Fewest steps a phase (glasses free, glasses bound) may get: a run too short for that is refused
(``run_problem``) instead of binding glasses that have barely moved."""


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


@dataclass
class RunState:
    """Where a run stands after a completed step: what ``run_problem(resume=...)`` needs to continue it
    so that the rest is bit for bit the uninterrupted run's. Nothing random is left to restore: ray
    samplings are drawn from the spec's seed when the problem is built, image batches and their noise
    from (seed, step).

    Attributes:
        step, total: completed steps and the planned total.
        method: ``lm`` or ``adam``.
        bind_step: the step at which the glasses are (or were) bound; None: never.
        theta_at_bind: θ of the glasses-free problem when they were bound (binding again from it gives the
            same catalog glasses and the same bound problem); None while they are free.
        optimizer: the optimizer's ``snapshot()`` (tensors, JSON values).
        phase: the phase's name; history, image_history, start_*: the result's so far.
        elapsed_s: wall time of the run so far (earlier sessions included).
        final: the run has ended (finished, stopped or interrupted).
    """

    step: int
    total: int
    method: str
    bind_step: int | None
    theta_at_bind: torch.Tensor | None
    optimizer: tuple[dict[str, torch.Tensor], dict[str, Any]]
    phase: str
    history: list[tuple[int, float, float, float]]
    image_history: list[tuple[int, float]]
    start_esr_um: float
    start_merit: float
    start_psnr_db: float
    elapsed_s: float
    final: bool = False


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
                bind: Rebind | None = None, resume: RunState | None = None,
                on_state: Callable[[RunState], None] | None = None) -> OptimizeResult:
    """Optimize ``problem`` from its start θ0.

    Ctrl-C (KeyboardInterrupt) ends the run early; the result then holds the best lens so far.
    ``optimizer``: ``lm`` or ``adam`` (default: the settings'); ``steps``: default the settings';
    ``jacobian``: ``eager`` or ``compiled`` (see ``make_optimizer``); ``bind``: how the glasses are bound
    at ``bind_at`` of the run (None: they are not). ``on_state`` sees the ``RunState`` after every
    completed step and once more at the end (``final``: after an interrupt it is the last completed
    step's); ``resume`` continues from such a state (same problem, optimizer and steps).

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
    if bind_step is not None:
        _check_phases(total, bind_step, opt.bind_at, "--steps" if steps is not None else "optimize.steps")
    state = make_optimizer(problem, problem.theta0, method, jacobian)
    phase = "glasses free" if problem.num_glasses else "fixed glasses"
    failing = 1.0 - start.valid_fraction
    event = f"{100 * failing:.1f} % of the rays fail at the start" if failing > 0 else ""
    k = 0
    theta_at_bind: torch.Tensor | None = None
    before = 0.0  # wall time of the earlier sessions of a resumed run
    if resume is not None:
        if (resume.method, resume.total) != (method, total):
            raise OptimizeError(f"the run to resume used {resume.method} for {resume.total} steps, this one "
                                f"{method} for {total}: resume with the same settings")
        k, bind_step, before = resume.step, resume.bind_step, resume.elapsed_s
        result.history, result.image_history = list(resume.history), list(resume.image_history)
        result.start_esr_um, result.start_merit = resume.start_esr_um, resume.start_merit
        result.start_psnr_db = resume.start_psnr_db
        if resume.theta_at_bind is not None and bind is not None:
            theta_at_bind = resume.theta_at_bind.to(problem.theta0)
            problem, state, _ = _bind(problem, theta_at_bind, result, method, bind, jacobian)
        state.restore(*resume.optimizer)
        phase, event = resume.phase, ""

    def run_state(final: bool = False) -> RunState:
        return RunState(k, total, method, bind_step, theta_at_bind, state.snapshot(), phase,
                        list(result.history), list(result.image_history), result.start_esr_um,
                        result.start_merit, result.start_psnr_db, before + time.perf_counter() - t0, final)

    last = run_state() if on_state is not None else None
    try:
        while k < total:
            if bind_step is not None and k >= bind_step and not result.bound:
                theta_at_bind = state.theta.clone()
                problem, state, event = _bind(problem, theta_at_bind, result, method, bind, jacobian)
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
            elapsed = before + time.perf_counter() - t0
            result.history.append((k, elapsed, info.merit, esr))
            if on_state is not None:
                last = run_state()
                on_state(last)
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
            theta_at_bind = state.theta.clone()
            problem, state, _ = _bind(problem, theta_at_bind, result, method, bind, jacobian)
            phase = "glasses bound"
    except KeyboardInterrupt:
        result.interrupted = True
        result.stop_reason = "interrupted"
    result.steps = k
    _finish(result, problem, state.theta)
    result.elapsed_s = before + time.perf_counter() - t0
    if on_state is not None:
        if result.interrupted:  # the last completed step's state (an interrupt may land inside a step)
            last.final = True
            on_state(last)
        else:
            on_state(run_state(final=True))
    return result


def _check_phases(total: int, bind_step: int, bind_at: float, path: str) -> None:
    """Refuse a run whose glasses-free or glasses-bound phase would get fewer than ``MIN_PHASE_STEPS``."""

    def phases(n: int) -> dict[str, int]:
        b = round(bind_at * n)
        return {"glasses-free": b, "glasses-bound": n - b} if bind_at > 0 else {"glasses-bound": n}

    short = {name: n for name, n in phases(total).items() if n < MIN_PHASE_STEPS}
    if short:
        need = MIN_PHASE_STEPS
        while min(phases(need).values()) < MIN_PHASE_STEPS:
            need += 1
        what = " and ".join(f"{n} to the {name} phase" for name, n in short.items())
        raise OptimizeError(f"{total} steps leave {what} (glasses bound at {bind_at:g} of the run); each phase "
                            f"needs at least {MIN_PHASE_STEPS}: use {need} steps or more", path=path, got=total)


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


def _bind(problem: Problem, theta: torch.Tensor, result: OptimizeResult, method: str, bind: Rebind,  # noqa: ANN202
          jacobian: str = "eager"):
    """Bind glasses to the catalog at ``theta`` (``bind`` rebuilds the problem without glass variables),
    with a fresh optimizer."""
    new, bound = bind(problem, theta)
    ev = new.evaluate(new.theta0)
    if not ev.physical:
        raise OptimizeError(f"binding the glasses to the catalog made the lens unusable: {ev.reason}")
    result.bound = bound
    names = ", ".join(b.name for b in bound)
    return new, make_optimizer(new, new.theta0, method, jacobian), f"bound glasses: {names}"
