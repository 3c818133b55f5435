"""Image files through OpenImageIO: sRGB linearization on read, re-encoding on write; metrics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lensopt.errors import LensoptError
from lensopt.imaging.io import linear_to_srgb, read_image, srgb_to_linear, write_image
from lensopt.imaging.metrics import psnr, ssim

EXAMPLE = Path(__file__).resolve().parents[2] / "lensopt" / "imaging" / "data" / "coffee.png"


def test_srgb_transfer_function_closed_form() -> None:
    # IEC 61966-2-1: linear = ((v + 0.055)/1.055)^2.4 above 0.04045, v/12.92 below.
    v = np.array([0.0, 0.02, 0.5, 1.0], dtype=np.float32)
    lin = srgb_to_linear(v)
    assert lin[1] == pytest.approx(0.02 / 12.92, rel=1e-6)
    assert lin[2] == pytest.approx(((0.5 + 0.055) / 1.055) ** 2.4, rel=1e-6)  # 0.21404
    assert np.allclose(linear_to_srgb(lin), v, atol=1e-6)


def test_png_roundtrip_is_linearized_and_reencoded(tmp_path: Path) -> None:
    img, info = read_image(EXAMPLE)
    assert (info.width, info.height, info.channels, info.bits, info.encoding) == (600, 400, 3, 8, "sRGB")
    assert img.dtype == np.float32 and 0.0 <= img.min() and img.max() <= 1.0
    desc = write_image(tmp_path / "out.png", img, info)
    assert desc == "uint8 sRGB"
    back, info2 = read_image(tmp_path / "out.png")
    assert info2.encoding == "sRGB"
    assert np.abs(linear_to_srgb(back) - linear_to_srgb(img)).max() <= 0.5 / 255 + 1e-6


def test_exr_stays_linear_and_grayscale_has_one_channel(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    lin = (rng.random((20, 30, 1)) * 3.0).astype(np.float32)  # HDR values above 1 survive in float files
    _, src = read_image(EXAMPLE)
    assert write_image(tmp_path / "g.exr", lin, src) == "float linear"
    back, info = read_image(tmp_path / "g.exr")
    assert info.encoding == "linear" and info.channels == 1 and info.is_float
    assert np.array_equal(back, lin)


def test_16_bit_png_stays_16_bit(tmp_path: Path) -> None:
    _, src = read_image(EXAMPLE)
    rgb = np.random.default_rng(1).random((8, 8, 3)).astype(np.float32)
    write_image(tmp_path / "a.png", rgb, src)
    _, info8 = read_image(tmp_path / "a.png")
    import dataclasses

    src16 = dataclasses.replace(src, bits=16)
    assert write_image(tmp_path / "b.png", rgb, src16) == "uint16 sRGB"
    back, info16 = read_image(tmp_path / "b.png")
    assert info8.bits == 8 and info16.bits == 16
    assert np.abs(linear_to_srgb(back) - linear_to_srgb(rgb)).max() <= 0.5 / 65535 + 1e-6


def test_missing_file_is_a_one_line_error(tmp_path: Path) -> None:
    with pytest.raises(LensoptError, match="IMAGE: no such image file"):
        read_image(tmp_path / "nope.png", option="IMAGE")


def test_psnr_and_ssim() -> None:
    a = np.random.default_rng(2).random((32, 32, 3))
    # PSNR = 10 log10(1 / MSE): a constant offset of 0.1 gives MSE 0.01 → 20 dB exactly.
    assert psnr(a, a + 0.1, data_range=1.0) == pytest.approx(20.0, abs=1e-9)
    assert ssim(a, a) == pytest.approx(1.0)
    # Wang et al. 2004 for two constant images: contrast and structure terms are 1, the luminance term is
    # (2 μa μb + C1)/(μa² + μb² + C1) with C1 = (0.01 L)²: (0.24 + 1e-4)/(0.40 + 1e-4) for 0.2 vs 0.6.
    ca, cb = np.full((32, 32), 0.2), np.full((32, 32), 0.6)
    assert ssim(ca, cb) == pytest.approx((0.24 + 1e-4) / (0.40 + 1e-4), rel=1e-9)


def test_tiff_follows_the_source_encoding(tmp_path: Path) -> None:
    import dataclasses

    _, src = read_image(EXAMPLE)
    rgb = np.random.default_rng(4).random((6, 9, 3)).astype(np.float32)
    assert write_image(tmp_path / "i.tif", rgb, src) == "uint8 sRGB"  # from an 8-bit source
    float_src = dataclasses.replace(src, is_float=True, bits=32, encoding="linear")
    assert write_image(tmp_path / "f.tif", rgb, float_src) == "float linear"
    back, info = read_image(tmp_path / "f.tif")
    assert info.encoding == "linear" and np.array_equal(back, rgb)
    back8, info8 = read_image(tmp_path / "i.tif")
    assert info8.encoding == "sRGB" and np.abs(linear_to_srgb(back8) - linear_to_srgb(rgb)).max() <= 0.5 / 255 + 1e-6
