"""The single-stage conditioned restoration model of S3.2:

    x₁ = NAFNet₁(x) (+ x)
    w  = Wiener(x₁, K̄; SNR)              K̄: mean of the patch's sub-tile PSFs (S3.3.1)
    x₂ = x₁ + g · (w − x₁)                Wiener in residual form, learnable gate g (starts at 0)
    y  = NAFNet₂([x₂, w − x₁]) (+ x₂)

At initialisation NAFNet₁ and NAFNet₂ are identities and g = 0, so y = x exactly; the gate and the
second network learn how much of the deconvolution to use.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from lensopt.restore.config import RestoreConfig
from lensopt.restore.nafnet import NAFNet
from lensopt.restore.wiener import Wiener

__all__ = ["mean_patch_psf", "restore_patches", "ConditionedRestorer"]


def mean_patch_psf(psfs: Tensor) -> Tensor:
    """(B, T, C, k, k) PSFs of the T sub-tiles of each patch → their mean (B, C, k, k), renormalised
    to unit sum per channel."""
    if psfs.ndim != 5:
        raise ValueError(f"expected (B, T, C, k, k) PSFs, got {tuple(psfs.shape)}")
    k = psfs.mean(1)
    return k / k.sum((-2, -1), keepdim=True).clamp_min(torch.finfo(k.dtype).tiny)


def restore_patches(model: ConditionedRestorer, image: Tensor, psf: Tensor) -> Tensor:
    """Functional entry point: ``model(image, psf)`` with shape checks. image (B, C, H, W), psf (B, C, k, k)."""
    if image.ndim != 4 or psf.ndim != 4 or psf.shape[0] != image.shape[0]:
        raise ValueError(f"expected image (B, C, H, W) and psf (B, C|1, k, k), got {tuple(image.shape)}, "
                         f"{tuple(psf.shape)}")
    return model(image, psf)


class ConditionedRestorer(nn.Module):
    """NAFNet → Wiener(patch PSF) → NAFNet, configured by ``RestoreConfig``."""

    def __init__(self, config: RestoreConfig | None = None) -> None:
        super().__init__()
        self.config = cfg = config or RestoreConfig()
        arch = dict(width=cfg.width, encoder_blocks=cfg.encoder_blocks, middle_blocks=cfg.middle_blocks,
                    decoder_blocks=cfg.decoder_blocks)
        self.pre = NAFNet(cfg.channels, cfg.channels, **arch)
        self.post = NAFNet(2 * cfg.channels, cfg.channels, **arch)
        self.wiener = Wiener(cfg.snr)
        self.gate = nn.Parameter(torch.zeros(()))

    def forward(self, x: Tensor, psf: Tensor) -> Tensor:
        x1 = self.pre(x)
        delta = self.wiener(x1, psf) - x1
        x2 = x1 + self.gate.to(x.dtype) * delta
        return self.post(torch.cat([x2, delta], dim=1), skip=x2)
