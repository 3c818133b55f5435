"""Devices: the optimization problem creates its tensors on the device asked for; ``--device``
checks the device before any work; the CUDA test runs where CUDA exists."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from lensopt.cli.app import app
from lensopt.design import build_problem, optimize
from lensopt.optim.lm import damped_step
from lensopt.spec import parse_spec, save_json

runner = CliRunner()


def _spec(make_cooke):  # noqa: ANN001, ANN202
    data = make_cooke(solves=[{"type": "efl", "surface": -1, "value": 50.0}],
                      constraints={"ray_failure": {"penalty_mm": 2.0}})
    for i in (0, 2, 4):
        data["surfaces"][i]["vary"] = ["radius"]
    data["surfaces"][3]["vary"] = ["thickness"]
    return parse_spec(data)


def _write(tmp_path: Path, make_cooke) -> Path:  # noqa: ANN001
    path = tmp_path / "start.json"
    save_json(_spec(make_cooke), path)
    return path


@pytest.mark.skipif(torch.cuda.is_available(), reason="CUDA is available here: the error path cannot be reached")
def test_cuda_without_cuda_is_one_line_and_exit_2(tmp_path: Path, make_cooke) -> None:  # noqa: ANN001
    start = _write(tmp_path, make_cooke)
    out = tmp_path / "x.json"
    r = runner.invoke(app, ["optimize", str(start), "-o", str(out), "--device", "cuda", "-q"])
    assert r.exit_code == 2 and r.output.count("\n") == 1
    assert "--device: CUDA is not available on this machine" in r.output
    assert not out.exists()


def test_bad_device_and_jacobian_names_are_one_line_and_exit_2(tmp_path: Path, make_cooke) -> None:  # noqa: ANN001
    start = _write(tmp_path, make_cooke)
    out = tmp_path / "x.json"
    r = runner.invoke(app, ["optimize", str(start), "-o", str(out), "--device", "gpu0", "-q"])
    assert r.exit_code == 2 and r.output.count("\n") == 1 and "--device" in r.output and "gpu0" in r.output
    r = runner.invoke(app, ["optimize", str(start), "-o", str(out), "--jacobian", "numeric", "-q"])
    assert r.exit_code == 2 and r.output.count("\n") == 1 and "--jacobian" in r.output
    assert not out.exists()


def _check_on(device: torch.device, make_cooke) -> None:  # noqa: ANN001
    """Every tensor the LM path touches lives on ``device``; the numbers equal the CPU problem's."""
    spec = _spec(make_cooke)
    cpu = build_problem(spec)
    p = build_problem(spec, device=device)
    assert p.theta0.device.type == device.type and p.pupil.device.type == device.type
    assert p.field_weights.device.type == device.type and p.row_scale(0.5).device.type == device.type
    lens, _ = p.lens(p.theta0)
    assert lens.curvature.device.type == device.type
    J, r = p.jacobian(p.theta0)
    assert J.device.type == device.type and r.device.type == device.type
    J0, r0 = cpu.jacobian(cpu.theta0)
    torch.testing.assert_close(J.cpu(), J0, rtol=1e-10, atol=1e-12)
    torch.testing.assert_close(r.cpu(), r0, rtol=1e-10, atol=1e-12)
    ev = p.evaluate(p.theta0)
    assert ev.physical and ev.residuals.device.type == device.type
    D = torch.linalg.vector_norm(J, dim=0).clamp_min(1e-6)
    step = damped_step(J, r, D, 1e-2)
    assert step.device.type == device.type and bool(torch.isfinite(step).all())
    res = optimize(spec, steps=4, device=device)
    assert res.theta.device.type == device.type and res.steps == 4


def test_problem_on_the_cpu_device(make_cooke) -> None:  # noqa: ANN001
    _check_on(torch.device("cpu"), make_cooke)


def test_auto_device_is_cuda_when_there_is_one() -> None:
    from lensopt.devices import resolve_device

    assert resolve_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    assert resolve_device(None).type == "cpu" and resolve_device("cpu").type == "cpu"


@pytest.mark.skipif(not torch.cuda.is_available(),
                    reason="no CUDA device on this machine (torch CPU build or no GPU): the CUDA path was not run")
def test_problem_on_cuda(make_cooke) -> None:  # noqa: ANN001
    _check_on(torch.device("cuda"), make_cooke)
