"""The fast image paths of ``lensopt simulate`` (issue 14) give the values of the plain ones.

References are independent of the code under test: OpenImageIO's own integer ↔ float conversion (what
``read_image``/``write_image`` used before), scipy's ``next_fast_len``, and autograd.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from lensopt.imaging.io import PNG_OPTIONS, encode_integer, linear_to_srgb, read_image, srgb_to_linear, write_image

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "lensopt" / "imaging" / "data" / "coffee.png"


def _oiio_write(path: Path, arr: np.ndarray, pixel_type: str, colorspace: str | None = None) -> None:
    import OpenImageIO as oiio

    h, w, c = arr.shape
    spec = oiio.ImageSpec(w, h, c, {"uint8": oiio.UINT8, "uint16": oiio.UINT16}[pixel_type])
    if colorspace:
        spec.attribute("oiio:ColorSpace", colorspace)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    assert out.write_image(np.ascontiguousarray(arr))
    out.close()


def _oiio_read(path: Path, pixel_type: str) -> np.ndarray:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    data = np.asarray(inp.read_image(0, 0, 0, spec.nchannels, pixel_type))
    inp.close()
    return data.reshape(spec.height, spec.width, spec.nchannels)


@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("nch", [1, 2, 3, 4])
def test_integer_read_equals_openimageio_float_conversion(tmp_path: Path, bits: int, nch: int) -> None:
    # Every code value appears; the old path read floats from OpenImageIO and linearized them.
    pixel_type = f"uint{bits}"
    top = (1 << bits) - 1
    rng = np.random.default_rng(bits + nch)
    codes = rng.integers(0, top + 1, size=(37, 300, nch), dtype=np.int64)
    codes.reshape(-1)[: min(codes.size, top + 1)] = np.arange(min(codes.size, top + 1))
    path = tmp_path / "a.png"
    _oiio_write(path, codes.astype(pixel_type), pixel_type)
    arr, info = read_image(path)
    used = 1 if nch in (1, 2) else 3
    expected = srgb_to_linear(_oiio_read(path, "float")[..., :used])
    assert (info.bits, info.channels, info.encoding, info.is_float) == (bits, used, "sRGB", False)
    assert arr.shape == expected.shape and arr.dtype == np.float32
    assert np.array_equal(arr, expected)  # bit for bit
    assert arr.transpose(2, 0, 1).flags["C_CONTIGUOUS"]  # the planar layout the convolution takes


def test_linear_tagged_integer_file_is_not_linearized(tmp_path: Path) -> None:
    codes = np.random.default_rng(3).integers(0, 256, size=(20, 30, 3)).astype(np.uint8)
    path = tmp_path / "lin.png"  # PNG keeps the tag (gAMA 1.0); TIFF does not
    _oiio_write(path, codes, "uint8", colorspace="lin_rec709")
    arr, info = read_image(path)
    assert info.encoding == "linear"
    assert np.array_equal(arr, _oiio_read(path, "float"))


@pytest.mark.parametrize("pixel_type", ["uint8", "uint16"])
def test_encoding_equals_openimageio_float_to_integer_conversion(tmp_path: Path, pixel_type: str) -> None:
    # The old write path: linear_to_srgb on the whole float image, OpenImageIO converts to integers.
    rng = np.random.default_rng(5)
    lin = rng.random((300, 257, 3), dtype=np.float32) ** 2.2
    lin[0, :4, 0] = [-0.5, 0.0, 1.0, 3.0]  # clipped on both sides
    planar_view = np.ascontiguousarray(lin.transpose(2, 0, 1)).transpose(1, 2, 0)
    ours = encode_integer(planar_view, pixel_type)
    import OpenImageIO as oiio

    srgb = linear_to_srgb(lin)
    path = tmp_path / "ref.tif"
    out = oiio.ImageOutput.create(str(path))
    fmt = {"uint8": oiio.UINT8, "uint16": oiio.UINT16}[pixel_type]
    assert out.open(str(path), oiio.ImageSpec(lin.shape[1], lin.shape[0], 3, fmt))
    assert out.write_image(np.ascontiguousarray(srgb))
    out.close()
    ref = _oiio_read(path, pixel_type)
    assert ours.dtype == np.dtype(pixel_type) and ours.flags["C_CONTIGUOUS"]
    # Equal codes, except where srgb × max is exactly k + ½ in float32: OpenImageIO's vector loop rounds
    # such ties to even (as we do), its scalar remainder loop rounds them up.
    scaled = srgb * np.float32(np.iinfo(pixel_type).max)
    tie = scaled - np.floor(scaled) == 0.5
    diff = ours.astype(np.int64) - ref
    assert not diff[~tie].any()
    assert np.abs(diff[tie]).max(initial=0) <= 1


def test_png_written_fast_is_lossless_and_tagged(tmp_path: Path) -> None:
    img, info = read_image(EXAMPLE)
    assert PNG_OPTIONS["png:compressionLevel"] == 1
    write_image(tmp_path / "o.png", img, info)
    codes = _oiio_read(tmp_path / "o.png", "uint8")
    assert np.array_equal(codes, encode_integer(img, "uint8"))
    # An 8-bit sRGB file read and written again is the same file content (codes), to the last bit.
    assert np.array_equal(codes, _oiio_read(EXAMPLE, "uint8")[..., :3])


def test_next_fast_len_matches_scipy() -> None:
    from scipy.fft import next_fast_len as scipy_next_fast_len

    from lensopt.analysis.fft_size import next_fast_len

    for n in list(range(1, 3000)) + [4097, 10007, 65537, 123457]:
        assert next_fast_len(n) == scipy_next_fast_len(n, real=True), n


def test_convolution_without_autograd_equals_the_differentiable_path(monkeypatch: pytest.MonkeyPatch) -> None:
    import lensopt.imaging.convolve as conv
    from lensopt.imaging.convolve import overlap_add_convolve

    monkeypatch.setattr(conv, "PLANE_MIN_BYTES", 0)  # these small patches go plane by plane too

    g = torch.Generator().manual_seed(0)
    img = torch.rand(3, 40, 50, generator=g, dtype=torch.float64)
    psfs = torch.rand(2, 3, 3, 7, 7, generator=g, dtype=torch.float64)
    psfs = (psfs / psfs.sum((-1, -2), keepdim=True)).requires_grad_(True)
    out = overlap_add_convolve(img, psfs)
    out.square().sum().backward()  # batched, out of place
    with torch.no_grad():
        fast = overlap_add_convolve(img, psfs)  # plane by plane through reused FFT buffers
    assert torch.allclose(out.detach(), fast, rtol=0, atol=1e-13)
    # d/dψ of Σ out² by a central difference on one kernel value
    eps = 1e-6
    with torch.no_grad():
        p = psfs.detach().clone()
        p[1, 2, 0, 3, 3] += eps
        hi = overlap_add_convolve(img, p).square().sum()
        p[1, 2, 0, 3, 3] -= 2 * eps
        lo = overlap_add_convolve(img, p).square().sum()
    assert psfs.grad[1, 2, 0, 3, 3].item() == pytest.approx(((hi - lo) / (2 * eps)).item(), rel=1e-6)


def test_run_plan_leaves_the_callers_image_alone(cooke) -> None:
    from lensopt.imaging.plan import PlanOptions, parse_effects
    from lensopt.imaging.simulate import plan_scene, run_plan
    from lensopt.spec import camera_of

    img, info = read_image(EXAMPLE)
    keep = img.copy()
    camera = camera_of(cooke)
    meta = {"width": info.width, "height": info.height, "channels": 3}
    for effects in ("-convolution,-noise", "+convolution,-noise"):
        opts = PlanOptions(sampling="rings:4")
        plan, pilot, reg, sensor = plan_scene(camera, meta, region="center", effects=parse_effects(effects),
                                              options=opts)
        with torch.inference_mode():
            res = run_plan(camera, plan, pilot, reg, sensor, img, opts)
        assert not np.shares_memory(res.image, img)
        assert np.array_equal(img, keep)


def test_simulate_command_imports_neither_scipy_nor_sympy(tmp_path: Path) -> None:
    # scipy.fft (0.3 s) and sympy (0.8 s, through torch.broadcast_shapes) were imported by every run.
    code = ("import sys; from lensopt.cli.app import app; sys.argv[0] = 'lensopt'\n"
            "try:\n    app()\nexcept SystemExit as e:\n    assert not e.code, e.code\n"
            "bad = sorted(m for m in ('scipy', 'sympy', 'skimage') if m in sys.modules)\n"
            "assert not bad, bad\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    r = subprocess.run([sys.executable, "-c", code, "simulate", str(ROOT / "specs" / "cooke_triplet.toml"),
                        str(EXAMPLE), "-o", str(tmp_path / "o.png"), "--rays", "rings:8", "--json"],
                       env=env, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "o.png").is_file()


@pytest.mark.parametrize("shape", [(11, 11), (12, 40, 3), (90, 31, 3), (53, 47), (41, 30, 1), (30, 20, 2)])
def test_banded_scores_equal_scikit_image_on_the_whole_image(monkeypatch: pytest.MonkeyPatch,
                                                            shape: tuple[int, ...]) -> None:
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    import lensopt.imaging.metrics as metrics

    monkeypatch.setattr(metrics, "BAND_ROWS", 7)  # many bands, and a last one of a few rows
    rng = np.random.default_rng(len(shape) * 100 + shape[0])
    a = rng.random(shape).astype(np.float32)
    b = np.clip(a + 0.1 * rng.standard_normal(shape), 0, 1).astype(np.float32)
    aa, bb = np.asarray(a, np.float64), np.asarray(b, np.float64)
    axis = -1 if len(shape) == 3 else None
    if len(shape) == 3 and shape[-1] == 1:
        aa, bb, axis = aa[..., 0], bb[..., 0], None
    ref = structural_similarity(aa, bb, data_range=1.0, channel_axis=axis, gaussian_weights=True, sigma=1.5,
                                use_sample_covariance=False)
    assert metrics.ssim(a, b) == pytest.approx(ref, rel=1e-13, abs=1e-15)
    assert metrics.psnr(a, b) == pytest.approx(peak_signal_noise_ratio(aa, bb, data_range=1.0), rel=1e-13)


def test_scores_with_a_transform_equal_scores_of_the_transformed_images() -> None:
    from lensopt.imaging.metrics import psnr, ssim

    rng = np.random.default_rng(9)
    a = (rng.random((40, 33, 3)) * 1.2).astype(np.float32)  # some values above 1: clipped by the transform
    b = np.clip(a + 0.05 * rng.standard_normal(a.shape), 0, None).astype(np.float32)
    sa, sb = linear_to_srgb(a), linear_to_srgb(b)
    assert psnr(a, b, transform=linear_to_srgb) == psnr(sa, sb)
    assert ssim(a, b, transform=linear_to_srgb) == ssim(sa, sb)
    c = a.copy()
    c[a > 1] = 5.0  # differs from a only where both encode to 1
    assert psnr(a, c, transform=linear_to_srgb) == float("inf")


def test_effects_in_bands_equal_one_whole_image_band(cooke, monkeypatch: pytest.MonkeyPatch) -> None:
    # One band covering the image is the whole-image computation that the effects did before.
    import lensopt.imaging.effects as effects
    from lensopt.imaging.pilot import run_pilot
    from lensopt.imaging.scene import parse_region
    from lensopt.imaging.simulate import sensor_of
    from lensopt.spec import camera_of

    camera = camera_of(cooke)
    img = torch.from_numpy(np.random.default_rng(11).random((3, 45, 61), dtype=np.float32))
    sensor, _ = sensor_of(camera, 61, 45)
    region = parse_region("corner", sensor, 61, 45)
    pilot = run_pilot(camera.lens, camera.system, camera.system.wavelength_weights)
    results = {}
    for rows in (10**9, 7):
        monkeypatch.setattr(effects, "BAND_ROWS", rows)
        results[rows] = (effects.warp_distortion(img, pilot, region, sensor),
                         effects.apply_relative_illumination(img, pilot, region, sensor))
    for whole, banded in zip(results[10**9], results[7], strict=True):
        assert torch.equal(whole, banded)
    assert not torch.equal(results[7][0], img) and not torch.equal(results[7][1], img)


def test_noise_is_the_image_plus_scaled_seeded_gaussian() -> None:
    from lensopt.imaging.effects import add_noise

    img = torch.rand(3, 20, 30, generator=torch.Generator().manual_seed(1))
    expected = img + 0.05 * float(img.max()) * torch.randn(img.shape, generator=torch.Generator().manual_seed(4))
    assert torch.equal(add_noise(img, 0.05, seed=4), expected)
    x = img.clone().requires_grad_(True)
    add_noise(x, 0.05, seed=4).sum().backward()  # differentiable rendering adds noise too
    assert torch.equal(x.grad, torch.ones_like(img))
