"""One colour model from training to restoration: the channels of a network are the lens's (its spectrum's
R, G, B), the same as ``simulate``/``evaluate`` render; a checkpoint whose channels or lens structure differ
is refused in one line naming both; a gray capture through an RGB network is converted with a notice."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch
from typer.testing import CliRunner

from lensopt.checkpoint import Checkpoint, save_checkpoint
from lensopt.cli.app import app
from lensopt.design.restore import configs_from_spec
from lensopt.imaging.io import ImageInfo, read_image, write_image
from lensopt.imaging.rgb import rgb_weights_from_spectrum
from lensopt.restore import ConditionedRestorer, RestoreConfig
from lensopt.restore.apply import match_channels
from lensopt.restore.capture import imaging_setup
from lensopt.restore.checkpoint import network_fingerprint
from lensopt.spec import build, dump_json, load_spec

runner = CliRunner()


def test_training_channels_follow_the_spectrum_rule(cmount) -> None:
    # C-mount: 12 wavelengths. With its rgb_weights the network images in them; without, RGB by the seed's
    # split (S4.1.2), as simulate renders.
    setup = imaging_setup(cmount.camera(), patch=64)
    np.testing.assert_array_equal(setup.channel_weights.numpy(), np.asarray(cmount.spec.spectrum.rgb_weights))
    assert setup.describe()["colour"] == "spectrum.rgb_weights"
    bare = cmount.spec.model_copy(update={"spectrum": cmount.spec.spectrum.model_copy(update={"rgb_weights": None})})
    spec = bare.spectrum
    assert spec.rgb_weights is None and len(spec.wavelengths_nm) == 12
    setup = imaging_setup(build(bare).camera(), patch=64)
    want = rgb_weights_from_spectrum(spec.wavelengths_nm, spec.weights_or_uniform)
    assert setup.channels == 3
    np.testing.assert_allclose(setup.channel_weights.numpy(), want, rtol=0, atol=1e-15)
    assert "contiguous thirds of the spectrum" in setup.describe()["colour"]  # the seed's rule, S4.1.2


def test_match_channels_gray_and_colour() -> None:
    gray = torch.rand(1, 5, 7)
    rgb, note = match_channels(gray, 3)
    assert rgb.shape == (3, 5, 7) and note and "gray" in note
    assert torch.equal(rgb[0], gray[0]) and torch.equal(rgb[2], gray[0])
    back, note = match_channels(rgb, 1)
    assert note and torch.allclose(back, gray)
    same, note = match_channels(rgb, 3)
    assert same is rgb and note is None


def _checkpoint(lens: Path, out: Path, *, channels: int) -> None:
    """A fresh (identity) network of ``channels`` channels for ``lens``, written through the library."""
    spec = load_spec(lens)
    net_cfg, _ = configs_from_spec(spec.restore)
    net_cfg = RestoreConfig(**{**net_cfg.to_dict(), "channels": channels})
    meta = {"network_config": net_cfg.to_dict(),
            "settings": {"imaging": {"fields": 3, "psf_size": 9, "grid": [3, 3], "patch": 16, "sampling": "rings:4"}}}
    save_checkpoint(out, Checkpoint(kind="train-irm", step=0, lens_json=dump_json(spec),
                                    network=dict(ConditionedRestorer(net_cfg).state_dict()), meta=meta,
                                    fingerprint=network_fingerprint(spec, net_cfg)))


def test_gray_capture_through_rgb_network_is_converted(tiny_lens: Path, tmp_path: Path) -> None:
    ck = tmp_path / "id"
    _checkpoint(tiny_lens, ck, channels=3)
    img = np.random.default_rng(1).random((40, 56, 1)).astype(np.float32)
    src, out = tmp_path / "gray.png", tmp_path / "out.png"
    write_image(src, img, ImageInfo(56, 40, 1, 8, False, "sRGB", "png"))
    r = runner.invoke(app, ["restore", str(tiny_lens), str(ck), str(src), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "note: IMAGE is a 1-channel (gray) capture" in r.output
    got, info = read_image(out)
    want, _ = read_image(src)
    # written back gray; the fresh network is the identity, so R = G = B restored and averaged is the capture
    assert got.shape == (40, 56, 1)
    np.testing.assert_allclose(got, want, atol=1.5 / 255)


def test_network_of_other_channels_is_refused_naming_both(tiny_lens: Path, tmp_path: Path) -> None:
    ck = tmp_path / "gray_net"
    _checkpoint(tiny_lens, ck, channels=1)
    img = np.random.default_rng(0).random((32, 32, 3)).astype(np.float32)
    src, out = tmp_path / "in.png", tmp_path / "out.png"
    write_image(src, img, ImageInfo(32, 32, 3, 8, False, "sRGB", "png"))
    r = runner.invoke(app, ["restore", str(tiny_lens), str(ck), str(src), "-o", str(out)])
    assert r.exit_code == 2
    assert "1-channel" in r.output and "3 channels" in r.output
    assert len(r.output.strip().splitlines()) == 1 and not out.exists()
    r = runner.invoke(app, ["evaluate", str(tiny_lens), "--count", "1", "--patch", "32", "--irm", str(ck), "--json"])
    assert r.exit_code == 2 and "1-channel" in r.output


def test_train_irm_records_channels_and_structure(tiny_lens: Path, tmp_path: Path) -> None:
    ck = tmp_path / "ck"
    r = runner.invoke(app, ["train-irm", str(tiny_lens), "-o", str(ck), "--steps", "1", "--fields", "3",
                            "--sampling", "rings:4", "--psf-size", "9", "--val-patches", "1"])
    assert r.exit_code == 0, r.output
    meta = json.loads((ck / "meta.json").read_text())["meta"]
    assert meta["network_config"]["channels"] == 3 == meta["colour"]["channels"]
    assert meta["settings"]["imaging"]["channels"] == 3
    assert meta["lens_structure"]["wavelengths"] == 3
