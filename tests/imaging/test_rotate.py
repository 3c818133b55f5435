"""PSF rotation by three shears (S1.5.1 step 4) and area resampling (step 5)."""

from __future__ import annotations

import math

import pytest
import torch

from lensopt.imaging.rotate import resample_matrix, resample_psf, rotate_psf, shear_rows

F64 = torch.float64


def test_rotation_by_shears_conserves_energy() -> None:
    gen = torch.Generator().manual_seed(0)
    psf = torch.rand(7, 3, 21, 21, generator=gen, dtype=F64) ** 4
    psf = psf / psf.sum((-1, -2), keepdim=True)
    angles = torch.tensor([0.0, 0.3, -0.9, 1.57, 2.5, -3.0, 6.0], dtype=F64)[:, None]
    out = rotate_psf(psf, angles)
    assert torch.allclose(out.sum((-1, -2)), torch.ones(7, 3, dtype=F64), atol=1e-12)
    assert float(out.min()) >= -1e-15


def test_rotation_moves_mass_counter_clockwise() -> None:
    # A point at +y (row c + 4) rotated by +90° must land at −x (column c − 4); by 180° at −y; by −90° at +x.
    psf = torch.zeros(1, 21, 21, dtype=F64)
    psf[0, 14, 10] = 1.0
    for angle, (row, col) in [(math.pi / 2, (10, 6)), (math.pi, (6, 10)), (-math.pi / 2, (10, 14)), (0.0, (14, 10))]:
        out = rotate_psf(psf, torch.tensor([angle], dtype=F64))[0]
        assert float(out[row, col]) == pytest.approx(1.0, abs=1e-9), angle


def test_rotation_matches_the_rotated_centroid() -> None:
    psf = torch.zeros(1, 31, 31, dtype=F64)
    psf[0, 15 + 6, 15 + 2] = 0.7
    psf[0, 15 - 3, 15 + 5] = 0.3
    phi = 0.6
    out = rotate_psf(psf, torch.tensor([phi], dtype=F64))[0]
    c = torch.arange(31, dtype=F64) - 15
    mx, my = float((out.sum(0) * c).sum()), float((out.sum(1) * c).sum())
    x0, y0 = 0.7 * 2 + 0.3 * 5, 0.7 * 6 - 0.3 * 3
    assert mx == pytest.approx(x0 * math.cos(phi) - y0 * math.sin(phi), abs=1e-9)
    assert my == pytest.approx(x0 * math.sin(phi) + y0 * math.cos(phi), abs=1e-9)


def test_energy_leaving_the_crop_is_spread_uniformly() -> None:
    psf = torch.zeros(1, 5, 5, dtype=F64)
    psf[0, 4, 4] = 1.0  # a corner: rotating by 45° pushes it off the 5×5 crop
    out = rotate_psf(psf, torch.tensor([math.pi / 4], dtype=F64))[0]
    assert float(out.sum()) == pytest.approx(1.0, abs=1e-12)
    assert float(out.min()) > 0.0


def test_shear_is_mass_conserving_splatting() -> None:
    img = torch.tensor([[0.0, 1.0, 0.0, 0.0, 0.0]], dtype=F64)
    out = shear_rows(img, torch.tensor([1.25], dtype=F64))
    assert out.tolist() == [[0.0, 0.0, 0.75, 0.25, 0.0]]


def test_resampling_conserves_energy_and_is_identity_at_equal_pitch() -> None:
    gen = torch.Generator().manual_seed(1)
    psf = torch.rand(4, 15, 15, generator=gen, dtype=F64)
    assert torch.allclose(resample_psf(psf, 2.0, 2.0), psf, atol=1e-14)
    for p_out in (0.7, 3.0, 7.3):
        out = resample_psf(psf, 2.0, p_out)
        assert torch.allclose(out.sum((-1, -2)), psf.sum((-1, -2)), atol=1e-12)
        assert out.shape[-1] % 2 == 1
    # Overlap matrix by hand: 3 bins of 1 onto one bin of 3 → all ones; onto bins of 1.5 (2 bins) → halves.
    assert resample_matrix(3, 1.0, 1, 3.0).tolist() == [[1.0, 1.0, 1.0]]
    assert resample_matrix(3, 1.0, 2, 1.5).tolist() == [[1.0, 0.5, 0.0], [0.0, 0.5, 1.0]]
