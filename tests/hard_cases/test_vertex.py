"""Rays exactly at r = 0 on an even asphere and on a diffractive surface (on an aspheric base).

Sag slopes and phase gradients are written in u = r² so nothing divides by r; at the vertex every
value and every derivative must be finite, and the first derivatives there are the paraxial ones:
d(image height)/d(launch height) at r = 0 equals the paraxial y-ω trace, worked out by hand here with
surface powers K = (n' − n) c for refraction and K = −m λ d2 / π for the phase φ = d2 r² + ….
"""

from __future__ import annotations

import dataclasses
import math

import torch

from lensopt.optics.trace import Rays, trace
from tests.hard_cases.hard_tools import LENS_TENSORS, counts, make_lens, make_rays, trace_checked

D = torch.float64
N = 1.6
LAM_UM = 0.55
C0, C1, T0, T1, D2 = 1 / 30, -1 / 50, 4.0, 40.0, -40.0


def _lens():
    return make_lens([
        {"kind": "asphere", "c": C0, "k": -0.5, "a": [1e-4, -1e-6], "t": T0},
        {"kind": "asphere", "c": C1, "a": [2e-5], "phase": [D2, 0.1], "t": T1},
    ], index=[1.0, N, 1.0], wavelength_um=LAM_UM)


def _axial_ray(xy: torch.Tensor) -> Rays:
    pos = torch.cat([xy, torch.tensor([-1.0], dtype=D)]).unsqueeze(0)
    return Rays(pos=pos, dir=torch.tensor([[0.0, 0.0, 1.0]], dtype=D), wavelength=torch.zeros((), dtype=torch.long))


def test_on_axis_ray_values_and_gradients() -> None:
    result, grads = trace_checked(_lens(), make_rays(torch.tensor([[0.0, 0.0, -1.0]], dtype=D),
                                                      torch.tensor([[0.0, 0.0, 1.0]], dtype=D)))
    assert counts(result) == {}
    assert result.pos[0].tolist() == [0.0, 0.0, T0 + T1]
    assert result.dir[0].tolist() == [0.0, 0.0, 1.0]
    for hit in result.hits:
        assert hit.normal[0].tolist() == [0.0, 0.0, 1.0]
    # By symmetry the on-axis image point does not move with any lens parameter.
    leaves = {n: getattr(_lens(), n).clone().requires_grad_(True) for n in LENS_TENSORS}
    out = trace(dataclasses.replace(_lens(), **leaves), _axial_ray(torch.zeros(2, dtype=D)))
    for coord in (0, 1):
        gs = torch.autograd.grad(out.pos[0, coord], list(leaves.values()), retain_graph=True, allow_unused=True)
        for name, g in zip(leaves, gs, strict=True):
            assert g is None or float(g.abs().max()) == 0.0, name
    assert all(bool(g.isfinite().all()) for g in grads.values())


def test_first_derivatives_at_the_vertex_are_paraxial() -> None:
    lam_mm = LAM_UM * 1e-3
    k0 = (N - 1.0) * C0
    k1 = (1.0 - N) * C1 - lam_mm * D2 / math.pi
    omega = -k0 * 1.0  # y0 = 1, ω0 = 0
    y1 = 1.0 + T0 * omega / N
    omega = omega - y1 * k1
    y2 = y1 + T1 * omega
    lens = _lens()

    def image_xy(xy: torch.Tensor) -> torch.Tensor:
        return trace(lens, _axial_ray(xy)).pos[0, :2]

    def image_dir(xy: torch.Tensor) -> torch.Tensor:
        return trace(lens, _axial_ray(xy)).dir[0, :2]

    zero = torch.zeros(2, dtype=D)
    expected = torch.tensor([[y2, 0.0], [0.0, y2]], dtype=D)
    torch.testing.assert_close(torch.func.jacfwd(image_xy)(zero), expected, rtol=1e-13, atol=1e-15)
    torch.testing.assert_close(torch.func.jacrev(image_xy)(zero), expected, rtol=1e-13, atol=1e-15)
    # Direction cosine slope: dM/dy0 = ω' (image space in air).
    expected_dir = torch.tensor([[omega, 0.0], [0.0, omega]], dtype=D)
    torch.testing.assert_close(torch.func.jacfwd(image_dir)(zero), expected_dir, rtol=1e-13, atol=1e-15)


def test_tilted_ray_through_the_vertex() -> None:
    # A 5° ray aimed at the vertex of surface 1: r = 0 exactly there, then off axis at surface 2.
    a = math.radians(5.0)
    pos = torch.tensor([[0.0, -math.tan(a), -1.0]], dtype=D)
    d = torch.tensor([[0.0, math.sin(a), math.cos(a)]], dtype=D)
    result, grads = trace_checked(_lens(), make_rays(pos, d))
    assert counts(result) == {}
    assert float(result.hits[0].pos[0, :2].abs().max()) < 1e-15
    # At the vertex the normal is the axis: Snell in angle form, sin a = n sin a'.
    torch.testing.assert_close(result.hits[0].dir_out[0, 1], torch.tensor(math.sin(a) / N, dtype=D),
                               rtol=1e-14, atol=0)
    assert all(bool(g.isfinite().all()) for g in grads.values())
