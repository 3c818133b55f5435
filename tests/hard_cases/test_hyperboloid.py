"""Conics with κ ≤ −1: a hyperboloid (κ = −3, two sheets) and a paraboloid (κ = −1), through the
closed-form quadric intersection and the Newton (asphere) path.

With c = 0.1/mm and κ = −3 the quadric c r² + c(1 + κ) z² − 2z = 0 has its vertex sheet through the
origin (the sag z(r) = c r²/(1 + sqrt(1 + 2 c² r²)) ≥ 0) and a second sheet with vertex at
z = 2/(c(1 + κ)) = −10 mm. Rays start at z = −50 mm, so the first crossing along the ray is the
second sheet; the trace must return the sag branch. Expected hits: the sag formula for rays parallel
to the axis, and scipy's brentq on sag(r(t)) − z(t) for tilted rays (independent of the trace)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.optimize import brentq

from tests.hard_cases.hard_tools import collimated, counts, make_lens, trace_checked

D = torch.float64
C = 0.1


def _sag(r: np.ndarray | float, k: float) -> np.ndarray | float:
    return C * r * r / (1 + np.sqrt(1 - (1 + k) * C * C * r * r))


def _lens(kind: str, k: float):
    extra = {"a": [0.0]} if kind == "asphere" else {}
    return make_lens([{"kind": kind, "c": C, "k": k, "t": 60.0, **extra}], index=[1.0, 1.5])


@pytest.mark.parametrize("kind", ["conic", "asphere"])
@pytest.mark.parametrize("k", [-3.0, -1.0])
def test_axial_rays_hit_the_sag_branch(kind: str, k: float) -> None:
    heights = torch.tensor([0.0, 1.0, 5.0, 10.0, 20.0, 30.0], dtype=D)  # sag ≤ 45 < 60 (image plane)
    result, _ = trace_checked(_lens(kind, k), collimated(heights, z=-50.0))
    assert counts(result) == {}
    z = result.hits[0].pos[:, 2]
    expected = torch.as_tensor(_sag(heights.numpy(), k))
    if k == -1.0:  # paraboloid: z = c r²/2 exactly
        torch.testing.assert_close(expected, C * heights**2 / 2, rtol=1e-15, atol=0)
    torch.testing.assert_close(z, expected, rtol=1e-13, atol=1e-13)
    assert bool((z >= 0).all())  # never the second sheet (z ≤ −10)


@pytest.mark.parametrize("kind", ["conic", "asphere"])
@pytest.mark.parametrize("k", [-3.0, -1.0])
def test_tilted_rays_hit_the_sag_branch_or_miss(kind: str, k: float) -> None:
    angle = math.radians(10.0)
    dy, dz = math.sin(angle), math.cos(angle)
    heights = torch.tensor([-30.0, -10.0, 0.0, 10.0, 30.0], dtype=D)
    result, _ = trace_checked(_lens(kind, k), collimated(heights, angle_deg=10.0, z=-50.0))
    # Paraboloid: c/2 (y0 + t dy)² = −50 + t dz is a quadratic in t with discriminant
    # (c y0 dy − dz)² − 2 c dy² (c y0²/2 + 50): negative for y0 = 30 (0.215 − 0.573): that ray passes
    # outside the bowl. The hyperboloid's vertex sheet is met by all five rays.
    misses = [k == -1.0 and (C * y0 * dy - dz) ** 2 - 2 * C * dy**2 * (C * y0**2 / 2 + 50) < 0
              for y0 in heights.tolist()]
    assert misses == ([False] * 4 + [True] if k == -1.0 else [False] * 5)
    # The closed form knows a miss; Newton on the asphere path cannot tell a miss from a failure to
    # converge (the sag is defined everywhere when κ ≤ −1), so it reports that reason.
    reason = "missed surface" if kind == "conic" else "Newton not converged"
    assert counts(result) == ({reason: 1} if k == -1.0 else {})
    for i, y0 in enumerate(heights.tolist()):
        if misses[i]:
            continue

        def f(t: float, y0: float = y0) -> float:
            return float(_sag(abs(y0 + t * dy), k)) - (-50.0 + t * dz)

        t = brentq(f, 45.0 / dz, 110.0 / dz, xtol=1e-14, rtol=1e-15)  # z from −5 (between sheets) to 60
        expected = torch.tensor([0.0, y0 + t * dy, -50.0 + t * dz], dtype=D)
        torch.testing.assert_close(result.hits[0].pos[i], expected, rtol=0, atol=1e-11)
