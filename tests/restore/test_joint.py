"""Joint lens + network optimization (objective = "restored", S3.3): gradient of the restored image
w.r.t. a lens curvature against central finite differences, GTRA of the restored loss, one joint step
improving both parts, checkpoint + resume bit-identical, the CLI."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from lensopt.checkpoint import load_checkpoint
from lensopt.cli.app import app
from lensopt.design import build_problem
from lensopt.design.joint import RestoredObjective
from lensopt.design.joint_run import run_joint
from lensopt.optim import Problem
from lensopt.optim.gtra import gtra_residual
from lensopt.restore import ConditionedRestorer, RestoreConfig
from lensopt.spec import parse_spec
from tests.restore.joint_spec import joint_data

TINY = RestoreConfig(width=4, encoder_blocks=(1, 1), middle_blocks=1, decoder_blocks=(1, 1))


def _objective(noise: float = 0.0, psf_size: int = 9) -> tuple[Problem, RestoredObjective, ConditionedRestorer]:
    spec = parse_spec(joint_data(noise=noise, psf_size=psf_size))
    problem = build_problem(spec, method="lm")
    torch.manual_seed(0)
    net = ConditionedRestorer(TINY).double()
    with torch.no_grad():  # away from the identity initialisation, so that every stage matters
        for p in net.parameters():
            p.add_(0.1 * torch.randn_like(p))
        net.gate.fill_(0.5)
    obj = RestoredObjective(problem.setup.camera, problem.opt.image, net, dtype=torch.float64)
    return problem, obj, net


def test_restored_loss_gradient_wrt_a_curvature_equals_central_differences() -> None:
    problem, obj, net = _objective()
    lens0 = problem.setup.lens

    def f(c1: torch.Tensor) -> torch.Tensor:
        curv = torch.cat([lens0.curvature[:1], c1.reshape(1), lens0.curvature[2:]])
        return obj.loss(dataclasses.replace(lens0, curvature=curv))

    c = lens0.curvature[1].detach().clone().requires_grad_(True)
    (g,) = torch.autograd.grad(f(c), c)
    h = 1e-6 * abs(float(c.detach()))
    with torch.no_grad():
        fd = (f(c + h) - f(c - h)) / (2 * h)
    assert float(g) != 0.0
    assert abs(float(g) - float(fd)) <= 1e-5 * abs(float(fd))
    # the network is part of that gradient: the identity network gives another one
    obj.net = ConditionedRestorer(TINY).double()
    (g_id,) = torch.autograd.grad(f(c), c)
    assert abs(float(g_id) - float(g)) > 1e-3 * abs(float(g))


def test_gtra_of_the_restored_loss_reproduces_loss_and_gradient() -> None:
    # S66: at θ₀, ½‖ℓ_GTRA‖² = L and ∂/∂ε of ½‖ℓ_GTRA‖² = ∇_ε L (no clipping at this size).
    problem, obj, net = _objective(psf_size=25)
    lens = problem.setup.lens
    t = obj.update(lens)
    assert t.clipped == 0
    with torch.no_grad():
        direct = obj.loss(lens)
    assert float(t.loss) == pytest.approx(float(direct), rel=1e-12)
    spots = obj.spots(lens)
    e = spots.xy.detach().clone().requires_grad_(True)
    half_sq = 0.5 * (gtra_residual(e, spots.valid, t) ** 2).sum()
    assert float(half_sq.detach()) == pytest.approx(float(direct), rel=1e-10)
    (g,) = torch.autograd.grad(half_sq, e)
    torch.testing.assert_close(g, t.grad, rtol=1e-8, atol=1e-12)


def test_resume_of_a_joint_run_is_bit_identical(tmp_path: Path) -> None:
    spec = parse_spec(joint_data(steps=3))
    full = run_joint(spec, steps=3, checkpoint=tmp_path / "full", evaluate=False)
    calls = {"n": 0}

    def stop() -> bool:
        calls["n"] += 1
        return calls["n"] > 2  # two steps, then a "Ctrl-C" at the boundary

    part = run_joint(spec, steps=3, checkpoint=tmp_path / "part", evaluate=False, stop=stop)
    assert part.interrupted and part.steps == 2 and load_checkpoint(tmp_path / "part").step == 2
    rest = run_joint(spec, steps=3, checkpoint=tmp_path / "part", resume=True, evaluate=False)
    assert rest.steps == 3
    a, b = load_checkpoint(tmp_path / "full"), load_checkpoint(tmp_path / "part")
    assert torch.equal(a.state["lm.theta"], b.state["lm.theta"])
    for k in a.network:
        assert torch.equal(a.network[k], b.network[k]), k
    assert a.lens_json == b.lens_json
    assert [h["mae"] for h in full.history] == [h["mae"] for h in rest.history]


def test_joint_steps_move_both_lens_and_network(tmp_path: Path) -> None:
    spec = parse_spec(joint_data(steps=2))
    res = run_joint(spec, steps=2, evaluate=True, log_dir=tmp_path / "tb", validate_every=2)
    assert res.start is not None and res.final is not None
    # identity network at the start: restored = raw exactly
    assert res.start["psnr_restored"] == res.start["psnr_raw"]
    assert res.final["psnr_restored"] != res.final["psnr_raw"]
    r0 = [s.radius for s in spec.surfaces[:3]]
    r1 = [s.radius for s in res.spec.surfaces[:3]]
    assert r0[0] != r1[0] and r0[2] != r1[2] and r0[1] == r1[1]
    assert all(h["accepted"] in (True, False) and h["mae"] > 0 for h in res.history)
    assert "psnr_restored" in res.history[-1]
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(tmp_path / "tb"))
    acc.Reload()
    assert {"joint/psnr_restored", "joint/mae", "joint/esr_um"} <= set(acc.Tags()["scalars"])
    assert "joint/scene_capture_restored" in acc.Tags()["images"]


def test_cli_optimize_restored_and_errors(tmp_path: Path) -> None:
    runner = CliRunner()
    spec = tmp_path / "joint.json"
    spec.write_text(json.dumps(joint_data(steps=1)))
    out, ck = tmp_path / "lens.json", tmp_path / "ck"
    r = runner.invoke(app, ["optimize", str(spec), "-o", str(out), "--checkpoint", str(ck), "--json"])
    assert r.exit_code == 0, r.output
    s = json.loads(r.output)
    assert s["steps"] == 1 and s["final"]["psnr_restored"] > 0
    assert out.exists() and load_checkpoint(ck).kind == "joint"
    # the joint checkpoint restores images with the written lens
    r = runner.invoke(app, ["optimize", str(spec), "-o", str(out), "--checkpoint", str(ck)])
    assert r.exit_code == 2 and "--resume" in r.output
    other = joint_data(steps=1)
    other["restore"]["width"] = 8
    spec2 = tmp_path / "other.json"
    spec2.write_text(json.dumps(other))
    r = runner.invoke(app, ["optimize", str(spec2), "-o", str(out), "--checkpoint", str(ck), "--resume"])
    assert r.exit_code == 2 and "another lens structure or network" in r.output
    if not torch.cuda.is_available():
        r = runner.invoke(app, ["optimize", str(spec), "-o", str(tmp_path / "c.json"), "--device", "cuda"])
        assert r.exit_code == 2 and "CUDA" in r.output and not (tmp_path / "c.json").exists()


def test_optimize_restored_without_checkpoint_writes_the_network_beside_the_lens(tmp_path: Path) -> None:
    # issue 27: objective = "restored" without --checkpoint used to throw the trained network away
    runner = CliRunner()
    spec = tmp_path / "joint.json"
    spec.write_text(json.dumps(joint_data(steps=1)))
    out = tmp_path / "lens.json"
    r = runner.invoke(app, ["optimize", str(spec), "-o", str(out), "--json"])
    assert r.exit_code == 0, r.output
    s = json.loads(r.output)
    beside = tmp_path / "lens.irm"
    assert s["checkpoint"] == str(beside) and load_checkpoint(beside).kind == "joint"
    # the network written is the one restore/evaluate --irm load for the written lens
    from lensopt.restore.apply import load_restorer
    from lensopt.spec import build, load_spec

    net, setup, _ = load_restorer(beside, build(load_spec(out)))
    assert net.config.channels == setup.channels == 3
    # a second run with the same -o does not overwrite it silently
    r = runner.invoke(app, ["optimize", str(spec), "-o", str(out)])
    assert r.exit_code == 2 and "--resume" in r.output and len(r.output.strip().splitlines()) == 1
