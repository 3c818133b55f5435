"""TensorBoard logs of the restoration runs (``train-irm`` and the joint lens + network run): the
custom-scalars layout of each, and example images (scene | capture | restored, conditioning PSFs)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from torch import Tensor

__all__ = ["LAYOUTS", "tensorboard_layout", "tensorboard_writer", "log_examples"]

LAYOUTS: dict[str, dict[str, dict[str, list[Any]]]] = {
    # train-irm: training vs held-out MAE, held-out PSNR before vs after restoration, learning rate, step time.
    "train-irm": {"train-irm (network on a fixed lens)": {
        "MAE: training batch vs held-out": ["Multiline", ["train-irm/loss", "train-irm/mae"]],
        "held-out PSNR dB: raw capture vs restored": ["Multiline", ["train-irm/psnr_raw", "train-irm/psnr_restored"]],
        "Adam learning rate (cosine)": ["Multiline", ["train-irm/lr"]],
        "step wall time s": ["Multiline", ["train-irm/wall_s"]],
    }},
    # joint: one category, each chart a multiline plot of the ``joint/…`` scalars written every step (the
    # held-out ``psnr_raw``/``psnr_restored`` at validation steps only).
    "joint": {"joint run (lens LM step + network Adam step)": {
        "PSNR dB: training batch (restored) vs held-out raw and restored":
            ["Multiline", ["joint/psnr_batch_db", "joint/psnr_raw", "joint/psnr_restored"]],
        "losses: network MAE (Adam), restored MSE and merit (LM)":
            ["Multiline", ["joint/mae", "joint/loss_restored_mse", "joint/merit"]],
        "LM damping λ and step accepted": ["Multiline", ["joint/damping", "joint/accepted"]],
        "ESR µm (spot size of the lens)": ["Multiline", ["joint/esr_um"]],
        "Adam learning rate (cosine)": ["Multiline", ["joint/lr"]],
        "step wall time s": ["Multiline", ["joint/wall_s"]],
    }},
}


def tensorboard_layout(kind: str) -> dict[str, dict[str, list[Any]]]:
    """The custom-scalars layout (``SummaryWriter.add_custom_scalars``) of a ``train-irm`` or ``joint`` run."""
    return LAYOUTS[kind]


def tensorboard_writer(log_dir: Path | None, kind: str) -> Any:
    """A ``SummaryWriter`` on ``log_dir`` with the layout of ``kind`` written, or None without a folder."""
    if log_dir is None:
        return None
    from torch.utils.tensorboard import SummaryWriter

    writer = SummaryWriter(str(log_dir))
    writer.add_custom_scalars(tensorboard_layout(kind))
    return writer


def log_examples(writer: Any, tag: str, step: int, ex: dict[str, Tensor], count: int = 4) -> None:
    """TensorBoard images: scene | capture | restored side by side per patch, and the conditioning PSFs
    (each scaled to its maximum)."""
    if not ex:
        return
    n = min(count, ex["scene"].shape[0])
    rows = torch.cat([ex["scene"][:n], ex["capture"][:n], ex["restored"][:n]], dim=-1).clamp(0, 1)
    if rows.shape[1] == 1:
        rows = rows.expand(-1, 3, -1, -1)
    writer.add_images(f"{tag}/scene_capture_restored", (rows ** (1 / 2.2)).cpu(), step)  # ~sRGB for display
    k = ex["psf"][:n]
    k = k / k.amax((-2, -1), keepdim=True).clamp_min(1e-12)
    if k.shape[1] == 1:
        k = k.expand(-1, 3, -1, -1)
    writer.add_images(f"{tag}/conditioning_psf", k.cpu(), step)

