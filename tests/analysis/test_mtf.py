"""MTF against the closed form of a perfect lens (issue 12).

Oracle: the diffraction-limited MTF of an aberration-free system with a uniformly filled circular
pupil, ``(2/π)(acos s − s sqrt(1 − s²))``, ``s = ν λ N_w`` (Goodman, *Introduction to Fourier Optics*,
§6.3.3). The lens: a plano-convex singlet, flat side to a collimated beam, the exit surface a
hyperboloid of conic κ = −n² — a Cartesian surface that images the axial point at infinity without
aberration at the paraxial focus (checked: the traced spot is below 1e-9 mm), f/10, one wavelength.
"""

from __future__ import annotations

import dataclasses

import pytest
import torch

from lensopt.analysis.mtf import diffraction_limited_mtf, lens_mtf, mtf_from_psf
from lensopt.analysis.spot import spot_stats
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import pupil_grid
from lensopt.spec import build
from lensopt.spec.io import parse_spec

LAMBDA_UM = 0.58756


def perfect_lens():
    data = {
        "name": "Cartesian plano-hyperbolic singlet",
        "system": {"aperture": {"epd": 5.0}, "field": {"hfov_deg": 0.01, "relative": [0.0]}},
        "spectrum": {"wavelengths_nm": [LAMBDA_UM * 1e3]},
        "surfaces": [
            {"type": "plane", "thickness": 4.0, "material": {"nd": 1.5, "vd": 60.0}, "stop": True},
            {"type": "conic", "radius": -25.0, "conic": -2.25, "thickness": 50.0},
        ],
    }
    model = build(parse_spec(data))
    n = float(model.lens.index[1, 0])
    lens = dataclasses.replace(model.lens, conic=torch.tensor([0.0, -n * n], dtype=torch.float64))
    bfl = float(first_order(lens, model.system).bfl)
    lens = dataclasses.replace(lens, thickness=torch.tensor([4.0, bfl], dtype=torch.float64))
    return lens, model.system


def test_lens_is_aberration_free() -> None:
    lens, system = perfect_lens()
    b = trace_bundle(lens, system, pupil_grid(21, dtype=torch.float64))
    assert float(spot_stats(b, system.wavelength_weights).rms_radius[0]) < 1e-9


def test_mtf_of_a_gaussian_psf() -> None:
    """A sampled Gaussian of σ: MTF = exp(−2π²σ²ν²) (its Fourier transform), both directions."""
    pitch, sigma = 0.001, 0.004
    c = (torch.arange(201, dtype=torch.float64) - 100) * pitch
    g = torch.exp(-(c[:, None] ** 2 + c[None, :] ** 2) / (2 * sigma**2))
    nu = torch.tensor([0.0, 20.0, 50.0, 100.0], dtype=torch.float64)
    sag, tan = mtf_from_psf(g, pitch, nu)
    expect = torch.exp(-2 * torch.pi**2 * sigma**2 * nu**2)
    assert torch.allclose(sag, expect, atol=1e-9) and torch.allclose(tan, expect, atol=1e-9)


@pytest.mark.parametrize("method", ["reference", "heuristic"])
def test_perfect_lens_mtf_equals_closed_form(method: str) -> None:
    lens, system = perfect_lens()
    wn = float(first_order(lens, system).working_fnumber)
    cutoff = 1.0 / (LAMBDA_UM * 1e-3 * wn)
    nu = torch.tensor([0.1, 0.25, 0.5, 0.75, 0.9], dtype=torch.float64) * cutoff
    res = lens_mtf(lens, system, nu, method=method, sampling="rings:16", pupil_samples=96,
                   size=121 if method == "reference" else None)
    expect = diffraction_limited_mtf(nu, LAMBDA_UM, wn)
    # Reference: a Debye sum over the exit pupil on a finite grid (the Airy wings beyond it are lost):
    # measured 0.0086 off. Heuristic: geometric OTF (1 for a point spot) × the closed form.
    tol = 0.01 if method == "reference" else 1e-9
    assert torch.allclose(res.sagittal[0], expect, atol=tol), (res.sagittal, expect)
    assert torch.allclose(res.tangential[0], expect, atol=tol), (res.tangential, expect)


def test_defocused_geometric_mtf_is_the_disc_transform() -> None:
    """Defocus δ: the geometric spot is a uniform disc of radius ρ = δ·tan u' (to the small
    non-uniformity of a real f/10 ray mapping), whose transform is 2 J1(2πνρ)/(2πνρ) (Goodman §6.4)."""
    from scipy.special import j1

    lens, system = perfect_lens()
    delta = 0.2
    lens = dataclasses.replace(lens, thickness=lens.thickness + torch.tensor([0.0, delta], dtype=torch.float64))
    b = trace_bundle(lens, system, torch.tensor([[0.0, 1.0]], dtype=torch.float64))
    rho = float(b.result.pos[0, 0, 0, 1].abs())  # the marginal ray's height on the image: the disc edge
    nu = torch.tensor([0.5, 1.0, 2.0, 4.0], dtype=torch.float64) / (2 * rho * 3.8317 / torch.pi)
    # grid sampling: equal-area cells (rings:N puts its outer ring on the rim and converges as 1/N:
    # 0.017, 0.012, 0.009 off at N = 32, 64, 128; grid:201 0.0014).
    res = lens_mtf(lens, system, nu, method="geometric", sampling="grid:201")
    x = 2 * torch.pi * nu * rho
    expect = torch.from_numpy(2 * j1(x.numpy()) / x.numpy()).abs()
    assert torch.allclose(res.sagittal[0], expect, atol=0.003), (res.sagittal, expect)
    assert torch.allclose(res.tangential[0], expect, atol=0.003)
