"""The wavefront merit (``[optimize.wavefront]``, issue 28): RMS wavefront error per field and wavelength as
LM residuals. ‖ℓ‖² must be the field- and wavelength-weighted mean of the squared RMS wavefront errors that
``analysis.wavefront.rms_wavefront_error`` reports (its own masked RMS, tested against optiland and closed
forms); its Jacobian (staged) equals jacfwd's and central differences; a few LM steps lower it."""

from __future__ import annotations

import tomllib
from pathlib import Path

import torch

from lensopt.analysis.wavefront import map_grid, rms_wavefront_error
from lensopt.design import build_problem
from lensopt.optim.driver import make_optimizer
from lensopt.spec import parse_spec

SPECS = Path(__file__).resolve().parents[2] / "specs"


def _data(**wavefront: object) -> dict:
    data = tomllib.loads((SPECS / "cooke_triplet_opt.toml").read_text())
    data["optimize"]["sampling"] = "rings:3"
    data["optimize"]["wavefront"] = {"weight": 2.0, "n": 8, **wavefront}
    return data


def test_the_merit_is_the_weighted_mean_square_rms_wavefront_error() -> None:
    p = build_problem(parse_spec(_data()))
    with torch.no_grad():
        rows = p.terms(p.theta0)["wavefront"] / 2.0
        lens, _ = p.lens(p.theta0)
        pts, inside = map_grid(8, dtype=torch.float64)
        rms = rms_wavefront_error(lens, p.system, pts[inside])  # (F, W), waves
    ww = p.system.wavelength_weights / p.system.wavelength_weights.sum()
    fw = p.field_weights / p.field_weights.sum()
    want = float((fw[:, None] * ww[None, :] * rms**2).sum())
    assert abs(float((rows**2).sum()) - want) <= 1e-12 * want
    assert "tra" in p.slices  # beside the TRA by default


def test_alone_without_tra_and_its_jacobian() -> None:
    data = _data(tilt=False)
    data["optimize"]["tra"] = {"weight": 0.0}
    for s in data["surfaces"]:
        s["vary"] = [v for v in s.get("vary", []) if v != "material"]
    p = build_problem(parse_spec(data))
    assert "tra" not in p.slices and "wavefront" in p.slices
    theta = p.theta0 * (1 + 1e-3)
    J, r = p.jacobian(theta)
    Jf, rf = p.jacobian_jacfwd(theta)
    torch.testing.assert_close(J, Jf, rtol=1e-10, atol=1e-12)
    # Central differences of W lose digits: W is a difference of optical paths of ~1e5 waves, so its
    # rounding is ~1e-11 waves and the difference quotient's noise ~1e-11/h. h = 1e-5 keeps that and the
    # truncation (~h²) below 1e-5 of each column's largest entry.
    h = 1e-5
    for n in range(p.num_variables):
        e = torch.zeros_like(theta)
        e[n] = h
        with torch.no_grad():
            fd = (p.residuals(theta + e) - p.residuals(theta - e)) / (2 * h)
        sl = p.slices["wavefront"]
        torch.testing.assert_close(J[sl, n], fd[sl], rtol=0, atol=1e-5 * float(J[sl, n].abs().max()))


def test_lm_lowers_the_wavefront_error() -> None:
    data = _data()
    data["optimize"]["tra"] = {"weight": 0.0}
    p = build_problem(parse_spec(data))
    opt = make_optimizer(p, p.theta0, "lm")
    scale = p.row_scale(0.0)
    start = opt.merit(scale)
    merits = [opt.step(scale).merit for _ in range(8)]
    assert merits == sorted(merits, reverse=True) and merits[-1] < 0.9 * start
