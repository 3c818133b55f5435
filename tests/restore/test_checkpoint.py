"""Checkpoints (lensopt.checkpoint) and train-irm runs: round trip, corruption and structure checks, atomic
writes, and --resume continuing bit-identically to an uninterrupted run."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from lensopt.checkpoint import (
    Checkpoint,
    CheckpointError,
    flatten_optimizer,
    load_checkpoint,
    save_checkpoint,
    unflatten_optimizer,
)
from lensopt.cli.app import app

runner = CliRunner()


def _ckpt(step: int = 3) -> Checkpoint:
    g = torch.Generator().manual_seed(5)
    return Checkpoint(kind="train-irm", step=step, lens_json='{"name": "x"}',
                      network={"w": torch.arange(6.0).reshape(2, 3), "s": torch.tensor(1.5)},
                      state={"rng.scenes": g.get_state(), "adam.0.step": torch.tensor(3.0)},
                      meta={"a": [1, 2]}, fingerprint="abc")


def test_round_trip_and_overwrite(tmp_path: Path) -> None:
    p = tmp_path / "ck"
    save_checkpoint(p, _ckpt(1))
    save_checkpoint(p, _ckpt(2))  # replaces the previous one
    ck = load_checkpoint(p, expect_fingerprint="abc")
    assert ck.step == 2 and ck.meta == {"a": [1, 2]} and ck.lens_json == '{"name": "x"}'
    assert torch.equal(ck.network["w"], torch.arange(6.0).reshape(2, 3))
    assert torch.equal(ck.state["rng.scenes"], torch.Generator().manual_seed(5).get_state())
    assert sorted(os.listdir(tmp_path)) == ["ck"]  # no temporary folders left


def test_corrupt_missing_and_foreign(tmp_path: Path) -> None:
    p = tmp_path / "ck"
    save_checkpoint(p, _ckpt())
    with pytest.raises(CheckpointError, match="another lens structure"):
        load_checkpoint(p, expect_fingerprint="zzz")
    data = bytearray((p / "network.safetensors").read_bytes())
    data[-1] ^= 0xFF
    (p / "network.safetensors").write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="corrupt checkpoint: network.safetensors"):
        load_checkpoint(p)
    (p / "meta.json").write_text("{not json")
    with pytest.raises(CheckpointError, match="corrupt"):
        load_checkpoint(p)
    with pytest.raises(CheckpointError, match="no such checkpoint"):
        load_checkpoint(tmp_path / "nope")


def test_failed_write_keeps_the_previous_checkpoint(tmp_path: Path) -> None:
    p = tmp_path / "ck"
    save_checkpoint(p, _ckpt(1))
    bad = _ckpt(2)
    bad.meta = {"x": object()}  # not JSON-serialisable: fails after the tensors were written
    with pytest.raises(TypeError):
        save_checkpoint(p, bad)
    assert load_checkpoint(p).step == 1
    assert sorted(os.listdir(tmp_path)) == ["ck"]


def test_optimizer_state_round_trip() -> None:
    torch.manual_seed(0)
    lin = torch.nn.Linear(3, 2)
    opt = torch.optim.Adam(lin.parameters(), lr=1e-3, betas=(0.9, 0.9))
    lin(torch.randn(4, 3)).sum().backward()
    opt.step()
    tensors, info = flatten_optimizer("adam", opt.state_dict())
    info = json.loads(json.dumps(info))
    opt2 = torch.optim.Adam(lin.parameters(), lr=5.0)
    opt2.load_state_dict(unflatten_optimizer("adam", tensors, info))
    a, b = opt.state_dict(), opt2.state_dict()
    assert a["param_groups"] == b["param_groups"]
    for i in a["state"]:
        for k in a["state"][i]:
            assert torch.equal(a["state"][i][k], b["state"][i][k])


def _train(lens: Path, out: Path, *extra: str) -> object:
    return runner.invoke(app, ["train-irm", str(lens), "-o", str(out), "--fields", "3", "--psf-size", "9",
                               "--sampling", "rings:4", "--json", *extra])


def test_resume_is_bit_identical(tiny_lens: Path, tmp_path: Path) -> None:
    full = _train(tiny_lens, tmp_path / "full", "--steps", "4")
    assert full.exit_code == 0, full.output
    # An interrupted run: SIGTERM during step 3 stops it at the step boundary with a checkpoint (exit 143).
    part = tmp_path / "part"
    from lensopt.restore import train as training

    calls = {"n": 0}
    orig = training.network_step

    def term_during_third(*a, **k):  # noqa: ANN002, ANN003
        calls["n"] += 1
        if calls["n"] == 3:
            os.kill(os.getpid(), signal.SIGTERM)
        return orig(*a, **k)

    training.network_step = term_during_third
    try:
        r = _train(tiny_lens, part, "--steps", "4", "--checkpoint-every", "0")
    finally:
        training.network_step = orig
    assert r.exit_code == 143, r.output
    assert load_checkpoint(part).step == 3
    res = _train(tiny_lens, part, "--steps", "4", "--resume")
    assert res.exit_code == 0, res.output
    a, b = load_checkpoint(tmp_path / "full"), load_checkpoint(part)
    assert a.step == b.step == 4
    for k in a.network:
        assert torch.equal(a.network[k], b.network[k]), k
    for k in a.state:
        assert torch.equal(a.state[k], b.state[k]), k


def test_train_irm_errors(tiny_lens: Path, other_lens: Path, tmp_path: Path) -> None:
    out = tmp_path / "ck"
    assert _train(tiny_lens, out, "--steps", "1", "--log-dir", str(tmp_path / "tb")).exit_code == 0
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(tmp_path / "tb"))
    acc.Reload()
    assert "train-irm/psnr_restored" in acc.Tags()["scalars"]
    assert {"train-irm/scene_capture_restored", "train-irm/conditioning_psf"} <= set(acc.Tags()["images"])
    r = _train(tiny_lens, out, "--steps", "1")  # exists, no --resume
    assert r.exit_code == 2 and "--resume" in r.output
    r = _train(other_lens, out, "--steps", "2", "--resume")
    assert r.exit_code == 2 and "another lens structure" in r.output
    r = _train(tiny_lens, out, "--steps", "2", "--batch", "3", "--resume")
    assert r.exit_code == 2 and "other settings" in r.output and "batch" in r.output
    if not torch.cuda.is_available():
        r = _train(tiny_lens, tmp_path / "c", "--steps", "1", "--device", "cuda")
        assert r.exit_code == 2 and "CUDA is not available" in r.output
        assert not (tmp_path / "c").exists()
    (out / "state.safetensors").write_bytes(b"garbage")
    r = _train(tiny_lens, out, "--steps", "2", "--resume")
    assert r.exit_code == 2 and "corrupt" in r.output
    assert len(r.output.strip().splitlines()) == 1


def test_restore_command(tiny_lens: Path, other_lens: Path, tmp_path: Path) -> None:
    import numpy as np

    from lensopt.imaging.io import ImageInfo, read_image, write_image

    ck = tmp_path / "ck"
    assert _train(tiny_lens, ck, "--steps", "1").exit_code == 0
    img = np.random.default_rng(0).random((40, 56, 3)).astype(np.float32)
    src = tmp_path / "in.png"
    write_image(src, img, ImageInfo(56, 40, 3, 8, False, "sRGB", "png"))
    out = tmp_path / "out.png"
    r = runner.invoke(app, ["restore", str(tiny_lens), str(ck), str(src), "-o", str(out)])
    assert r.exit_code == 0, r.output
    got, info = read_image(out)
    assert got.shape == (40, 56, 3)
    r = runner.invoke(app, ["restore", str(other_lens), str(ck), str(src), "-o", str(tmp_path / "x.png")])
    # both structures named: the network's (6 spheres) and the lens's (conic first surface)
    assert r.exit_code == 2 and "trained for 6 surfaces (sphere×6)" in r.output, r.output
    assert "the lens has 6 surfaces (conic, sphere×5)" in r.output
    assert len(r.output.strip().splitlines()) == 1
    assert not (tmp_path / "x.png").exists()


def _identity_checkpoint(lens: Path, out: Path) -> None:
    """A checkpoint holding a fresh (identity) network for ``lens``, written through the library."""
    from lensopt.checkpoint import Checkpoint, save_checkpoint
    from lensopt.design.restore import configs_from_spec
    from lensopt.restore import ConditionedRestorer
    from lensopt.restore.checkpoint import network_fingerprint
    from lensopt.spec import dump_json, load_spec

    spec = load_spec(lens)
    net_cfg, _ = configs_from_spec(spec.restore)
    meta = {"network_config": net_cfg.to_dict(),
            "settings": {"imaging": {"fields": 3, "psf_size": 9, "grid": [3, 3], "patch": 16, "sampling": "rings:4"}}}
    save_checkpoint(out, Checkpoint(kind="train-irm", step=0, lens_json=dump_json(spec),
                                    network=dict(ConditionedRestorer(net_cfg).state_dict()), meta=meta,
                                    fingerprint=network_fingerprint(spec, net_cfg)))


def test_identity_network_restores_tiles_exactly_and_evaluate_irm(tiny_lens: Path, tmp_path: Path) -> None:
    # restore_image cuts the image into 16-px tiles with context; an identity network must give the
    # capture back exactly, so evaluate --irm must score the same as without it.
    ck = tmp_path / "id"
    _identity_checkpoint(tiny_lens, ck)
    r = runner.invoke(app, ["evaluate", str(tiny_lens), "--count", "2", "--patch", "32", "--rays", "rings:4",
                            "--noise", "0.01", "--irm", str(ck), "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.output)
    assert out["restored"] is False and out["after_restoration"]["restored"] is True
    assert out["after_restoration"]["psnr_db"] == out["psnr_db"]
    assert out["after_restoration"]["ssim"] == out["ssim"]
