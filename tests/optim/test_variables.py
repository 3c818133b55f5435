"""Parameterization (S2.1, Table S4): θ scalings, the Bézier map, θ → lens → spec round trips."""

from __future__ import annotations

import math

import pytest
import torch

from lensopt.design import build_problem, to_spec
from lensopt.errors import SpecError
from lensopt.optim.variables import bernstein_to_monomial
from lensopt.spec import build, parse_spec


def _asphere_lens(make_cooke, basis: str) -> dict:  # noqa: ANN001
    data = make_cooke(asphere_basis=basis)
    s = data["surfaces"][4]
    data["surfaces"][4] = {**{k: v for k, v in s.items() if k != "type"}, "type": "asphere", "conic": -0.5,
                           "coefficients": {4: 2.0e-5, 6: -3.0e-7, 8: 1.0e-9}, "vary": ["coefficients", "conic"]}
    data["surfaces"][1]["vary"] = ["thickness", "radius"]
    return data


def test_theta_holds_the_seed_scalings(make_cooke) -> None:  # noqa: ANN001
    data = _asphere_lens(make_cooke, "monomial")
    data["optimize"]["alpha"] = 4.0
    p = build_problem(parse_spec(data))
    a = 4.0
    lens = build(parse_spec(data)).lens
    names = [v.path for v in p.param.variables]
    assert names == ["surfaces[1].thickness", "surfaces[1].radius", "surfaces[4].conic",
                     "surfaces[4].coefficients.4", "surfaces[4].coefficients.6", "surfaces[4].coefficients.8"]
    expected = torch.stack([lens.thickness[1] / a, lens.curvature[1] * a, lens.conic[4],
                            lens.asphere[4, 0] * a**4, lens.asphere[4, 1] * a**6, lens.asphere[4, 2] * a**8])
    torch.testing.assert_close(p.theta0, expected, rtol=1e-15, atol=0)


def test_alpha_defaults_to_half_the_epd(cooke_opt: dict) -> None:
    cooke_opt["surfaces"][0]["vary"] = ["radius"]
    assert build_problem(parse_spec(cooke_opt)).alpha == pytest.approx(5.0)  # EPD 10 mm


def test_bernstein_to_monomial_degree_two() -> None:
    # q(x) = b0 (1−x)² + 2 b1 x (1−x) + b2 x² = b0 + (2b1 − 2b0) x + (b0 − 2b1 + b2) x².
    M = bernstein_to_monomial(3, dtype=torch.float64)
    b = torch.tensor([1.0, 2.0, 5.0], dtype=torch.float64)
    torch.testing.assert_close(M @ b, torch.tensor([1.0, 2.0, 2.0], dtype=torch.float64))


@pytest.mark.parametrize("basis", ["monomial", "bezier"])
def test_theta_to_lens_reproduces_the_spec(make_cooke, basis: str) -> None:  # noqa: ANN001
    spec = parse_spec(_asphere_lens(make_cooke, basis))
    p = build_problem(spec)
    lens, ok = p.lens(p.theta0)
    ref = build(spec).lens
    assert bool(ok)
    for name in ("curvature", "thickness", "conic", "asphere", "index"):
        torch.testing.assert_close(getattr(lens, name), getattr(ref, name), rtol=1e-14, atol=1e-20)


def test_bezier_control_points_are_sag_shape_of_the_asphere(make_cooke) -> None:  # noqa: ANN001
    # The Bernstein points b_k of q (f = ρ⁴ q(ρ²), ρ = r/α) satisfy q(0) = b_0 and q(1) = b_K-1:
    # b_0 = α⁴ a4 and b_last = Σ α^2i a_2i (the asphere term at r = α over ρ⁴ = 1).
    data = _asphere_lens(make_cooke, "bezier")
    p = build_problem(parse_spec(data))
    a = p.alpha
    coeff = {4: 2.0e-5, 6: -3.0e-7, 8: 1.0e-9}
    b = p.theta0[3:]  # after surfaces[1] thickness, radius and surfaces[4] conic
    assert float(b[0]) == pytest.approx(coeff[4] * a**4, rel=1e-12)
    assert float(b[-1]) == pytest.approx(sum(c * a**k for k, c in coeff.items()), rel=1e-12)


def test_spec_round_trip_after_a_change(cooke_opt: dict) -> None:
    cooke_opt["surfaces"][2]["vary"] = ["radius"]
    cooke_opt["surfaces"][3]["vary"] = ["thickness"]
    p = build_problem(parse_spec(cooke_opt))
    theta = p.theta0 + torch.tensor([0.01, -0.02], dtype=torch.float64)
    spec = to_spec(p, theta)
    assert spec.surfaces[2].radius == pytest.approx(p.alpha / float(theta[0]), rel=1e-14)
    assert spec.surfaces[3].thickness == pytest.approx(p.alpha * float(theta[1]), rel=1e-14)
    again = build_problem(spec)
    torch.testing.assert_close(again.theta0, theta, rtol=1e-14, atol=0)


def test_varied_glass_starts_at_its_catalog_values(cooke_opt: dict) -> None:
    cooke_opt["surfaces"][2]["vary"] = ["material"]
    cooke_opt["optimize"]["catalog"] = "schott-preferred"
    p = build_problem(parse_spec(cooke_opt))
    nd, vd, dpgf = p.param.glass_physical(p.theta0)[0].tolist()
    # F2 (Schott): nd 1.62004, vd 36.37 (catalog).
    assert nd == pytest.approx(1.62004, abs=1e-5)
    assert vd == pytest.approx(36.37, abs=0.01)
    assert math.isfinite(dpgf)


def test_bad_variables_name_the_field(cooke_opt: dict) -> None:
    cooke_opt["surfaces"][1]["vary"] = ["material"]  # surfaces[1] is followed by air
    with pytest.raises(SpecError, match=r"surfaces\[1\]\.vary: air cannot vary"):
        build_problem(parse_spec(cooke_opt))
    cooke_opt["surfaces"][1]["vary"] = ["radius"]
    cooke_opt["optimize"]["solves"] = [{"type": "efl", "surface": 1, "value": 50.0}]
    with pytest.raises(SpecError, match=r"surfaces\[1\]\.vary: radius is set by a solve"):
        build_problem(parse_spec(cooke_opt))
