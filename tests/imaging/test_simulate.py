"""End-to-end simulation: pass-through, delta-PSF identity, one channel for grayscale, noise, effects."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lensopt.imaging.plan import PlanOptions, parse_effects
from lensopt.imaging.simulate import plan_scene, run_plan
from lensopt.spec import camera_of
from tests.helpers import imaging_oval


def simulate(model, img: np.ndarray, region: str | None = None, effects: str | None = None, **opts):
    h, w, c = img.shape
    options = PlanOptions(sampling="rings:8", **opts)
    plan, pilot, reg, sensor = plan_scene(model, {"width": w, "height": h, "channels": c}, region=region,
                                          effects=parse_effects(effects), options=options)
    return plan, run_plan(model, plan, pilot, reg, sensor, img, options)


def scene(h: int, w: int, c: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).random((h, w, c), dtype=np.float32)


def test_pass_through_returns_the_image_untouched() -> None:
    img = scene(48, 64, 3)
    plan, res = simulate(imaging_oval(rgb=True, pitch_um=60.0), img)
    assert plan.effects["convolution"]["on"] is False
    assert res.psf_grid is None and np.array_equal(res.image, img)


def test_delta_psf_lens_leaves_the_image_unchanged_when_forced_to_convolve() -> None:
    # The oval's PSFs are Dirac deltas at 30 µm pixels (Airy radius 10.8 µm < half a pixel: no diffraction).
    img = scene(48, 64, 1)
    plan, res = simulate(imaging_oval(), img, effects="+convolution", grid=(3, 2))
    assert plan.effects["convolution"]["on"] and not plan.diffraction["on"]
    assert res.psf_grid.shape[:3] == (2, 3, 1)
    assert np.abs(res.image - img).max() < 1e-5


def test_grayscale_scene_computes_one_channel(cooke, tmp_path: Path) -> None:
    img = scene(50, 50, 1)  # one 125 × 125 sensor-pixel tile of a 32 × 24 grid (seed S3.3.1), in a corner
    plan, res = simulate(cooke, img, region="tile:31,0/32x24")
    assert plan.channels == ["Y"]
    assert res.psfs is not None and res.psfs.psf.shape[1] == 3  # all three wavelengths weigh in the sum
    assert res.psf_grid.shape[2] == 1 and res.image.shape == (50, 50, 1)


def test_uniform_scene_stays_uniform_through_a_real_lens(cooke) -> None:
    img = np.full((60, 80, 3), 0.4, dtype=np.float32)
    plan, res = simulate(cooke, img, region="corner", grid=(4, 3))
    assert plan.effects["convolution"]["on"]
    assert np.abs(res.image - 0.4).max() < 1e-5


def test_noise_is_seeded_and_scaled() -> None:
    img = np.full((64, 64, 1), 0.5, dtype=np.float32)
    model = imaging_oval()
    _, a = simulate(model, img, effects="noise=0.02")
    _, b = simulate(model, img, effects="noise=0.02")
    _, c = simulate(model, img, effects="noise=0.02", seed=1)
    assert np.array_equal(a.image, b.image) and not np.array_equal(a.image, c.image)
    assert float(np.std(a.image - img)) == pytest.approx(0.02 * 0.5, rel=0.05)


def test_relative_illumination_and_distortion_effects(cooke) -> None:
    img = np.full((30, 40, 1), 1.0, dtype=np.float32)
    plan, res = simulate(cooke, img, region="corner", effects="-convolution,ri")
    ri = plan.effects["relative_illumination"]
    assert ri["on"] and res.image.max() <= 1.0 + 1e-6 and res.image.min() < 0.95  # falls off towards the corner
    assert res.image[-1, 0, 0] > res.image[0, -1, 0]  # the inner corner of the region is brighter
    ramp = np.tile(np.linspace(0, 1, 40, dtype=np.float32), (30, 1))[..., None]
    plan, res = simulate(cooke, ramp, region="corner", effects="-convolution,distortion")
    assert plan.effects["distortion"]["on"] and not np.array_equal(res.image, ramp)
    assert np.isfinite(res.image).all()


def test_a_built_model_or_its_camera_give_the_same_image(cooke) -> None:
    # The core takes a plain Camera; a built model is accepted through model.camera() (no spec import below).
    model = cooke
    img = scene(24, 32, 3)
    a = simulate(model, img, region="corner")[1].image
    b = simulate(camera_of(model), img, region="corner")[1].image
    assert np.array_equal(a, b)
