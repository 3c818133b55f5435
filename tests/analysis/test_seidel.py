"""Seidel sums (``analysis.seidel``) against optiland and the classical relations.

Oracles:
- optiland 0.6.3's ``ThirdOrderAberrations`` on the same prescriptions (Cooke triplet, double Gauss,
  microscope objective): its per-surface transverse coefficients TSC, CC, TAC, TPC, DC, TAchC, TchC are
  S/(2n'u') and C/(n'u') in lensopt's (Welford's) sign, to 1e-12 relative; its ``seidels()`` sums are
  −S (it multiplies the transverse sums by −2 n'u'), checked as such.
- Petzval sum from the curvatures and indices alone: S_IV = H² Σ c (n' − n)/(n n'), H = n ū y on the
  entrance pupil (object at infinity: H = tan θ · EPD/2).
- Stop-shift equations (Welford §8.5): moving the stop leaves the marginal ray and H unchanged and
  changes the chief ray by ȳ* = ȳ + E y; then S_I* = S_I, S_II* = S_II + E S_I, S_III* = S_III + 2E S_II
  + E² S_I, S_IV* = S_IV, S_V* = S_V + E(3 S_III + S_IV) + 3E² S_II + E³ S_I, C_I* = C_I,
  C_II* = C_II + E C_I.
- Thin lens in air with the stop at the lens (Welford eq. 9.? / Kingslake): S_I = (y⁴K³/4) [ (n/(n−1))²
  + (n+2)/(n(n−1)²) B² + 4(n+1)/(n(n−1)) B C + (3n+2)/n C² ], B = (c1 + c2)/(c1 − c2) the shape factor,
  C = (u + u')/(u − u') the conjugate factor (u' = u − yK; object at infinity: C = −1).
- A Cartesian oval (ellipsoid κ = −1/n², object at infinity) images the axis without aberration, so the
  conic term must cancel the sphere's S_I exactly.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from lensopt.analysis.seidel import seidel_sums
from lensopt.errors import LensoptError
from lensopt.optics.paraxial import first_order
from lensopt.spec import build, load_spec, parse_spec
from tests.helpers import COOKE, SPECS, oval_spec

pytestmark = [pytest.mark.filterwarnings("ignore::DeprecationWarning"),
              pytest.mark.filterwarnings("ignore:.*:numba.core.errors.NumbaIRAssumptionWarning")]

PEERS = ("cooke", "double_gauss", "microscope")


@pytest.mark.parametrize("name", PEERS)
def test_matches_optiland_per_surface(name: str) -> None:
    pytest.importorskip("optiland")
    from optiland.aberrations import SeidelAberrations, ThirdOrderAberrations

    from tests.analysis.optiland_peer import optic_from_model, peer_model

    model = peer_model(name)
    optic = optic_from_model(model)
    s = seidel_sums(model.lens, model.system)
    out = [np.asarray(x, dtype=float).ravel() for x in ThirdOrderAberrations(optic).third_order()]
    tsc, _, cc, _, tac, _, tpc, _, dc, tachc, _, tchc, _ = out
    theirs = np.stack([tsc, cc, tac, tpc, dc, tachc, tchc])
    mine = s.transverse("surfaces").numpy()
    scale = np.abs(theirs).max(1, keepdims=True)
    assert np.abs(mine - theirs).max(1).max() <= 1e-12 * scale.max(), (mine, theirs)
    assert np.all(np.abs(mine - theirs) <= 1e-12 * scale)
    # optiland's Seidel sums are −S (documented in analysis.seidel)
    sums = np.asarray(SeidelAberrations(optic).seidels(), dtype=float).ravel()
    np.testing.assert_allclose(-sums, s.total[:5].numpy(), rtol=1e-12, atol=0)


def test_petzval_sum_from_curvatures_and_indices(cooke) -> None:
    model = cooke
    lens, system = model.lens, model.system
    s = seidel_sums(lens, system)
    n = lens.index[:, system.reference].tolist()
    c = lens.curvature.tolist()
    h = math.tan(math.radians(system.field_max)) * 10.0 / 2  # H = ū y, EPD 10 mm, air
    petzval = h**2 * sum(ci * (n[i + 1] - n[i]) / (n[i] * n[i + 1]) for i, ci in enumerate(c))
    assert float(s.total[3]) == pytest.approx(petzval, rel=1e-12)
    assert float(s.invariant) == pytest.approx(h, rel=1e-12)


def _with_stop(path: Path, stop: int):
    spec = load_spec(path).model_dump(mode="json", exclude_none=True)
    for i, surf in enumerate(spec["surfaces"]):
        surf["stop"] = i == stop
    return build(parse_spec(spec))


@pytest.mark.parametrize("stop", [0, 1, 4, 5])
def test_stop_shift_equations(cooke, stop: int) -> None:
    base = cooke
    moved = _with_stop(COOKE, stop)
    from lensopt.optics.paraxial import field_tangents, trace_paraxial

    def chief(model):
        lens, system = model.lens, model.system
        fo = first_order(lens, system)
        tan = field_tangents(lens, system, torch.ones((), dtype=lens.dtype))
        n0 = lens.index[0, system.reference]
        return trace_paraxial(lens, system.reference, -tan * fo.entrance_pupil_z, n0 * tan)[0][:-1]

    y, _ = trace_paraxial(base.lens, base.system.reference, torch.tensor(5.0, dtype=torch.float64),
                          torch.tensor(0.0, dtype=torch.float64))
    e_all = (chief(moved) - chief(base)) / y[:-1]
    e = float(e_all[0])
    assert torch.allclose(e_all, torch.full_like(e_all, e), rtol=1e-9, atol=1e-12)  # E is one number
    a = seidel_sums(base.lens, base.system).total.tolist()
    b = seidel_sums(moved.lens, moved.system).total.tolist()
    s1, s2, s3, s4, s5, c1, c2 = a
    expect = [s1, s2 + e * s1, s3 + 2 * e * s2 + e**2 * s1, s4,
              s5 + e * (3 * s3 + s4) + 3 * e**2 * s2 + e**3 * s1, c1, c2 + e * c1]
    np.testing.assert_allclose(b, expect, rtol=1e-9, atol=1e-12 * max(abs(v) for v in a))


def _singlet(r1: float | None, r2: float | None, *, t: float, epd: float, n: float = 1.5) -> dict:
    def surf(r, **kw):
        return ({"type": "plane"} if r is None else {"type": "sphere", "radius": r}) | kw

    return {"name": "singlet", "system": {"aperture": {"epd": epd}, "field": {"hfov_deg": 1.0, "relative": [0, 1]}},
            "spectrum": {"wavelengths_nm": [587.5618]},
            "surfaces": [surf(r1, thickness=t, material={"nd": n, "vd": 64.0}, stop=True),
                         surf(r2, thickness=100.0)],
            "image": {"defocus": 0.0}}


@pytest.mark.parametrize("r1,r2", [(50.0, None), (None, -50.0), (80.0, -80.0), (40.0, 120.0)])
def test_thin_lens_spherical_aberration_formula(r1, r2) -> None:
    model = build(parse_spec(_singlet(r1, r2, t=1e-7, epd=4.0)))
    lens, system = model.lens, model.system
    n = float(lens.index[1, 0])
    c1 = 0.0 if r1 is None else 1.0 / r1
    c2 = 0.0 if r2 is None else 1.0 / r2
    k = (n - 1.0) * (c1 - c2)
    y = 2.0
    b = (c1 + c2) / (c1 - c2)
    c = -1.0  # object at infinity: u = 0, u' = −yK
    closed = y**4 * k**3 / 4 * ((n / (n - 1)) ** 2 + (n + 2) / (n * (n - 1) ** 2) * b**2
                                + 4 * (n + 1) / (n * (n - 1)) * b * c + (3 * n + 2) / n * c**2)
    assert float(seidel_sums(lens, system).total[0]) == pytest.approx(closed, rel=1e-5)  # thickness 1e-7 mm


def test_cartesian_oval_has_no_spherical_aberration() -> None:
    spec = oval_spec()
    sphere_spec = copy.deepcopy(spec)
    del sphere_spec["surfaces"][0]["conic"]
    sphere_spec["surfaces"][0]["type"] = "sphere"
    sphere = build(parse_spec(sphere_spec))
    n = float(sphere.lens.index[1, 0])
    spec["surfaces"][0]["conic"] = -1.0 / n**2
    oval = build(parse_spec(spec))
    s_sphere = float(seidel_sums(sphere.lens, sphere.system).total[0])
    s_oval = float(seidel_sums(oval.lens, oval.system).total[0])
    assert s_sphere > 0  # an under-corrected refracting sphere
    assert abs(s_oval) <= 1e-12 * s_sphere


def test_waves_and_units(cooke) -> None:
    model = cooke
    s = seidel_sums(model.lens, model.system)
    lam_mm = 550e-6
    w = s.waves()
    assert float(w[0]) == pytest.approx(float(s.total[0]) / 8 / lam_mm, rel=1e-14)
    assert float(w[3]) == pytest.approx(float(s.total[3]) / 4 / lam_mm, rel=1e-14)
    d = s.as_dict()
    assert set(d["total_mm"]) == {"S_I", "S_II", "S_III", "S_IV", "S_V", "C_I", "C_II"}
    assert len(d["surfaces_mm"]) == model.lens.num_surfaces
    assert d["color_wavelengths_nm"] == [480.0, 650.0]


def test_diffractive_lens_is_refused() -> None:
    model = build(load_spec(SPECS / "hybrid_achromat.toml"))
    with pytest.raises(LensoptError, match="^seidel: Seidel sums of diffractive"):
        seidel_sums(model.lens, model.system)
