"""Glass variables (S2.1.2, S2.2.4): the whitening transform of a design catalog, the pruned Delaunay
mesh of the catalog in whitened space, and the two distances the residuals use.

- Whitening (S30): ``g = W [nd, vd(, ΔPgF)] + b`` with W = Σ^(−1/2) (symmetric, "ZCA") of the
  catalog's weighted covariance. Weights grow with the volume each glass stands for (the distance to
  its k-th nearest neighbour, raised to the dimension), so sparse regions count more than dense ones.
- Mesh (S55): Delaunay simplices in g space; simplices with an edge longer than ``max_edge`` are
  removed, except that a vertex left with no simplex keeps its simplest one (the smallest longest
  edge). The distance of g to the mesh is 0 inside a simplex, else the distance to the nearest
  boundary facet (segment in 2D, triangle in 3D).
- Catalog distance (S56): distance to the nearest catalog glass.

Distances are pure torch functions of g (values and first derivatives finite everywhere), so they
sit inside the residual function under ``torch.func.jacfwd``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial import Delaunay, cKDTree
from torch import Tensor

from lensopt.errors import LensoptError
from lensopt.materials.catalog import DesignCatalog
from lensopt.transforms import capturing, carries_derivatives, vmapped

__all__ = ["GlassSpace", "GlassMesh", "glass_space", "glass_mesh", "mesh_distance", "catalog_distance",
           "nearest_glass"]


@dataclass(frozen=True, eq=False)
class GlassSpace:
    """A design catalog in whitened glass-variable space.

    Attributes:
        catalog: the design catalog.
        dims: 2 (nd, vd) or 3 (nd, vd, ΔPgF).
        W: (d, d) whitening matrix; b: (d,) offset: g = W x + b with x = (nd, vd[, ΔPgF]).
        points: (n, d) catalog glasses in g space.
    """

    catalog: DesignCatalog
    dims: int
    W: np.ndarray
    b: np.ndarray
    points: np.ndarray

    def to_g(self, x: Tensor) -> Tensor:
        """(…, d) physical glass values → (…, d) whitened variables."""
        W = torch.as_tensor(self.W, dtype=x.dtype, device=x.device)
        return x @ W.T + torch.as_tensor(self.b, dtype=x.dtype, device=x.device)

    def from_g(self, g: Tensor) -> Tensor:
        """(…, d) whitened variables → (…, d) physical (nd, vd[, ΔPgF])."""
        Winv = torch.as_tensor(np.linalg.inv(self.W), dtype=g.dtype, device=g.device)
        return (g - torch.as_tensor(self.b, dtype=g.dtype, device=g.device)) @ Winv.T

    def points_tensor(self, like: Tensor) -> Tensor:
        return torch.as_tensor(self.points, dtype=like.dtype, device=like.device)


def glass_space(catalog: DesignCatalog, dims: int, *, neighbours: int = 5) -> GlassSpace:
    """Fit the density-weighted whitening transform of ``catalog`` (S30)."""
    x = np.asarray(catalog.values[:, :dims], dtype=np.float64)
    n = x.shape[0]
    if n < dims + 1:
        raise LensoptError(f"design catalog {catalog.name} has {n} glasses; at least {dims + 1} are needed "
                           f"to fit {dims} glass variables", path="optimize.catalog")
    z = (x - x.mean(0)) / np.where(x.std(0) > 0, x.std(0), 1.0)
    k = min(neighbours, n - 1)
    dist, _ = cKDTree(z).query(z, k=k + 1)
    volume = np.maximum(dist[:, -1], 1e-12) ** dims
    w = volume / volume.sum()
    mu = w @ x
    cov = (x - mu).T @ ((x - mu) * w[:, None])
    evals, evecs = np.linalg.eigh(cov)
    if evals.min() <= 1e-14 * max(evals.max(), 1e-300):
        raise LensoptError(f"design catalog {catalog.name} is degenerate in {dims} glass variables "
                           "(use glass_parameters = 2)", path="optimize.glass_parameters")
    W = evecs @ np.diag(evals**-0.5) @ evecs.T
    b = -W @ mu
    return GlassSpace(catalog=catalog, dims=dims, W=W, b=b, points=x @ W.T + b)


@dataclass(frozen=True, eq=False)
class GlassMesh:
    """The pruned Delaunay mesh of a catalog in g space.

    Attributes:
        simplices: (K, d+1) vertex indices of the kept simplices.
        facets: (B, d) vertex indices of the boundary facets (faces of exactly one kept simplex).
        points: (n, d) vertices (the catalog in g space).
    """

    simplices: np.ndarray
    facets: np.ndarray
    points: np.ndarray


def glass_mesh(space: GlassSpace, max_edge: float) -> GlassMesh:
    """Delaunay mesh of the catalog with long-edge pruning and the keep-one-simplex rule (S55)."""
    pts = space.points
    tri = Delaunay(pts)
    simp = tri.simplices
    d = pts.shape[1]
    pairs = [(i, j) for i in range(d + 1) for j in range(i + 1, d + 1)]
    longest = np.max([np.linalg.norm(pts[simp[:, i]] - pts[simp[:, j]], axis=1) for i, j in pairs], axis=0)
    # Zero-volume simplices (slivers) cover nothing; leaving them out keeps the inverses finite.
    edges = np.stack([pts[simp[:, i + 1]] - pts[simp[:, 0]] for i in range(d)], axis=-1)
    solid = np.abs(np.linalg.det(edges)) > 1e-12
    keep = (longest <= max_edge) & solid
    for v in range(pts.shape[0]):
        mine = np.flatnonzero((simp == v).any(1) & solid)
        if mine.size and not keep[mine].any():
            keep[mine[np.argmin(longest[mine])]] = True
    kept = simp[keep]
    faces: dict[tuple[int, ...], int] = {}
    for s in kept:
        for skip in range(d + 1):
            key = tuple(sorted(int(v) for k, v in enumerate(s) if k != skip))
            faces[key] = faces.get(key, 0) + 1
    facets = np.array([f for f, c in faces.items() if c == 1], dtype=np.int64).reshape(-1, d)
    return GlassMesh(simplices=kept, facets=facets, points=pts)


def _norm(v: Tensor) -> Tensor:
    """Euclidean norm over the last axis with a finite derivative at 0."""
    return torch.sqrt((v * v).sum(-1).clamp_min(torch.finfo(v.dtype).tiny))


def _segment_distance(p: Tensor, a: Tensor, b: Tensor) -> Tensor:
    ab = b - a
    t = (((p - a) * ab).sum(-1) / (ab * ab).sum(-1).clamp_min(torch.finfo(p.dtype).tiny)).clamp(0.0, 1.0)
    return _norm(p - a - t.unsqueeze(-1) * ab)


def _triangle_distance(p: Tensor, a: Tensor, b: Tensor, c: Tensor) -> Tensor:
    """Distance from points p (…, 3) to triangles (a, b, c) (…, 3): the plane distance where the
    projection falls inside the triangle, else the nearest edge."""
    e0, e1, v = b - a, c - a, p - a
    d00, d01, d11 = (e0 * e0).sum(-1), (e0 * e1).sum(-1), (e1 * e1).sum(-1)
    d20, d21 = (v * e0).sum(-1), (v * e1).sum(-1)
    den = (d00 * d11 - d01 * d01).clamp_min(torch.finfo(p.dtype).tiny)
    s = (d11 * d20 - d01 * d21) / den
    t = (d00 * d21 - d01 * d20) / den
    inside = (s >= 0) & (t >= 0) & (s + t <= 1)
    proj = a + s.unsqueeze(-1) * e0 + t.unsqueeze(-1) * e1
    plane = _norm(p - proj)
    edges = torch.minimum(torch.minimum(_segment_distance(p, a, b), _segment_distance(p, b, c)),
                          _segment_distance(p, c, a))
    return torch.where(inside, plane, edges)


def mesh_distance(g: Tensor, mesh: GlassMesh) -> Tensor:
    """(G,) distance of glass variables g (G, d) to the mesh: 0 inside a kept simplex (S55)."""
    pts = torch.as_tensor(mesh.points, dtype=g.dtype, device=g.device)
    d = pts.shape[1]
    simp = pts[torch.as_tensor(mesh.simplices)]  # (K, d+1, d)
    v0 = simp[:, 0]
    T = (simp[:, 1:] - v0[:, None]).transpose(1, 2)  # (K, d, d)
    Tinv = torch.linalg.inv(T)
    lam = torch.einsum("kij,gkj->gki", Tinv, g[:, None, :] - v0[None])  # (G, K, d)
    tol = 1e-12
    inside = ((lam >= -tol).all(-1) & (lam.sum(-1) <= 1 + tol)).any(-1)  # (G,)
    fac = pts[torch.as_tensor(mesh.facets)]  # (B, d, d)

    def facet_distance(p: Tensor, f: Tensor) -> Tensor:
        if d == 2:
            return _segment_distance(p, f[..., 0, :], f[..., 1, :])
        return _triangle_distance(p, f[..., 0, :], f[..., 1, :], f[..., 2, :])

    # The distance is the minimum over every facet, found on the values; its derivatives are taken
    # through the nearest facets alone (a minimum's derivative is the mean of its ties', as amin's): on
    # the seed's 3-D mesh this spares forward mode ~180 facets per glass. ``low + (x − x)``: the value
    # of ``low``, bit for bit, with the tangent of x.
    plain = not carries_derivatives(g)
    if capturing() or vmapped(g.detach()):  # no sizes from data: every facet with its derivatives
        nearest = facet_distance(g[:, None, :], fac[None]).amin(-1)
        return torch.where(inside, torch.zeros_like(nearest), nearest)
    with torch.no_grad():
        dist = facet_distance(g.detach()[:, None, :], fac[None])  # (G, B)
        low = dist.amin(-1)
    if plain:
        return torch.where(inside, torch.zeros_like(low), low)
    with torch.no_grad():
        at = dist == low[:, None]
        ties = int(at.sum(-1).max()) if dist.shape[-1] else 1
        order = torch.sort((~at).to(torch.uint8), dim=-1, stable=True).indices[:, :ties]
        tie = torch.gather(at, 1, order)
    sub = facet_distance(g[:, None, :], fac[order])  # (G, ties)
    mean = sub[:, 0] if ties == 1 else torch.where(tie, sub, 0.0).sum(-1) / tie.sum(-1).to(g.dtype)
    nearest = low + (mean - mean.detach())
    return torch.where(inside, torch.zeros_like(nearest), nearest)


def catalog_distance(g: Tensor, space: GlassSpace) -> Tensor:
    """(G,) distance of glass variables g (G, d) to the nearest catalog glass (S56)."""
    pts = space.points_tensor(g)
    return _norm(g[:, None, :] - pts[None]).amin(-1)


def nearest_glass(g: Tensor, space: GlassSpace) -> list[int]:
    """Catalog index of the nearest glass to each row of g (G, d) (for binding)."""
    pts = space.points_tensor(g)
    return [int(i) for i in torch.cdist(g.detach(), pts).argmin(-1)]
