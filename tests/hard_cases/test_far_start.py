"""Rays that start more than one radius of curvature away from a surface's vertex: a ball lens (the
second surface is 2R behind the first) and rays launched from an entrance pupil that lies far behind
a strongly curved first surface. The quadric root that tends to the plane intersection must be
chosen relative to the vertex plane; chosen relative to the start point it flips to the far root
and every ray is wrongly reported as missed (the bug this file was written for)."""

from __future__ import annotations

import math

import pytest
import torch

from tests.hard_cases.hard_tools import collimated, counts, make_lens, trace_checked

D = torch.float64


@pytest.mark.parametrize("kind", ["sphere", "asphere"])
def test_ball_lens_focuses_at_its_paraxial_focus(kind: str) -> None:
    # Ball lens, n = 1.5, radius 5 mm: EFL = n D / (4 (n − 1)) = 7.5 mm from the centre, so the
    # back focus lies 7.5 − 5 = 2.5 mm behind the rear vertex (z = 12.5 mm).
    n, r = 1.5, 5.0
    extra = {"a": [0.0]} if kind == "asphere" else {}
    lens = make_lens([{"kind": kind, "c": 1 / r, "t": 2 * r, **extra},
                      {"kind": kind, "c": -1 / r, "t": 2.5, **extra}], index=[1.0, n, 1.0])
    heights = torch.tensor([1e-4, 0.5, 1.0, 2.0], dtype=D)
    result, _ = trace_checked(lens, collimated(heights, z=-1.0))
    assert counts(result) == {}
    centre = torch.tensor([0.0, 0.0, r], dtype=D)
    for hit in result.hits:
        torch.testing.assert_close(torch.linalg.vector_norm(hit.pos - centre, dim=-1),
                                   torch.full_like(heights, r), rtol=0, atol=1e-12)
    # The paraxial ray (y = 1e-4 mm) crosses the axis at the back focus: image height ≈ 0 there,
    # relative to its entrance height (spherical aberration is O(y³)).
    assert abs(float(result.pos[0, 1])) / 1e-4 < 1e-6
    # Marginal rays focus short of the paraxial focus (undercorrected spherical aberration).
    assert bool((result.pos[1:, 1] < 0).all())


def test_rays_launched_behind_a_strongly_curved_first_surface() -> None:
    # Rays start on a plane 30 mm behind surface 1 (R = 20 mm), as from an entrance pupil inside the
    # lens; the trace goes back along them to surface 1 (negative distance, not flagged for surface 1).
    # Rays parallel to the axis meet the sphere at z = R − sqrt(R² − y²).
    radius = 20.0
    lens = make_lens([{"kind": "sphere", "c": 1 / radius, "t": 5.0}], index=[1.0, 1.5])
    heights = torch.tensor([0.0, 3.0, 6.0, 9.0], dtype=D)
    result, _ = trace_checked(lens, collimated(heights, z=30.0), upto=0)
    assert counts(result) == {}
    expected_z = radius - torch.sqrt(radius**2 - heights**2)
    torch.testing.assert_close(result.pos[:, 2], expected_z, rtol=0, atol=1e-13)
    assert math.isclose(float(expected_z[3]), 2.1394, abs_tol=1e-4)  # 20 − sqrt(319)
