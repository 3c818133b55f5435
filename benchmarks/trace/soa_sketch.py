"""A *reference ceiling*, not lensopt's trace: spheres + vector Snell written component-wise.

``lensopt.optics.trace`` keeps vectors as ``[..., 3]`` tensors (STYLE rule 2). Under
``torch.compile`` on CPU, Inductor then materializes an (N, 3) buffer per surface step and runs
scalar loops over the rays (the inner dimension of 3 is what it tries to vectorize). This sketch
traces the same rays through the same spheres with x, y, z as separate (N,) tensors, which
Inductor fuses into SIMD loops over the rays. It handles spheres only and has no failure masks:
it exists to measure what a component-wise formulation of the trace would give
on the machine the benchmark runs on (the DESIGN.md "Speed" measurement), in the same run.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from lensopt.optics.lens import Lens
from lensopt.optics.trace import Rays


def _sketch(x: Tensor, y: Tensor, z: Tensor, dx: Tensor, dy: Tensor, dz: Tensor, n1: Tensor,
            curvature: Tensor, vertex_z: Tensor, n_after: Tensor) -> tuple[Tensor, Tensor]:
    for s in range(curvature.shape[0]):
        c = curvature[s]
        pz = z - vertex_z[s]
        b = dz - c * (x * dx + y * dy + pz * dz)
        cc = c * (x * x + y * y + pz * pz) - 2.0 * pz
        root = torch.sqrt((b * b - c * cc).clamp_min(0.0))
        t = cc / (b + torch.where(b >= 0, root, -root))
        x, y, pz = x + t * dx, y + t * dy, pz + t * dz
        nx, ny, nz = -c * x, -c * y, 1.0 - c * pz
        cos_i = dx * nx + dy * ny + dz * nz
        n2 = n_after[s]
        mu = n1 / n2
        g = torch.sqrt((1.0 - mu * mu * (1.0 - cos_i * cos_i)).clamp_min(0.0)) - mu * cos_i
        dx, dy, dz = mu * dx + g * nx, mu * dy + g * ny, mu * dz + g * nz
        z, n1 = pz + vertex_z[s], n2
    t = (vertex_z[-1] - z) / dz
    return x + t * dx, y + t * dy


def sketch_runner(lens: Lens, rays: Rays) -> Callable[[], Tensor]:
    """Compiled sketch on (N,) ray batches of a lens of spheres; returns (N, 2) image x, y."""
    if any(s.kind != "sphere" or s.diffractive for s in lens.shapes):
        raise ValueError("the sketch handles spheres only")
    wl = rays.wavelength
    args = (*rays.pos.T.contiguous(), *rays.dir.T.contiguous(), lens.index[0][wl].contiguous(),
            lens.curvature, lens.vertex_z(), lens.index[1:][:, wl].contiguous())
    fn = torch.compile(_sketch, fullgraph=True)
    return lambda: torch.stack(fn(*args), -1)
