"""A ray exactly parallel to a plane surface never meets it (the plane equation z = 0 has no solution
for a direction with γ = 0): it is reported as missed, with finite placeholders, while the other
rays of the batch are traced normally and keep finite gradients."""

from __future__ import annotations

import math

import torch

from tests.hard_cases.hard_tools import counts, make_lens, make_rays, trace_checked

D = torch.float64


def test_rays_parallel_to_a_plane_are_missed() -> None:
    lens = make_lens([{"kind": "plane", "t": 5.0}, {"kind": "sphere", "c": -0.05, "t": 20.0}], index=[1.0, 1.5, 1.0])
    pos = torch.tensor([[0.0, 0.0, -1.0],   # parallel, 1 mm before the plane
                        [0.0, 0.0, 0.0],    # parallel, lying in the plane itself
                        [0.0, 1.0, -1.0],   # an ordinary ray parallel to the axis
                        [0.0, 0.0, -1.0]],  # an ordinary ray at 20°
                       dtype=D)
    a = math.radians(20.0)
    d = torch.tensor([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, math.sin(a), math.cos(a)]], dtype=D)
    result, grads = trace_checked(lens, make_rays(pos, d))
    assert counts(result) == {"missed surface": 2}
    assert result.status.tolist() == [1, 1, 0, 0]
    # Placeholders: the start point is kept.
    assert result.pos[:2].tolist() == pos[:2].tolist()
    # The ordinary rays are unaffected: the axial one stays at y = 1 through the plane; after the
    # sphere it bends, so check only its hit on the plane; the 20° ray meets the plane at tan 20°.
    assert result.hits[0].pos[2].tolist() == [0.0, 1.0, 0.0]
    torch.testing.assert_close(result.hits[0].pos[3, 1], torch.tensor(math.tan(a), dtype=D), rtol=1e-15, atol=0)
    assert float(grads["curvature"].abs().sum()) > 0
