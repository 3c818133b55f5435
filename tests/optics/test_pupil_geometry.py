"""Pupil-region geometry behind the front aperture (S1.3.2): the clipped ellipse against brute force
on a fine 2-D grid, and the S19–S20 factor algebra (independent of any lens)."""

import math

import pytest
import torch

from lensopt.optics.vignetting import (
    apply_vignetting,
    clip_ellipse_to_disc,
    compose_factors,
    ellipse_to_factors,
    factors_to_ellipse,
)

F64 = torch.float64
N = 801  # grid cells per axis over [-3, 3]: cell 0.0075 relative pupil units (< 1 % of the radius)
CASES = [  # (ellipse y_c, a, b), disc (centre, radius)
    ((0.0, 1.0, 1.0), (0.3, 1.0)),  # the seed's case: D = EPD, the aperture's image shifted up
    ((0.0, 1.0, 1.0), (0.9, 1.2)),
    ((0.0, 1.0, 1.0), (-0.4, 0.8)),  # clips the top instead
    ((0.25, 1.1, 1.3), (1.0, 1.1)),  # an aimed (shifted, stretched) pupil
    ((0.0, 1.0, 1.0), (0.0, 2.0)),  # disc contains the pupil: nothing changes
]


def _brute(ellipse: tuple, disc: tuple) -> tuple[float, float, float]:
    """y extent and widest half-width of {inside ellipse} ∩ {inside disc} on a cell-centred grid."""
    c = -3.0 + 6.0 * (torch.arange(N, dtype=F64) + 0.5) / N
    y, x = torch.meshgrid(c, c, indexing="ij")
    (y0, a, b), (yc, r) = ellipse, disc
    inside = ((x / a) ** 2 + ((y - y0) / b) ** 2 <= 1.0) & (x**2 + (y - yc) ** 2 <= r**2)
    ys, xs = y[inside], x[inside]
    return float(ys.min()), float(ys.max()), float(xs.abs().max())


@pytest.mark.parametrize(("ellipse", "disc"), CASES)
def test_extent_clip_matches_grid(ellipse: tuple, disc: tuple) -> None:
    (y_c, a, b), blocked = clip_ellipse_to_disc(tuple(torch.tensor(v, dtype=F64) for v in ellipse),
                                                torch.tensor(disc[0], dtype=F64), torch.tensor(disc[1], dtype=F64),
                                                lateral="extent")
    lo, hi, wide = _brute(ellipse, disc)
    cell = 6.0 / N
    assert not bool(blocked)
    assert float(y_c - b) == pytest.approx(lo, abs=cell)
    assert float(y_c + b) == pytest.approx(hi, abs=cell)
    assert float(a) == pytest.approx(wide, abs=cell)


@pytest.mark.parametrize(("ellipse", "disc"), CASES)
def test_inscribed_clip_is_the_widest_ellipse_inside(ellipse: tuple, disc: tuple) -> None:
    (y_c, a, b), _ = clip_ellipse_to_disc(tuple(torch.tensor(v, dtype=F64) for v in ellipse),
                                          torch.tensor(disc[0], dtype=F64), torch.tensor(disc[1], dtype=F64))
    lo, hi, _ = _brute(ellipse, disc)
    assert float(y_c - b) == pytest.approx(lo, abs=6.0 / N)
    assert float(y_c + b) == pytest.approx(hi, abs=6.0 / N)
    t = torch.linspace(0, 2 * math.pi, 20001, dtype=F64)

    def worst(scale: float) -> float:
        """Largest excursion of the ellipse boundary (x semi-axis a·scale) outside either region."""
        x, y = a * scale * torch.cos(t), y_c + b * torch.sin(t)
        (y0, ea, eb), (yc, r) = ellipse, disc
        out_e = (x / ea) ** 2 + ((y - y0) / eb) ** 2 - 1.0
        out_d = (x**2 + (y - yc) ** 2) / r**2 - 1.0
        return float(torch.maximum(out_e, out_d).max())

    assert worst(1.0) <= 1e-9  # inside both
    assert worst(1.01) > 0.0  # and no wider one is (1 % wider pokes out)


def test_disc_above_the_pupil_blocks_everything() -> None:
    ell = tuple(torch.tensor(v, dtype=F64) for v in (0.0, 1.0, 1.0))
    (y_c, a, b), blocked = clip_ellipse_to_disc(ell, torch.tensor(2.5, dtype=F64), torch.tensor(1.0, dtype=F64))
    assert bool(blocked)
    assert all(math.isfinite(float(v)) for v in (y_c, a, b))
    assert float(a) == 0.0 and float(b) == 0.0


def test_clip_is_differentiable() -> None:
    # Gradient of the inscribed semi-axis against central differences, in the seed's tangent case.
    def a_of(centre: torch.Tensor) -> torch.Tensor:
        ell = tuple(torch.tensor(v, dtype=F64) for v in (0.0, 1.0, 1.0))
        (_, a, _), _ = clip_ellipse_to_disc(ell, centre, torch.tensor(1.0, dtype=F64))
        return a

    c = torch.tensor(0.3, dtype=F64, requires_grad=True)
    (g,) = torch.autograd.grad(a_of(c), c)
    h = 1e-6
    fd = (a_of(torch.tensor(0.3 + h, dtype=F64)) - a_of(torch.tensor(0.3 - h, dtype=F64))) / (2 * h)
    # Closed form for D = EPD: V_i = c, b = 1 − c/2, a = sqrt(b) (osculating at the top), da/dc = −1/(4 sqrt(b)).
    assert float(g) == pytest.approx(float(fd), rel=1e-7)
    assert float(g) == pytest.approx(-1.0 / (4.0 * math.sqrt(1 - 0.15)), rel=1e-12)


def test_factor_algebra_round_trips_and_composes() -> None:
    f = torch.tensor([[0.2, 0.1, 0.3], [-0.5, 0.4, -0.2]], dtype=F64)
    assert torch.allclose(ellipse_to_factors(*factors_to_ellipse(f)), f, atol=1e-15)
    g = torch.tensor([[0.1, 0.0, 0.05], [0.3, 0.2, 0.1]], dtype=F64)
    pts = torch.tensor([[0.0, -1.0], [0.0, 1.0], [1.0, 0.0], [0.3, 0.4]], dtype=F64).view(1, 1, 4, 2).expand(2, 1, 4, 2)
    two_step = apply_vignetting(apply_vignetting(pts, g.view(2, 1, 3)), f.view(2, 1, 3))
    assert torch.allclose(apply_vignetting(pts, compose_factors(f, g).view(2, 1, 3)), two_step, atol=1e-15)
