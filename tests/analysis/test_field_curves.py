"""Field curves (``analysis.field_curves``): against optiland's field curvature, and against the Seidel
sums in the third-order limit.

Oracles:
- optiland 0.6.3 ``FieldCurvature`` (parabasal ray pairs at ±1e-5 of the pupil, crossing in the
  tangential / sagittal plane, axial distance from the image surface) on the Cooke triplet, the double
  Gauss and the microscope objective: same convention, ≤ 1e-6 relative.
- Third order (Welford ch. 8), with the image surface at the paraxial focus and η the chief-ray slope
  relative to the full field's (η = tan(u θ_max)/tan θ_max for a relative field u): the sagittal and
  tangential foci lie at −(S_III + S_IV) η² / (2 n'u'²) and −(3 S_III + S_IV) η² / (2 n'u'²) (from
  W = ¼(S_III + S_IV) η² ρ² + ½ S_III η² ρ² cos²θ, δz = −2 W020 / (n'u'²) for an ahead-positive W), the
  distortion is S_V η² / (2 n'u' y'_max), the lateral colour (λ_short − λ_long) C_II η / (n'u').
  The differences fall as η² (fifth order).
- Chromatic focal shift of a thin singlet: f(λ) = 1/((n(λ) − 1)(c1 − c2)), exactly (paraxial).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from lensopt.analysis.field_curves import chromatic_focal_shift, field_curves
from lensopt.analysis.mtf_field import defocused
from lensopt.analysis.seidel import seidel_sums
from lensopt.optics.paraxial import first_order
from lensopt.spec import build, load_spec, parse_spec
from tests.helpers import SPECS

pytestmark = [pytest.mark.filterwarnings("ignore::DeprecationWarning"),
              pytest.mark.filterwarnings("ignore:.*:numba.core.errors.NumbaIRAssumptionWarning")]


@pytest.mark.parametrize("name", ["cooke", "double_gauss", "microscope"])
def test_field_curvature_matches_optiland(name: str) -> None:
    pytest.importorskip("optiland")
    from optiland.analysis import FieldCurvature

    from tests.analysis.optiland_peer import optic_from_model, peer_model

    model = peer_model(name)
    points = 9
    theirs = FieldCurvature(optic_from_model(model), num_points=points)
    mine = field_curves(model.lens, model.system, torch.linspace(0.0, 1.0, points, dtype=torch.float64), delta=1e-5)
    assert bool(mine.valid.all())
    for w in range(len(theirs.wavelengths)):
        tan, sag = (np.asarray(x, dtype=float) for x in theirs.data[w])
        scale = max(np.abs(tan).max(), np.abs(sag).max())
        assert np.abs(mine.tangential_mm[:, w].numpy() - tan).max() <= 1e-6 * scale
        assert np.abs(mine.sagittal_mm[:, w].numpy() - sag).max() <= 1e-6 * scale


@pytest.mark.parametrize("name", ["cooke_triplet.toml", "double_gauss.toml"])
def test_third_order_limit(name: str) -> None:
    model = build(load_spec(SPECS / name))
    system = model.system
    fo = first_order(model.lens, system)
    lens = defocused(model.lens, fo.bfl - model.lens.thickness[-1])  # the image at the paraxial focus
    s = seidel_sums(lens, system)
    s1, s2, s3, s4, s5, c1, c2 = s.total.tolist()
    nu = float(s.image_nu)
    u = nu / float(lens.index[-1, system.reference])
    y_max = float(first_order(lens, system).paraxial_image_height)
    ref = system.reference
    short, long_ = int(lens.wavelength_um.argmin()), int(lens.wavelength_um.argmax())
    errors = []
    for rel in (0.1, 0.05, 0.025):
        eta = math.tan(rel * math.radians(system.field_max)) / math.tan(math.radians(system.field_max))
        fc = field_curves(lens, system, torch.tensor([0.0, rel], dtype=torch.float64))
        got = np.array([fc.sagittal_mm[1, ref] - fc.sagittal_mm[0, ref],
                        fc.tangential_mm[1, ref] - fc.tangential_mm[0, ref],
                        fc.distortion[1], fc.chief_y_mm[1, short] - fc.chief_y_mm[1, long_]])
        third = np.array([-(s3 + s4) / (2 * nu * u), -(3 * s3 + s4) / (2 * nu * u), s5 / (2 * nu * y_max), 0.0])
        third = third * eta**2
        third[3] = c2 / nu * eta
        errors.append(np.abs(got / third - 1.0))
    # colour: C_II is first order in δn, so it is only good to a few per cent; the rest to O(η²)
    assert np.all(errors[2][:3] < 1.5e-3), errors
    for a, b in zip(errors[:-1], errors[1:], strict=True):  # converging like η²: ÷4 per halving
        assert np.all((a[:3] / b[:3] > 3.5) & (a[:3] / b[:3] < 4.5)), errors
    assert errors[2][3] < 0.05


def test_distortion_is_zero_on_axis_and_real(cooke) -> None:
    model = cooke
    fc = field_curves(model.lens, model.system, torch.tensor([0.0, 0.5, 1.0], dtype=torch.float64))
    assert float(fc.distortion[0]) == 0.0
    ref = model.system.reference
    d = (fc.chief_y_mm[2, ref] - fc.paraxial_y_mm[2]) / fc.paraxial_y_mm[2]
    assert float(fc.distortion[2]) == pytest.approx(float(d), rel=1e-15)
    assert bool((fc.lateral_color_mm[:, ref] == 0).all())


def test_thin_singlet_focal_shift() -> None:
    spec = {"name": "thin", "system": {"aperture": {"epd": 4.0}, "field": {"hfov_deg": 1.0, "relative": [0, 1]}},
            "spectrum": {"wavelengths_nm": [486.1327, 587.5618, 656.2725], "reference_nm": 587.5618},
            "surfaces": [{"type": "sphere", "radius": 60.0, "thickness": 1e-9, "material": "N-BK7", "stop": True},
                         {"type": "sphere", "radius": -60.0, "thickness": 58.0}]}
    model = build(parse_spec(spec))
    shift = chromatic_focal_shift(model.lens, model.system)
    n = model.lens.index[1].tolist()
    f = [1.0 / ((ni - 1.0) * (1 / 60.0 + 1 / 60.0)) for ni in n]
    np.testing.assert_allclose(shift.shift_mm.numpy(), np.array(f) - f[1], rtol=1e-7, atol=1e-12)
    dense = chromatic_focal_shift(model.lens, model.system, media=model.media, samples=11)
    assert dense.wavelength_um.shape[0] == 12  # 11 spread + the reference
    got = {round(float(w), 9): float(s) for w, s in zip(dense.wavelength_um, dense.shift_mm, strict=True)}
    assert got[round(0.5875618, 9)] == 0.0
    assert float(dense.shift_mm[0]) == pytest.approx(float(shift.shift_mm[0]), rel=1e-9)  # 486.13 nm, both ways
