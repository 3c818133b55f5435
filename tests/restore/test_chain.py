"""The README's restoration chain on a shipped lens with a sensor (issue 27), at a tiny budget:
``train-irm`` → ``simulate`` → ``restore`` → ``evaluate --irm`` → ``tolerance --irm``.

The lens is ``lenses/cmount_4p.json`` (12 wavelengths, no ``rgb_weights``: R, G, B by the seed's split,
S4.1.2) with a tiny ``[restore]`` network and a ``[tolerance]`` section of 2 scenes. Values are checked
against independent sources: the channel count against ``imaging.rgb``'s rule, the restored image's PSNR
against scikit-image's, and the tolerance nominal against ``evaluate`` of the same lens, network and noise
(one path, two commands).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from lensopt.cli.app import app
from lensopt.imaging.io import ImageInfo, read_image, write_image
from tests.helpers import CMOUNT

runner = CliRunner()

TINY = {"width": 4, "encoder_blocks": [1], "middle_blocks": 1, "decoder_blocks": [1],
        "train": {"validation_patches": 1}}
TRAIN = ["--steps", "2", "--batch", "2", "--patch", "32", "--fields", "3", "--sampling", "rings:2",
         "--psf-size", "9", "--grid", "2x2", "--validate-every", "2"]
NOISE = "0.005"


def _ok(args: list[str]) -> str:
    r = runner.invoke(app, args)
    assert r.exit_code == 0, (args, r.output)
    return r.stdout


def _refused(args: list[str], *words: str) -> str:
    r = runner.invoke(app, args)
    assert r.exit_code == 2, (args, r.output)
    assert len(r.output.strip().splitlines()) == 1, r.output
    assert "Traceback" not in r.output and all(w in r.output for w in words), r.output
    return r.output


@pytest.fixture(scope="module")
def chain(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    tmp = tmp_path_factory.mktemp("chain")
    data = json.loads(Path(CMOUNT).read_text(encoding="utf-8"))
    assert data["sensor"]["pixel_pitch_um"] and data["sensor"]["resolution"]  # a shipped lens with a sensor
    data["restore"] = TINY
    data["tolerance"] = {"profile": "s6.2", "psnr_count": 2, "psnr_patch": 64, "psnr_noise": float(NOISE)}
    lens = tmp / "cmount_tiny.json"
    lens.write_text(json.dumps(data), encoding="utf-8")
    ck = tmp / "irm"
    train = json.loads(_ok(["train-irm", str(lens), "-o", str(ck), *TRAIN, "--json"]))
    scene = np.random.default_rng(0).random((48, 64, 3)).astype(np.float32)
    src, cap, rest = tmp / "scene.png", tmp / "capture.png", tmp / "restored.png"
    write_image(src, scene, ImageInfo(64, 48, 3, 8, False, "sRGB", "png"))
    _ok(["simulate", str(lens), str(src), "-o", str(cap), "--rays", "rings:4", "--region", "center"])
    _ok(["restore", str(lens), str(ck), str(cap), "-o", str(rest), "--region", "center"])
    ev = json.loads(_ok(["evaluate", str(lens), "--count", "2", "--patch", "64", "--rays", "rings:8", "--noise",
                         NOISE, "--irm", str(ck), "--json"]))
    tol = json.loads(_ok(["tolerance", str(lens), "--irm", str(ck), "--trials", "2", "--scheduler", "serial",
                          "--no-sensitivity", "--json"]))
    return {"lens": lens, "data": data, "ck": ck, "train": train, "src": src, "cap": cap, "rest": rest, "ev": ev,
            "tol": tol, "tmp": tmp}


def test_channels_follow_the_spectrum_rule(chain: dict) -> None:
    sp = chain["data"]["spectrum"]
    want = len(sp["rgb_weights"][0])  # the lens's colour model: its rgb_weights, R, G, B
    meta = json.loads((chain["ck"] / "meta.json").read_text())["meta"]
    assert meta["network_config"]["channels"] == want == meta["colour"]["channels"]
    for name in ("cap", "rest"):
        img, info = read_image(chain[name])
        assert img.shape[-1] == info.channels == want


def test_restored_capture_scores_finite(chain: dict) -> None:
    from skimage.metrics import peak_signal_noise_ratio

    scene, _ = read_image(chain["src"])
    cap, _ = read_image(chain["cap"])
    rest, _ = read_image(chain["rest"])
    assert not np.array_equal(cap, scene)  # the lens blurs: PSNR is a number, not ∞
    for img in (cap, rest):
        assert math.isfinite(peak_signal_noise_ratio(scene, img, data_range=1.0))
    v = chain["train"]["validation"]
    assert math.isfinite(v["psnr_raw"]) and math.isfinite(v["psnr_restored"])


def test_tolerance_nominal_is_evaluate_of_the_same_lens_network_and_noise(chain: dict) -> None:
    ev, tol = chain["ev"], chain["tol"]
    after = ev["after_restoration"]
    assert ev["noise_sigma"] == after["noise_sigma"] == float(NOISE)
    assert math.isfinite(after["psnr_db"]) and math.isfinite(ev["psnr_db"])
    # the nominal of tolerance --irm is imaged on evaluate's path with evaluate's defaults (4 → 2 scenes, 64 px,
    # rings:8, seed 0): the same numbers, not merely close
    assert tol["nominal"]["psnr_post_db"] == after["psnr_db"] == tol["nominal"]["value"]
    assert tol["nominal"]["psnr_pre_db"] == ev["psnr_db"]
    stats = tol["monte_carlo"]["stats"]
    assert all(math.isfinite(stats[k]) for k in ("mean", "min", "max"))


def test_bad_inputs_are_one_line_exit_2_nothing_written(chain: dict, tmp_path: Path) -> None:
    lens, ck = str(chain["lens"]), str(chain["ck"])
    # a shipped lens without a [sensor]
    no_sensor = str(Path(CMOUNT).parent / "cooke_triplet_opt.json")
    _refused(["train-irm", no_sensor, "-o", str(tmp_path / "k"), *TRAIN], "sensor")
    assert not (tmp_path / "k").exists()
    _refused(["restore", lens, ck, str(tmp_path / "missing.png"), "-o", str(tmp_path / "r.png")], "IMAGE")
    _refused(["restore", lens, str(tmp_path / "nock"), str(chain["cap"]), "-o", str(tmp_path / "r.png")],
             "CHECKPOINT")
    _refused(["restore", no_sensor, ck, str(chain["cap"]), "-o", str(tmp_path / "r.png")], "trained for", "has")
    assert not (tmp_path / "r.png").exists()
    _refused(["evaluate", lens, "--count", "1", "--patch", "32", "--irm", str(tmp_path / "nock")], "--irm")
    _refused(["tolerance", lens, "--irm", str(tmp_path / "nock"), "--trials", "1", "--scheduler", "serial",
              "--no-sensitivity", "-o", str(tmp_path / "tol")], "--irm")
    assert not (tmp_path / "tol").exists()


def test_nominal_psnr_that_is_not_a_number_is_an_error_with_its_reason(tmp_path: Path) -> None:
    # 700 µm pixels: the C-mount's blur stays within a pixel, the plan does not convolve, the capture is the
    # scene and PSNR is ∞ — before issue 27 the sensitivities were NaN (∞ − ∞) and the command exited 0
    data = json.loads(Path(CMOUNT).read_text(encoding="utf-8"))
    data["sensor"] = {"pixel_pitch_um": 700.0, "resolution": [16, 16]}
    data["tolerance"] = {"profile": "s6.2", "metric": "psnr", "psnr_count": 1, "psnr_patch": 16}
    lens = tmp_path / "coarse.json"
    lens.write_text(json.dumps(data), encoding="utf-8")
    _refused(["tolerance", str(lens), "--trials", "1", "--scheduler", "serial", "--no-sensitivity", "-o",
              str(tmp_path / "out")], "tolerance.metric", "PSNR ∞", "psnr_noise")
    assert not (tmp_path / "out").exists()


def test_an_error_of_the_restoration_hook_is_raised_not_scored_minus_inf(cmount) -> None:
    from lensopt.errors import LensoptError
    from lensopt.tolerance.psnr import PsnrSetup, trial_psnr

    def broken(capture, info):  # a network that does not fit the captures
        raise LensoptError("the network restores 1-channel images", path="--irm")

    setup = PsnrSetup(cmount.camera(), count=1, patch=16, sampling="rings:2", restore=broken)
    with pytest.raises(LensoptError, match="1-channel"):
        trial_psnr(setup, [cmount.lens])
    # without the hook the same lens scores a finite number
    assert np.isfinite(trial_psnr(PsnrSetup(cmount.camera(), count=1, patch=16, sampling="rings:2"),
                                  [cmount.lens])["psnr_pre"]).all()
