"""Wavefront error (``analysis.wavefront``) and Zernike fits (``analysis.zernike``): closed forms,
invariants and gradients.

Oracles:
- Perfect refracting conics on axis have W ≡ 0: the Cartesian oval (ellipsoid κ = −1/n², collimated light
  into glass; Born & Wolf §4.2.3) and the plano-hyperbolic lens (flat face first, rear hyperboloid
  κ = −n², R = −(n − 1) f: collimated light in glass focused in air). lensopt traces refraction only (no
  mirrors), so these take the place of the paraboloidal mirror, the perfect conic of reflection.
- A plano-convex singlet at its paraxial focus: W at the pupil edge → S_I/8 (Seidel) as the aperture
  shrinks, the difference falling as EPD² (the fifth-order term W060 ∝ y⁶ against W040 ∝ y⁴).
- A focus shift dz of a perfect wave: W = n' dz (1 − cos θ) ≈ n' dz u'² ρ²/2 (ahead-positive: moving the
  image surface away from the lens leaves the rim of the wavefront ahead of the sphere about the new point).
- Zernike tables: Noll (1976) Table 1 and the Fringe list (Wyant & Creath 1992, Table 2) for the first
  terms; orthonormality of the normalized sets over the unit disc by a Gauss quadrature.
- Gradients: ``rms_wavefront_error`` by ``torch.func.jacfwd`` against central finite differences.
"""

from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np
import pytest
import torch

from lensopt.analysis.mtf_field import defocused
from lensopt.analysis.seidel import seidel_sums
from lensopt.analysis.wavefront import (
    map_grid,
    opd_fans,
    remove_tilt,
    rms_wavefront_error,
    wavefront_map,
    wavefront_stats,
)
from lensopt.analysis.zernike import fit_zernike, zernike_basis, zernike_indices
from lensopt.errors import LensoptError
from lensopt.optics.paraxial import first_order
from lensopt.spec import build, parse_spec
from tests.helpers import oval_model

AXIS = torch.zeros(1, dtype=torch.float64)


def _plano_hyperbolic(epd: float = 10.0, f: float = 100.0) -> tuple:
    spec = {"name": "plano-hyperbolic", "system": {"aperture": {"epd": epd},
                                                   "field": {"hfov_deg": 0.01, "relative": [0, 1]}},
            "spectrum": {"wavelengths_nm": [587.5618]},
            "surfaces": [{"type": "plane", "thickness": 5.0, "material": {"nd": 1.5, "vd": 64.0}, "stop": True},
                         {"type": "conic", "radius": -50.0, "conic": -2.25, "thickness": f}]}
    model = build(parse_spec(copy.deepcopy(spec)))
    n = float(model.lens.index[1, 0])
    spec["surfaces"][1]["radius"] = -(n - 1.0) * f
    spec["surfaces"][1]["conic"] = -(n**2)
    return build(parse_spec(spec))


@pytest.mark.parametrize("builder", [oval_model, _plano_hyperbolic], ids=["oval", "plano-hyperbolic"])
def test_perfect_conic_has_zero_opd_on_axis(builder) -> None:
    model = builder()
    wm = wavefront_map(model.lens, model.system, n=32, rel_field=AXIS)
    assert int(wm.valid.sum()) > 700
    assert float(wm.opd.abs().max()) < 1e-9  # waves (the aberrations of a sphere here: ~ 10 waves)
    sphere = dataclasses.replace(model.lens, conic=torch.zeros_like(model.lens.conic))
    assert float(wavefront_map(sphere, model.system, n=32, rel_field=AXIS).opd.abs().max()) > 0.1


def _plano_convex(epd: float):
    spec = {"name": "pc", "system": {"aperture": {"epd": epd}, "field": {"hfov_deg": 1.0, "relative": [0, 1]}},
            "spectrum": {"wavelengths_nm": [587.5618]},
            "surfaces": [{"type": "sphere", "radius": 50.0, "thickness": 3.0, "material": {"nd": 1.5, "vd": 64.0},
                          "stop": True}, {"type": "plane", "thickness": 97.0}]}
    model = build(parse_spec(spec))
    fo = first_order(model.lens, model.system)
    return defocused(model.lens, fo.bfl - model.lens.thickness[-1]), model.system  # image at the paraxial focus


def test_plano_convex_spherical_aberration_matches_third_order() -> None:
    errors = []
    for epd in (4.0, 2.0, 1.0):
        lens, system = _plano_convex(epd)
        edge = float(opd_fans(lens, system, points=3, rel_field=AXIS).tangential[0, 0, -1])
        w040 = float(seidel_sums(lens, system).waves()[0])
        assert w040 > 0 and edge > 0  # under-corrected: S_I > 0, wavefront ahead at the rim
        errors.append(edge / w040 - 1.0)
    assert errors[-1] < 1e-4
    # fifth order: the relative difference falls as EPD² (ratio 4 per halving)
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.02)
    assert errors[1] / errors[2] == pytest.approx(4.0, rel=0.02)


def test_focus_shift_is_a_quadratic_wavefront() -> None:
    model = oval_model(epd=4.0)
    lens, system = model.lens, model.system
    n_img = float(lens.index[-1, 0])
    u = 1.0 / (2.0 * float(first_order(lens, system).working_fnumber))  # |u'| of the marginal ray
    lam_mm = float(lens.wavelength_um[0]) * 1e-3
    dz = 0.05
    fans = opd_fans(defocused(lens, dz), system, points=41, rel_field=AXIS)
    rho = fans.coord.numpy()
    # the image surface moved away from the lens: the wave focuses before it, so the rim of the wavefront
    # is ahead of the sphere about the new image point: W > 0
    expect = n_img * dz * u**2 * rho**2 / 2 / lam_mm
    got = fans.tangential[0, 0].numpy()
    assert np.abs(got - expect).max() <= 2e-3 * np.abs(expect).max()  # (1 − cos θ) vs θ²/2 at NA 0.013
    np.testing.assert_allclose(fans.sagittal[0, 0].numpy(), got, rtol=1e-9, atol=1e-12)


def test_stats_of_a_known_wavefront() -> None:
    pts, inside = map_grid(256, dtype=torch.float64)
    px, py = pts[:, 0], pts[:, 1]
    rho2 = px**2 + py**2
    w = (0.3 + 0.2 * px - 0.1 * py + 0.25 * rho2)[None, None]
    valid = inside[None, None]
    resid = remove_tilt(pts, w, valid)
    # the tilt-free part is 0.25 ρ² minus its mean 0.125: RMS 0.25/√12, P-V 0.25
    m = valid.double()
    rms = float(torch.sqrt((resid**2 * m).sum() / m.sum()))
    assert rms == pytest.approx(0.25 / math.sqrt(12), rel=2e-3)  # grid quadrature of the disc
    piston_only = remove_tilt(pts, w, valid, tilt=False)
    assert abs(float((piston_only * m).sum())) <= 1e-10 * float((w.abs() * m).sum())


def test_wavefront_stats_fields_and_shapes(cooke) -> None:
    model = cooke
    wm = wavefront_map(model.lens, model.system, n=24)
    assert wm.opd.shape == (3, 3, 24, 24)
    st = wavefront_stats(wm.wavefront)
    assert bool((st.rms <= st.rms_chief + 1e-12).all())  # removing tilt never raises the RMS
    assert bool((st.pv > 0).all()) and bool((st.pv_chief >= st.rms_chief).all())
    assert not bool(wm.valid[..., 0, 0].any())  # the grid's corner lies outside the pupil


def test_zernike_tables() -> None:
    # Noll (1976), Table 1: j = 1 … 11
    assert zernike_indices("noll", 11) == ((0, 0), (1, 1), (1, -1), (2, 0), (2, -2), (2, 2), (3, -1), (3, 1),
                                           (3, -3), (3, 3), (4, 0))
    # Fringe: Z1 piston, Z2/3 tilt, Z4 focus, Z5/6 astigmatism, Z7/8 coma, Z9 spherical, Z16 5th-order spherical
    f = zernike_indices("fringe", 37)
    assert f[:9] == ((0, 0), (1, 1), (1, -1), (2, 0), (2, 2), (2, -2), (3, 1), (3, -1), (4, 0))
    assert f[15] == (6, 0) and f[24] == (8, 0) and f[35] == (10, 0)
    assert f[36] == (12, 0)  # the set's exception: Z37 is 12th-order spherical, not (6, 6) of the pattern
    with pytest.raises(LensoptError, match="^zernike.terms: the Fringe set has 37 terms"):
        zernike_indices("fringe", 38)
    # OSA/ANSI: j = (n(n+2) + m)/2 from 0
    a = zernike_indices("ansi", 10)
    assert all((n * (n + 2) + m) // 2 == j for j, (n, m) in enumerate(a))
    with pytest.raises(LensoptError, match="^zernike.ordering: must be one of"):
        zernike_indices("zemax", 5)


@pytest.mark.parametrize("ordering", ["noll", "ansi"])
def test_normalized_zernikes_are_orthonormal(ordering: str) -> None:
    x, wx = np.polynomial.legendre.leggauss(40)
    r = (x + 1) / 2
    theta = np.arange(80) * 2 * np.pi / 80
    rr, tt = np.meshgrid(r, theta, indexing="ij")
    weight = np.repeat(wx / 2 * r, 80) * (2 * np.pi / 80) / np.pi  # ∫∫ r dr dθ / π
    pts = torch.from_numpy(np.stack([(rr * np.cos(tt)).ravel(), (rr * np.sin(tt)).ravel()], -1))
    z = zernike_basis(pts, zernike_indices(ordering, 28), normalized=True).numpy()
    gram = (z * weight[:, None]).T @ z
    np.testing.assert_allclose(gram, np.eye(28), atol=1e-12)


def test_fit_recovers_coefficients() -> None:
    pts, inside = map_grid(48, dtype=torch.float64)
    idx = zernike_indices("fringe", 16)
    truth = torch.linspace(-0.4, 0.7, 16, dtype=torch.float64)
    values = zernike_basis(pts, idx, normalized=False) @ truth
    fit = fit_zernike(pts, values[None], inside[None], ordering="fringe", terms=16)
    assert torch.allclose(fit.coefficients[0], truth, atol=1e-12)
    assert float(fit.residual_rms) < 1e-12


def test_rms_wavefront_gradient_matches_finite_differences(cooke) -> None:
    model = cooke
    lens, system = model.lens, model.system
    pts, inside = map_grid(12, dtype=torch.float64)
    pupil = pts[inside]
    which = torch.tensor([0, 4])

    def rms(theta: torch.Tensor) -> torch.Tensor:
        c = torch.index_put(lens.curvature, (which,), theta)
        return rms_wavefront_error(dataclasses.replace(lens, curvature=c), system, pupil)

    theta = lens.curvature[which].clone()
    jac = torch.func.jacfwd(rms)(theta)  # (F, W, 2)
    assert jac.shape == (3, 3, 2) and bool(torch.isfinite(jac).all())
    h = 1e-7  # the central difference's error is O(h²) (1e-5: 7e-3, 1e-6: 6e-5, 1e-7: 2e-6 relative)
    fd = torch.stack([(rms(theta + h * e) - rms(theta - h * e)) / (2 * h) for e in torch.eye(2, dtype=torch.float64)],
                     -1)
    assert float(((jac - fd).abs() / jac.abs().clamp_min(1.0)).max()) < 1e-5


def test_rms_wavefront_is_finite_for_a_perfect_lens_and_failed_rays() -> None:
    model = oval_model(epd=10.0)
    lens, system = model.lens, model.system
    pupil = torch.tensor([[0.0, 0.3], [0.5, 0.5], [0.0, 1.0], [0.0, 40.0]], dtype=torch.float64)  # last one fails

    def rms(c: torch.Tensor) -> torch.Tensor:
        return rms_wavefront_error(dataclasses.replace(lens, conic=c), system, pupil, rel_field=AXIS)

    value = rms(lens.conic)
    jac = torch.func.jacfwd(rms)(lens.conic)
    assert float(value.max()) < 1e-9 and bool(torch.isfinite(jac).all())
    assert float(jac.abs().max()) < 1e-9  # the perfect wavefront: RMS at its minimum (safe_sqrt: no NaN)
