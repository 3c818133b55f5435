"""Training the restoration network on a fixed lens (S4.3.2; the network step of S3.3.1), and a whole
``train-irm`` run around it.

One step: a batch of scene patches and pseudo-random sensor tiles (``restore.capture``), the captures
through the lens (per-tile 3×3 PSF grid, overlap-add, 0.5 % noise), the conditioned network restores
them with the mean of each tile's sub-tile PSFs, Adam on the MAE with a cosine learning rate. Every
random draw comes from three seeded ``torch.Generator``s (scenes, tiles, noise), so a checkpoint
(``restore.checkpoint``) holding their states, the weights and Adam's moments continues bit-identically.

``train_irm`` is the whole run: the network, its checkpoints, ``--resume``, validation and optional
TensorBoard logs. The loop stops cleanly at a step boundary when ``stop()`` returns true (the CLI sets
it on Ctrl-C or SIGTERM) and checkpoints there.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import Tensor, nn

from lensopt.checkpoint import Checkpoint, CheckpointError, lens_structure, save_checkpoint
from lensopt.errors import LensoptError
from lensopt.imaging.metrics import psnr_batch
from lensopt.optics.lens import Lens, System
from lensopt.parallel import Dist
from lensopt.restore.capture import (
    GridCache,
    ImagingSetup,
    Source,
    ValidationSet,
    capture,
    draw_batch,
    lens_psfs,
    validation_set,
)
from lensopt.restore.checkpoint import network_fingerprint, resume_run, run_state
from lensopt.restore.config import RestoreConfig, TrainConfig
from lensopt.restore.model import ConditionedRestorer, mean_patch_psf
from lensopt.restore.tensorboard import log_examples, tensorboard_writer

__all__ = ["cosine_lr", "network_optimizer", "NetworkRun", "network_step", "validate", "train_network",
           "IrmResult", "train_irm"]


def cosine_lr(step: int, steps: int, lr: float, lr_min: float = 0.0) -> float:
    """Cosine schedule: ``lr`` at step 0 down to ``lr_min`` at ``steps``."""
    return lr_min + 0.5 * (lr - lr_min) * (1.0 + math.cos(math.pi * min(step, steps) / max(steps, 1)))


def network_optimizer(model: nn.Module, cfg: TrainConfig) -> torch.optim.Adam:
    """Adam on the network's weights with ``cfg``'s learning rate and betas."""
    return torch.optim.Adam(model.parameters(), lr=cfg.lr, betas=tuple(cfg.betas))


@dataclass
class NetworkRun:
    """The mutable state of a network-training run (what a checkpoint holds)."""

    model: nn.Module
    optimizer: torch.optim.Optimizer
    generators: dict[str, torch.Generator]
    step: int = 0
    history: list[dict[str, float]] = field(default_factory=list)

    @staticmethod
    def fresh(model: nn.Module, cfg: TrainConfig, seed: int) -> NetworkRun:
        gens = {name: torch.Generator().manual_seed(seed * 1000 + k) for k, name in
                enumerate(("scenes", "tiles", "noise"))}
        return NetworkRun(model=model, optimizer=network_optimizer(model, cfg), generators=gens)


def network_step(model: nn.Module, optimizer: torch.optim.Optimizer, captured: Tensor, kpsf: Tensor,
                 target: Tensor, lr: float) -> float:
    """One Adam step on the MAE between restored captures and scenes (lens frozen); returns the loss."""
    for g in optimizer.param_groups:
        g["lr"] = lr
    optimizer.zero_grad(set_to_none=True)
    loss = (model(captured, kpsf) - target).abs().mean()
    loss.backward()
    optimizer.step()
    return float(loss.detach())


def validate(model: nn.Module, grids_of: Callable[[Tensor], Tensor], val: ValidationSet, setup: ImagingSetup, *,
             chunk: int = 8, examples: dict[str, Tensor] | None = None) -> dict[str, float]:
    """Mean PSNR (dB) and MAE of the captures and of their restorations on the validation set.

    ``examples`` (a dict) receives the first chunk's scenes, captures, restorations and conditioning
    PSFs (for TensorBoard images)."""
    raw, rest, mae = [], [], []
    device = next(model.parameters()).device
    with torch.no_grad():
        for i in range(0, len(val.tiles), chunk):
            sl = slice(i, i + chunk)
            scenes = val.scenes[sl].to(device)
            grids = grids_of(val.tiles[sl]).to(device)
            cap = capture(scenes, grids, setup.settings, val.noise[sl].to(device))
            kpsf = mean_patch_psf(grids.flatten(1, 2)).to(cap.dtype)
            out = model(cap, kpsf)
            if examples is not None and i == 0:
                examples.update(scene=scenes, capture=cap, restored=out, psf=kpsf)
            raw.append(psnr_batch(scenes, cap))
            rest.append(psnr_batch(scenes, out))
            mae.append((out - scenes).abs().flatten(1).mean(1))
    return {"psnr_raw": float(torch.cat(raw).mean()), "psnr_restored": float(torch.cat(rest).mean()),
            "mae": float(torch.cat(mae).mean())}


def train_network(
    run: NetworkRun,
    lens: Lens,
    system: System,
    setup: ImagingSetup,
    source: Source,
    cfg: TrainConfig,
    *,
    steps: int,
    val: ValidationSet | None = None,
    checkpoint: Callable[[NetworkRun], None] | None = None,
    on_progress: Callable[[dict[str, Any]], None] | None = None,
    stop: Callable[[], bool] = lambda: False,
    on_validate: Callable[[int, dict[str, Tensor]], None] | None = None,
    share: slice | None = None,
    mean: Callable[[Tensor], Tensor] | None = None,
) -> bool:
    """Continue ``run`` up to ``steps`` steps; returns True if stopped early by ``stop()``.

    ``on_validate(step, examples)`` receives the first validation patches (scene, capture, restored,
    psf) at each validation.

    Data parallel (``torch.distributed``): every rank draws the same combined batch from the same
    generators and trains on its ``share`` of it; ``run.model`` is then a ``DistributedDataParallel``
    module (gradients averaged) and ``mean`` averages the reported loss over ranks.
    """
    device = next(run.model.parameters()).device
    with torch.no_grad():
        psf, center = lens_psfs(lens, system, setup)
    grids_of = GridCache(psf, center, setup)
    interrupted = False
    while run.step < steps:
        if stop():
            interrupted = True
            break
        t0 = time.perf_counter()
        scenes, tiles, noise = draw_batch(source, setup, cfg.batch, run.generators, device=device)
        if share is not None:
            scenes, tiles, noise = scenes[share], tiles[share], noise[share]
        grids = grids_of(tiles).to(device)
        cap = capture(scenes, grids, setup.settings, noise)
        kpsf = mean_patch_psf(grids.flatten(1, 2)).to(cap.dtype)
        lr = cosine_lr(run.step, steps, cfg.lr, cfg.lr_min)
        loss = network_step(run.model, run.optimizer, cap, kpsf, scenes, lr)
        if mean is not None:
            loss = float(mean(torch.tensor(loss, dtype=torch.float64)))
        run.step += 1
        rec: dict[str, Any] = {"step": run.step, "loss": loss, "lr": lr, "wall_s": time.perf_counter() - t0}
        if val is not None and cfg.validate_every and (run.step % cfg.validate_every == 0 or run.step == steps):
            ex: dict[str, Tensor] = {}
            rec.update(validate(run.model, grids_of, val, setup, examples=ex))
            if on_validate is not None:
                on_validate(run.step, ex)
        run.history.append(rec)
        if on_progress is not None:
            on_progress(rec)
        if checkpoint is not None and cfg.checkpoint_every and run.step % cfg.checkpoint_every == 0:
            checkpoint(run)
    if checkpoint is not None:
        checkpoint(run)
    return interrupted


@dataclass
class IrmResult:
    steps: int
    interrupted: bool
    history: list[dict[str, Any]]
    validation: dict[str, float] | None
    checkpoint: str


def _settings(setup: ImagingSetup, cfg: TrainConfig, data: str) -> dict[str, Any]:
    t = asdict(cfg)
    # What does not change the trajectory may change on --resume (steps: the schedule follows the new total).
    for k in ("extra", "steps", "checkpoint_every", "validate_every", "validation_patches"):
        t.pop(k, None)
    t["betas"] = list(cfg.betas)
    return {"imaging": setup.describe(), "train": t, "data": data}


def train_irm(
    spec: Any,
    lens_json: str,
    lens_system: tuple[Any, Any],
    setup: ImagingSetup,
    net: RestoreConfig,
    cfg: TrainConfig,
    source: Source,
    val_source: Source,
    *,
    steps: int,
    data: str,
    output: Path,
    resume: bool = False,
    device: torch.device | str = "cpu",
    log_dir: Path | None = None,
    stop: Callable[[], bool] = lambda: False,
    on_progress: Callable[[dict[str, Any]], None] | None = None,
    dist: Dist | None = None,
) -> IrmResult:
    """Train a fresh network (or continue the checkpoint at ``output`` with ``resume``) on a fixed lens.

    ``dist``: data parallel over torch.distributed ranks (rank 0 writes)."""
    dist = dist or Dist()
    if cfg.batch % dist.world:
        raise LensoptError(f"must be divisible by the number of processes ({dist.world})", path="--batch",
                           got=cfg.batch)
    lens, system = lens_system
    fp = network_fingerprint(spec, net)
    settings = _settings(setup, cfg, data)
    torch.manual_seed(cfg.seed)
    model = ConditionedRestorer(net).to(device)
    run = NetworkRun.fresh(model, cfg, cfg.seed)
    if resume:
        resume_run(run, output, fp, settings)
    elif output.exists() and dist.rank == 0:
        raise CheckpointError("exists; pass --resume to continue it or choose another -o", path="--output",
                              got=str(output))
    writer = tensorboard_writer(log_dir, "train-irm") if dist.rank == 0 else None
    if dist.active:
        from torch.nn.parallel import DistributedDataParallel

        run.model = DistributedDataParallel(model)

    def checkpoint(r: NetworkRun) -> None:
        if dist.rank != 0:
            return
        network, state, info = run_state(r)
        info["settings"] = settings
        info["network_config"] = net.to_dict()
        info["lens_structure"] = lens_structure(spec)
        info["colour"] = {"channels": setup.channels, "weights": setup.colour}
        save_checkpoint(output, Checkpoint(kind="train-irm", step=r.step, lens_json=lens_json, network=network,
                                           state=state, meta=info, fingerprint=fp))

    def progress(rec: dict[str, Any]) -> None:
        if writer is not None:
            for k, v in rec.items():
                if k != "step":
                    writer.add_scalar(f"train-irm/{k}", v, rec["step"])
        if on_progress is not None:
            on_progress(rec)

    val = validation_set(val_source, setup, cfg.validation_patches, seed=cfg.seed + 7919)
    try:
        interrupted = train_network(run, lens, system, setup, source, cfg, steps=steps, val=val,
                                    checkpoint=checkpoint, on_progress=progress, stop=stop,
                                    on_validate=None if writer is None else
                                    (lambda step, ex: log_examples(writer, "train-irm", step, ex)),
                                    share=dist.share(cfg.batch) if dist.active else None,
                                    mean=dist.mean if dist.active else None)
    finally:
        if writer is not None:
            writer.close()
    last_val = next((h for h in reversed(run.history) if "psnr_restored" in h), None)
    return IrmResult(run.step, interrupted, run.history, last_val, str(output))
