"""Ray fans (S1.3.4): definitions checked against single real rays, symmetry and masking invariants."""

from __future__ import annotations

import math

import pytest
import torch

from lensopt.analysis.fans import ray_fans
from lensopt.analysis.report import ray_report
from lensopt.optics.bundle import trace_bundle
from lensopt.spec import build
from lensopt.spec.io import parse_spec
from tests.helpers import cooke_data

POINTS = 65  # odd: py = 0 is a sample; py = k/32, px = k/64


@pytest.fixture(scope="module")
def fans(cooke):
    with torch.no_grad():
        return ray_fans(cooke.lens, cooke.system, points=POINTS)


def vignetted_model():
    """The Cooke triplet at EPD 12 mm with surface 5 clipped at 6 mm: off-axis fans lose their upper rays."""
    data = cooke_data()
    data["system"]["aperture"] = {"epd": 12.0}
    data["surfaces"][4].update(semi_diameter=6.0, clip=True)
    return build(parse_spec(data))


def test_shapes_and_axes(fans, cooke):
    nf, nw = len(cooke.system.rel_field), cooke.lens.wavelength_um.numel()
    assert fans.tangential.shape == fans.tangential_valid.shape == (nf, nw, POINTS)
    assert fans.sagittal.shape == fans.sagittal_valid.shape == (nf, nw, POINTS)
    assert torch.equal(fans.py, torch.linspace(-1, 1, POINTS, dtype=torch.float64))
    assert torch.equal(fans.px, torch.linspace(0, 1, POINTS, dtype=torch.float64))
    assert fans.tangential_valid.all() and fans.sagittal_valid.all()  # the Cooke triplet does not vignette
    # Field angles of the spec: 0, 0.7·20°, 20°.
    assert fans.field_deg.tolist() == pytest.approx([0.0, 14.0, 20.0], abs=1e-12)


def test_tangential_fan_is_zero_at_the_chief_ray(fans):
    mid = POINTS // 2
    assert fans.py[mid] == 0.0
    assert torch.all(fans.tangential[:, fans.reference, mid] == 0.0)
    assert torch.all(fans.sagittal[:, fans.reference, 0] == 0.0)


def test_fan_origin_of_other_wavelengths_is_lateral_colour(cooke, fans):
    """At py = 0 a non-reference wavelength's curve sits at its chief ray minus the reference chief ray,
    checked with two independent single-ray traces (``ray_report`` rebuilds a one-wavelength lens)."""
    mid = POINTS // 2
    for h, deg in enumerate((0.0, 14.0, 20.0)):
        ref_y = ray_report(cooke, field_deg=deg, px=0.0, py=0.0, wavelength_nm=550.0)["image"]["y"]
        for w, nm in enumerate((480.0, 550.0, 650.0)):
            y = ray_report(cooke, field_deg=deg, px=0.0, py=0.0, wavelength_nm=nm)["image"]["y"]
            assert float(fans.tangential[h, w, mid]) == pytest.approx(y - ref_y, abs=1e-12)
    assert abs(float(fans.tangential[2, 0, mid])) > 1e-4  # real lateral colour at full field (≈ −1 µm)


@pytest.mark.parametrize(("h", "deg", "w", "nm"), [(1, 14.0, 0, 480.0), (2, 20.0, 2, 650.0), (2, 20.0, 1, 550.0)])
def test_fan_point_equals_single_ray_minus_chief(cooke, fans, h, deg, w, nm):
    chief = ray_report(cooke, field_deg=deg, px=0.0, py=0.0, wavelength_nm=550.0)["image"]
    k_t = 48  # py = 16/32 = 0.5
    k_s = 48  # px = 48/64 = 0.75
    assert float(fans.py[k_t]) == 0.5 and float(fans.px[k_s]) == 0.75
    tan_ray = ray_report(cooke, field_deg=deg, px=0.0, py=0.5, wavelength_nm=nm)["image"]
    sag_ray = ray_report(cooke, field_deg=deg, px=0.75, py=0.0, wavelength_nm=nm)["image"]
    assert float(fans.tangential[h, w, k_t]) == pytest.approx(tan_ray["y"] - chief["y"], abs=1e-12)
    assert float(fans.sagittal[h, w, k_s]) == pytest.approx(sag_ray["x"] - chief["x"], abs=1e-12)
    assert float(fans.chief[h, 1]) == pytest.approx(chief["y"], abs=1e-12)


def test_sagittal_fan_is_antisymmetric(cooke, fans):
    """Mirror symmetry about the meridional plane: a ray at −px lands at (−x, y). Traced explicitly."""
    px = fans.px
    mirrored = torch.stack([-px, torch.zeros_like(px)], -1)
    direct = torch.stack([px, torch.zeros_like(px)], -1)
    with torch.no_grad():
        neg = trace_bundle(cooke.lens, cooke.system, mirrored).result.pos
        pos = trace_bundle(cooke.lens, cooke.system, direct).result.pos
    chief_x = fans.chief[:, None, None, 0]
    assert torch.allclose(neg[..., 0] - chief_x, -fans.sagittal, rtol=0, atol=1e-12)
    assert torch.allclose(neg[..., 1], pos[..., 1], rtol=0, atol=1e-12)
    assert torch.allclose(pos[..., 0] - chief_x, fans.sagittal, rtol=0, atol=1e-12)
    assert fans.sagittal[2, 1].abs().max() > 1e-3  # a real, non-zero fan (≈ 17 µm at full field)


def test_on_axis_tangential_and_sagittal_fans_agree(fans):
    """Rotational symmetry: on axis, ε_y(py = t) = ε_x(px = t) for t ≥ 0."""
    mid = POINTS // 2
    assert torch.allclose(fans.tangential[0, :, mid:], fans.sagittal[0, :, ::2], rtol=0, atol=1e-13)


def test_failed_rays_are_masked_not_nan():
    model = vignetted_model()
    with torch.no_grad():
        fans = ray_fans(model.lens, model.system, points=POINTS)
        direct = trace_bundle(model.lens, model.system, torch.stack(
            [torch.zeros_like(fans.py), fans.py], -1)).result
    assert torch.equal(fans.tangential_valid, direct.valid)
    n_failed = int((~fans.tangential_valid).sum())
    assert n_failed > 0 and bool(fans.tangential_valid[0].all())  # only off-axis rays are clipped
    assert torch.isfinite(fans.tangential).all() and torch.isfinite(fans.sagittal).all()
    assert torch.all(fans.tangential[~fans.tangential_valid] == 0.0)
    # The clipped rays are the upper ones (py near +1) of the off-axis fields.
    assert not bool(fans.tangential_valid[2, :, -1].any()) and bool(fans.tangential_valid[2, :, 0].all())


def test_fans_are_differentiable(cooke):
    """d ε_y(py = 1, full field, 550 nm) / d c_1: autograd against a central finite difference."""
    lens, system = cooke.lens, cooke.system
    c = lens.curvature.clone().requires_grad_(True)

    def value(curv):
        from dataclasses import replace
        return ray_fans(replace(lens, curvature=curv), system, points=5).tangential[2, 1, -1]

    (grad,) = torch.autograd.grad(value(c), c)
    step = 1e-7
    for i in (0, 3):
        e = torch.zeros_like(c)
        e[i] = step
        with torch.no_grad():
            fd = (value(c + e) - value(c - e)) / (2 * step)
        assert math.isfinite(float(grad[i]))
        assert float(grad[i]) == pytest.approx(float(fd), rel=1e-6)
