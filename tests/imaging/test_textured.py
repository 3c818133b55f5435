"""Textured dead leaves (issue 27): the spectrum estimator against closed forms, the scenes' power-law
slope, colour statistics, blur and tone against independent computations, determinism and dtype/device."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from lensopt.errors import LensoptError
from lensopt.imaging.datasets import dead_leaves, leaf_geometry
from lensopt.imaging.textured import TexturedLeaves, _gaussian_blur, pink_noise, radial_power_slope, textured_leaves


def _power_law_field(n: int, exponent: float, seed: int) -> torch.Tensor:
    """Gaussian noise whose power spectrum is f^exponent, built with numpy's FFT (independent of pink_noise)."""
    rng = np.random.default_rng(seed)
    spec = np.fft.fft2(rng.standard_normal((n, n)))
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(n), np.fft.fftfreq(n), indexing="ij"))
    f[0, 0] = 1.0
    field = np.real(np.fft.ifft2(spec * f ** (exponent / 2)))
    return torch.from_numpy(field)[None]


@pytest.mark.parametrize("exponent", [0.0, -2.0, -3.0])
def test_spectrum_slope_estimator_recovers_known_power_laws(exponent: float) -> None:
    # Closed form: noise filtered by f^(e/2) has power ∝ f^e; white noise (e = 0) has a flat spectrum.
    slopes = [radial_power_slope(_power_law_field(256, exponent, s)) for s in range(4)]
    assert abs(float(np.mean(slopes)) - exponent) < 0.15, slopes


def test_pink_noise_is_unit_variance_with_power_one_over_f_squared() -> None:
    f = pink_noise(3, 128, 160, torch.Generator().manual_seed(0), dtype=torch.float64)
    assert f.shape == (3, 128, 160) and f.dtype == torch.float64
    assert torch.allclose(f.mean((-2, -1)), torch.zeros(3, dtype=torch.float64), atol=1e-12)
    assert torch.allclose(f.std((-2, -1)), torch.ones(3, dtype=torch.float64), atol=1e-12)
    assert abs(np.mean([radial_power_slope(f[i:i + 1]) for i in range(3)]) + 2.0) < 0.15


def test_textured_scenes_fall_as_one_over_f_squared() -> None:
    # Photographs' power spectra fall as ≈ 1/f² (Field 1987; van der Schaaf & van Hateren 1996). Measured
    # over 8 scenes at 256² (0.02–0.25 cycles/pixel): textured ≈ −1.90, plain dead leaves ≈ −1.83.
    slopes = [radial_power_slope(textured_leaves(256, 256, seed=s)) for s in range(8)]
    assert -2.3 < float(np.mean(slopes)) < -1.7, slopes
    assert all(-2.8 < s < -1.2 for s in slopes), slopes


def test_textured_leaves_keep_the_dead_leaves_disks() -> None:
    # The same seed draws the same disks: a leaf of the plain scene (one flat colour) maps to one leaf index.
    h = w = 64
    _, leaves = leaf_geometry(h, w, seed=5, r_min=0.004, r_max=0.25, coverage=6.0, max_disks=20000)
    plain = dead_leaves(h, w, seed=5, dtype=torch.float64).reshape(3, -1).T
    idx = leaves.index.reshape(-1)
    for k in torch.unique(idx)[:50]:
        assert torch.unique(plain[idx == k], dim=0).shape[0] == 1


def test_textured_colours_are_less_saturated_than_the_rgb_cube() -> None:
    # Plain dead leaves draw each channel uniformly in [0, 1] (sRGB-encoded): the expected range of 3 uniform
    # draws is (n − 1)/(n + 1) = 0.5. Textured leaves are mostly desaturated, like photographs.
    from lensopt.imaging.io import linear_to_srgb

    def mean_range(img: torch.Tensor) -> float:
        s = linear_to_srgb(img.permute(1, 2, 0).numpy())
        return float((s.max(-1) - s.min(-1)).mean())

    plain = np.mean([mean_range(dead_leaves(128, 128, seed=s)) for s in range(6)])
    tex = np.mean([mean_range(textured_leaves(128, 128, seed=s)) for s in range(6)])
    assert abs(plain - 0.5) < 0.04, plain
    assert tex < 0.3, tex


def test_gaussian_blur_matches_scipy() -> None:
    from scipy.ndimage import gaussian_filter

    img = torch.rand(2, 40, 33, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    for sigma in (0.6, 1.3, 2.0):
        ref = np.stack([gaussian_filter(c, sigma, mode="mirror", radius=math.ceil(3 * sigma)) for c in img.numpy()])
        assert np.allclose(_gaussian_blur(img, sigma).numpy(), ref, atol=1e-12)


def test_blur_gamma_and_channels_act_as_documented() -> None:
    base = textured_leaves(96, 96, seed=3, blur=0.0, gamma=None, dtype=torch.float64)
    # A fixed power law γ = 2 squares every linear value (the other draws do not depend on gamma).
    sq = textured_leaves(96, 96, seed=3, blur=0.0, gamma=(2.0, 2.0), dtype=torch.float64)
    assert torch.allclose(sq, base**2, atol=1e-12)
    # Every leaf out of focus: less power above 0.25 cycles/pixel than with every leaf sharp.
    soft = textured_leaves(96, 96, seed=3, blur=1.0, gamma=None, dtype=torch.float64)

    def high(img: torch.Tensor) -> float:
        p = torch.fft.fft2(img.mean(0) - img.mean()).abs() ** 2
        f = torch.sqrt(torch.fft.fftfreq(96)[:, None] ** 2 + torch.fft.fftfreq(96)[None, :] ** 2)
        return float(p[f > 0.25].sum())

    assert high(soft) < 0.5 * high(base)
    gray = textured_leaves(32, 32, seed=3, channels=1, dtype=torch.float64)
    assert gray.shape == (1, 32, 32)
    full = textured_leaves(32, 32, seed=3, dtype=torch.float64)
    w = torch.tensor([0.2126, 0.7152, 0.0722], dtype=torch.float64)
    assert torch.allclose(gray[0], (full * w[:, None, None]).sum(0), atol=1e-12)


def test_textured_leaves_deterministic_seeded_dtype() -> None:
    a = textured_leaves(48, 64, seed=2)
    assert a.shape == (3, 48, 64) and a.dtype == torch.float32
    assert torch.equal(a, textured_leaves(48, 64, seed=2))
    assert not torch.equal(a, textured_leaves(48, 64, seed=4))
    assert float(a.min()) >= 0.0 and float(a.max()) <= 1.0
    b = textured_leaves(48, 64, seed=2, dtype=torch.float64, device="cpu")
    assert b.dtype == torch.float64 and torch.allclose(a.double(), b, atol=1e-5)
    src = TexturedLeaves(seed=1)
    g1, g2 = torch.Generator().manual_seed(0), torch.Generator().manual_seed(0)
    assert torch.equal(src.random_patch(32, g1), src.random_patch(32, g2))


@pytest.mark.parametrize("kw", [{"blur": 1.5}, {"grating": -0.1}, {"texture": float("nan")}, {"gamma": (1.2, 0.8)},
                                {"channels": 2}])
def test_textured_leaves_bad_settings(kw: dict) -> None:
    with pytest.raises(LensoptError, match="textured_leaves"):
        textured_leaves(16, 16, seed=0, **kw)
