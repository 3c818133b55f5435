"""Solves (Table S5) hold their targets exactly and are differentiable."""

from __future__ import annotations

import math

import pytest
import torch

from lensopt.design import build_problem
from lensopt.errors import SpecError
from lensopt.optics.paraxial import first_order, trace_paraxial
from lensopt.optim import Problem
from lensopt.spec import parse_spec


def _problem(cooke_opt: dict, solves: list[dict], defocus: float = 0.0) -> Problem:
    cooke_opt["surfaces"][1]["vary"] = ["radius", "thickness"]
    cooke_opt["surfaces"][4]["vary"] = ["radius"]
    cooke_opt["optimize"]["solves"] = solves
    cooke_opt["image"] = {"defocus": defocus}
    return build_problem(parse_spec(cooke_opt))


def _perturbed(p: Problem) -> torch.Tensor:
    return p.theta0 * torch.tensor([1.3, 0.9, 1.1], dtype=torch.float64)


def test_efl_solve(cooke_opt: dict) -> None:
    p = _problem(cooke_opt, [{"type": "efl", "surface": -1, "value": 47.0}])
    lens, ok = p.lens(_perturbed(p))
    assert bool(ok)
    assert float(first_order(lens, p.system).efl) == pytest.approx(47.0, rel=1e-13)


def test_image_height_solve_with_defocus(cooke_opt: dict) -> None:
    p = _problem(cooke_opt, [{"type": "image_height", "surface": 5, "value": 17.5}], defocus=0.3)
    lens, ok = p.lens(_perturbed(p))
    assert bool(ok)
    assert float(first_order(lens, p.system).paraxial_image_height) == pytest.approx(17.5, rel=1e-13)


def test_ttl_then_efl_solve(cooke_opt: dict) -> None:
    p = _problem(cooke_opt, [{"type": "efl", "value": 50.0}, {"type": "ttl", "value": 61.0}])
    lens, _ = p.lens(_perturbed(p))
    fo = first_order(lens, p.system)
    assert float(fo.total_track) == pytest.approx(61.0, rel=1e-14)
    assert float(fo.efl) == pytest.approx(50.0, rel=1e-13)


def test_focus_solve_puts_the_image_at_the_paraxial_focus_plus_defocus(cooke_opt: dict) -> None:
    p = _problem(cooke_opt, [{"type": "focus"}], defocus=0.25)
    lens, _ = p.lens(_perturbed(p))
    fo = first_order(lens, p.system)
    # Infinite object: the paraxial focus is the back focal point (BFL from the last vertex).
    assert float(lens.thickness[-1]) == pytest.approx(float(fo.bfl) + 0.25, rel=1e-13)
    y, _ = trace_paraxial(lens, p.system.reference, torch.tensor(1.0, dtype=torch.float64),
                          torch.tensor(0.0, dtype=torch.float64))
    w = p.system.reference
    # Marginal ray height at the image = defocus × its slope.
    slope = (y[-1] - y[-2]) / lens.thickness[-1]
    assert float(y[-1]) == pytest.approx(float(slope) * 0.25, rel=1e-10)
    assert w == 1


def test_solved_curvature_derivative_matches_finite_differences(cooke_opt: dict) -> None:
    p = _problem(cooke_opt, [{"type": "efl", "surface": -1, "value": 50.0}])
    theta = p.theta0.clone()

    def solved_c(t: torch.Tensor) -> torch.Tensor:
        return p.lens(t)[0].curvature[-1]

    J = torch.func.jacfwd(solved_c)(theta)
    h = 1e-6
    for i in range(theta.shape[0]):
        e = torch.zeros_like(theta)
        e[i] = h
        fd = (solved_c(theta + e) - solved_c(theta - e)) / (2 * h)
        assert float(J[i]) == pytest.approx(float(fd), rel=1e-6, abs=1e-12)


def test_solve_errors_name_the_field(cooke_opt: dict) -> None:
    cooke_opt["surfaces"][0]["vary"] = ["thickness"]
    cooke_opt["optimize"]["solves"] = [{"type": "image_height", "surface": 1, "value": 10.0}]
    with pytest.raises(SpecError, match=r"optimize\.solves\[0\]\.surface: an image_height solve must act"):
        build_problem(parse_spec(cooke_opt))
    cooke_opt["optimize"]["solves"] = [{"type": "ttl", "value": 60.0}, {"type": "focus"}]
    with pytest.raises(SpecError, match=r"optimize\.solves\[1\]: only one solve"):
        parse_spec(cooke_opt)
    cooke_opt["optimize"]["solves"] = [{"type": "efl"}]
    with pytest.raises(SpecError, match=r"optimize\.solves\[0\]\.value: a efl solve needs a target"):
        parse_spec(cooke_opt)


def test_ttl_and_image_height_solves_hold_together(cooke_opt: dict) -> None:
    # The telephoto study's pair (seed S4.1.5): the TTL solve sets the last airspace, then the last
    # curvature is solved for the paraxial image height on that (fixed-track) image plane. Both targets
    # must hold at once, at any θ.
    p = _problem(cooke_opt, [{"type": "image_height", "surface": 5, "value": 17.5}, {"type": "ttl", "value": 58.0}])
    for theta in (p.theta0, _perturbed(p)):
        lens, ok = p.lens(theta)
        assert bool(ok)
        fo = first_order(lens, p.system)
        assert float(fo.total_track) == pytest.approx(58.0, rel=1e-14)
        assert float(fo.paraxial_image_height) == pytest.approx(17.5, rel=1e-12)
        # By hand: the chief ray (through the stop centre) traced paraxially lands at 17.5 mm.
        w = p.system.reference
        u = torch.tensor(math.tan(math.radians(p.system.field_max)), dtype=torch.float64)
        y0 = -u * fo.entrance_pupil_z  # height on surface 1 of the ray through the entrance pupil centre
        ys, _ = trace_paraxial(lens, w, y0, lens.index[0, w] * u)
        assert abs(float(ys[-1])) == pytest.approx(17.5, rel=1e-10)
