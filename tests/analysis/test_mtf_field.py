"""MTF against field and through focus (``analysis.mtf_field``), and the analyses' argument checks.

Oracles:
- A perfect lens defocused by dz: its geometric spot is a uniformly lit disc of radius a = dz tan u'
  (Cartesian oval, rays evenly spread over the pupil), whose OTF is 2 J1(x)/x, x = 2π ν a; the
  ``heuristic`` MTF multiplies it by the diffraction-limited MTF (2/π)(acos s − s sqrt(1 − s²)),
  s = ν λ N_w (``analysis.mtf``'s closed form), so the through-focus curve is their product.
- MTF vs field at given fields is ``lens_mtf`` at those fields (the same computation, by construction).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.special import j1

from lensopt.analysis.checks import frequencies, relative_fields, wavelength_indices
from lensopt.analysis.encircled import geometric_energy
from lensopt.analysis.field_curves import field_curves
from lensopt.analysis.mtf import diffraction_limited_mtf, lens_mtf
from lensopt.analysis.mtf_field import mtf_vs_field, through_focus_mtf
from lensopt.analysis.strehl import strehl
from lensopt.analysis.wavefront import opd_fans
from lensopt.errors import LensoptError
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import first_order
from tests.helpers import oval_model

AXIS = torch.zeros(1, dtype=torch.float64)


def test_through_focus_of_a_perfect_lens() -> None:
    model = oval_model(epd=10.0)
    lens, system = model.lens, model.system
    nu = torch.tensor([20.0, 60.0], dtype=torch.float64)
    focus = torch.tensor([-0.02, -0.01, 0.0, 0.01, 0.02], dtype=torch.float64)
    tf = through_focus_mtf(lens, system, nu, focus_mm=focus, rel_field=AXIS, sampling="rings:64")
    marginal = trace_bundle(lens, system, torch.tensor([[0.0, 1.0]], dtype=torch.float64), rel_field=AXIS)
    d = marginal.result.dir[0, 0, 0]
    slope = float(d[1].abs() / d[2])
    wn = float(first_order(lens, system).working_fnumber)
    lam = float(lens.wavelength_um[0])
    dl = diffraction_limited_mtf(nu, lam, wn).numpy()
    for i, dz in enumerate(focus.tolist()):
        x = 2 * math.pi * nu.numpy() * abs(dz) * slope
        geo = np.where(x > 0, 2 * j1(x) / np.where(x > 0, x, 1.0), 1.0)
        np.testing.assert_allclose(tf.tangential[i, 0].numpy(), dl * np.abs(geo), atol=3e-3)
        np.testing.assert_allclose(tf.sagittal[i, 0].numpy(), tf.tangential[i, 0].numpy(), atol=1e-9)
    assert bool((tf.best_focus_mm == 0.0).all())


def test_mtf_vs_field_is_lens_mtf_at_those_fields(cooke) -> None:
    model = cooke
    res = mtf_vs_field(model.lens, model.system, [10.0, 30.0], fields=5)
    assert res.sagittal.shape == (5, 2) and res.rel_field.tolist() == [0.0, 0.25, 0.5, 0.75, 1.0]
    ref = lens_mtf(model.lens, model.system, torch.tensor([10.0, 30.0], dtype=torch.float64),
                   rel_field=res.rel_field)
    assert torch.equal(res.tangential, ref.tangential) and torch.equal(res.sagittal, ref.sagittal)
    assert float(res.field_deg[-1]) == pytest.approx(20.0, rel=1e-12)


@pytest.mark.parametrize("bad", [0.0, -5.0, float("nan")])
def test_frequency_must_be_positive(cooke, bad: float) -> None:
    model = cooke
    with pytest.raises(LensoptError, match=r"^frequency: spatial frequency must be > 0 cycles/mm \(got"):
        mtf_vs_field(model.lens, model.system, [10.0, bad])
    with pytest.raises(LensoptError, match="^frequency:"):
        frequencies([bad])


def test_field_past_the_field_of_view(cooke) -> None:
    model = cooke
    with pytest.raises(LensoptError) as err:
        relative_fields(model.system, [0.5, 1.2])
    assert str(err.value) == "field: relative field must lie in [0, 1] (1 = the full field, 20°) (got 1.2)"
    assert "\n" not in str(err.value)
    assert relative_fields(model.system, None).tolist() == [0.0, 0.7, 1.0]
    past = torch.tensor([0.0, 1.5], dtype=torch.float64)
    for call in (lambda: opd_fans(model.lens, model.system, rel_field=past),
                 lambda: field_curves(model.lens, model.system, past),
                 lambda: geometric_energy(model.lens, model.system, rel_field=past),
                 lambda: strehl(model.lens, model.system, rel_field=past),
                 lambda: through_focus_mtf(model.lens, model.system, [10.0], rel_field=past,
                                           focus_mm=torch.zeros(1, dtype=torch.float64))):
        with pytest.raises(LensoptError, match=r"^field: relative field must lie in \[0, 1\].*\(got 1.5\)$"):
            call()


def test_wavelength_not_in_the_spec(cooke) -> None:
    model = cooke
    assert wavelength_indices(model.lens, [650.0, 480.0]) == [2, 0]
    with pytest.raises(LensoptError) as err:
        wavelength_indices(model.lens, [587.6], path="--wavelength")
    assert str(err.value) == "--wavelength: not a wavelength of the spec; one of 480, 550, 650 nm (got 587.6)"
