"""Total internal reflection (glass → air beyond the critical angle arcsin(1/n)) and its diffractive
twin, an evanescent diffraction order (S18: |tangential direction| > 1). Both are counted under
``total internal reflection``; values and gradients stay finite."""

from __future__ import annotations

import math

import numpy as np
import torch

from tests.hard_cases.hard_tools import collimated, counts, make_lens, trace_checked

D = torch.float64
N = 1.5
RADIUS = -10.0  # rear surface of a plano-convex lens, centre of curvature at z = 11 − 10 = 1 mm


def _plano_convex():
    # Plane front at z = 0 (air → glass), sphere R = −10 mm at z = 11 (glass → air), image at z = 31.
    return make_lens([{"kind": "plane", "t": 11.0}, {"kind": "sphere", "c": 1 / RADIUS, "t": 20.0}],
                     index=[1.0, N, 1.0])


def test_tir_on_axis_beam_starts_at_the_critical_height() -> None:
    # Rays parallel to the axis meet the sphere at sin i = y/|R|: TIR exactly when y > |R|/n = 6.667 mm.
    heights = torch.linspace(0.05, 9.85, 99, dtype=D)
    result, _ = trace_checked(_plano_convex(), collimated(heights))
    expected = int((heights > abs(RADIUS) / N).sum())
    assert expected == 32
    assert counts(result) == {"total internal reflection": expected}
    assert bool((result.valid == (heights < abs(RADIUS) / N)).all())


def test_tir_of_a_tilted_beam_follows_the_critical_angle() -> None:
    # 10° field: the refraction at the plane gives sin θ1 = sin 10°/n inside the glass; the incidence
    # angle on the sphere then follows from the hit point P: cos i = |d1 · (P − C)| / |R|.
    heights = torch.linspace(-9.5, 9.5, 96, dtype=D)
    result, _ = trace_checked(_plano_convex(), collimated(heights, angle_deg=10.0))
    th0 = math.radians(10.0)
    s1 = math.sin(th0) / N
    d1 = np.array([s1, math.sqrt(1 - s1 * s1)])  # (y, z) direction in the glass
    expected = 0
    for y in heights.tolist():
        p = np.array([y + math.tan(th0), 0.0])  # on the plane z = 0 (the ray starts at z = −1)
        rel = p - np.array([0.0, 11.0 + RADIUS])
        b = rel @ d1
        t = -b + math.sqrt(b * b - (rel @ rel - RADIUS**2))  # the far root: the sag branch z > 1
        hit = rel + t * d1
        cos_i = abs(d1 @ hit) / abs(RADIUS)
        expected += N * math.sqrt(1 - cos_i**2) > 1.0
    assert 0 < expected < len(heights)
    assert counts(result) == {"total internal reflection": expected}


def test_evanescent_diffraction_order() -> None:
    # Flat diffractive surface in air, φ = d2 r²: the first order leaves with tangential direction
    # λ ∂φ/∂r / (2π) = λ d2 r / π, evanescent beyond r = π/(λ d2) = 2.6732 mm (λ = 0.5876 µm, d2 = 2000).
    d2 = 2000.0
    lens = make_lens([{"kind": "plane", "phase": [d2], "t": 1.0}], index=[1.0, 1.0])
    heights = torch.linspace(0.025, 4.975, 100, dtype=D)
    result, _ = trace_checked(lens, collimated(heights))
    r_crit = math.pi / (0.5876e-3 * d2)
    assert abs(r_crit - 2.6732) < 1e-4
    expected = int((heights > r_crit).sum())
    assert counts(result) == {"total internal reflection": expected}
    # The surviving rays obey the grating law: direction cosine M = λ d2 y / π (outward for d2 > 0).
    ok = result.valid
    torch.testing.assert_close(result.dir[ok, 1], 0.5876e-3 * d2 * heights[ok] / math.pi, rtol=0, atol=1e-15)
