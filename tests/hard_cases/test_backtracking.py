"""Overlapping surfaces (S1.2.1): a negative air gap puts the next surface behind the current one, so
the ray-marching distance is negative while the ray goes forward. The ray is *flagged* as
backtracking and traced on (the seed keeps it: it is well behaved), never failed."""

from __future__ import annotations

import math

import torch

from tests.hard_cases.hard_tools import collimated, counts, make_lens, trace_checked

D = torch.float64


def test_negative_air_gap_between_planes() -> None:
    # Planes at z = 0 (air → n), 4 (n → air), 2 (air → n: the −2 mm gap), 5 (n → air), image at 15.
    # A ray at θ0 = 10° runs at θ1 = asin(sin θ0 / n) in the glass, so its image height is
    # y0 + (1 − 2 + 10) tan θ0 + (4 + 3) tan θ1 (it starts at z = −1; the −2 mm gap goes backwards).
    n = 1.5
    lens = make_lens([{"kind": "plane", "t": 4.0}, {"kind": "plane", "t": -2.0},
                      {"kind": "plane", "t": 3.0}, {"kind": "plane", "t": 10.0}], index=[1.0, n, 1.0, n, 1.0])
    heights = torch.tensor([-2.0, 0.0, 1.5], dtype=D)
    result, grads = trace_checked(lens, collimated(heights, angle_deg=10.0, z=-1.0))
    assert counts(result) == {"backtracking (flagged)": 3}
    assert bool(result.valid.all())
    th0 = math.radians(10.0)
    th1 = math.asin(math.sin(th0) / n)
    expected = heights + 9 * math.tan(th0) + 7 * math.tan(th1)
    torch.testing.assert_close(result.pos[:, 1], expected, rtol=0, atol=1e-14)
    assert float(result.hits[2].t[0].detach()) < 0  # the backwards step, −2 / cos θ0
    torch.testing.assert_close(result.hits[2].t, torch.full_like(heights, -2 / math.cos(th0)), rtol=1e-14, atol=0)
    # d(image y)/d(gap) = tan θ0 for the negative gap too: the masked loss Σ y² gives 2 Σ y tan θ0.
    torch.testing.assert_close(grads["thickness"][1], 2 * expected.sum() * math.tan(th0), rtol=1e-12, atol=0)


def test_surfaces_crossing_inside_the_beam() -> None:
    # Biconvex "lens" with 1 mm centre thickness and R = ±10 mm (index 1 inside, so rays stay
    # straight): the surfaces cross where the sag R − sqrt(R² − y²) reaches 0.5 mm, at
    # y = sqrt(100 − 9.5²) = 3.1225 mm. Beyond that the rear surface lies before the front one.
    lens = make_lens([{"kind": "sphere", "c": 0.1, "t": 1.0}, {"kind": "sphere", "c": -0.1, "t": 5.0}],
                     index=[1.0, 1.0, 1.0])
    heights = torch.linspace(0.05, 4.95, 50, dtype=D)
    result, _ = trace_checked(lens, collimated(heights, z=-1.0))
    crossing = math.sqrt(100 - 9.5**2)
    assert abs(crossing - 3.1225) < 1e-4
    assert counts(result) == {"backtracking (flagged)": int((heights > crossing).sum())}
    assert bool((result.backtrack == (heights > crossing)).all())
    torch.testing.assert_close(result.pos[:, 1], heights, rtol=0, atol=1e-14)
