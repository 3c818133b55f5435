"""Restoration model (S3.2): Wiener stage against the closed form, NAFNet block function vs module,
identity at initialisation, shapes, gradients."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from lensopt.restore import ConditionedRestorer, NAFNet, RestoreConfig, Wiener, mean_patch_psf, wiener_deconvolve
from lensopt.restore.nafnet import NAFBlock, nafnet_block

TINY = RestoreConfig(width=4, encoder_blocks=(1, 1), middle_blocks=1, decoder_blocks=(1, 1))


def gaussian_psf(k: int, sigma: float, dtype=torch.float64) -> torch.Tensor:
    r = torch.arange(k, dtype=dtype) - k // 2
    g = torch.exp(-(r[:, None] ** 2 + r[None, :] ** 2) / (2 * sigma**2))
    return g / g.sum()


def numpy_circular_blur(img: np.ndarray, psf: np.ndarray) -> np.ndarray:
    """Direct circular convolution by a centred kernel (independent of any FFT): y[i] = Σ k[u] x[i−u]."""
    out = np.zeros_like(img)
    c = psf.shape[0] // 2
    for u in range(psf.shape[0]):
        for v in range(psf.shape[1]):
            out += psf[u, v] * np.roll(img, (u - c, v - c), axis=(-2, -1))
    return out


def numpy_wiener(blurred: np.ndarray, psf: np.ndarray, snr: float) -> np.ndarray:
    """Textbook Wiener filter X = conj(K) Y / (|K|² + 1/SNR) with numpy's complex FFT."""
    h, w = blurred.shape[-2:]
    k = np.zeros((h, w))
    c = psf.shape[0] // 2
    k[: psf.shape[0], : psf.shape[1]] = psf
    k = np.roll(k, (-c, -c), axis=(0, 1))
    kf = np.fft.fft2(k)
    return np.real(np.fft.ifft2(np.conj(kf) * np.fft.fft2(blurred) / (np.abs(kf) ** 2 + 1.0 / snr)))


def test_wiener_equals_closed_form_on_known_blur():
    rng = np.random.default_rng(0)
    img = rng.random((2, 3, 24, 20))
    psf = gaussian_psf(7, 1.3).numpy()
    blurred = numpy_circular_blur(img, psf)
    want = numpy_wiener(blurred, psf, 300.0)
    got = wiener_deconvolve(torch.from_numpy(blurred), torch.from_numpy(psf).expand(2, 3, 7, 7), 300.0, pad=0)
    np.testing.assert_allclose(got.numpy(), want, atol=1e-12)
    # the module (learnable log SNR, reflect padding by k // 2) is the function with the same SNR
    mod = Wiener(300.0).double()
    y, k = torch.from_numpy(blurred), torch.from_numpy(psf)[None, None]
    np.testing.assert_allclose(mod(y, k).detach().numpy(), wiener_deconvolve(y, k, 300.0).numpy(),
                               rtol=1e-6)  # log SNR is stored in float32


def test_wiener_inverts_a_noiseless_blur_at_high_snr():
    # A mild Gaussian blur has no zeros in its OTF: Wiener with SNR → ∞ is the exact inverse filter.
    rng = np.random.default_rng(1)
    img = rng.random((1, 1, 32, 32))
    psf = gaussian_psf(5, 0.7).numpy()
    blurred = numpy_circular_blur(img, psf)
    got = wiener_deconvolve(torch.from_numpy(blurred), torch.from_numpy(psf)[None, None], 1e12, pad=0)
    np.testing.assert_allclose(got.numpy(), img, atol=1e-6)


def test_wiener_delta_psf_is_shrinkage():
    # K = δ: X = Y / (1 + 1/SNR).
    y = torch.rand(1, 3, 16, 16, dtype=torch.float64)
    delta = torch.zeros(1, 1, 5, 5, dtype=torch.float64)
    delta[..., 2, 2] = 1
    np.testing.assert_allclose(wiener_deconvolve(y, delta, 4.0).numpy(), (y / 1.25).numpy(), atol=1e-12)


def test_wiener_snr_gradient_matches_finite_differences():
    torch.manual_seed(0)
    y = torch.rand(1, 1, 12, 12, dtype=torch.float64)
    psf = gaussian_psf(5, 1.0)[None, None]
    torch.autograd.gradcheck(lambda s: wiener_deconvolve(y, psf, s.exp()), (torch.tensor(2.0, dtype=torch.float64,
                                                                                        requires_grad=True),))


def test_block_function_matches_module_and_gradcheck():
    torch.manual_seed(0)
    blk = NAFBlock(4).double()
    for p in blk.parameters():  # move β, γ off zero so both branches count
        torch.nn.init.normal_(p, std=0.5)
    x = torch.randn(2, 4, 6, 6, dtype=torch.float64, requires_grad=True)
    params = dict(blk.named_parameters())
    torch.testing.assert_close(blk(x), nafnet_block(x, params))
    # a hand-written reference of the first half (norm → 1×1 → depthwise → gate → SCA → 1×1)
    with torch.no_grad():
        mu = x.mean(1, keepdim=True)
        sd = ((x - mu) ** 2).mean(1, keepdim=True).add(1e-6).sqrt()
        n = (x - mu) / sd * params["norm1.weight"].view(1, -1, 1, 1) + params["norm1.bias"].view(1, -1, 1, 1)
        y = blk.conv2(blk.conv1(n))
        y = y[:, :4] * y[:, 4:]
        y = y * blk.sca(y.mean((2, 3), keepdim=True))
        half = x + blk.conv3(y) * blk.beta
        n2 = (half - half.mean(1, keepdim=True)) / ((half - half.mean(1, keepdim=True)) ** 2).mean(
            1, keepdim=True).add(1e-6).sqrt() * params["norm2.weight"].view(1, -1, 1, 1) + params[
            "norm2.bias"].view(1, -1, 1, 1)
        z = blk.conv4(n2)
        ref = half + blk.conv5(z[:, :4] * z[:, 4:]) * blk.gamma
    torch.testing.assert_close(blk(x).detach(), ref)
    torch.autograd.gradcheck(lambda t: blk(t), (x,))


def test_fresh_model_is_identity_like_on_random_crops():
    # Default architecture (width 16, [1,1,1,4], 1, [1,1,1,1], SNR 1000): PSNR(out, in) > 40 dB.
    torch.manual_seed(0)
    model = ConditionedRestorer()
    x = torch.rand(2, 3, 64, 48)
    psf = gaussian_psf(9, 2.0, torch.float32).expand(2, 3, 9, 9)
    with torch.no_grad():
        y = model(x, psf)
    mse = float(((y - x) ** 2).mean())
    psnr = math.inf if mse == 0 else 10 * math.log10(1 / mse)
    assert psnr > 40
    assert y.shape == x.shape and y.dtype == x.dtype


def test_default_architecture_and_parameter_count():
    model = ConditionedRestorer()
    cfg = model.config
    assert (cfg.width, cfg.encoder_blocks, cfg.middle_blocks, cfg.decoder_blocks, cfg.snr) == (
        16, (1, 1, 1, 4), 1, (1, 1, 1, 1), 1000.0)
    assert len(model.pre.encoders[3]) == 4 and len(model.pre.middle) == 1
    assert model.pre.middle[0].conv1.in_channels == 16 * 2**4
    assert math.isclose(float(model.wiener.log_snr.detach().exp()), 1000.0, rel_tol=1e-6)


def test_model_trains_away_from_identity_and_uses_the_wiener_stage():
    # A few Adam steps on blurred → sharp pairs lower the MAE and open the Wiener gate.
    torch.manual_seed(0)
    model = ConditionedRestorer(TINY)
    psf = gaussian_psf(7, 1.0, torch.float32)
    sharp = torch.rand(4, 3, 8, 8).repeat_interleave(4, -1).repeat_interleave(4, -2)  # piecewise constant
    blurred = torch.from_numpy(numpy_circular_blur(sharp.double().numpy(), psf.double().numpy())).float()
    k = psf.expand(4, 3, 7, 7)
    opt = torch.optim.Adam(model.parameters(), lr=1e-2, betas=(0.9, 0.9))
    with torch.no_grad():
        first = float((model(blurred, k) - sharp).abs().mean())
    for _ in range(30):
        opt.zero_grad()
        loss = (model(blurred, k) - sharp).abs().mean()
        loss.backward()
        opt.step()
    assert float(loss.detach()) < 0.7 * first
    assert abs(float(model.gate)) > 0.05


def test_odd_sizes_and_float64():
    model = ConditionedRestorer(TINY).double()
    x = torch.rand(1, 3, 13, 22, dtype=torch.float64)
    psf = gaussian_psf(5, 1.0).expand(1, 3, 5, 5)
    assert model(x, psf).shape == x.shape


def test_mean_patch_psf():
    a = torch.rand(2, 9, 3, 5, 5)
    m = mean_patch_psf(a)
    torch.testing.assert_close(m.sum((-2, -1)), torch.ones(2, 3))
    torch.testing.assert_close(m, a.mean(1) / a.mean(1).sum((-2, -1), keepdim=True))
    with pytest.raises(ValueError):
        mean_patch_psf(a[0])


def test_nafnet_alone_is_identity_at_init():
    net = NAFNet(3, 3, width=8, encoder_blocks=(1, 2), decoder_blocks=(1, 1))
    x = torch.rand(1, 3, 17, 9)
    torch.testing.assert_close(net(x), x)
