"""A conic/asphere whose sag is undefined beyond some radius: κ = 0.5 (oblate ellipsoid) with
c = 0.2/mm. The square root in z(r) = c r²/(1 + sqrt(1 − (1 + κ) c² r²)) is real only for
r ≤ r_max = 1/(c sqrt(1 + κ)) = 4.0825 mm; rays parallel to the axis keep their height, so those with
|y| > r_max must be reported as missed (closed form and Newton path alike), with finite values and
gradients, and those inside must land on the sag."""

from __future__ import annotations

import math

import pytest
import torch

from tests.hard_cases.hard_tools import collimated, counts, make_lens, trace_checked

D = torch.float64
C, K, A4 = 0.2, 0.5, 1e-3
R_MAX = 1 / (C * math.sqrt(1 + K))


@pytest.mark.parametrize("kind", ["conic", "asphere"])
def test_rays_beyond_the_sag_domain_are_missed(kind: str) -> None:
    assert abs(R_MAX - 4.0825) < 1e-4
    extra = {"a": [A4]} if kind == "asphere" else {}
    lens = make_lens([{"kind": kind, "c": C, "k": K, "t": 10.0, **extra}], index=[1.0, 1.5])
    heights = torch.linspace(-5.95, 5.95, 120, dtype=D)
    result, _ = trace_checked(lens, collimated(heights, z=-1.0))
    outside = heights.abs() > R_MAX
    assert int(outside.sum()) == 38
    assert counts(result) == {"missed surface": int(outside.sum())}
    assert bool((result.valid == ~outside).all())
    y = heights[~outside]
    u = y * y
    z = C * u / (1 + torch.sqrt(1 - (1 + K) * C * C * u)) + (A4 * u * u if kind == "asphere" else 0.0)
    torch.testing.assert_close(result.hits[0].pos[~outside, 2], z, rtol=0, atol=1e-12)


def test_rays_close_inside_the_rim_stay_finite() -> None:
    # At r → r_max the slope dz/dr diverges (the ellipsoid's rim is vertical): the normal turns
    # radial and the ray meets the surface at grazing incidence; still traced, finite gradients.
    lens = make_lens([{"kind": "asphere", "c": C, "k": K, "a": [A4], "t": 10.0}], index=[1.0, 1.5])
    heights = torch.tensor([R_MAX * (1 - 1e-6), R_MAX * (1 - 1e-9)], dtype=D)
    result, grads = trace_checked(lens, collimated(heights, z=-1.0))
    assert counts(result) == {}
    assert float(result.hits[0].cos2_in.max()) < 1e-4  # incidence within ~0.6° of grazing
    assert all(bool(g.isfinite().all()) for g in grads.values())
