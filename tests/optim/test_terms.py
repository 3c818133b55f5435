"""The residual terms: one static, ordered tuple (``optim.terms.TERMS``); Problem concatenates the active
terms in that order with their static weights, whatever modules were imported before."""

from __future__ import annotations

import subprocess
import sys

import pytest
import torch

import lensopt.optim.problem as problem_module
from lensopt.design import build_problem
from lensopt.optim import Problem
from lensopt.optim.terms import TERMS, Term
from lensopt.spec import parse_spec


def test_the_rows_follow_the_order_of_terms(cooke_opt) -> None:  # noqa: ANN001
    cooke_opt["surfaces"][0]["vary"] = ["radius"]
    p = build_problem(parse_spec(cooke_opt))
    order = [t.name for t in TERMS]
    names = list(p.slices)
    assert names == sorted(names, key=order.index)
    assert names[0] == "tra"


def test_the_order_does_not_depend_on_imports() -> None:
    # Importing the image objective first (it once registered its terms at import time) changes nothing.
    code = ("import lensopt.optim.image_objective, lensopt.optim.terms as t; "
            "print(','.join(x.name for x in t.TERMS))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == ",".join(t.name for t in TERMS)


def test_a_term_joins_the_residuals_with_its_weight(cooke_opt, monkeypatch: pytest.MonkeyPatch) -> None:  # noqa: ANN001
    cooke_opt["surfaces"][0]["vary"] = ["radius"]
    spec = parse_spec(cooke_opt)
    base = build_problem(spec)
    extra = Term("centre_height", "test: y of each field's centroid", lambda s: 3.0, lambda c: c.stats.centroid[:, 1])
    monkeypatch.setattr(problem_module, "TERMS", (TERMS[0], extra, *TERMS[1:]))
    p = build_problem(spec)
    names = list(p.slices)
    assert names[names.index("tra") + 1] == "centre_height"
    parts = p.terms(p.theta0)
    torch.testing.assert_close(parts["centre_height"], 3.0 * _centroids(p))
    assert p.size == base.size + len(spec.system.field.relative)


def _centroids(p: Problem) -> torch.Tensor:
    from lensopt.analysis.spot import spot_stats
    from lensopt.optim.rays import head

    lens, _ = p.lens(p.theta0)
    spot = head(p.bundle(lens), p.num_spot)
    return spot_stats(spot, p.system.wavelength_weights, p.field_weights).centroid[:, 1]


@pytest.mark.parametrize("sampling", ["rings:3", "grid:6"])
def test_the_context_computes_the_centroids_alone_with_the_statistics_numbers(cooke_opt, sampling: str) -> None:  # noqa: ANN001
    # TRA and distortion read only the fields' centroids: ``TermContext.centroid`` computes those alone
    # (not the RMS radii: under the Jacobian's stage C every operation carries N tangents), the same
    # numbers as the full statistics (``stats``, still there for a term that reads it), in value and in
    # derivative (pupil weights: tests/analysis/test_spot_weights.py).
    from lensopt.analysis.spot import spot_stats

    cooke_opt["optimize"]["sampling"] = sampling
    cooke_opt["surfaces"][0]["vary"] = ["radius"]
    p = build_problem(parse_spec(cooke_opt))

    def centroids(t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        lens, _ = p.lens(t)
        ctx = p._context(t, lens, p.bundle(lens))
        alone = ctx.centroid
        assert "stats" not in ctx.__dict__  # the radii were not computed
        return alone, ctx.stats.centroid

    (alone, full), (d_alone, d_full) = torch.func.jvp(centroids, (p.theta0,), (torch.ones_like(p.theta0),))
    assert torch.equal(alone, full) and torch.equal(d_alone, d_full) and float(d_alone.abs().max()) > 0
    lens, _ = p.lens(p.theta0)
    spot = p._context(p.theta0, lens, p.bundle(lens)).spot
    assert torch.equal(full, spot_stats(spot, p.system.wavelength_weights, p.field_weights).centroid)
