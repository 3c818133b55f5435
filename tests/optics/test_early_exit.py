"""Iterative solves that stop at convergence (``transforms.all_settled``) give the numbers of the
fixed iteration count (what a captured graph runs) to rounding, with the same flags.

The reference is the same code with early exits switched off; the shipped telephoto (ten even aspheres
with coefficients up to r¹⁴, full aiming behind a front aperture) exercises the asphere Newton and the
chief-ray Newton on a real design. Bounds: positions to 1e-12 mm, pupil offsets to 1e-13.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

import lensopt.optics.aiming as aiming
import lensopt.optics.intersect as intersect
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build, load_spec
from lensopt.transforms import all_settled

LENS = Path(__file__).resolve().parents[2] / "lenses" / "telephoto_5p_tr080.json"


def _bundle():  # noqa: ANN202
    model = build(load_spec(LENS), dtype=torch.float64)
    pupil = PupilSampling.parse("rings:4").points(dtype=torch.float64)
    with torch.no_grad():
        return trace_bundle(model.lens, model.system, pupil, record=True)


def test_early_exit_gives_the_fixed_count_numbers(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []
    real = intersect.all_settled

    def counting(done: torch.Tensor) -> bool:
        out = real(done)
        calls.append(out)
        return out

    monkeypatch.setattr(intersect, "all_settled", counting)
    early = _bundle()
    assert any(calls)  # some intersection did stop early
    monkeypatch.setattr(intersect, "all_settled", lambda done: False)
    monkeypatch.setattr(aiming, "all_settled", lambda done: False)
    fixed = _bundle()
    assert torch.equal(early.result.status, fixed.result.status)
    assert float((early.result.pos - fixed.result.pos).abs().max()) <= 1e-12
    assert float((early.aim.offset - fixed.aim.offset).abs().max()) <= 1e-13
    assert torch.equal(early.aim.converged, fixed.aim.converged)


def test_values_are_not_looked_at_under_vmap_or_capture() -> None:
    done = torch.ones(3, dtype=torch.bool)
    assert all_settled(done)
    assert torch.func.vmap(lambda d: torch.tensor(all_settled(d)))(done.unsqueeze(0).expand(2, 3)).tolist() == [
        False, False]
    from torch.fx.experimental.proxy_tensor import make_fx

    seen = []
    make_fx(lambda d: (seen.append(all_settled(d > 0)), d)[1])(torch.ones(3))
    assert seen == [False]
