"""Overlap-add spatially varying convolution (S1.5.2)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.signal import fftconvolve

from lensopt.imaging.convolve import hann_weights, overlap_add_convolve

F32, F64 = torch.float32, torch.float64


def random_psfs(gh: int, gw: int, c: int, k: int, seed: int = 0) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    p = torch.rand(gh, gw, c, k, k, generator=gen, dtype=F64) ** 3
    return p / p.sum((-1, -2), keepdim=True)


@pytest.mark.parametrize(("length", "parts", "overlap"), [(100, 1, 0.25), (100, 4, 0.25), (97, 5, 0.5), (30, 7, 0.0)])
def test_hann_weights_sum_to_one(length: int, parts: int, overlap: float) -> None:
    w, support = hann_weights(length, parts, overlap, dtype=F64)
    assert torch.allclose(w.sum(0), torch.ones(length, dtype=F64), atol=1e-12)
    for i, (a, b) in enumerate(support):  # each part's weight vanishes outside its support
        assert float(w[i, :max(a, 0)].abs().sum()) == 0.0 and float(w[i, b:].abs().sum()) == 0.0


def test_uniform_image_stays_uniform_with_different_psfs() -> None:
    img = torch.full((3, 90, 120), 0.37, dtype=F64)
    out = overlap_add_convolve(img, random_psfs(4, 5, 3, 11), overlap=0.25)
    assert torch.allclose(out, img, atol=1e-12)


def test_delta_psfs_leave_the_image_unchanged() -> None:
    gen = torch.Generator().manual_seed(2)
    img = torch.rand(1, 50, 70, generator=gen, dtype=F64)
    psfs = torch.zeros(3, 4, 1, 7, 7, dtype=F64)
    psfs[..., 3, 3] = 1.0
    assert torch.allclose(overlap_add_convolve(img, psfs), img, atol=1e-12)


def test_one_psf_is_plain_convolution_with_reflected_borders() -> None:
    # Independent oracle: scipy's FFT convolution of the reflect-padded image.
    gen = torch.Generator().manual_seed(3)
    img = torch.rand(2, 40, 56, generator=gen, dtype=F64)
    psf = random_psfs(1, 1, 2, 9)
    out = overlap_add_convolve(img, psf.expand(3, 2, 2, 9, 9).contiguous(), overlap=0.3)
    for ch in range(2):
        padded = np.pad(img[ch].numpy(), 4, mode="reflect")
        ref = fftconvolve(padded, psf[0, 0, ch].numpy(), mode="valid")
        assert np.abs(out[ch].numpy() - ref).max() < 1e-12


def test_chunked_processing_gives_the_same_result(monkeypatch: pytest.MonkeyPatch) -> None:
    import lensopt.imaging.convolve as conv

    gen = torch.Generator().manual_seed(4)
    img = torch.rand(3, 64, 80, generator=gen, dtype=F32)
    psfs = random_psfs(3, 4, 3, 7).to(F32)
    small = overlap_add_convolve(img, psfs)  # small patches, no autograd: one batch
    monkeypatch.setattr(conv, "PLANE_MIN_BYTES", 0)
    whole = overlap_add_convolve(img, psfs)  # no autograd: plane by plane
    assert torch.allclose(whole, small, atol=1e-6)
    batched = overlap_add_convolve(img, psfs.requires_grad_(True))  # autograd: all patches in one batch
    tiled = overlap_add_convolve(img, psfs, max_bytes=1)  # autograd, one patch at a time
    assert torch.allclose(whole, batched.detach(), atol=1e-6)
    assert torch.allclose(whole, tiled.detach(), atol=1e-6)


def test_energy_is_kept_in_the_interior() -> None:
    # A point source far from borders and patch seams keeps its energy through its patch's PSF.
    img = torch.zeros(1, 60, 60, dtype=F64)
    img[0, 15, 15] = 1.0
    psfs = random_psfs(2, 2, 1, 5)
    out = overlap_add_convolve(img, psfs, overlap=0.2)
    assert float(out.sum()) == pytest.approx(1.0, abs=1e-12)
    assert torch.allclose(out[0, 13:18, 13:18], psfs[0, 0, 0], atol=1e-12)
