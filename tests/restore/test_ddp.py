"""Data parallelism on CPU: torchrun with 2 gloo ranks gives the same lens and network, to rounding, as
one process on the combined batch; ranks started with different settings stop with one-line errors."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from lensopt.checkpoint import load_checkpoint
from tests.restore.joint_spec import joint_data

ROOT = Path(__file__).resolve().parents[2]
TORCHRUN = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2"]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["OMP_NUM_THREADS"] = "1"
    return env


@pytest.mark.slow
def test_two_gloo_ranks_equal_one_process_with_the_combined_batch(tmp_path: Path) -> None:
    spec = tmp_path / "j.json"
    spec.write_text(json.dumps(joint_data(batch=2, steps=2)))
    base = ["-m", "lensopt", "optimize", str(spec), "--json", "-q"]
    one = subprocess.run([sys.executable, *base, "-o", str(tmp_path / "one.json"), "--checkpoint",
                          str(tmp_path / "ck1")], env=_env(), capture_output=True, text=True, timeout=600)
    assert one.returncode == 0, one.stderr
    two = subprocess.run([*TORCHRUN, *base, "-o", str(tmp_path / "two.json"), "--checkpoint", str(tmp_path / "ck2")],
                         env=_env(), capture_output=True, text=True, timeout=600)
    assert two.returncode == 0, two.stderr[-3000:]
    assert json.loads(two.stdout)["processes"] == 2
    a, b = load_checkpoint(tmp_path / "ck1"), load_checkpoint(tmp_path / "ck2")
    # Lens: float64 LM on all-reduced GTRA targets (rounding of the sum order only).
    torch.testing.assert_close(a.state["lm.theta"], b.state["lm.theta"], rtol=1e-9, atol=1e-12)
    assert not torch.equal(a.state["lm.theta"], torch.zeros_like(a.state["lm.theta"]))
    # Network: float32, DDP's averaged gradients vs the combined batch's.
    for k in a.network:
        torch.testing.assert_close(a.network[k], b.network[k], rtol=1e-4, atol=1e-6)


@pytest.mark.slow
def test_ranks_with_different_settings_stop_with_one_line_errors() -> None:
    r = subprocess.run([*TORCHRUN, str(ROOT / "tests" / "restore" / "ddp_mismatch.py")], env=_env(),
                       capture_output=True, text=True, timeout=300)
    assert r.returncode != 0
    # Each rank's line is written whole (issue 27: with PYTHONUNBUFFERED, print's two writes interleaved into
    # "…same command and specrank 0: error: …"); torchrun's own report lines start with spaces or "[".
    lines = [ln for ln in r.stderr.splitlines() if re.match(r"rank \d+: ", ln)]
    assert sorted(ln[:15] for ln in lines) == ["rank 0: error: ", "rank 1: error: "], r.stdout + r.stderr[-2000:]
    assert all(ln.count("error:") == 1 and ln.endswith("same command and spec") for ln in lines), lines


@pytest.mark.slow
def test_train_irm_two_gloo_ranks_equal_one_process(tiny_lens: Path, tmp_path: Path) -> None:
    base = ["-m", "lensopt", "train-irm", str(tiny_lens), "--steps", "2", "--batch", "2", "--fields", "3",
            "--psf-size", "9", "--sampling", "rings:4", "--json"]
    one = subprocess.run([sys.executable, *base, "-o", str(tmp_path / "ck1")], env=_env(), capture_output=True,
                         text=True, timeout=600)
    assert one.returncode == 0, one.stderr
    two = subprocess.run([*TORCHRUN, *base, "-o", str(tmp_path / "ck2")], env=_env(), capture_output=True, text=True,
                         timeout=600)
    assert two.returncode == 0, two.stderr[-3000:]
    a, b = load_checkpoint(tmp_path / "ck1"), load_checkpoint(tmp_path / "ck2")
    assert a.step == b.step == 2
    moved = 0
    for k in a.network:
        torch.testing.assert_close(a.network[k], b.network[k], rtol=1e-4, atol=1e-6)
        moved += int(not torch.equal(a.network[k], torch.zeros_like(a.network[k])))
    assert moved > 0
