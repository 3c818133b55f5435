"""``lensopt evaluate`` (seed S4.3.1): pairing with sensor tiles, the simulate path, rings, restore hook, errors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from lensopt.cli.app import app
from lensopt.imaging.datasets import DeadLeaves
from lensopt.imaging.evaluate import evaluate, scene_source
from lensopt.imaging.io import ImageInfo, write_image
from lensopt.imaging.plan import PlanOptions
from lensopt.spec import build, camera_of, load_spec
from tests.helpers import CMOUNT, imaging_oval

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()


def _png(path: Path, h: int, w: int, seed: int = 0) -> None:
    arr = np.random.default_rng(seed).random((h, w, 3)).astype(np.float32)
    write_image(path, arr, ImageInfo(w, h, 3, 8, False, "sRGB", "png"))


def test_delta_psf_lens_scores_perfectly_and_every_tile_once() -> None:
    # The Cartesian oval images a point to a point at its one wavelength (tests.helpers.imaging_oval):
    # pass-through, so every capture equals its scene (PSNR ∞, SSIM 1); its one wavelength feeds R, G and B
    # (the S4.1.2 rule with n_w = 1). 64×48 sensor, 16 px tiles → 4×3 = 12 tiles; 12 scenes use each
    # tile exactly once.
    camera = camera_of(imaging_oval(pitch_um=30.0, resolution=(64, 48)))
    scenes, names, _ = scene_source(None, count=12, patch=16, seed=1)
    ev = evaluate(camera, scenes, names, patch=16, seed=1, options=PlanOptions(sampling="rings:4"))
    assert ev.tiles == 12 and ev.count == 12
    assert sorted(it.tile for it in ev.items) == sorted({it.tile for it in ev.items})
    assert all(math.isinf(it.psnr_db) and it.ssim == pytest.approx(1.0) for it in ev.items)


def test_noise_is_seeded_and_costs_psnr() -> None:
    camera = camera_of(imaging_oval(pitch_um=30.0, resolution=(64, 48)))
    scenes, names, _ = scene_source(None, count=4, patch=16, seed=1)
    runs = [evaluate(camera, scenes, names, patch=16, seed=1, noise_sigma=0.01, options=PlanOptions(sampling="rings:4"))
            for _ in range(2)]
    assert [it.psnr_db for it in runs[0].items] == [it.psnr_db for it in runs[1].items]
    assert all(25 < it.psnr_db < 60 for it in runs[0].items)  # finite: the delta lens alone scores ∞


def test_restore_hook_sees_the_capture_and_its_output_is_scored() -> None:
    camera = camera_of(build(load_spec(CMOUNT)))
    src = DeadLeaves(seed=2)
    calls = []

    def restore(capture: torch.Tensor, info: dict) -> torch.Tensor:
        calls.append((tuple(capture.shape), info["index"]))
        return src.scene(info["index"], 32, 32).unsqueeze(0)  # a perfect restoration

    names = [f"s{k}" for k in range(3)]
    ev = evaluate(camera, lambda k: src.scene(k, 32, 32), names, patch=32, options=PlanOptions(sampling="rings:6"),
                  restore=restore)
    assert calls == [((1, 3, 32, 32), 0), ((1, 3, 32, 32), 1), ((1, 3, 32, 32), 2)]
    assert ev.restored and all(math.isinf(it.psnr_db) for it in ev.items)


def test_scores_equal_lensopt_simulate_on_the_same_tile(tmp_path: Path) -> None:
    # Evaluate's per-scene score is `lensopt simulate`'s score of that scene on that tile (same path).
    camera = camera_of(build(load_spec(CMOUNT)))
    src = DeadLeaves(seed=0)
    opts = PlanOptions(sampling="rings:8")
    ev = evaluate(camera, lambda k: src.scene(k, 64, 64), ["a", "b"], patch=64, seed=3, options=opts, rings=2)
    # ring breakdown: count-weighted ring means are the overall mean
    tot = sum(r["count"] * r["psnr_db"] for r in ev.rings if r["count"])
    assert tot / ev.count == pytest.approx(ev.psnr_db)
    assert sum(r["tiles"] for r in ev.rings) == ev.tiles == 32 * 32
    for k, item in enumerate(ev.items):
        exr = tmp_path / f"scene{k}.exr"  # float EXR: read back linear, bit for bit
        write_image(exr, src.scene(k, 64, 64).permute(1, 2, 0).numpy(), ImageInfo(64, 64, 3, 32, True, "linear", "exr"))
        r = runner.invoke(app, ["simulate", str(CMOUNT), str(exr), "-o", str(tmp_path / f"o{k}.exr"), "--region",
                                item.tile, "--rays", "rings:8", "--json", "--score"])
        assert r.exit_code == 0, r.output
        m = json.loads(r.stdout)["metrics"]
        assert m["psnr_db"] == pytest.approx(item.psnr_db, abs=1e-9)
        assert m["ssim"] == pytest.approx(item.ssim, abs=1e-9)


def test_cli_json_and_images_folder(tmp_path: Path) -> None:
    for k in range(3):
        _png(tmp_path / f"im{k}.png", 80, 90, seed=k)
    r = runner.invoke(app, ["evaluate", str(CMOUNT), "--images", str(tmp_path), "--count", "5", "--patch", "64",
                            "--rays", "rings:6", "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["count"] == 3 and [it["scene"] for it in out["items"]] == ["im0.png", "im1.png", "im2.png"]
    assert 5 < out["psnr_db"] < 60 and 0 < out["ssim"] < 1
    assert {"ring", "radius_rel", "count", "tiles", "psnr_db", "ssim"} <= set(out["rings"][0])
    assert any("channel weights: spectrum.rgb_weights" in n for n in out["notes"])  # the lens's own colour model


@pytest.mark.parametrize("args, path", [
    (["--images", "{tmp}/missing"], "--images: no such image folder"),
    (["--images", "{tmp}/empty"], "--images: no images"),
    (["--images", "{tmp}/small", "--patch", "64"], "--images: image 40×30 is smaller than the 64×64 patch"),
    (["--images", "{tmp}/bad"], "--images: cannot read image"),
    (["--count", "0"], "--count"),
    (["--patch", "4096"], "--patch"),
    (["--rays", "nonsense"], "--rays"),
])
def test_bad_input_is_one_line_exit_2(tmp_path: Path, args: list[str], path: str) -> None:
    (tmp_path / "empty").mkdir()
    (tmp_path / "small").mkdir()
    _png(tmp_path / "small" / "tiny.png", 30, 40)
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "x.png").write_bytes(b"not a png")
    r = runner.invoke(app, ["evaluate", str(CMOUNT), *[a.format(tmp=tmp_path) for a in args]])
    assert r.exit_code == 2, r.output
    assert path in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_lens_without_sensor_is_one_line_exit_2() -> None:
    r = runner.invoke(app, ["evaluate", str(ROOT / "specs" / "double_gauss.toml"), "--count", "1"])
    assert r.exit_code == 2 and r.stderr.startswith("error: sensor:"), r.output
    assert "give [sensor] pixel_pitch_um" in r.stderr  # the message's brackets survive rich's markup
