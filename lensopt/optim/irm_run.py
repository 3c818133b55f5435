"""A whole ``train-irm`` run: the network, its checkpoints (``lensopt.checkpoint``), ``--resume``,
validation and optional TensorBoard logs around ``optim.irm.train_network``; and restoring a full
image with a trained network (``lensopt restore``, and the ``--irm`` hook of evaluate and tolerance)."""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from lensopt.checkpoint import (
    Checkpoint,
    CheckpointError,
    fingerprint,
    lens_structure,
    load_checkpoint,
    save_checkpoint,
)
from lensopt.errors import LensoptError
from lensopt.optim.irm import (
    ImagingSetup,
    NetworkRun,
    Source,
    imaging_setup,
    lens_psfs,
    load_run_state,
    log_examples,
    region_grids,
    run_state,
    train_network,
    validation_set,
)
from lensopt.restore.config import RestoreConfig, TrainConfig
from lensopt.restore.model import ConditionedRestorer, mean_patch_psf

__all__ = ["IrmResult", "network_fingerprint", "train_irm", "load_network", "load_restorer", "restoration_hook",
           "restore_image", "tensorboard_layout"]

log = logging.getLogger(__name__)


def network_fingerprint(spec: Any, net: RestoreConfig) -> str:
    return fingerprint(lens_structure(spec), net.to_dict())


def tensorboard_layout() -> dict[str, dict[str, list[Any]]]:
    """The TensorBoard custom-scalars layout of a ``train-irm`` run (``SummaryWriter.add_custom_scalars``):
    training vs held-out MAE, held-out PSNR before vs after restoration, learning rate, step time."""
    return {"train-irm (network on a fixed lens)": {
        "MAE: training batch vs held-out": ["Multiline", ["train-irm/loss", "train-irm/mae"]],
        "held-out PSNR dB: raw capture vs restored": ["Multiline", ["train-irm/psnr_raw", "train-irm/psnr_restored"]],
        "Adam learning rate (cosine)": ["Multiline", ["train-irm/lr"]],
        "step wall time s": ["Multiline", ["train-irm/wall_s"]],
    }}


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
    dist: Any = None,
) -> IrmResult:
    """Train a fresh network (or continue the checkpoint at ``output`` with ``resume``) on a fixed lens.

    ``dist`` (``optim.joint.Dist``): data parallel over torch.distributed ranks (rank 0 writes)."""
    from lensopt.optim.joint import Dist

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
        ck = load_checkpoint(output, expect_fingerprint=fp, option="--resume")
        if ck.kind != "train-irm":
            raise CheckpointError(f"is a {ck.kind} checkpoint, not train-irm", path="--resume", got=str(output))
        if ck.meta.get("settings") != json.loads(json.dumps(settings)):
            old = ck.meta.get("settings", {})
            diff = sorted(k for part in ("imaging", "train") for k in set(old.get(part, {})) | set(settings[part])
                          if old.get(part, {}).get(k) != settings[part].get(k))
            if old.get("data") != settings["data"]:
                diff.append("images")
            raise CheckpointError(f"was written with other settings ({', '.join(diff)}); resume with the same ones",
                                  path="--resume", got=str(output))
        load_run_state(run, ck.network, ck.state, ck.meta, ck.step)
    elif output.exists() and dist.rank == 0:
        raise CheckpointError("exists; pass --resume to continue it or choose another -o", path="--output",
                              got=str(output))

    writer = None
    if log_dir is not None and dist.rank == 0:
        from torch.utils.tensorboard import SummaryWriter

        writer = SummaryWriter(str(log_dir))
        writer.add_custom_scalars(tensorboard_layout())

    if dist.active:
        from torch.nn.parallel import DistributedDataParallel

        run.model = DistributedDataParallel(model)

    def checkpoint(r: NetworkRun) -> None:
        if dist.rank != 0:
            return
        network, state, info = run_state(r)
        info["settings"] = settings
        info["network_config"] = net.to_dict()
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


def load_network(path: Path, spec: Any, *, device: torch.device | str = "cpu",
                 option: str = "CKPT") -> tuple[ConditionedRestorer, Checkpoint]:
    """The network of a checkpoint, refused unless it was written for this lens structure."""
    from lensopt.checkpoint import load_checkpoint as _load

    probe = _load(path, option=option)
    net = RestoreConfig.from_dict(probe.meta.get("network_config", {}))
    fp = network_fingerprint(spec, net)
    if probe.fingerprint != fp:
        raise CheckpointError("was written for another lens structure (surface kinds, stop or number of wavelengths "
                              "differ)", path=option, got=str(path))
    model = ConditionedRestorer(net).to(device)
    try:
        model.load_state_dict({k: v.to(device) for k, v in probe.network.items()})
    except RuntimeError as err:
        raise CheckpointError(f"weights do not fit the network: {str(err).splitlines()[0]}", path=option) from None
    model.eval()
    return model, probe


def load_restorer(path: Path, model: Any, *, device: torch.device | str = "cpu",
                  option: str = "CKPT") -> tuple[ConditionedRestorer, ImagingSetup, int]:
    """The network of a checkpoint for ``model`` (a built lens spec: ``lensopt.spec.Model``), on ``device``,
    with the imaging set-up it was trained with and its tile size (``restore_image``'s ``tile``)."""
    net, ck = load_network(path, model.spec, device=device, option=option)
    im = ck.meta.get("settings", {}).get("imaging", {})
    setup = imaging_setup(model.camera(), patch=16, fields=int(im.get("fields", 9)),
                          sampling=im.get("sampling", "rings:8"), psf_size=int(im.get("psf_size", 31)),
                          grid=tuple(im.get("grid", (3, 3))))
    return net, setup, int(im.get("patch", 256))


def restoration_hook(model: Any, path: Path, *, option: str = "--irm") -> Callable[[Tensor, dict[str, Any]], Tensor]:
    """The ``restore`` hook of ``imaging.evaluate`` (and of the tolerance ``psnr`` metric): the checkpoint's
    network restores each capture (1, C, H, W) at its sensor region ``info["region"]`` (``--irm``)."""
    device = model.lens.device
    net, setup, tile = load_restorer(path, model, device=device, option=option)

    def hook(capture: Tensor, info: dict[str, Any]) -> Tensor:
        if capture.shape[1] != net.config.channels:
            raise LensoptError(f"the network restores {net.config.channels}-channel images", path=option,
                               got=f"{capture.shape[1]} channels")
        out = restore_image(net, model.lens, model.system, setup, capture[0].to(device), info["region"], tile=tile)
        return out[None].cpu()

    return hook


def restore_image(model: ConditionedRestorer, lens: Any, system: Any, setup: ImagingSetup, image: Tensor,
                  region: Any, *, tile: int = 256, margin: int = 32) -> Tensor:
    """Restore a whole capture (C, H, W) covering ``region`` of the sensor: tiles of ``tile`` pixels,
    each restored with ``margin`` pixels of context and the mean PSF of its own sub-tile grid."""
    from lensopt.imaging.scene import Region

    c, h, w = image.shape
    with torch.no_grad():
        psf, center = lens_psfs(lens, system, setup)
        out = torch.zeros_like(image)
        sx, sy = region.w / region.image_w, region.h / region.image_h
        for y0 in range(0, h, tile):
            for x0 in range(0, w, tile):
                y1, x1 = min(h, y0 + tile), min(w, x0 + tile)
                ya, yb, xa, xb = max(0, y0 - margin), min(h, y1 + margin), max(0, x0 - margin), min(w, x1 + margin)
                sub = Region(region.x0 + xa * sx, region.y0 + ya * sy, (xb - xa) * sx, (yb - ya) * sy, xb - xa, yb - ya,
                             "tile")
                grids = region_grids(psf, center, [sub], setup)
                k = mean_patch_psf(grids.flatten(1, 2)).to(image.device, image.dtype)
                k = _fit_psf(k, min(yb - ya, xb - xa))
                res = model(image[None, :, ya:yb, xa:xb], k)[0]
                out[:, y0:y1, x0:x1] = res[:, y0 - ya:y1 - ya, x0 - xa:x1 - xa]
    return out


def _fit_psf(k: Tensor, side: int) -> Tensor:
    """Crop an odd PSF to at most ``side`` − 1 (odd) pixels so that it fits a small tile; renormalise."""
    n = k.shape[-1]
    m = min(n, side - 1 if side % 2 == 0 else side - 2)
    if m >= n or m < 1:
        return k
    a = (n - m) // 2
    k = k[..., a:a + m, a:a + m]
    return k / k.sum((-2, -1), keepdim=True)
