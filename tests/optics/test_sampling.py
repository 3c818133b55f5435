"""Pupil sampling schemes (seed S1.3.1, Figure S1) and the ``--sampling`` grammar.

Expected values are derived by hand from the definitions: ``rings:N`` puts 2i − 1 rays on ring
i = 1..N at radius i/N on the half pupil x ≥ 0 (N² rays in all, Figure S1); ``grid:N`` keeps the
cell-centred points −1 + (2i + 1)/N of an N×N grid inside the unit circle (issue 2).
"""

from __future__ import annotations

import math

import pytest
import torch

from lensopt.errors import SpecError
from lensopt.optics.sampling import PupilSampling, pupil_grid, pupil_rings

D = torch.float64


@pytest.mark.parametrize("n", [1, 2, 5, 24])
@pytest.mark.parametrize("jitter", [False, True])
def test_rings_layout(n: int, jitter: bool) -> None:
    pts = pupil_rings(n, jitter=jitter, seed=3, dtype=D)
    assert pts.shape == (n * n, 2)  # Σ_{i=1..N} (2i − 1) = N²
    radius = torch.linalg.vector_norm(pts, dim=-1)
    start = 0
    for i in range(1, n + 1):
        ring = slice(start, start + 2 * i - 1)
        torch.testing.assert_close(radius[ring], torch.full((2 * i - 1,), i / n, dtype=D), rtol=0, atol=1e-15)
        start += 2 * i - 1
    assert bool((pts[:, 0] >= 0).all()), "rings sample the half pupil x ≥ 0 only"


def test_rings_without_jitter_sit_at_cell_centres() -> None:
    # Ring i holds m = 2i − 1 rays at polar angles ψ_j = π (j + 1/2) / m from the +y axis.
    n = 4
    pts = pupil_rings(n, jitter=False, dtype=D)
    start = 0
    for i in range(1, n + 1):
        m = 2 * i - 1
        psi = torch.atan2(pts[start:start + m, 0], pts[start:start + m, 1])
        expected = torch.tensor([math.pi * (j + 0.5) / m for j in range(m)], dtype=D)
        torch.testing.assert_close(psi, expected, rtol=0, atol=1e-14)
        start += m


def test_ring_jitter_is_seeded_and_deterministic() -> None:
    a = pupil_rings(8, jitter=True, seed=7, dtype=D)
    b = pupil_rings(8, jitter=True, seed=7, dtype=D)
    c = pupil_rings(8, jitter=True, seed=8, dtype=D)
    plain = pupil_rings(8, jitter=False, dtype=D)
    assert torch.equal(a, b)
    assert not torch.equal(a, c)
    assert not torch.equal(a, plain)
    # Jitter rotates each ring by less than half a cell: radii are unchanged, angles stay in [0, π].
    torch.testing.assert_close(torch.linalg.vector_norm(a, dim=-1), torch.linalg.vector_norm(plain, dim=-1))
    assert bool((a[:, 0] >= -1e-15).all())
    # The same through the parsed scheme.
    s = PupilSampling.parse("rings:8", seed=7)
    assert torch.equal(s.points(dtype=D), a)
    assert torch.equal(PupilSampling.parse("rings:8:nojitter").points(dtype=D), plain)


@pytest.mark.parametrize(("n", "count"), [(1, 1), (2, 4), (3, 9), (4, 12), (5, 21)])
def test_grid_counts(n: int, count: int) -> None:
    # By hand: N=4 has coordinates ±1/4, ±3/4 and drops the 4 corners (3/4)²·2 = 9/8 > 1;
    # N=5 has 0, ±2/5, ±4/5 and drops the 4 corners (4/5)²·2 = 32/25 > 1; N ≤ 3 keeps every point.
    pts = pupil_grid(n, dtype=D)
    assert pts.shape == (count, 2)


@pytest.mark.parametrize("n", [4, 7, 41])
def test_grid_points_are_the_cell_centres_inside_the_circle(n: int) -> None:
    pts = pupil_grid(n, dtype=D)
    coords = [-1.0 + (2 * i + 1) / n for i in range(n)]
    expected = {(x, y) for y in coords for x in coords if x * x + y * y <= 1.0}
    got = {(float(x), float(y)) for x, y in pts}
    assert len(got) == len(pts)
    assert got == expected


def test_parse_roundtrip_and_half_pupil() -> None:
    assert str(PupilSampling.parse("rings:24")) == "rings:24"
    assert str(PupilSampling.parse(" rings:6:nojitter ")) == "rings:6:nojitter"
    assert str(PupilSampling.parse("grid:41")) == "grid:41"
    assert PupilSampling.parse("rings:3").half and not PupilSampling.parse("grid:3").half


@pytest.mark.parametrize("text", ["rings", "rings:0", "grid:0", "grid:5:nojitter", "ring:5", "rings:-2", "rings:2.5",
                                  "", "grid:x"])
def test_parse_rejects_bad_schemes(text: str) -> None:
    with pytest.raises(SpecError) as info:
        PupilSampling.parse(text, path="--sampling")
    msg = str(info.value)
    assert msg.startswith("--sampling: ")
    assert f"(got {text!r})" in msg


# ------------------------------------------------------------------------------------------- gauss:N


@pytest.mark.parametrize("n", [1, 3, 16])
def test_gauss_layout_is_legendre_radii_times_midpoint_angles(n: int) -> None:
    import numpy as np

    from lensopt.optics.sampling import pupil_gauss

    pts, w = pupil_gauss(n, dtype=D)
    assert pts.shape == (2 * n * n, 2) and w.shape == (2 * n * n,)
    # Radii: the Gauss–Legendre nodes of [−1, 1] mapped to [0, 1] (numpy's leggauss, the definition).
    nodes = (np.polynomial.legendre.leggauss(n)[0] + 1) / 2
    r = torch.linalg.vector_norm(pts, dim=-1).reshape(n, 2 * n)
    torch.testing.assert_close(r, torch.tensor(nodes, dtype=D)[:, None].expand(n, 2 * n), rtol=0, atol=1e-15)
    # Angles from +y: the midpoints π (j + ½) / 2N of 2N equal cells on (0, π), each ring the same.
    psi = torch.atan2(pts[:, 0], pts[:, 1]).reshape(n, 2 * n).sort(-1).values
    expected = torch.tensor([math.pi * (j + 0.5) / (2 * n) for j in range(2 * n)], dtype=D)
    torch.testing.assert_close(psi, expected.expand(n, 2 * n), rtol=0, atol=1e-14)
    assert bool((pts[:, 0] > 0).all()), "the half pupil x > 0"
    # Exact mirror pairs py → −py (what makes an on-axis centroid 0): the multiset of py is symmetric.
    assert torch.equal(pts[:, 1].sort().values, (-pts[:, 1]).sort().values)
    assert float(w.mean()) == pytest.approx(1.0, abs=1e-15)


@pytest.mark.parametrize("k", [0, 1, 2, 3, 5])
def test_gauss_weights_integrate_disc_moments_exactly(k: int) -> None:
    # Closed form: the disc average of ρ^2k is ∫₀¹ ρ^2k 2ρ dρ = 1/(k + 1); of py² it is 1/4 (= ⟨ρ²⟩/2).
    # gauss:N integrates ρ^2k·ρ exactly while 2k + 1 ≤ 2N − 1 (Gauss–Legendre with N nodes).
    from lensopt.optics.sampling import pupil_gauss

    pts, w = pupil_gauss(max(k + 1, 2), dtype=D)  # py² = ρ² cos²ψ needs N ≥ 2
    rho2 = (pts**2).sum(-1)
    assert float((w * rho2**k).mean()) == pytest.approx(1 / (k + 1), rel=1e-13)
    assert float((w * pts[:, 1] ** 2).mean()) == pytest.approx(0.25, rel=1e-13)
    # Equal-weight rings are not exact: rings:24 overstates ⟨ρ²⟩ (its outer ring sits on the rim).
    rings = pupil_rings(24, jitter=False, dtype=D)
    assert float((rings**2).sum(-1).mean()) > 0.5 * (1 + 1e-3)


def test_gauss_is_only_parsed_where_weights_are_used() -> None:
    s = PupilSampling.parse("gauss:16", weighted=True)
    assert (s.kind, s.n, s.half, s.count, str(s)) == ("gauss", 16, True, 512, "gauss:16")
    assert s.weights(dtype=D) is not None and PupilSampling.parse("rings:4").weights(dtype=D) is None
    with pytest.raises(SpecError, match=r"^--rays: gauss:N weights its rays unequally.*\(got 'gauss:16'\)"):
        PupilSampling.parse("gauss:16", path="--rays")
    with pytest.raises(SpecError, match="gauss:N with N ≥ 1"):
        PupilSampling.parse("gauss:16:nojitter", weighted=True)
