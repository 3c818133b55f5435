"""The compiled LM Jacobian (accel/jacobian.py) equals the eager forward-mode Jacobian.

Oracle: ``Problem.jacobian`` (eager ``torch.func.jacfwd``, itself checked against reverse mode and
central differences in test_jacobian.py). The default tests check the captured graph run as Python
(no compiler: the capture is what can go wrong — a dropped dependency, a baked-in branch); the
Inductor-compiled graph is checked by the slow test (its compile takes minutes on a loaded machine).
"""

from __future__ import annotations

import logging

import pytest
import torch

from lensopt.accel.jacobian import CompiledJacobian, capture_jacobian
from lensopt.design import build_problem
from lensopt.optim import Problem
from lensopt.spec import load_spec, parse_spec
from tests.helpers import ROOT, SPECS, small_problem_data


def _small_problem() -> Problem:
    return build_problem(parse_spec(small_problem_data()))


def _rel(a: torch.Tensor, b: torch.Tensor) -> float:
    return float((a - b).abs().max() / b.abs().max())


def test_captured_graph_equals_eager_jacfwd() -> None:
    p = _small_problem()
    J0, r0 = p.jacobian(p.theta0)
    assert J0.shape == (p.size, 6) and bool((J0.abs().sum(0) > 0).all())
    assert bool(J0[p.slices["relative_illumination"]].abs().sum() > 0)  # active, so compared below
    gm = capture_jacobian(p.residuals, p.theta0)
    J, r = gm(p.theta0)
    assert _rel(J, J0) <= 1e-12 and _rel(r, r0) <= 1e-12
    # Another θ (a step away): the graph depends on θ, nothing of θ0 is baked in.
    theta = p.theta0 + 0.01 * torch.linspace(-1, 1, 6, dtype=torch.float64)
    J1, r1 = p.jacobian(theta)
    J2, r2 = gm(theta)
    assert _rel(J1, J0) > 1e-4  # the point really moved
    assert _rel(J2, J1) <= 1e-12 and _rel(r2, r1) <= 1e-12

    # The failure-margin walk is skipped in eager when no ray fails (as at θ0, where the graph was
    # captured); the graph must keep it, so that a θ where rays fail gets the same rows as eager.
    theta = p.theta0.clone()
    theta[0] *= 3.0  # a much stronger first surface: marginal rays fail
    assert p.failure_summary(theta)[0] > 0
    J1, r1 = p.jacobian(theta)
    J2, r2 = gm(theta)
    assert bool(r1[p.slices["ray_failure"]].abs().max() > 0)
    assert _rel(J2, J1) <= 1e-12 and _rel(r2, r1) <= 1e-12


class _Branching:
    """A residual function with a branch on θ (which a captured graph cannot represent)."""

    def residuals(self, theta: torch.Tensor) -> torch.Tensor:
        return theta**2 if bool(theta.sum() > 0) else -theta

    def jacobian(self, theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return torch.func.jacfwd(self.residuals)(theta), self.residuals(theta)


def test_branch_on_theta_falls_back_to_eager(caplog) -> None:
    theta = torch.tensor([1.0, 2.0], dtype=torch.float64)
    jac = CompiledJacobian(_Branching(), backend="graph")
    with caplog.at_level(logging.WARNING, logger="lensopt.accel.jacobian"):
        J, r = jac(theta)
    assert not jac.compiled and jac.failed and "eager" in caplog.text
    torch.testing.assert_close(J, torch.diag(2 * theta), rtol=0, atol=0)  # d(θ²)/dθ = 2θ
    J, r = jac(-theta)  # the other branch: eager follows it
    torch.testing.assert_close(J, -torch.eye(2, dtype=torch.float64), rtol=0, atol=0)


@pytest.mark.slow
def test_inductor_compiled_jacobian_equals_eager_on_cooke() -> None:
    p = build_problem(load_spec(SPECS / "cooke_triplet_opt.toml"))
    jac = CompiledJacobian(p)
    J, r = jac(p.theta0)
    assert jac.compiled, jac.failed
    J0, r0 = p.jacobian(p.theta0)
    assert _rel(J, J0) <= 1e-12 and _rel(r, r0) <= 1e-12


# ------------------------------------------------------------------------------ AOT packages per problem

def test_problem_key_follows_what_the_residual_function_is_made_of(monkeypatch) -> None:
    from lensopt import accel
    from lensopt.accel.jacobian import problem_key

    key = problem_key(_small_problem())
    assert key is not None and key == problem_key(_small_problem())  # rebuilt from the same spec
    data = small_problem_data()
    assert problem_key(build_problem(parse_spec(data))) == key
    changed = []
    data["surfaces"][1]["radius"] *= 1.0 + 1e-12  # a fixed radius, changed in its last digits
    changed.append(build_problem(parse_spec(data)))
    data["surfaces"][1]["radius"] /= 1.0 + 1e-12
    data["optimize"]["constraints"]["distortion"]["max_percent"] = 0.02
    changed.append(build_problem(parse_spec(data)))
    data["optimize"]["constraints"]["distortion"]["max_percent"] = 0.01
    changed.append(build_problem(parse_spec(data), seed=1))  # another pupil jitter
    keys = [problem_key(p) for p in changed]
    assert None not in keys and len({key, *keys}) == 4
    data = small_problem_data()
    # the trace backend can change the captured graph
    assert problem_key(build_problem(parse_spec(data), engine=accel.engine("compiled"))) not in (key, None)
    for name in ("eager", "auto"):  # under jacfwd, auto traces eagerly: one graph, one package
        assert problem_key(build_problem(parse_spec(data), engine=accel.engine(name))) == key


def test_problem_key_refuses_what_it_cannot_fingerprint() -> None:
    import hashlib

    from lensopt.accel.jacobian import _feed, problem_key

    with pytest.raises(TypeError, match="cannot fingerprint"):
        _feed(hashlib.sha256(), {"weight": lambda t: t})  # a callable could hold any state
    p = _small_problem()
    p.image = object()  # an image objective: its residual function changes with every batch
    assert problem_key(p) is None


def test_a_damaged_package_falls_back_to_eager(monkeypatch, tmp_path, caplog) -> None:
    from lensopt.accel import jacobian as cj

    monkeypatch.setenv("TORCHINDUCTOR_CACHE_DIR", str(tmp_path))
    p = _small_problem()
    path = cj.package_path(cj.problem_key(p))
    assert path.parent == tmp_path / "lensopt_aot"
    path.parent.mkdir(parents=True)
    path.write_bytes(b"PK\x03\x04 not a package")  # truncated / foreign file under this problem's name
    jac = CompiledJacobian(p)
    with caplog.at_level(logging.WARNING, logger="lensopt.accel.jacobian"):
        J, r = jac(p.theta0)
    assert not jac.compiled and jac.failed and "eager" in caplog.text
    J0, r0 = p.jacobian(p.theta0)
    torch.testing.assert_close(J, J0, rtol=0, atol=0)
    jac2 = CompiledJacobian(p)  # not tried again in this process: a second instance goes eager at once
    J2, _ = jac2(p.theta0)
    assert not jac2.compiled and "failed earlier" in jac2.failed
    torch.testing.assert_close(J2, J0, rtol=0, atol=0)


@pytest.mark.slow
def test_aot_package_is_built_once_and_loaded_by_another_process(monkeypatch, tmp_path) -> None:
    import json
    import os
    import subprocess
    import sys

    from lensopt.accel import jacobian as cj

    monkeypatch.setenv("TORCHINDUCTOR_CACHE_DIR", str(tmp_path))
    p = _small_problem()
    jac = CompiledJacobian(p)
    J, r = jac(p.theta0)
    assert jac.compiled and jac.source == "package built", jac.failed
    J0, r0 = p.jacobian(p.theta0)
    assert _rel(J, J0) <= 1e-12 and _rel(r, r0) <= 1e-12
    theta = p.theta0 + 0.01 * torch.linspace(-1, 1, 6, dtype=torch.float64)
    J1, r1 = p.jacobian(theta)
    J2, r2 = jac(theta)
    assert _rel(J1, J0) > 1e-4 and _rel(J2, J1) <= 1e-12 and _rel(r2, r1) <= 1e-12
    assert cj.package_path(cj.problem_key(p)).exists()
    # Another process with the same problem loads the package: no capture, no compile.
    script = """
import json, torch
from tests.helpers import small_problem_data
from lensopt.accel.jacobian import CompiledJacobian
from lensopt.design import build_problem
from lensopt.spec import parse_spec
p = build_problem(parse_spec(small_problem_data()))
jac = CompiledJacobian(p)
theta = p.theta0 + 0.01 * torch.linspace(-1, 1, 6, dtype=torch.float64)
J, r = jac(theta)
J0, r0 = p.jacobian(theta)
print(json.dumps({"source": jac.source, "failed": jac.failed,
                   "dj": float((J - J0).abs().max() / J0.abs().max())}))
"""
    env = {**os.environ, "TORCHINDUCTOR_CACHE_DIR": str(tmp_path), "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["source"] == "package loaded" and not got["failed"] and got["dj"] <= 1e-12


def test_a_failed_build_is_remembered_across_processes(monkeypatch, tmp_path, caplog) -> None:
    from lensopt.accel import jacobian as cj

    monkeypatch.setenv("TORCHINDUCTOR_CACHE_DIR", str(tmp_path))
    calls: list[str] = []

    def failing_build(problem, theta, key=None):  # type: ignore[no-untyped-def]
        calls.append(key)
        raise RuntimeError("C++ compile error (stand-in)")

    monkeypatch.setattr(cj, "build_package", failing_build)
    p = _small_problem()
    J0, _ = p.jacobian(p.theta0)
    jac = CompiledJacobian(p)
    J, _ = jac(p.theta0)
    assert not jac.compiled and len(calls) == 1 and "stand-in" in jac.failed
    torch.testing.assert_close(J, J0, rtol=0, atol=0)
    marker = cj.package_path(cj.problem_key(p)).with_suffix(".failed")
    assert "stand-in" in marker.read_text()
    monkeypatch.setattr(cj, "_broken", set())  # as in a new process
    with caplog.at_level(logging.WARNING, logger="lensopt.accel.jacobian"):
        J, _ = CompiledJacobian(p)(p.theta0)
    assert len(calls) == 1 and "delete" in caplog.text and str(marker) in caplog.text  # no second build
    torch.testing.assert_close(J, J0, rtol=0, atol=0)
    marker.unlink()  # deleted: the next process tries again
    CompiledJacobian(p)(p.theta0)
    assert len(calls) == 2
