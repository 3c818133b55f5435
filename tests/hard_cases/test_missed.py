"""Rays that miss a surface: a sphere smaller than the beam. A ray parallel to the axis at height y
meets a sphere of radius R only if y ≤ R; a tilted ray meets the sag branch (the hemisphere on the
vertex side, z ≤ R for c > 0) only if its line passes within R of the centre and one of the two
crossings lies on that hemisphere — computed independently below with numpy."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tests.hard_cases.hard_tools import collimated, counts, make_lens, trace_checked

D = torch.float64
R = 5.0


def _small_sphere(kind: str):
    extra = {"a": [0.0]} if kind == "asphere" else {}
    return make_lens([{"kind": kind, "c": 1 / R, "t": 8.0, **extra}, {"kind": "plane", "t": 10.0}],
                     index=[1.0, 1.5, 1.0])


@pytest.mark.parametrize("kind", ["sphere", "asphere"])
def test_collimated_beam_wider_than_the_sphere(kind: str) -> None:
    heights = torch.linspace(-6.95, 6.95, 140, dtype=D)
    result, grads = trace_checked(_small_sphere(kind), collimated(heights, z=-1.0))
    expected = int((heights.abs() > R).sum())
    assert expected == 40
    assert counts(result) == {"missed surface": expected}
    assert bool((result.valid == (heights.abs() < R)).all())
    # Missed rows keep finite placeholders: their start position and a forward direction.
    missed = ~result.valid
    torch.testing.assert_close(result.pos[missed, 1], heights[missed])
    assert bool((result.dir[missed] == torch.tensor([0.0, 0.0, 1.0], dtype=D)).all())
    assert float(grads["curvature"].abs().sum()) > 0  # the surviving rays still carry gradient


def _expected_hits(y0: np.ndarray, angle: float) -> np.ndarray:
    d = np.array([np.sin(angle), np.cos(angle)])  # (y, z)
    p = np.stack([y0, np.full_like(y0, -1.0)], -1)  # rays start at z = −1
    rel = p - np.array([0.0, R])  # from the centre (0, R)
    b = rel @ d
    disc = b * b - (np.einsum("ij,ij->i", rel, rel) - R * R)
    hit = np.zeros(len(y0), dtype=bool)
    for i in range(len(y0)):
        if disc[i] < 0:
            continue
        for t in (-b[i] - np.sqrt(disc[i]), -b[i] + np.sqrt(disc[i])):
            if p[i, 1] + t * d[1] <= R:  # crossing on the vertex hemisphere
                hit[i] = True
    return hit


@pytest.mark.parametrize("angle_deg", [20.0, -35.0])
def test_tilted_beam_misses_where_the_geometry_says(angle_deg: float) -> None:
    heights = torch.linspace(-9.9, 9.9, 199, dtype=D)
    result, _ = trace_checked(_small_sphere("sphere"), collimated(heights, angle_deg=angle_deg, z=-1.0))
    hits = _expected_hits(heights.numpy(), np.radians(angle_deg))
    assert 0 < hits.sum() < len(hits)
    status0 = torch.tensor(~hits)
    assert counts(result).get("missed surface", 0) == int(status0.sum())
    assert bool(((result.status == 1) == status0).all())
