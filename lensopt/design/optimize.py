"""``lensopt optimize`` on a spec: build the problem (``design.setup``), run it (``optim.driver``), bind the
glasses through the spec (``design.writeback``), and write the optimized lens back as a spec."""

from __future__ import annotations

from collections.abc import Callable

import torch

from lensopt.design.setup import build_problem
from lensopt.design.writeback import BoundGlass, bind_glasses, to_spec
from lensopt.devices import resolve_device
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.optim.driver import JACOBIANS, OptimizeResult, Progress, run_problem
from lensopt.optim.problem import Problem
from lensopt.spec.models import LensSpec

__all__ = ["optimize"]


def optimize(spec: LensSpec, *, optimizer: str | None = None, steps: int | None = None, seed: int = 0,
             callback: Callable[[Progress], None] | None = None, device: str | torch.device | None = None,
             jacobian: str = "eager", full_weight: bool = False, engine: Engine | None = None) -> OptimizeResult:
    """Optimize ``spec`` (its ``vary`` lists and ``[optimize]`` section); ``result.spec`` is the optimized lens.

    Ctrl-C (KeyboardInterrupt) ends the run early; the result then holds the best lens so far.
    ``device``: where the problem's tensors live (default CPU); ``jacobian``: ``eager`` or
    ``compiled`` (see ``lensopt.optim.driver.make_optimizer``); ``full_weight``: no weight schedules, each
    group at the weight its schedule ends on from the first step (``OptimizeSpec.at_full_weight``), for
    continuing a written lens; the written lens keeps the spec's schedules; ``engine``: trace backend,
    memory budget and allocator setting of the run (default ``Engine()``).

    Raises:
        OptimizeError: nothing varies, or the start lens is not usable (the message says why).
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

    result = run_problem(problem, optimizer=method, steps=steps, callback=callback, jacobian=jacobian, bind=bind)
    result.spec = to_spec(result.problem, result.theta)
    if full_weight and opt0 is not None and result.spec.optimize is not None:  # the schedules as written
        result.spec.optimize = result.spec.optimize.model_copy(update={"tra": opt0.tra,
                                                                       "constraints": opt0.constraints})
    return result
