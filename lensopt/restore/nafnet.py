"""NAFNet (Chen et al. 2022, "Simple Baselines for Image Restoration"): nonlinear-activation-free
blocks in a UNet. The block is written as a function of its parameters first (``nafnet_block``);
the modules hold parameters and call it.

Every block's residual scales β and γ start at zero (as in NAFNet), and the network's last
convolution starts at zero here, so a fresh ``NAFNet`` is exactly the identity: the conditioned
model starts as identity, which keeps the first joint lens steps stable (S3.2).
"""

from __future__ import annotations

import torch
from torch import Tensor, nn
from torch.nn import functional as tnf

__all__ = ["layer_norm_2d", "simple_gate", "nafnet_block", "NAFBlock", "NAFNet"]


def layer_norm_2d(x: Tensor, weight: Tensor, bias: Tensor, eps: float = 1e-6) -> Tensor:
    """Layer norm over the channel axis of (B, C, H, W), per pixel."""
    mu = x.mean(1, keepdim=True)
    var = (x - mu).pow(2).mean(1, keepdim=True)
    return (x - mu) / (var + eps).sqrt() * weight[:, None, None] + bias[:, None, None]


def simple_gate(x: Tensor) -> Tensor:
    """Split channels in two halves and multiply them: (B, 2C, H, W) → (B, C, H, W)."""
    a, b = x.chunk(2, dim=1)
    return a * b


def nafnet_block(x: Tensor, p: dict[str, Tensor]) -> Tensor:
    """One NAFNet block on (B, C, H, W) with parameters ``p`` (names as in ``NAFBlock``)."""
    c2 = p["conv2.weight"].shape[0]
    y = layer_norm_2d(x, p["norm1.weight"], p["norm1.bias"])
    y = tnf.conv2d(y, p["conv1.weight"], p["conv1.bias"])
    y = tnf.conv2d(y, p["conv2.weight"], p["conv2.bias"], padding=1, groups=c2)
    y = simple_gate(y)
    y = y * tnf.conv2d(y.mean((2, 3), keepdim=True), p["sca.weight"], p["sca.bias"])
    y = tnf.conv2d(y, p["conv3.weight"], p["conv3.bias"])
    x = x + y * p["beta"]
    y = layer_norm_2d(x, p["norm2.weight"], p["norm2.bias"])
    y = simple_gate(tnf.conv2d(y, p["conv4.weight"], p["conv4.bias"]))
    y = tnf.conv2d(y, p["conv5.weight"], p["conv5.bias"])
    return x + y * p["gamma"]


class _Norm(nn.Module):
    def __init__(self, c: int) -> None:
        super().__init__()
        self.weight = nn.Parameter(torch.ones(c))
        self.bias = nn.Parameter(torch.zeros(c))


class NAFBlock(nn.Module):
    """Parameters of one block (expansion 2 for both the depthwise and the feed-forward branch)."""

    def __init__(self, c: int) -> None:
        super().__init__()
        self.norm1, self.norm2 = _Norm(c), _Norm(c)
        self.conv1 = nn.Conv2d(c, 2 * c, 1)
        self.conv2 = nn.Conv2d(2 * c, 2 * c, 3, padding=1, groups=2 * c)
        self.sca = nn.Conv2d(c, c, 1)
        self.conv3 = nn.Conv2d(c, c, 1)
        self.conv4 = nn.Conv2d(c, 2 * c, 1)
        self.conv5 = nn.Conv2d(c, c, 1)
        self.beta = nn.Parameter(torch.zeros(1, c, 1, 1))
        self.gamma = nn.Parameter(torch.zeros(1, c, 1, 1))

    def forward(self, x: Tensor) -> Tensor:
        return nafnet_block(x, dict(self.named_parameters()))


class NAFNet(nn.Module):
    """UNet of NAFNet blocks: (B, C_in, H, W) → (B, C_out, H, W), output = ``skip`` + network.

    H and W are reflect-padded to a multiple of 2**len(encoder_blocks) and cropped back.
    """

    def __init__(self, in_channels: int, out_channels: int, width: int = 16,
                 encoder_blocks: tuple[int, ...] = (1, 1, 1, 4), middle_blocks: int = 1,
                 decoder_blocks: tuple[int, ...] = (1, 1, 1, 1)) -> None:
        super().__init__()
        if len(encoder_blocks) != len(decoder_blocks):
            raise ValueError("encoder_blocks and decoder_blocks must have the same length")
        self.intro = nn.Conv2d(in_channels, width, 3, padding=1)
        self.ending = nn.Conv2d(width, out_channels, 3, padding=1)
        nn.init.zeros_(self.ending.weight)
        nn.init.zeros_(self.ending.bias)
        self.encoders, self.downs = nn.ModuleList(), nn.ModuleList()
        self.ups, self.decoders = nn.ModuleList(), nn.ModuleList()
        c = width
        for n in encoder_blocks:
            self.encoders.append(nn.Sequential(*[NAFBlock(c) for _ in range(n)]))
            self.downs.append(nn.Conv2d(c, 2 * c, 2, stride=2))
            c *= 2
        self.middle = nn.Sequential(*[NAFBlock(c) for _ in range(middle_blocks)])
        for n in decoder_blocks:
            self.ups.append(nn.Sequential(nn.Conv2d(c, 2 * c, 1, bias=False), nn.PixelShuffle(2)))
            c //= 2
            self.decoders.append(nn.Sequential(*[NAFBlock(c) for _ in range(n)]))
        self.multiple = 2 ** len(encoder_blocks)

    def forward(self, x: Tensor, skip: Tensor | None = None) -> Tensor:
        h, w = x.shape[-2:]
        m = self.multiple
        ph, pw = (-h) % m, (-w) % m
        y = tnf.pad(x, (0, pw, 0, ph), mode="reflect") if ph or pw else x
        y = self.intro(y)
        skips = []
        for enc, down in zip(self.encoders, self.downs, strict=True):
            y = enc(y)
            skips.append(y)
            y = down(y)
        y = self.middle(y)
        for dec, up, s in zip(self.decoders, self.ups, reversed(skips), strict=True):
            y = dec(up(y) + s)
        y = self.ending(y)[..., :h, :w]
        return y + (x if skip is None else skip)
