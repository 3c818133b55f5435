"""``lensopt optimize`` on a spec: build the problem (``design.setup``), run it (``optim.driver``), bind the
glasses through the spec (``design.writeback``), and write the optimized lens back as a spec."""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable
from pathlib import Path

import torch

from lensopt.checkpoint import Checkpoint, CheckpointError, load_checkpoint, save_checkpoint
from lensopt.design.setup import build_problem
from lensopt.design.writeback import BoundGlass, bind_glasses, to_spec
from lensopt.devices import resolve_device
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.optim.driver import JACOBIANS, OptimizeResult, Progress, RunState, run_problem
from lensopt.optim.problem import Problem
from lensopt.spec.models import LensSpec

__all__ = ["optimize", "CHECKPOINT_EVERY_S"]

CHECKPOINT_EVERY_S = 30.0
"""Wall seconds between checkpoint writes of ``optimize(checkpoint=...)`` (also after the first step and
at the end or on an interrupt)."""


def optimize(spec: LensSpec, *, optimizer: str | None = None, steps: int | None = None, seed: int = 0,
             callback: Callable[[Progress], None] | None = None, device: str | torch.device | None = None,
             jacobian: str = "eager", full_weight: bool = False, engine: Engine | None = None,
             checkpoint: Path | None = None, resume: bool = False,
             checkpoint_every_s: float = CHECKPOINT_EVERY_S) -> OptimizeResult:
    """Optimize ``spec`` (its ``vary`` lists and ``[optimize]`` section); ``result.spec`` is the optimized lens.

    Ctrl-C (KeyboardInterrupt) ends the run early; the result then holds the best lens so far.
    ``device``: where the problem's tensors live (default CPU); ``jacobian``: ``eager`` or
    ``compiled`` (see ``lensopt.optim.driver.make_optimizer``); ``full_weight``: no weight schedules, each
    group at the weight its schedule ends on from the first step (``OptimizeSpec.at_full_weight``), for
    continuing a written lens; the written lens keeps the spec's schedules; ``engine``: trace backend,
    memory budget and allocator setting of the run (default ``Engine()``).

    ``checkpoint``: a folder that holds the run's state (``lensopt.checkpoint``, kind ``optimize``: θ, the
    optimizer's damping and history, the schedule position, the bound glasses), written after the first
    step, every ``checkpoint_every_s`` and at the end or on an interrupt; ``resume``: continue the run
    it holds: the same spec and settings give the uninterrupted run's lens bit for bit.

    Raises:
        OptimizeError: nothing varies, or the start lens is not usable (the message says why).
        CheckpointError: ``resume`` without a checkpoint of this spec and these settings.
    """
    dev = device if isinstance(device, torch.device) else resolve_device(device)
    if jacobian not in JACOBIANS:
        raise LensoptError(f"must be one of {', '.join(JACOBIANS)}", path="--jacobian", got=jacobian)
    opt0 = spec.optimize
    if full_weight and opt0 is not None:
        spec = spec.model_copy(update={"optimize": opt0.at_full_weight()})
    method = optimizer or (opt0.optimizer if opt0 is not None else "lm")
    problem = build_problem(spec, seed=seed, method=method, device=dev, engine=engine)

    def bind(current: Problem, theta: torch.Tensor) -> tuple[Problem, list[BoundGlass]]:
        bound_spec, bound = bind_glasses(current, theta)  # a SpecProblem: run_problem hands back what it got
        if bound_spec.optimize is not None and bound_spec.optimize.sampling_after_binding:
            bound_spec.optimize = bound_spec.optimize.model_copy(
                update={"sampling": bound_spec.optimize.sampling_after_binding})
        return build_problem(bound_spec, seed=seed, method=method, device=current.device, engine=engine), bound

    total = steps if steps is not None else problem.opt.steps
    fp = _run_fingerprint(spec, method, total, seed, jacobian)
    start = _load_state(checkpoint, fp) if resume else None
    on_state = None if checkpoint is None else _writer(checkpoint, fp, spec, checkpoint_every_s)
    result = run_problem(problem, optimizer=method, steps=total, callback=callback, jacobian=jacobian, bind=bind,
                         resume=start, on_state=on_state)
    result.spec = to_spec(result.problem, result.theta)
    if full_weight and opt0 is not None and result.spec.optimize is not None:  # the schedules as written
        result.spec.optimize = result.spec.optimize.model_copy(update={"tra": opt0.tra,
                                                                       "constraints": opt0.constraints})
    return result


def _run_fingerprint(spec: LensSpec, method: str, total: int, seed: int, jacobian: str) -> str:
    """What must be equal for a checkpoint to continue this run: the spec (after ``full_weight``), the
    optimizer, the steps, the seed and the Jacobian (16 hex digits of a SHA-256)."""
    text = json.dumps({"spec": spec.model_dump(mode="json"), "optimizer": method, "steps": total, "seed": seed,
                       "jacobian": jacobian}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _writer(folder: Path, fp: str, spec: LensSpec, every_s: float) -> Callable[[RunState], None]:
    """``on_state`` for ``run_problem``: the state into ``folder`` after the first step, every ``every_s``
    wall seconds and at the end. ``lens.json`` holds the spec the run started from."""
    last = [-float("inf")]
    spec_json = spec.model_dump_json(indent=2)

    def write(st: RunState) -> None:
        now = time.monotonic()
        if not (st.final or st.step <= 1 or now - last[0] >= every_s):
            return
        last[0] = now
        tensors, values = st.optimizer
        state = {f"optimizer.{k}": v for k, v in tensors.items()}
        if st.theta_at_bind is not None:
            state["theta_at_bind"] = st.theta_at_bind
        meta = {"total": st.total, "method": st.method, "bind_step": st.bind_step, "phase": st.phase,
                "optimizer": values, "history": st.history, "image_history": st.image_history,
                "start_esr_um": st.start_esr_um, "start_merit": st.start_merit,
                "start_psnr_db": st.start_psnr_db, "elapsed_s": st.elapsed_s, "final": st.final}
        save_checkpoint(folder, Checkpoint(kind="optimize", step=st.step, lens_json=spec_json, network={},
                                           state=state, meta=meta, fingerprint=fp))

    return write


def _load_state(folder: Path | None, fp: str) -> RunState:
    """The ``RunState`` in checkpoint ``folder`` (``CheckpointError``: none, another kind, or another run's)."""
    if folder is None:
        raise CheckpointError("needs --checkpoint DIR (the folder of the run to continue)", path="--resume")
    ck = load_checkpoint(folder, option="--checkpoint")
    if ck.kind != "optimize":
        raise CheckpointError(f"holds a {ck.kind} run, not an optimize run", path="--checkpoint", got=str(folder))
    if ck.fingerprint != fp:
        raise CheckpointError("was written by another spec or other settings (--steps, --optimizer, --seed, "
                              "--jacobian, --full-weight): resume with the command that wrote it",
                              path="--checkpoint", got=str(folder))
    m = ck.meta
    tensors = {k.removeprefix("optimizer."): v for k, v in ck.state.items() if k.startswith("optimizer.")}
    return RunState(ck.step, int(m["total"]), m["method"], m["bind_step"], ck.state.get("theta_at_bind"),
                    (tensors, m["optimizer"]), m["phase"], [tuple(h) for h in m["history"]],
                    [tuple(h) for h in m["image_history"]], float(m["start_esr_um"]), float(m["start_merit"]),
                    float(m["start_psnr_db"]), float(m["elapsed_s"]))
