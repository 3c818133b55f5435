"""Textured dead leaves: procedural scenes whose statistics are closer to photographs' (issue 27).

The leaves of ``datasets.dead_leaves`` (the same disks for the same seed: p(r) ∝ r⁻³, occlusion), but
each leaf is no longer a flat patch of a random saturated colour:

* colour: a luminance (sRGB-encoded) drawn from Beta(2, 2.5) (mean ≈ 0.44, as photographs' grey level)
  and a small chroma (per-channel offsets with a per-leaf saturation ~ |N(0, 0.12)|), so most leaves are
  desaturated and a few are vivid — photographs' colour distribution rather than the uniform RGB cube;
* shading: a linear luminance gradient across the leaf (a random direction, up to ±60 % at its rim);
* texture: a multiplicative pink-noise modulation (one of four 1/f-amplitude fields, i.e. power ∝ 1/f²,
  per-leaf strength), and on some leaves an oriented sinusoidal grating (1–8 cycles per diameter);
* edges: a share of the leaves is blurred (one Gaussian σ per scene, 0.6–2 pixels, as out-of-focus
  objects), the others keep sharp edges;
* tone: optionally a random power law per scene (linear value ** γ, γ in ``gamma``), as sensors' and
  tone curves' differences.

Everything after the disk geometry is vectorised torch on ``device``; every draw comes from ``seed``.
The overall power spectrum falls as ≈ 1/f² (the slope photographs show, Field 1987; van der Schaaf &
van Hateren 1996), which tests measure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import torch
import torch.nn.functional as F

from lensopt.errors import LensoptError
from lensopt.imaging.datasets import DeadLeaves, leaf_geometry

__all__ = ["TexturedLeaves", "textured_leaves", "pink_noise", "radial_power_slope"]

_FIELDS = 4  # pink-noise fields a scene draws; each leaf modulates by one of them


def _srgb_to_linear_t(v: torch.Tensor) -> torch.Tensor:
    return torch.where(v <= 0.04045, v / 12.92, ((v.clamp_min(0.04045) + 0.055) / 1.055) ** 2.4)


def pink_noise(count: int, height: int, width: int, generator: torch.Generator, *,
               device: torch.device | str | None = None, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """``[count, height, width]`` zero-mean, unit-variance periodic noise with power ∝ 1/f² (amplitude 1/f).

    White Gaussian noise (drawn on the CPU from ``generator``, so the same seed gives the same field on
    every device) filtered in the Fourier domain; the DC term is removed."""
    white = torch.randn(count, height, width, generator=generator, dtype=torch.float64).to(device=device)
    fy = torch.fft.fftfreq(height, device=device, dtype=torch.float64)[:, None]
    fx = torch.fft.rfftfreq(width, device=device, dtype=torch.float64)[None, :]
    f = torch.sqrt(fx * fx + fy * fy)
    amp = torch.where(f > 0, 1.0 / f.clamp_min(1e-12), torch.zeros_like(f))
    field = torch.fft.irfft2(torch.fft.rfft2(white) * amp, s=(height, width))
    field = field - field.mean(dim=(-2, -1), keepdim=True)
    field = field / field.std(dim=(-2, -1), keepdim=True).clamp_min(1e-12)
    return field.to(dtype)


def _gaussian_blur(img: torch.Tensor, sigma: float) -> torch.Tensor:
    """Separable Gaussian blur of ``[C, H, W]`` (σ in pixels, reflected borders)."""
    half = max(1, math.ceil(3.0 * sigma))
    x = torch.arange(-half, half + 1, device=img.device, dtype=img.dtype)
    k = torch.exp(-0.5 * (x / sigma) ** 2)
    k = k / k.sum()
    c, h, w = img.shape
    out = img[:, None]
    pad_w, pad_h = min(half, w - 1), min(half, h - 1)
    if pad_w > 0:
        kw = k[half - pad_w:half + pad_w + 1].view(1, 1, 1, -1)
        out = F.conv2d(F.pad(out, (pad_w, pad_w, 0, 0), mode="reflect"), kw)
    if pad_h > 0:
        kh = k[half - pad_h:half + pad_h + 1].view(1, 1, -1, 1)
        out = F.conv2d(F.pad(out, (0, 0, pad_h, pad_h), mode="reflect"), kh)
    return out[:, 0]


def textured_leaves(
    height: int,
    width: int,
    *,
    seed: int,
    channels: int = 3,
    r_min: float = 0.004,
    r_max: float = 0.25,
    coverage: float = 6.0,
    max_disks: int = 20000,
    texture: float = 1.0,
    grating: float = 0.25,
    blur: float = 0.3,
    gamma: tuple[float, float] | None = (0.8, 1.25),
    device: torch.device | str | None = None,
    dtype: torch.dtype = torch.float32,
) -> torch.Tensor:
    """A textured dead-leaves scene, ``[channels, height, width]`` in linear light, values in [0, 1].

    Args:
        height, width, seed, r_min, r_max, coverage, max_disks: the disks, as ``datasets.dead_leaves``
            (the same seed gives the same disks and occlusions).
        channels: 3 (colour) or 1 (the luminance only).
        texture: strength of the pink-noise modulation (0: none; 1: per-leaf amplitude up to 0.35).
        grating: share of leaves that carry an oriented grating (0…1).
        blur: share of leaves rendered out of focus (0…1).
        gamma: range of the per-scene power law applied to linear values, or None for none.
    """
    for name, v in (("texture", texture), ("grating", grating), ("blur", blur)):
        if not (math.isfinite(v) and v >= 0 and (name == "texture" or v <= 1)):
            raise LensoptError("must be ≥ 0 (a share: at most 1)", path=f"textured_leaves.{name}", got=v)
    if gamma is not None and not 0 < gamma[0] <= gamma[1]:
        raise LensoptError("need 0 < low ≤ high", path="textured_leaves.gamma", got=gamma)
    if channels not in (1, 3):
        raise LensoptError("must be 1 or 3", path="textured_leaves.channels", got=channels)
    _, leaves = leaf_geometry(height, width, seed=seed, r_min=r_min, r_max=r_max, coverage=coverage,
                              max_disks=max_disks, path="textured_leaves")
    n = leaves.count + 1  # with the background leaf
    rng = np.random.default_rng([int(seed) % 2**63, 27])  # leaf looks: a stream apart from the geometry's
    lum = rng.beta(2.0, 2.5, n)
    sat = np.abs(rng.normal(0.0, 0.12, n))
    chroma = rng.normal(0.0, 1.0, (n, 3))
    chroma -= chroma.mean(1, keepdims=True)
    base = np.clip(lum[:, None] + sat[:, None] * chroma, 0.0, 1.0)
    grad = rng.uniform(0.0, 0.6, n)
    grad_dir = rng.uniform(0.0, 2 * math.pi, n)
    tex_amp = texture * rng.uniform(0.0, 0.35, n)
    tex_field = rng.integers(0, _FIELDS, n)
    grating_amp = np.where(rng.random(n) < grating, rng.uniform(0.05, 0.3, n), 0.0)
    cycles = np.exp(rng.uniform(0.0, math.log(8.0), n))
    grating_dir = rng.uniform(0.0, 2 * math.pi, n)
    phase = rng.uniform(0.0, 2 * math.pi, n)
    blurred = rng.random(n) < blur
    sigma = float(rng.uniform(0.6, 2.0))
    u_gamma = float(rng.random())  # drawn whatever ``gamma`` is: the other draws do not depend on it
    gam = gamma[0] + u_gamma * (gamma[1] - gamma[0]) if gamma is not None else 1.0
    noise_seed = int(rng.integers(0, 2**62))
    # The background leaf: centred on the frame, the frame's half-diagonal as radius.
    radius = np.append(leaves.radius, 0.5 * math.hypot(height, width))
    cx, cy = np.append(leaves.cx, 0.5 * width), np.append(leaves.cy, 0.5 * height)
    # cycles per pixel of a grating, at most 0.35 (below Nyquist).
    freq = np.minimum(cycles / (2.0 * radius), 0.35)

    def per_leaf(a: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(a, dtype=torch.float64).to(device=device, dtype=dtype)

    idx = leaves.index.to(device)  # [H, W]
    yy = torch.arange(height, device=device, dtype=dtype)[:, None] + 0.5
    xx = torch.arange(width, device=device, dtype=dtype)[None, :] + 0.5
    dx, dy = xx - per_leaf(cx)[idx], yy - per_leaf(cy)[idx]
    r = per_leaf(radius)[idx]
    across = dx * per_leaf(np.cos(grad_dir))[idx] + dy * per_leaf(np.sin(grad_dir))[idx]
    shade = 1.0 + per_leaf(grad)[idx] * across / r
    fields = pink_noise(_FIELDS, height, width, torch.Generator().manual_seed(noise_seed), device=device, dtype=dtype)
    tex = fields.view(_FIELDS, -1).gather(0, per_leaf(tex_field).long()[idx].view(1, -1)).view(height, width)
    along = dx * per_leaf(np.cos(grating_dir))[idx] + dy * per_leaf(np.sin(grating_dir))[idx]
    wave = torch.sin(2 * math.pi * per_leaf(freq)[idx] * along + per_leaf(phase)[idx])
    mod = shade * (1.0 + per_leaf(tex_amp)[idx] * tex + per_leaf(grating_amp)[idx] * wave)
    srgb = (per_leaf(base)[idx].permute(2, 0, 1) * mod).clamp(0.0, 1.0)  # [3, H, W] sRGB-encoded
    img = _srgb_to_linear_t(srgb)
    if blurred.any():
        img = torch.where(per_leaf(blurred.astype(np.float64))[idx].bool(), _gaussian_blur(img, sigma), img)
    if gam != 1.0:
        img = img.clamp_min(0.0) ** gam
    if channels == 1:
        w = torch.tensor([0.2126, 0.7152, 0.0722], device=device, dtype=dtype)  # Rec. 709 luminance
        img = (img * w[:, None, None]).sum(0, keepdim=True)
    return img.clamp(0.0, 1.0).contiguous()


@dataclass(frozen=True)
class TexturedLeaves(DeadLeaves):
    """Procedural textured scenes: scene ``k`` is ``textured_leaves(..., seed=hash(seed, k))``."""

    tag: ClassVar[str] = "textured-leaves"

    def render(self, height: int, width: int, *, seed: int) -> torch.Tensor:
        return textured_leaves(height, width, seed=seed, channels=self.channels, r_min=self.r_min, r_max=self.r_max)


def radial_power_slope(img: torch.Tensor, *, f_lo: float = 0.02, f_hi: float = 0.25) -> float:
    """Slope of log power against log frequency of ``img`` ``[C, H, W]`` (mean over channels of a Hann-
    windowed, mean-removed image), fitted by least squares to the radially averaged spectrum on
    ``f_lo ≤ f ≤ f_hi`` cycles per pixel in log-spaced bins. Photographs give ≈ −2."""
    x = img.to(torch.float64).mean(0)
    h, w = x.shape
    win = torch.hann_window(h, periodic=False, dtype=torch.float64)[:, None] * \
        torch.hann_window(w, periodic=False, dtype=torch.float64)[None, :]
    x = (x - x.mean()) * win
    p = torch.fft.fft2(x).abs() ** 2
    fy = torch.fft.fftfreq(h, dtype=torch.float64)[:, None]
    fx = torch.fft.fftfreq(w, dtype=torch.float64)[None, :]
    f = torch.sqrt(fx * fx + fy * fy)
    edges = np.exp(np.linspace(math.log(f_lo), math.log(f_hi), 13))
    lf, lp = [], []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = (f >= lo) & (f < hi)
        if bool(m.any()):
            lf.append(math.log(float(f[m].mean())))
            lp.append(math.log(float(p[m].mean())))
    return float(np.polyfit(lf, lp, 1)[0])
