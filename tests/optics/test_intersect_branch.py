"""Quadric intersection picks the sag branch even when a ray starts beyond the centre of curvature.

Regression test: rays launched on an entrance pupil that lies behind surface 1's centre of curvature
(the double Gauss of ``specs/double_gauss.toml``: EP at z = 57.9 mm, R1 = 56.2 mm) used to get the
far-side root of the sphere and were all reported as missed.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from lensopt.optics.bundle import trace_bundle
from lensopt.optics.intersect import intersect_quadric
from lensopt.optics.sampling import pupil_grid
from lensopt.optics.trace import Status
from lensopt.spec import build, load_spec

SPECS = Path(__file__).resolve().parents[2] / "specs"


@pytest.mark.parametrize("conic", [0.0, -0.5, 0.8, -2.0])
@pytest.mark.parametrize("start_z", [5.0, 15.0, 40.0])
def test_sag_branch_root_from_any_start(conic: float, start_z: float) -> None:
    # Hand derivation: on the line x = 0, y = h the conic c h² + c(1+κ) z² − 2 z = 0 has the sag-branch
    # solution z = c h² / (1 + sqrt(1 − (1+κ) c² h²)); the ray (0, h, z0) + t (0, 0, 1) meets it at
    # t = z − z0, whatever side of the centre of curvature (z = R = 10 mm) it starts from.
    c, h = 0.1, 2.0
    z_sag = c * h * h / (1 + math.sqrt(1 - (1 + conic) * c * c * h * h))
    pos = torch.tensor([[0.0, h, start_z]], dtype=torch.float64)
    d = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)
    t, hit = intersect_quadric(pos, d, torch.tensor(c, dtype=torch.float64), torch.tensor(conic, dtype=torch.float64))
    assert bool(hit[0])
    assert float(t[0]) == pytest.approx(z_sag - start_z, abs=1e-12)


def test_oblique_ray_from_behind_centre() -> None:
    # Sphere R = 10: a ray from (0, 0, 15) with direction (0, sin a, cos a), a = 10°. Sag-branch point
    # solved by hand: y = (z − 15) tan a on x² + y² + (z − 10)² = 100 near the vertex (bisection).
    c, a = 0.1, math.radians(10.0)
    d = torch.tensor([[0.0, math.sin(a), math.cos(a)]], dtype=torch.float64)
    pos = torch.tensor([[0.0, 0.0, 15.0]], dtype=torch.float64)
    lo, hi = -15.0, 0.0  # f(t) = |p + t d − (0,0,10)|² − 100 changes sign between the two crossings

    def f(t: float) -> float:
        y, z = t * math.sin(a), 15.0 + t * math.cos(a)
        return y * y + (z - 10.0) ** 2 - 100.0

    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) > 0 else (lo, mid)
    t, hit = intersect_quadric(pos, d, torch.tensor(c, dtype=torch.float64), torch.tensor(0.0, dtype=torch.float64))
    assert bool(hit[0]) and float(t[0]) == pytest.approx(lo, abs=1e-10)


def test_double_gauss_traces_without_failures() -> None:
    model = build(load_spec(SPECS / "double_gauss.toml"))
    bundle = trace_bundle(model.lens, model.system, pupil_grid(11, dtype=torch.float64))
    assert float(bundle.first_order.entrance_pupil_z) > 1.0 / float(model.lens.curvature[0])
    assert int((bundle.result.status != Status.OK).sum()) == 0
