"""Spatially varying convolution by overlap-add with Hann windows (S1.5.2).

The image (C, H, W) is split into a W_g × H_g grid of patches; each patch is extended on every side
by half the overlap (OP × patch size), convolved (FFT) with its PSF, and the convolved patches are
recombined as a pixel-wise weighted average with separable Hann ramps across the patch borders. The
1D weights sum to exactly 1 everywhere, so a uniform image stays uniform and a single PSF gives plain
convolution. Image borders are padded by reflection, tile by tile (no padded copy of the whole image).
Large patches (``PLANE_MIN_BYTES``) without autograd go one channel at a time through zero-padded FFT
buffers made once (a few planes: the memory beyond the input and output images does not grow with the
image); small patches, and any with autograd (differentiable rendering), go in batches whose FFT
buffers stay under ``max_bytes``.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from lensopt.analysis.fft_size import next_fast_len

__all__ = ["patch_bounds", "hann_weights", "overlap_add_convolve", "PLANE_MIN_BYTES"]

#: Without autograd, patches whose FFT buffers (all channels) exceed this go one plane at a time.
PLANE_MIN_BYTES = 8 * 2**20


def patch_bounds(length: int, parts: int) -> list[tuple[int, int]]:
    """Split [0, length) into ``parts`` near-equal cores [a, b)."""
    edges = [round(i * length / parts) for i in range(parts + 1)]
    return [(edges[i], edges[i + 1]) for i in range(parts)]


def hann_weights(length: int, parts: int, overlap: float, *, dtype: torch.dtype = torch.float32,
                 device: torch.device | None = None) -> tuple[Tensor, list[tuple[int, int]]]:
    """1D blending weights (parts, length) that sum to 1 at every pixel, and each part's support.

    Across each interior border a Hann ramp (sin²) of total width 2·ov, ov = round(overlap·core/2),
    hands over from one part to the next.
    """
    cores = patch_bounds(length, parts)
    x = torch.arange(length, dtype=torch.float64, device=device) + 0.5
    w = torch.zeros(parts, length, dtype=torch.float64, device=device)
    ovs = [0] * (parts + 1)
    for i in range(1, parts):
        core = min(cores[i - 1][1] - cores[i - 1][0], cores[i][1] - cores[i][0])
        ovs[i] = max(0, min(round(overlap * core / 2), core // 2))
    for i, (a, b) in enumerate(cores):
        lo = torch.ones_like(x)
        hi = torch.ones_like(x)
        if i > 0:  # rising ramp across border a
            ov = ovs[i]
            lo = _ramp(x, a, ov)
        if i < parts - 1:
            ov = ovs[i + 1]
            hi = 1.0 - _ramp(x, b, ov)
        w[i] = lo * hi
    support = [(a - ovs[i], b + ovs[i + 1]) for i, (a, b) in enumerate(cores)]
    return w.to(dtype), support


def _ramp(x: Tensor, border: int, ov: int) -> Tensor:
    """0 before border − ov, 1 after border + ov, sin² in between (a step when ov = 0)."""
    if ov == 0:
        return (x >= border).to(x.dtype)
    t = ((x - (border - ov)) / (2 * ov)).clamp(0.0, 1.0)
    return torch.sin(0.5 * math.pi * t) ** 2


def overlap_add_convolve(
    image: Tensor,
    psfs: Tensor,
    *,
    overlap: float = 0.25,
    max_bytes: int = 128 * 2**20,
) -> Tensor:
    """Convolve ``image`` with a grid of PSFs.

    Args:
        image: (C, H, W) linear image.
        psfs: (H_g, W_g, C, K, K) PSF grid in image orientation (row 0 at the top of the image),
            K odd, each summing to 1; grid row r, column c applies to patch (r, c).
        overlap: OP, the fraction of a patch that overlaps its neighbour (S1.5.2).
        max_bytes: bound on the FFT buffers of one batch of patches (small patches; with autograd, all).

    Returns:
        (C, H, W) convolved image, same dtype.
    """
    c, h, w = image.shape
    gh, gw = psfs.shape[:2]
    k = psfs.shape[-1]
    r = k // 2
    wy, sup_y = hann_weights(h, gh, overlap, dtype=image.dtype, device=image.device)
    wx, sup_x = hann_weights(w, gw, overlap, dtype=image.dtype, device=image.device)
    ph = max(b - a for a, b in sup_y)
    pw = max(b - a for a, b in sup_x)
    fh = next_fast_len(ph + 2 * r)
    fw = next_fast_len(pw + 2 * r)
    whole = None  # the reflect-padded image, made only when a tile cannot be padded on its own
    out = torch.zeros_like(image)
    patches = [(i, j) for i in range(gh) for j in range(gw)]

    def tile_of(i: int, j: int) -> Tensor:
        nonlocal whole
        (y0, y1), (x0, x1) = sup_y[i], sup_x[j]
        tile = _tile(image, y0 - r, y1 + r, x0 - r, x1 + r)
        if tile is None:
            whole = _reflect_pad(image, r) if whole is None else whole
            tile = whole[:, y0:y1 + 2 * r, x0:x1 + 2 * r]
        return tile

    def add(i: int, j: int, conv: Tensor, channels: slice) -> None:
        (y0, y1), (x0, x1) = sup_y[i], sup_x[j]
        # Full linear convolution index (y − y0 + 2r) ↔ output pixel y (kernel centred on r).
        valid = conv[..., 2 * r: 2 * r + (y1 - y0), 2 * r: 2 * r + (x1 - x0)]
        out[channels, y0:y1, x0:x1] += valid * (wy[i, y0:y1, None] * wx[j, None, x0:x1])

    per_patch = c * fh * (fw // 2 + 1) * 8 * 3 + c * fh * fw * 4 * 2  # 3 spectra (tile, kernel, product), 2 real
    grad = torch.is_grad_enabled() and (image.requires_grad or psfs.requires_grad)
    if not grad and per_patch > PLANE_MIN_BYTES:
        # Large patches one channel at a time through FFT buffers made once: faster than batches with one
        # thread (MKL's FFT), and the FFT memory stays a few planes (batched 3-channel 1k² transforms left
        # ~140 MB more resident). Small patches go in batches: fewer, longer calls.
        bufs = _PlaneFft(fh, fw, k, image.dtype, image.device)
        for i, j in patches:
            tile = tile_of(i, j)
            for ch in range(c):
                add(i, j, bufs.convolve(tile[ch], psfs[i, j, ch]), slice(ch, ch + 1))
        return out
    # Batches of patches (and with autograd: differentiable rendering), out of place.
    chunk = max(1, int(max_bytes // max(per_patch, 1)))
    for start in range(0, len(patches), chunk):
        group = patches[start:start + chunk]
        tiles = torch.zeros(len(group), c, ph + 2 * r, pw + 2 * r, dtype=image.dtype, device=image.device)
        for n, (i, j) in enumerate(group):
            tile = tile_of(i, j)
            tiles[n, :, : tile.shape[-2], : tile.shape[-1]] = tile
        kern = torch.stack([psfs[i, j] for i, j in group]).to(image.dtype)
        conv = torch.fft.irfft2(torch.fft.rfft2(tiles, s=(fh, fw)) * torch.fft.rfft2(kern, s=(fh, fw)), s=(fh, fw))
        del tiles, kern
        for n, (i, j) in enumerate(group):
            add(i, j, conv[n], slice(None))
    return out


class _PlaneFft:
    """Linear convolution of one image plane with one kernel through zero-padded fh × fw FFT buffers made
    once: the same numbers as ``irfft2(rfft2(x, s) * rfft2(k, s), s)`` of the unpadded arrays."""

    def __init__(self, fh: int, fw: int, k: int, dtype: torch.dtype, device: torch.device) -> None:
        cdtype = torch.complex128 if dtype == torch.float64 else torch.complex64
        self.tile = torch.zeros(fh, fw, dtype=dtype, device=device)
        self.kern = torch.zeros(fh, fw, dtype=dtype, device=device)  # only [:k, :k] is ever written
        self.spec = torch.empty(fh, fw // 2 + 1, dtype=cdtype, device=device)
        self.kspec = torch.empty_like(self.spec)
        self.conv = torch.empty(fh, fw, dtype=dtype, device=device)
        self.k = k
        self.shape = (0, 0)  # of the tile last written (the rest of the buffer is zero)

    def convolve(self, plane: Tensor, kernel: Tensor) -> Tensor:
        th, tw = plane.shape
        ph, pw = self.shape
        if ph > th:
            self.tile[th:ph, :pw] = 0
        if pw > tw:
            self.tile[:th, tw:pw] = 0
        self.tile[:th, :tw] = plane
        self.shape = (th, tw)
        self.kern[: self.k, : self.k] = kernel
        torch.fft.rfft2(self.tile, out=self.spec)
        torch.fft.rfft2(self.kern, out=self.kspec)
        self.spec.mul_(self.kspec)
        return torch.fft.irfft2(self.spec, s=self.tile.shape, out=self.conv)


def _tile(image: Tensor, ya: int, yb: int, xa: int, xb: int) -> Tensor | None:
    """Rows [ya, yb) and columns [xa, xb) of the image reflected at its borders, or None when one
    reflection does not reach (a tile thinner than its padding)."""
    _, h, w = image.shape
    ca, cb, da, db = max(ya, 0), min(yb, h), max(xa, 0), min(xb, w)
    pads = (da - xa, xb - db, ca - ya, yb - cb)
    sub = image[:, ca:cb, da:db]
    if max(pads[0], pads[1]) >= sub.shape[-1] or max(pads[2], pads[3]) >= sub.shape[-2]:
        return None
    if not any(pads):
        return sub
    return torch.nn.functional.pad(sub.unsqueeze(0), pads, mode="reflect")[0]


def _reflect_pad(image: Tensor, r: int) -> Tensor:
    """Reflect-pad by r on every side (zeros beyond one reflection when r ≥ the image size)."""
    _, h, w = image.shape
    pad_h, pad_w = min(r, h - 1), min(r, w - 1)
    padded = torch.nn.functional.pad(image.unsqueeze(0), (pad_w, pad_w, pad_h, pad_h), mode="reflect")[0]
    if pad_h < r or pad_w < r:
        padded = torch.nn.functional.pad(padded, (r - pad_w, r - pad_w, r - pad_h, r - pad_h))
    return padded
