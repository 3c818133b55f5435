"""Glass variables: whitening (S30), pruned Delaunay mesh and its distance (S55), catalog distance
(S56)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.optimize import minimize

from lensopt.materials import design_catalog
from lensopt.materials.catalog import _design
from lensopt.materials.glass_space import (
    GlassSpace,
    catalog_distance,
    glass_mesh,
    glass_space,
    mesh_distance,
    nearest_glass,
)


def _space(points: list[tuple[float, float]]) -> GlassSpace:
    """A 2D 'catalog' whose whitening is the identity, to test the mesh in known coordinates."""
    cat = _design("toy", [f"g{i}" for i in range(len(points))], [(x, y, 0.0) for x, y in points])
    pts = np.array(points, dtype=np.float64)
    return GlassSpace(catalog=cat, dims=2, W=np.eye(2), b=np.zeros(2), points=pts)


@pytest.mark.parametrize(("name", "dims"), [("ohara-recommended", 3), ("ohara-recommended", 2),
                                            ("schott-preferred", 3), ("plastics", 2)])
def test_whitening_gives_identity_weighted_covariance(name: str, dims: int) -> None:
    # By construction W = Σ_w^(-1/2): recompute the density weights independently and check that the
    # weighted covariance of g is the identity and its weighted mean zero.
    from scipy.spatial import cKDTree

    cat = design_catalog(name)
    sp = glass_space(cat, dims)
    x = cat.values[:, :dims]
    z = (x - x.mean(0)) / x.std(0)
    dist, _ = cKDTree(z).query(z, k=6)
    w = dist[:, -1] ** dims
    w /= w.sum()
    mean = w @ sp.points
    cov = (sp.points - mean).T @ ((sp.points - mean) * w[:, None])
    np.testing.assert_allclose(mean, 0.0, atol=1e-10)
    np.testing.assert_allclose(cov, np.eye(dims), atol=1e-10)
    # Round trip physical ↔ whitened.
    t = torch.tensor(x[:5], dtype=torch.float64)
    torch.testing.assert_close(sp.from_g(sp.to_g(t)), t, rtol=1e-12, atol=1e-12)


def test_long_edges_pruned_and_an_isolated_vertex_keeps_its_simplest_simplex() -> None:
    # Unit square (two triangles, longest edge √2) plus a far vertex at (5, 0.5): every triangle that
    # touches it has an edge > 1.5 and would be pruned; the rule keeps the one with the shortest
    # longest edge: (1,0), (1,1), (5,0.5) with longest edge √(16 + 0.25) = 4.03.
    sp = _space([(0, 0), (1, 0), (1, 1), (0, 1), (5, 0.5)])
    mesh = glass_mesh(sp, 1.5)
    kept = {tuple(sorted(s)) for s in mesh.simplices.tolist()}
    assert (1, 2, 4) in kept
    assert len(kept) == 3  # the square's two triangles plus the kept one
    # With a generous threshold nothing is pruned: the convex hull's triangulation (3 triangles).
    assert len(glass_mesh(sp, 10.0).simplices) == 3


def test_mesh_distance_2d_hand_values() -> None:
    sp = _space([(0, 0), (1, 0), (1, 1), (0, 1)])
    mesh = glass_mesh(sp, 2.0)
    g = torch.tensor([[0.5, 0.5], [0.2, 0.9], [1.5, 0.5], [-1.0, -1.0], [0.5, 3.0]], dtype=torch.float64)
    d = mesh_distance(g, mesh)
    # inside, inside, 0.5 right of the edge x = 1, √2 from the corner (0, 0), 2 above the edge y = 1.
    torch.testing.assert_close(d, torch.tensor([0.0, 0.0, 0.5, math.sqrt(2), 2.0], dtype=torch.float64))


def test_mesh_distance_3d_matches_a_numerical_minimisation() -> None:
    # Independent check: the distance to the union of kept tetrahedra by minimising |g − Σ λ_i v_i|
    # over barycentric λ ≥ 0, Σλ = 1 (scipy SLSQP), tetrahedron by tetrahedron.
    sp = glass_space(design_catalog("ohara-recommended"), 3)
    mesh = glass_mesh(sp, 1.25)
    rng = np.random.default_rng(1)
    g = rng.normal(scale=1.6, size=(4, 3))
    ours = mesh_distance(torch.tensor(g), mesh).numpy()
    for gi, di in zip(g, ours, strict=True):
        best = math.inf
        centres = [mesh.points[s].mean(0) for s in mesh.simplices]
        for i in np.argsort([np.linalg.norm(gi - c) for c in centres]):
            v = mesh.points[mesh.simplices[i]]
            if np.linalg.norm(gi - centres[i]) - np.linalg.norm(v - centres[i], axis=1).max() > best:
                continue  # this tetrahedron cannot be nearer than the best so far
            res = minimize(lambda lam, v=v, gi=gi: float(np.sum((lam @ v - gi) ** 2)), np.full(4, 0.25),
                           bounds=[(0, 1)] * 4, constraints=[{"type": "eq", "fun": lambda lam: lam.sum() - 1}],
                           method="SLSQP", options={"ftol": 1e-14, "maxiter": 200})
            best = min(best, math.sqrt(max(res.fun, 0.0)))
        assert di == pytest.approx(best, abs=2e-5)
    assert (ours > 0).any()


def test_mesh_distance_is_differentiable_and_finite_inside_and_out() -> None:
    sp = glass_space(design_catalog("ohara-recommended"), 3)
    mesh = glass_mesh(sp, 1.25)
    inside = torch.tensor(mesh.points[mesh.simplices[0]].mean(0), dtype=torch.float64)  # a simplex centroid
    g = torch.stack([inside, torch.tensor([4.0, -3.0, 2.0], dtype=torch.float64)])
    J = torch.func.jacfwd(lambda x: mesh_distance(x, mesh))(g)
    assert torch.isfinite(J).all()
    assert float(mesh_distance(g[:1], mesh)) == 0.0
    assert torch.equal(J[0], torch.zeros_like(J[0]))
    # Outside, the gradient is a unit vector (a distance function).
    grad = J[1, 1]
    assert float(torch.linalg.vector_norm(grad)) == pytest.approx(1.0, abs=1e-9)


def test_catalog_distance_and_nearest() -> None:
    sp = glass_space(design_catalog("plastics"), 2)
    g = torch.tensor(sp.points[[3, 7]], dtype=torch.float64) + torch.tensor([[0.01, 0.0], [0.0, -0.02]],
                                                                            dtype=torch.float64)
    d = catalog_distance(g, sp)
    brute = np.min(np.linalg.norm(g.numpy()[:, None] - sp.points[None], axis=-1), axis=1)
    np.testing.assert_allclose(d.numpy(), brute, rtol=1e-12)
    assert nearest_glass(g, sp) == [3, 7]


def test_mesh_distance_differentiates_only_the_nearest_facets_exactly() -> None:
    # mesh_distance takes its derivatives through the nearest facets only. Reference: the distance to
    # every boundary facet and its minimum (amin: the mean of the ties' derivatives), by jacfwd.
    from lensopt.materials.glass_space import _segment_distance, _triangle_distance

    def every_facet(g: torch.Tensor, mesh) -> torch.Tensor:  # noqa: ANN001
        pts = torch.as_tensor(mesh.points, dtype=g.dtype)
        fac = pts[torch.as_tensor(mesh.facets)]
        p = g[:, None, :]
        if fac.shape[1] == 2:
            dist = _segment_distance(p, fac[None, :, 0], fac[None, :, 1])
        else:
            dist = _triangle_distance(p, fac[None, :, 0], fac[None, :, 1], fac[None, :, 2])
        inside = mesh_distance(g.detach(), mesh) == 0
        return torch.where(inside, 0.0, dist.amin(-1))

    rng = np.random.default_rng(7)
    sq = glass_mesh(_space([(0, 0), (1, 0), (1, 1), (0, 1)]), 2.0)
    ohara = glass_mesh(glass_space(design_catalog("ohara-recommended"), 3), 1.25)
    # Two 2-D points equidistant from two edges (a tie: amin's derivative is the mean of the two).
    cases = [(sq, torch.tensor([[0.5, 0.5], [1.5, 0.5], [-1.0, -1.0], [2.0, 2.0], [0.5, -0.25]], dtype=torch.float64)),
             (ohara, torch.tensor(rng.normal(scale=1.6, size=(40, 3))))]
    for mesh, g in cases:
        assert torch.equal(mesh_distance(g, mesh), every_facet(g, mesh))
        J = torch.func.jacfwd(lambda x, m=mesh: mesh_distance(x, m))(g)
        ref = torch.func.jacfwd(lambda x, m=mesh: every_facet(x, m))(g)
        torch.testing.assert_close(J, ref, rtol=0, atol=1e-14)


def test_mesh_distance_under_vmap_and_reverse_mode() -> None:
    # A batch of glass sets (vmap over θ: no sizes from values) and reverse mode give the same numbers.
    mesh = glass_mesh(glass_space(design_catalog("ohara-recommended"), 3), 1.25)
    g = torch.tensor(np.random.default_rng(2).normal(scale=1.6, size=(3, 5, 3)))
    batched = torch.func.vmap(lambda x: mesh_distance(x, mesh))(g)
    assert torch.equal(batched, torch.stack([mesh_distance(x, mesh) for x in g]))
    x = g[0].clone().requires_grad_(True)
    mesh_distance(x, mesh).sum().backward()
    fwd = torch.func.jacfwd(lambda v: mesh_distance(v, mesh).sum())(g[0])
    torch.testing.assert_close(x.grad, fwd, rtol=0, atol=1e-14)
