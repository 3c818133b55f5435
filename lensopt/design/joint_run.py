"""A whole joint run (``lensopt optimize`` with ``objective = "restored"``): problem and network set-up,
checkpoints every N steps and at a stop (Ctrl-C / SIGTERM at a step boundary), ``--resume``,
validation on held-out patches, TensorBoard scalars, and torch.distributed data parallelism. Each step
is ``design.joint.joint_step``."""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from lensopt.checkpoint import (
    Checkpoint,
    CheckpointError,
    fingerprint,
    flatten_optimizer,
    lens_structure,
    load_checkpoint,
    save_checkpoint,
    unflatten_optimizer,
)
from lensopt.design.joint import RestoredObjective, evaluate_pair, joint_step
from lensopt.design.restore import configs_from_spec
from lensopt.design.setup import SpecProblem, build_problem
from lensopt.design.writeback import to_spec
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.imaging.plan import lens_colour
from lensopt.optim.lm import LevenbergMarquardt, Trial
from lensopt.optim.settings import ImageSettings
from lensopt.parallel import Dist
from lensopt.restore.config import RestoreConfig, TrainConfig
from lensopt.restore.model import ConditionedRestorer
from lensopt.restore.tensorboard import log_examples, tensorboard_writer
from lensopt.restore.train import network_optimizer

__all__ = ["JointResult", "joint_spec", "run_joint"]

log = logging.getLogger(__name__)


@dataclass
class JointResult:
    spec: Any
    steps: int
    interrupted: bool
    history: list[dict[str, Any]] = field(default_factory=list)
    start: dict[str, float] | None = None
    final: dict[str, float] | None = None
    elapsed_s: float = 0.0
    notes: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)


def joint_spec(spec: Any) -> tuple[Any, list[str]]:
    """The spec for a joint run: glass variables are frozen (glasses are chosen by the spot or raw
    runs before, S6.2), the optimizer is LM. Returns (spec, notes)."""
    notes = []
    spec = spec.model_copy(deep=True)
    frozen = [i for i, s in enumerate(spec.surfaces) if "material" in s.vary]
    for i in frozen:
        spec.surfaces[i].vary = [v for v in spec.surfaces[i].vary if v != "material"]
    if frozen:
        notes.append(f"glass variables frozen for the joint run (surfaces {frozen})")
    if spec.optimize.optimizer != "lm":
        notes.append("objective restored uses Levenberg–Marquardt for the lens")
    return spec, notes


def _settings(spec: Any, net: RestoreConfig, cfg: TrainConfig, world: int) -> dict[str, Any]:
    """What a checkpoint must have been written with to be resumed (JSON-normalised)."""
    img = spec.optimize.image
    out = {"image": img.model_dump(mode="json") if img is not None else None, "network": net.to_dict(),
           "adam": {"lr": cfg.lr, "betas": list(cfg.betas), "lr_min": cfg.lr_min},
           "lm": spec.optimize.lm.model_dump(mode="json"), "world": world,
           "imaging": {"fields": img.fields, "psf_size": img.psf_size, "grid": list(img.grid), "patch": img.patch,
                       "sampling": img.sampling}}
    return json.loads(json.dumps(out))


@dataclass
class JointParts:
    """What a joint run works on: the problem, the network (``model``: DDP-wrapped under torchrun), Adam,
    the restored-image objective, the LM state, and what a checkpoint must match."""

    spec: Any
    problem: SpecProblem
    net_cfg: RestoreConfig
    cfg: TrainConfig
    net: ConditionedRestorer
    model: torch.nn.Module
    adam: torch.optim.Optimizer
    obj: RestoredObjective
    lm: LevenbergMarquardt
    settings: dict[str, Any]
    fingerprint: str


def joint_parts(start_spec: Any, *, seed: int = 0, device: torch.device | str = "cpu",
                dist: Dist | None = None, engine: Engine | None = None) -> tuple[JointParts, list[str]]:
    """The problem, network, objective and LM state of a joint run of ``start_spec`` (and the notes of
    ``joint_spec``)."""
    dist = dist or Dist()
    spec, notes = joint_spec(start_spec)
    net_cfg, cfg = configs_from_spec(spec.restore)
    net_cfg = RestoreConfig(**{**net_cfg.to_dict(), "channels": len(lens_colour(start_spec.spectrum)[1])})
    problem = build_problem(spec, seed=seed, method="lm", engine=engine)
    if problem.num_variables == 0:
        raise LensoptError("nothing to optimize: no surface has a vary list", path="surfaces")
    torch.manual_seed(seed)
    net = ConditionedRestorer(net_cfg).to(device)
    adam = network_optimizer(net, cfg)
    model: torch.nn.Module = net
    if dist.active:
        from torch.nn.parallel import DistributedDataParallel

        model = DistributedDataParallel(net)
    obj = RestoredObjective(problem.setup.camera, problem.opt.image or ImageSettings(), model, dist=dist,
                            device=device, engine=engine)
    problem.use_image(obj)

    def evaluate_fn(t: torch.Tensor) -> Trial:
        ev = problem.evaluate(t)
        return Trial(ev.residuals, ev.physical, ev.reason)

    lm = LevenbergMarquardt(problem.theta0, problem.jacobian, evaluate_fn, problem.opt.lm)
    start_ev = problem.evaluate(problem.theta0)
    if not start_ev.physical:
        raise LensoptError(f"the start lens cannot be optimized: {start_ev.reason}")
    parts = JointParts(spec, problem, net_cfg, cfg, net, model, adam, obj, lm,
                       _settings(spec, net_cfg, cfg, dist.world), fingerprint(lens_structure(spec), net_cfg.to_dict()))
    return parts, notes


def resume_joint(parts: JointParts, checkpoint: Path, start_spec: Any,
                 device: torch.device | str) -> tuple[int, list[dict[str, Any]]]:
    """Load a joint checkpoint into ``parts`` (network, Adam, LM state); returns (step, history). Refused
    unless it was written for the same start lens, network and settings."""
    ck = load_checkpoint(checkpoint, expect_fingerprint=parts.fingerprint, option="--resume")
    if ck.kind != "joint":
        raise CheckpointError(f"is a {ck.kind} checkpoint, not a joint one", path="--resume", got=str(checkpoint))
    if ck.meta.get("settings") != parts.settings:
        raise CheckpointError("was written with other [optimize.image], [restore], LM settings or process count",
                              path="--resume", got=str(checkpoint))
    if ck.meta.get("start_spec") != json.loads(start_spec.model_dump_json()):
        raise CheckpointError("was written for another start lens", path="--resume", got=str(checkpoint))
    lm = parts.lm
    parts.net.load_state_dict({k: v.to(device) for k, v in ck.network.items()})
    parts.adam.load_state_dict(unflatten_optimizer("adam", {k: v.to(device) for k, v in ck.state.items()},
                                                   ck.meta["adam"]))
    lm.theta = ck.state["lm.theta"].to(lm.theta.dtype)
    lm.D = ck.state.get("lm.D")
    m = ck.meta["lm"]
    lm.damping, lm.accepted, lm.rejected, lm.history = m["damping"], m["accepted"], m["rejected"], m["history"]
    return ck.step, list(ck.meta.get("history", []))


def save_joint(parts: JointParts, checkpoint: Path, start_spec: Any, step: int,
               history: list[dict[str, Any]]) -> None:
    """Write the joint checkpoint of ``parts`` at ``step`` (the current lens as its lens JSON)."""
    lm = parts.lm
    opt_t, opt_info = flatten_optimizer("adam", parts.adam.state_dict())
    state = dict(opt_t)
    state["lm.theta"] = lm.theta
    if lm.D is not None:
        state["lm.D"] = lm.D
    meta = {"adam": opt_info, "settings": parts.settings, "history": history,
            "network_config": parts.net_cfg.to_dict(), "lens_structure": lens_structure(parts.spec),
            "colour": {"channels": parts.net_cfg.channels,
                       "weights": lens_colour(parts.problem.setup.camera.spectrum)[2]},
            "start_spec": json.loads(start_spec.model_dump_json()),
            "lm": {"damping": lm.damping, "accepted": lm.accepted, "rejected": lm.rejected,
                   "history": list(lm.history)}}
    cur = to_spec(parts.problem, lm.theta)
    save_checkpoint(checkpoint, Checkpoint(kind="joint", step=step, lens_json=cur.model_dump_json(indent=2),
                                           network=dict(parts.net.state_dict()), state=state, meta=meta,
                                           fingerprint=parts.fingerprint))


def run_joint(
    start_spec: Any,
    *,
    steps: int | None = None,
    seed: int = 0,
    checkpoint: Path | None = None,
    resume: bool = False,
    device: torch.device | str = "cpu",
    log_dir: Path | None = None,
    dist: Dist | None = None,
    stop: Callable[[], bool] = lambda: False,
    on_progress: Callable[[dict[str, Any]], None] | None = None,
    checkpoint_every: int | None = None,
    validate_every: int | None = None,
    evaluate: bool = True,
    engine: Engine | None = None,
) -> JointResult:
    """Optimize the lens of ``start_spec`` jointly with a restoration network (S3.3.1)."""
    t_start = time.perf_counter()
    dist = dist or Dist()
    parts, notes = joint_parts(start_spec, seed=seed, device=device, dist=dist, engine=engine)
    spec, problem, lm, cfg = parts.spec, parts.problem, parts.lm, parts.cfg
    total = steps if steps is not None else spec.optimize.steps
    ck_every = cfg.checkpoint_every if checkpoint_every is None else checkpoint_every
    val_every = cfg.validate_every if validate_every is None else validate_every
    history: list[dict[str, Any]] = []
    step = 0
    if resume:
        if checkpoint is None:
            raise LensoptError("needs --checkpoint", path="--resume")
        step, history = resume_joint(parts, checkpoint, start_spec, device)
    elif checkpoint is not None and checkpoint.exists():
        raise CheckpointError("exists; pass --resume to continue it or choose another --checkpoint",
                              path="--checkpoint", got=str(checkpoint))

    def save() -> None:
        if checkpoint is not None and dist.rank == 0:
            save_joint(parts, checkpoint, start_spec, step, history)

    writer = tensorboard_writer(log_dir, "joint") if dist.rank == 0 else None
    count = spec.optimize.image.validation
    res = JointResult(spec=spec, steps=step, interrupted=False, notes=notes)
    if evaluate:
        res.start = evaluate_pair(parts.obj, problem.lens(lm.theta)[0], parts.net, count)
    try:
        while step < total:
            if stop():
                res.interrupted = True
                break
            rec = joint_step(problem, lm, parts.obj, parts.model, parts.adam, step, total, lr=cfg.lr,
                             lr_min=cfg.lr_min, dist=dist, timings=res.timings)
            step += 1
            rec["esr_um"] = 1e3 * problem.spot_esr_mm(lm.theta)
            if val_every and (step % val_every == 0 or step == total):
                ex: dict[str, torch.Tensor] = {}
                rec.update(evaluate_pair(parts.obj, problem.lens(lm.theta)[0], parts.net, count, examples=ex))
                if writer is not None:
                    log_examples(writer, "joint", step, ex)
            history.append(rec)
            if writer is not None:
                for k, v in rec.items():
                    if k != "step" and isinstance(v, (int, float)):
                        writer.add_scalar(f"joint/{k}", float(v), rec["step"])
            if on_progress is not None:
                on_progress(rec)
            if ck_every and step % ck_every == 0:
                save()
    finally:
        if writer is not None:
            writer.close()
    save()
    res.steps, res.history = step, history
    res.spec = to_spec(problem, lm.theta)
    res.spec.restore = spec.restore
    if evaluate and not res.interrupted:
        res.final = evaluate_pair(parts.obj, problem.lens(lm.theta)[0], parts.net, count)
    res.elapsed_s = time.perf_counter() - t_start
    return res
