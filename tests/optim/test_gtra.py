"""GTRA identities (S66–S68) in float64 on the Cooke triplet: at θ₀ ½‖ℓ_GTRA‖² = L exactly and
Jᵀℓ_GTRA = ∇_θ L (reverse mode through trace, rendering and loss); with clipped control values
½‖ℓ‖² = L still holds. Both identities follow from the definitions of w and ε′ in S66."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from lensopt.design import build_problem
from lensopt.errors import LensoptError
from lensopt.optim import Problem
from lensopt.optim.gtra import gtra_residual, gtra_target
from lensopt.spec import load_spec

SPECS = Path(__file__).resolve().parents[2] / "specs"


def _problem(psf_size: int = 21, method: str = "lm", **image) -> Problem:
    spec = load_spec(SPECS / "cooke_triplet.toml")
    for s in spec.surfaces[:3]:
        s.vary = ["radius"]
    spec.surfaces[3].vary = ["thickness"]
    settings = {"patch": 32, "batch": 2, "psf_size": psf_size, "fields": 3, "sampling": "rings:4", **image}
    opt = {"objective": "raw", "image": settings, "sampling": "rings:3", "rim_rays": 0}
    spec = spec.model_copy(update={"optimize": type(spec).model_fields["optimize"].annotation.__args__[0](**opt)})
    return build_problem(spec, method=method, image_dtype=torch.float64)


def _gtra_rows(p: Problem, theta: torch.Tensor) -> torch.Tensor:
    return p.terms(theta)["gtra"] / p.image.spec.weight


def test_half_squared_norm_equals_the_loss_and_jt_l_equals_the_gradient() -> None:
    p = _problem()
    theta = p.theta0.clone()
    lens, _ = p.lens(theta)
    target = p.image.update(lens)
    assert target.clipped == 0
    r = _gtra_rows(p, theta)
    assert float(0.5 * (r**2).sum()) == pytest.approx(float(target.loss), rel=1e-12)
    J = torch.func.jacfwd(lambda t: _gtra_rows(p, t))(theta)
    jtl = J.T @ r
    t = theta.clone().requires_grad_(True)
    (grad,) = torch.autograd.grad(p.image.loss(p.lens(t)[0]), t)  # reverse mode through everything
    assert float(grad.abs().max()) > 0
    torch.testing.assert_close(jtl, grad, rtol=1e-8, atol=1e-8 * float(grad.abs().max()))


def test_with_clipping_half_squared_norm_still_equals_the_loss() -> None:
    p = _problem(psf_size=3)  # a 3×3 PSF window: the control values leave it
    lens, _ = p.lens(p.theta0)
    target = p.image.update(lens)
    assert target.clipped > 0
    r = _gtra_rows(p, p.theta0)
    assert float(0.5 * (r**2).sum()) == pytest.approx(float(target.loss), rel=1e-12)


def test_failed_rays_carry_no_residual_and_a_flat_loss_gives_none() -> None:
    eps0 = torch.randn(2, 1, 5, 2, dtype=torch.float64)
    valid = torch.ones(2, 1, 5, dtype=torch.bool)
    valid[0, 0, 1] = False
    target = gtra_target(eps0, valid, lambda e: (e**2).sum() + 1.0)
    r = gtra_residual(eps0, valid, target).view(2, 1, 5, 2)
    assert float(r[0, 0, 1].abs().max()) == 0.0
    # L = Σ e² + 1 (all rays, analytic): ½‖ℓ‖² = L on the valid rays' share of the gradient.
    assert float(0.5 * (r**2).sum()) == pytest.approx(float(target.loss), rel=1e-12)
    flat = gtra_target(eps0, valid, lambda e: 0.0 * e.sum() + 2.0)
    assert float(gtra_residual(eps0 + 1.0, valid, flat).abs().max()) == 0.0


def test_raw_objective_without_a_sensor_is_a_one_line_error() -> None:
    spec = load_spec(SPECS / "cooke_triplet.toml")
    spec = spec.model_copy(update={"sensor": None})
    spec.surfaces[0].vary = ["radius"]
    from lensopt.spec.optim import OptimizeSpec

    spec = spec.model_copy(update={"optimize": OptimizeSpec(objective="raw")})
    with pytest.raises(LensoptError) as err:
        build_problem(spec)
    assert err.value.path == "sensor"


def test_batch_noise_changes_with_the_step_and_held_out_noise_stays_fixed() -> None:
    # The capture minus its noise-free rendering is the noise field: drawn anew for every step's batch (a
    # slot must not see the same field every step), identical for repeated evaluations within a step (LM's
    # trial steps compare like with like), and fixed for the held-out set.
    obj = _problem().image
    lens, _ = _problem().lens(_problem().theta0)
    spots = obj.spots(lens)

    def noise_of(images, regions):  # noqa: ANN001, ANN202
        noisy = obj.render(spots.xy, spots, None, images, regions)
        return noisy - obj.render(spots.xy, spots, None, images, regions, noise=False)

    obj.set_batch(0)
    n0 = noise_of(obj.images, obj.regions)
    assert float(n0.abs().max()) > 0
    torch.testing.assert_close(noise_of(obj.images, obj.regions), n0, rtol=0, atol=0)
    images0, regions0 = obj.images, obj.regions
    obj.set_batch(1)
    obj.images, obj.regions = images0, regions0  # same scenes and tiles, another step's noise
    n1 = noise_of(obj.images, obj.regions)
    assert float((n1 - n0).abs().max()) > 0.1 * float(n0.abs().max())
    held = obj.batch(-1, held_out=True, size=2)
    h0 = noise_of(held[0].clone(), held[1])
    obj.set_batch(5)
    torch.testing.assert_close(noise_of(held[0].clone(), held[1]), h0, rtol=0, atol=0)
