"""``lensopt evaluate``'s --backend (issue 13) and --device (issue 11) options."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from lensopt.cli.app import app
from tests.helpers import CMOUNT

ROOT = Path(__file__).resolve().parents[2]
SMALL = ["--count", "2", "--patch", "64", "--rays", "rings:4", "--json"]
runner = CliRunner()


def _spy(monkeypatch: pytest.MonkeyPatch) -> list[dict]:
    """Record the trace backend of the engine and the camera's device the library's evaluate is given."""
    import lensopt.imaging.evaluate as ev

    seen: list[dict] = []
    real = ev.evaluate

    def spy(camera, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
        seen.append({"backend": kwargs["engine"].backend, "device": str(camera.lens.device)})
        return real(camera, *args, **kwargs)

    monkeypatch.setattr(ev, "evaluate", spy)
    return seen


@pytest.mark.parametrize(("args", "backend"), [([], "auto"), (["--backend", "eager"], "eager")])
def test_backend_option_is_in_force_while_evaluating(monkeypatch: pytest.MonkeyPatch, args: list[str],
                                                     backend: str) -> None:
    seen = _spy(monkeypatch)
    r = runner.invoke(app, ["evaluate", str(CMOUNT), *SMALL, *args])
    assert r.exit_code == 0, r.stderr
    assert [s["backend"] for s in seen] == [backend]


def test_bad_backend_is_one_line_exit_2() -> None:
    r = runner.invoke(app, ["evaluate", str(CMOUNT), *SMALL, "--backend", "fast"])
    assert r.exit_code == 2 and r.stderr.startswith("error: ") and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "backend" in r.stderr


# ------------------------------------------------------------------------------------------- --device

IMAGE = ROOT / "lensopt" / "imaging" / "data" / "coffee.png"
SIM = ["--region", "corner", "--rays", "rings:4", "--effects", "+distortion,+ri,noise=0.01", "--json",
       "--score"]


def _simulate(tmp_path: Path, name: str, *args: str) -> tuple[dict, bytes]:
    out = tmp_path / name
    r = runner.invoke(app, ["simulate", str(CMOUNT), str(IMAGE), "-o", str(out), *SIM, *args])
    assert r.exit_code == 0, r.stderr
    return json.loads(r.stdout)["metrics"], out.read_bytes()


@pytest.mark.parametrize("device", ["cpu", "auto"])
def test_device_cpu_and_auto_give_the_default_results(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                      device: str) -> None:
    """On a machine without CUDA, cpu and auto are the CPU: the same files and scores as no option."""
    if device == "auto" and torch.cuda.is_available():
        pytest.skip("CUDA is available here: auto is CUDA (see the CUDA test)")
    assert _simulate(tmp_path, "a.png") == _simulate(tmp_path, "b.png", "--device", device)
    seen = _spy(monkeypatch)
    r0 = runner.invoke(app, ["evaluate", str(CMOUNT), *SMALL])
    r1 = runner.invoke(app, ["evaluate", str(CMOUNT), *SMALL, "--device", device])
    assert r0.exit_code == r1.exit_code == 0, r1.stderr
    assert [s["device"] for s in seen] == ["cpu", "cpu"]
    a, b = json.loads(r0.stdout), json.loads(r1.stdout)
    assert a["items"] == b["items"]


@pytest.mark.skipif(torch.cuda.is_available(), reason="CUDA is available here: the error path cannot be reached")
@pytest.mark.parametrize("command", ["simulate", "evaluate"])
@pytest.mark.parametrize("device", ["cuda", "cuda:1"])
def test_cuda_without_cuda_is_one_line_exit_2(tmp_path: Path, command: str, device: str) -> None:
    out = tmp_path / "o.png"
    args = [str(IMAGE), "-o", str(out)] if command == "simulate" else []
    r = runner.invoke(app, [command, str(CMOUNT), *args, "--device", device])
    assert r.exit_code == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert r.stderr.startswith("error: --device: CUDA is not available on this machine"), r.stderr
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", ["simulate", "evaluate"])
def test_bad_device_name_is_one_line_exit_2(tmp_path: Path, command: str) -> None:
    args = [str(IMAGE), "-o", str(tmp_path / "o.png")] if command == "simulate" else []
    r = runner.invoke(app, [command, str(CMOUNT), *args, "--device", "gpu0"])
    assert r.exit_code == 2 and len(r.stderr.strip().splitlines()) == 1 and "--device" in r.stderr, r.stderr


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device on this machine (the CPU tests above "
                    "cover the option; this one compares CUDA with the CPU)")
def test_cuda_matches_the_cpu(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The lens, the PSFs, the grid and the convolution on the GPU; the same image as the CPU's to float32
    rounding (scores to 1e-3 dB), and evaluate's scores likewise."""
    import numpy as np

    from lensopt.imaging.io import read_image

    m_cpu, _ = _simulate(tmp_path, "cpu.exr", "--device", "cpu")
    m_gpu, _ = _simulate(tmp_path, "gpu.exr", "--device", "cuda")
    a, _ = read_image(tmp_path / "cpu.exr")
    b, _ = read_image(tmp_path / "gpu.exr")
    assert np.abs(a - b).max() < 1e-4 * max(float(np.abs(a).max()), 1.0)
    assert m_gpu["psnr_db"] == pytest.approx(m_cpu["psnr_db"], abs=1e-3)
    seen = _spy(monkeypatch)
    r0 = runner.invoke(app, ["evaluate", str(CMOUNT), *SMALL, "--device", "cpu"])
    r1 = runner.invoke(app, ["evaluate", str(CMOUNT), *SMALL, "--device", "cuda"])
    assert r0.exit_code == r1.exit_code == 0, r1.stderr
    assert [s["device"] for s in seen] == ["cpu", "cuda:0"]
    for x, y in zip(json.loads(r0.stdout)["items"], json.loads(r1.stdout)["items"], strict=True):
        assert y["psnr_db"] == pytest.approx(x["psnr_db"], abs=1e-3)
