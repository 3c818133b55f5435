"""Quadric intersection: the root on the sag branch, also for rays that start behind the centre of
curvature (an entrance pupil deep inside the lens, as in a double Gauss)."""

import math

import pytest
import torch

from lensopt.optics.intersect import intersect_quadric


@pytest.mark.parametrize("start_z", [-10.0, 30.0, 57.9, 120.0])
@pytest.mark.parametrize("radius", [56.2, -56.2])
def test_axis_parallel_ray_meets_the_vertex_cap(start_z: float, radius: float) -> None:
    # Closed form: a ray parallel to the axis at height h meets the sphere's vertex cap at the sag
    # z = R − sign(R) sqrt(R² − h²), whatever its start point on that line (t may be negative).
    h = 25.0
    pos = torch.tensor([0.0, h, start_z], dtype=torch.float64)
    d = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    c = torch.tensor(1.0 / radius, dtype=torch.float64)
    t, hit = intersect_quadric(pos, d, c, torch.tensor(0.0, dtype=torch.float64))
    sag = radius - math.copysign(math.sqrt(radius**2 - h**2), radius)
    assert bool(hit)
    assert float(start_z + t) == pytest.approx(sag, abs=1e-12)


def test_tilted_ray_from_behind_the_centre_of_a_paraboloid_and_a_hyperboloid() -> None:
    # Paraboloid/hyperboloid (κ ≤ −1) have a single sheet on the sag branch: same closed-form check
    # along a tilted line, verified by substituting the point into the surface equation.
    for k in (-1.0, -2.5):
        c = 1.0 / 40.0
        pos = torch.tensor([0.0, 5.0, 80.0], dtype=torch.float64)
        d = torch.tensor([0.0, 0.1, 1.0], dtype=torch.float64)
        d = d / d.norm()
        t, hit = intersect_quadric(pos, d, torch.tensor(c, dtype=torch.float64), torch.tensor(k, dtype=torch.float64))
        p = pos + t * d
        r2 = float(p[0] ** 2 + p[1] ** 2)
        assert bool(hit)
        assert c * r2 + c * (1 + k) * float(p[2]) ** 2 - 2 * float(p[2]) == pytest.approx(0.0, abs=1e-12)
        assert (1 + k) * c * float(p[2]) <= 1.0
