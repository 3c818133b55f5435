"""``lensopt optimize --checkpoint DIR`` / ``--resume`` (issue 29): a run interrupted at any step and
continued from its checkpoint ends on the uninterrupted run's lens bit for bit, whether it stopped
before, at or after the glass binding, after a rejected LM step (its Jacobian held), or under Adam.

The reference is the same run without interruption (an independent execution of the same
arithmetic); equality is exact (``torch.equal``, equal JSON), not a tolerance."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import torch
from typer.testing import CliRunner

from lensopt.checkpoint import CheckpointError
from lensopt.cli.app import app
from lensopt.design import optimize
from lensopt.spec import parse_spec

STEPS = 20  # binding at step 10 (bind_at 0.5)


def _binding(make_cooke: Any, **extra: Any) -> Any:
    """The Cooke triplet with its flint free for half the run, then bound to a Schott preferred glass."""
    data = make_cooke(catalog="schott-preferred", bind_at=0.5, steps=STEPS, **extra)
    data["surfaces"][2]["vary"] = ["material", "radius"]
    data["surfaces"][0]["vary"] = ["radius"]
    data["surfaces"][4]["vary"] = ["radius"]
    return parse_spec(data)


class _StopAt:
    """A progress callback that interrupts the run after step ``k`` (as Ctrl-C would) and records which
    steps were accepted."""

    def __init__(self, k: int | None) -> None:
        self.k = k
        self.accepted: list[bool] = []

    def __call__(self, p: Any) -> None:
        self.accepted.append(p.last_accepted)
        if p.step == self.k:
            raise KeyboardInterrupt


def _same(a: Any, b: Any) -> None:
    assert torch.equal(a.theta, b.theta)
    assert a.spec.model_dump_json() == b.spec.model_dump_json()
    assert [h[2:] for h in a.history] == [h[2:] for h in b.history]  # merit and ESR of every step
    assert a.steps == b.steps and a.stop_reason == b.stop_reason
    assert [g.name for g in a.bound] == [g.name for g in b.bound]


_FULL: list[Any] = []


@pytest.fixture
def uninterrupted(make_cooke: Any) -> Any:
    """The uninterrupted run (computed once per module)."""
    if not _FULL:
        _FULL.append(optimize(_binding(make_cooke)))
    return _FULL[0]


@pytest.mark.parametrize("k", [8, 10, 11], ids=["before-binding", "at-binding", "after-binding"])
def test_resume_is_bit_identical_around_the_binding(tmp_path: Path, make_cooke: Any, uninterrupted: Any,
                                                    k: int) -> None:
    full = uninterrupted
    assert full.bound and full.steps == STEPS  # the reference binds and runs to the end
    spec = _binding(make_cooke)
    cut = optimize(spec, callback=_StopAt(k), checkpoint=tmp_path / "ck")
    assert cut.interrupted and cut.steps == k
    assert json.loads((tmp_path / "ck" / "meta.json").read_text())["step"] == k
    again = optimize(spec, checkpoint=tmp_path / "ck", resume=True)
    _same(again, full)


def test_resume_after_a_rejected_step_reuses_the_held_jacobian(tmp_path: Path, make_cooke: Any) -> None:
    # λ starts small, so some trial steps overshoot and are rejected; J at θ is then held and D has seen it.
    spec = _binding(make_cooke, lm={"damping": 1e-9})
    seen = _StopAt(None)
    full = optimize(spec, callback=seen)
    rejected = [i + 1 for i, ok in enumerate(seen.accepted) if not ok and i + 1 < STEPS]
    assert rejected, "the premise: λ = 1e-9 makes some trial step overshoot and be rejected"
    k = rejected[0]
    optimize(spec, callback=_StopAt(k), checkpoint=tmp_path / "ck")
    meta = json.loads((tmp_path / "ck" / "meta.json").read_text())
    assert meta["meta"]["optimizer"]["jacobian_held"] is True
    _same(optimize(spec, checkpoint=tmp_path / "ck", resume=True), full)


def test_adam_resumes_bit_identically(tmp_path: Path, make_cooke: Any) -> None:
    data = make_cooke(optimizer="adam", steps=10)
    data["surfaces"][0]["vary"] = ["radius"]
    data["surfaces"][2]["vary"] = ["radius"]
    spec = parse_spec(data)
    full = optimize(spec)
    optimize(spec, callback=_StopAt(4), checkpoint=tmp_path / "ck")
    _same(optimize(spec, checkpoint=tmp_path / "ck", resume=True), full)


def test_resume_refuses_another_run(tmp_path: Path, make_cooke: Any) -> None:
    spec = _binding(make_cooke)
    optimize(spec, callback=_StopAt(2), checkpoint=tmp_path / "ck")
    with pytest.raises(CheckpointError, match="another spec or other settings"):
        optimize(spec, steps=STEPS + 1, checkpoint=tmp_path / "ck", resume=True)
    with pytest.raises(CheckpointError, match="needs --checkpoint"):
        optimize(spec, resume=True)


def test_cli_resume_finishes_the_run_and_bad_checkpoints_are_one_line(tmp_path: Path, make_cooke: Any) -> None:
    spec = _binding(make_cooke)
    start = tmp_path / "start.json"
    start.write_text(spec.model_dump_json())
    runner = CliRunner()
    full = runner.invoke(app, ["optimize", str(start), "-o", str(tmp_path / "full.json"), "-q"])
    assert full.exit_code == 0, full.output
    optimize(spec, callback=_StopAt(5), checkpoint=tmp_path / "ck")  # as a Ctrl-C after step 5 leaves it
    r = runner.invoke(app, ["optimize", str(start), "-o", str(tmp_path / "resumed.json"), "-q",
                            "--checkpoint", str(tmp_path / "ck"), "--resume"])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "resumed.json").read_text() == (tmp_path / "full.json").read_text()
    r = runner.invoke(app, ["optimize", str(start), "-o", str(tmp_path / "x.json"), "-q", "--steps", "3",
                            "--checkpoint", str(tmp_path / "ck"), "--resume"])
    assert r.exit_code == 2 and r.output.count("\n") == 1 and "--checkpoint" in r.output
    assert not (tmp_path / "x.json").exists()
    r = runner.invoke(app, ["optimize", str(start), "-o", str(tmp_path / "x.json"), "-q", "--resume",
                            "--checkpoint", str(tmp_path / "nothing")])
    assert r.exit_code == 2 and "no such checkpoint folder" in r.output
