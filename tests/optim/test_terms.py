"""The residual-term registry: adding a term is one ``register_term`` call; Problem concatenates the
active terms in registry order with their static weights."""

from __future__ import annotations

import torch

from lensopt.design import build_problem
from lensopt.optim import Problem
from lensopt.optim.terms import TERMS, Term, register_term
from lensopt.spec import parse_spec


def test_a_registered_term_joins_the_residuals_with_its_weight(cooke) -> None:  # noqa: ANN001
    cooke["surfaces"][0]["vary"] = ["radius"]
    spec = parse_spec(cooke)
    base = build_problem(spec)
    term = Term("centre_height", "test: y of each field's centroid", lambda p: 3.0,
                lambda c: c.stats.centroid[:, 1])
    register_term(term, after="tra")
    try:
        p = build_problem(spec)
        names = list(p.slices)
        assert names[names.index("tra") + 1] == "centre_height"
        parts = p.terms(p.theta0)
        torch.testing.assert_close(parts["centre_height"], 3.0 * parts["tra"].new_tensor(
            [float(v) for v in _centroids(p)]))
        assert p.size == base.size + len(spec.system.field.relative)
    finally:
        del TERMS["centre_height"]
    assert "centre_height" not in build_problem(spec).slices


def _centroids(p: Problem) -> torch.Tensor:
    from lensopt.analysis.spot import spot_stats
    from lensopt.optim.rays import head

    lens, _ = p.lens(p.theta0)
    spot = head(p.bundle(lens), p.num_spot)
    return spot_stats(spot, p.system.wavelength_weights, p.field_weights).centroid[:, 1]
