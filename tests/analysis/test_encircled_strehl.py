"""Encircled/ensquared energy (``analysis.encircled``) and Strehl ratio (``analysis.strehl``).

Oracles:
- optiland 0.6.3 ``EncircledEnergy`` (geometric: rays of a hexapolar pupil centred on the chief ray,
  the count of rays within r; optiland plots the count, lensopt the fraction, so the count is divided
  by the number of rays here) on the Cooke triplet, the double Gauss and the microscope objective.
- The Airy pattern of a perfect lens: EE(r) = 1 − J0²(v) − J1²(v), v = 2π NA r/λ, NA = n'/(2 N_w)
  (Born & Wolf §8.5.2); the Cartesian oval images the axis perfectly (in glass, n' = 1.5).
- Strehl of a focus shift with λ/4 peak-to-valley wavefront error: for W = a ρ²,
  S = |∫₀¹ exp(2πi a ρ²) 2ρ dρ|² = [sin(π a)/(π a)]² = 0.8106 at a = 1/4 (Born & Wolf §9.1 / Mahajan);
  Maréchal: exp(−(2π a/√12)²) = 0.8141 (the RMS of a ρ² about its mean over the disc is a/√12).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.special import j0, j1

from lensopt.analysis.encircled import diffraction_energy, geometric_energy
from lensopt.analysis.mtf_field import defocused
from lensopt.analysis.strehl import marechal, strehl
from lensopt.analysis.wavefront import opd_fans
from lensopt.errors import LensoptError
from lensopt.optics.paraxial import first_order
from lensopt.spec import build, load_spec, parse_spec
from tests.helpers import COOKE, oval_model

pytestmark = [pytest.mark.filterwarnings("ignore::DeprecationWarning"),
              pytest.mark.filterwarnings("ignore:.*:numba.core.errors.NumbaIRAssumptionWarning")]
AXIS = torch.zeros(1, dtype=torch.float64)


@pytest.mark.parametrize("name", ["cooke", "double_gauss", "microscope"])
def test_geometric_encircled_energy_matches_optiland(name: str) -> None:
    pytest.importorskip("optiland")
    from optiland.analysis import EncircledEnergy
    from optiland.distribution import create_distribution

    from tests.analysis.optiland_peer import optic_from_model, peer_model

    model = peer_model(name)
    theirs = EncircledEnergy(optic_from_model(model), num_rays=8, distribution="hexapolar", wavelength="primary")
    spots = theirs._center_spots(theirs.data)  # centred on the chief ray (its default reference)
    dist = create_distribution("hexapolar")
    dist.generate_points(8)
    pupil = torch.stack([torch.as_tensor(np.asarray(dist.x)), torch.as_tensor(np.asarray(dist.y))], -1).double()
    ref = model.system.reference
    for f, u in enumerate(model.system.rel_field):
        x, y = np.asarray(spots[f][0].x, dtype=float), np.asarray(spots[f][0].y, dtype=float)
        r = np.hypot(x, y)
        radii = np.linspace(0.0, 1.2 * r.max(), 257)
        expect = np.array([(r <= v).sum() for v in radii]) / r.size
        mine = geometric_energy(model.lens, model.system, rel_field=torch.tensor([u], dtype=torch.float64),
                                pupil=pupil, center="chief", radii=torch.from_numpy(radii))
        np.testing.assert_array_equal(mine.encircled_w[0, ref].numpy(), expect)


def test_geometric_energy_invariants(cooke) -> None:
    model = cooke
    e = geometric_energy(model.lens, model.system, rel_field=torch.tensor([0.0, 1.0], dtype=torch.float64))
    assert bool((e.encircled[:, -1] == 1.0).all()) and bool((e.encircled[:, 0] == 0.0).all())
    assert bool((e.encircled.diff(dim=-1) >= 0).all())
    assert bool((e.ensquared >= e.encircled - 1e-15).all())  # the square holds the inscribed circle
    assert float(e.center[0, 0]) == 0.0  # x̄ = 0 by symmetry (half pupil)


def test_diffraction_encircled_energy_of_a_perfect_lens_is_airy() -> None:
    model = oval_model(epd=10.0)
    lens, system = model.lens, model.system
    wn = float(first_order(lens, system).working_fnumber)
    lam = float(lens.wavelength_um[0]) * 1e-3
    na = float(lens.index[-1, 0]) / (2 * wn)
    airy = 0.61 * lam / na
    radii = torch.linspace(0.0, 5 * airy, 21, dtype=torch.float64)
    e = diffraction_energy(lens, system, rel_field=AXIS, radii=radii, pupil_samples=96, pitch_mm=airy / 24)
    v = 2 * math.pi / lam * na * radii.numpy()
    closed = 1 - j0(v) ** 2 - j1(v) ** 2
    # pixels of a 24th of the Airy radius on a ramp: 1e-3 (64 pupil samples and a 12th: 4e-3)
    assert np.abs(e.encircled[0].numpy() - closed).max() < 2e-3
    assert bool((e.ensquared[0] >= e.encircled[0] - 2e-3).all())


def test_diffraction_energy_needs_enough_pupil_samples() -> None:
    model = oval_model(epd=10.0)
    with pytest.raises(LensoptError, match=r"^pupil_samples: too few for radii up to 1000 µm"):
        diffraction_energy(model.lens, model.system, rel_field=AXIS,
                           radii=torch.tensor([0.0, 1.0], dtype=torch.float64), pupil_samples=16)


def test_strehl_of_quarter_wave_defocus() -> None:
    model = oval_model(epd=10.0)
    lens, system = model.lens, model.system
    n_img = float(lens.index[-1, 0])
    u = 1 / (2 * float(first_order(lens, system).working_fnumber))
    lam = float(lens.wavelength_um[0]) * 1e-3
    dz = (lam / 4) * 2 / (n_img * u**2)  # W020 = n' dz u'²/2 = λ/4
    shifted = defocused(lens, dz)
    pv = abs(float(opd_fans(shifted, system, points=3, rel_field=AXIS).tangential[0, 0, 0]))
    assert pv == pytest.approx(0.25, rel=2e-3)  # the paraxial estimate of dz; the exact P-V is used below
    s = strehl(shifted, system, rel_field=AXIS, pupil_samples=256)
    analytic = (math.sin(math.pi * pv) / (math.pi * pv)) ** 2
    assert float(s.psf) == pytest.approx(analytic, abs=2e-4)  # 256² pupil grid (128²: 6e-4, 64²: 1.2e-3)
    assert float(s.psf) == pytest.approx(0.8106, abs=2e-3)
    assert float(s.marechal) == pytest.approx(math.exp(-((2 * math.pi * pv / math.sqrt(12)) ** 2)), abs=1e-3)
    assert float(s.peak_offset_mm.abs().max()) < 1e-3 * 1.22 * lam / (2 * u * n_img)  # peak on axis


def test_strehl_of_a_perfect_lens_and_marechal() -> None:
    model = oval_model(epd=10.0)
    s = strehl(model.lens, model.system, rel_field=AXIS, pupil_samples=48)
    assert float(s.psf) == pytest.approx(1.0, abs=1e-9)
    assert float(s.marechal) == pytest.approx(1.0, abs=1e-9)
    assert float(marechal(torch.tensor(0.1))) == pytest.approx(math.exp(-(0.2 * math.pi) ** 2))


def test_strehl_of_a_real_lens_both_estimates() -> None:
    spec = load_spec(COOKE).model_dump(mode="json", exclude_none=True)
    spec["system"]["aperture"] = {"epd": 4.0}  # stopped down to f/12.5: near the diffraction limit
    model = build(parse_spec(spec))
    s = strehl(model.lens, model.system, rel_field=torch.tensor([0.0, 0.5], dtype=torch.float64), pupil_samples=48)
    ok = s.rms_waves < 0.1  # where Maréchal holds (Strehl > 0.67) the two agree within a few per cent
    assert bool(ok.any())
    assert float((s.psf - s.marechal).abs()[ok].max()) < 0.03
    assert bool(((s.psf > 0) & (s.psf <= 1.0 + 1e-9)).all())
