"""Ray initialization (S1.3.1): pupil sampling schemes and object-space ray bundles.

Relative pupil coordinates (px, py) lie in the unit disc and are scaled by EPD/2 on the paraxial
entrance pupil plane. Off-axis bundles travel upward (+y) in object space, so by symmetry about the
meridional (y–z) plane the ``rings`` scheme samples only the half pupil x ≥ 0 (Figure S1).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.engine import Engine
from lensopt.errors import SpecError
from lensopt.optics.lens import Lens, System
from lensopt.optics.trace import Rays

__all__ = ["PupilSampling", "pupil_rings", "pupil_grid", "fan", "launch"]


@dataclass(frozen=True)
class PupilSampling:
    """A pupil sampling scheme: ``rings:N`` (seed Figure S1, jittered, half pupil), ``rings:N:nojitter``
    or ``grid:N`` (N×N cell-centred points clipped to the unit circle, full pupil)."""

    kind: str
    n: int
    jitter: bool = True
    seed: int = 0

    @classmethod
    def parse(cls, text: str, *, seed: int = 0, path: str = "sampling") -> PupilSampling:
        m = re.fullmatch(r"(rings|grid):(\d+)(:nojitter)?", text.strip())
        if not m or int(m.group(2)) < 1 or (m.group(1) == "grid" and m.group(3)):
            raise SpecError("expected rings:N, rings:N:nojitter or grid:N with N ≥ 1", path=path, got=text)
        return cls(kind=m.group(1), n=int(m.group(2)), jitter=m.group(3) is None, seed=seed)

    @property
    def half(self) -> bool:
        """Whether only the half pupil x ≥ 0 is sampled (x̄ = 0 by symmetry)."""
        return self.kind == "rings"

    def points(self, *, dtype: torch.dtype, device: torch.device | None = None, engine: Engine | None = None) -> Tensor:
        """(P, 2) relative pupil coordinates; refused (``LensoptError``) beyond the engine's memory budget."""
        (engine or Engine()).require(64 * self.n**2, f"{self} pupil sampling ({self.n**2:,} points)",
                                     lower="N of rings:N / grid:N")
        if self.kind == "rings":
            return pupil_rings(self.n, jitter=self.jitter, seed=self.seed, dtype=dtype, device=device)
        return pupil_grid(self.n, dtype=dtype, device=device)

    def __str__(self) -> str:
        suffix = "" if self.jitter or self.kind == "grid" else ":nojitter"
        return f"{self.kind}:{self.n}{suffix}"


def pupil_rings(
    n_rings: int, *, jitter: bool = True, seed: int = 0, dtype: torch.dtype, device: torch.device | None = None
) -> Tensor:
    """Seed Figure S1: ring i = 1..N at radius i/N holds 2i − 1 rays on the half pupil x ≥ 0.

    Every ray stands for the same pupil area (π/2)/N², and the outer ring samples the pupil edge.
    Rays sit at the centres of equal angular cells; with ``jitter`` each ring is rotated by a random
    fraction of its cell (seeded), which removes the aliasing of aligned rings.

    Returns:
        (N², 2) points (px, py) with px ≥ 0.
    """
    gen = torch.Generator().manual_seed(seed)
    pts = []
    for i in range(1, n_rings + 1):
        m = 2 * i - 1
        shift = float(torch.rand((), generator=gen, dtype=torch.float64)) - 0.5 if jitter else 0.0
        j = torch.arange(m, dtype=torch.float64)
        psi = math.pi * (j + 0.5 + shift) / m
        r = i / n_rings
        pts.append(torch.stack([r * torch.sin(psi), r * torch.cos(psi)], -1))
    return torch.cat(pts).to(dtype=dtype, device=device)


def pupil_grid(n: int, *, dtype: torch.dtype, device: torch.device | None = None) -> Tensor:
    """``grid:N``: cell-centred px, py = −1 + (2i + 1)/N, kept where px² + py² ≤ 1 (equal weights).

    Returns:
        (P, 2) points, row-major in (py, px).
    """
    c = -1.0 + (2.0 * torch.arange(n, dtype=torch.float64) + 1.0) / n
    py, px = torch.meshgrid(c, c, indexing="ij")
    keep = px**2 + py**2 <= 1.0 + 1e-12
    return torch.stack([px[keep], py[keep]], -1).to(dtype=dtype, device=device)


def fan(n: int, axis: str, *, dtype: torch.dtype, device: torch.device | None = None) -> Tensor:
    """Ray-fan pupil points: ``tangential`` py ∈ [−1, 1] (px = 0), ``sagittal`` px ∈ [0, 1] (py = 0)."""
    if axis == "tangential":
        v = torch.linspace(-1.0, 1.0, n, dtype=torch.float64)
        pts = torch.stack([torch.zeros_like(v), v], -1)
    elif axis == "sagittal":
        v = torch.linspace(0.0, 1.0, n, dtype=torch.float64)
        pts = torch.stack([v, torch.zeros_like(v)], -1)
    else:
        raise ValueError(f"fan axis must be tangential or sagittal, got {axis!r}")
    return pts.to(dtype=dtype, device=device)


def launch(
    lens: Lens,
    system: System,
    pupil: Tensor,
    tan_field: Tensor,
    *,
    epd: Tensor,
    entrance_pupil_z: Tensor,
    tan_field_x: Tensor | None = None,
) -> Rays:
    """Object-space rays through relative pupil points for each field and wavelength (S1.3.1).

    Infinite object: rays start on the entrance pupil plane at (px, py)·EPD/2 with direction
    (0, sin θ, cos θ). Finite object: rays start at the object point (0, h, −distance), with
    h = −tan θ (z_EP + distance), and aim at the pupil point.

    Args:
        pupil: (F, W, P, 2) or broadcastable relative pupil coordinates, already shaped by any
            vignetting factors or aiming offsets.
        tan_field: (F,) object-space chief-ray slopes.
        epd: () entrance pupil diameter, mm.
        entrance_pupil_z: () entrance pupil position from surface 1, mm.
        tan_field_x: (F,) object-space slopes in x for two-dimensional fields (non-symmetric lenses);
            None: 0. The direction is then ∝ (tan θ_x, tan θ_y, 1), the object point at
            (−tan θ_x, −tan θ_y)·(z_EP + distance).

    Returns:
        Rays of batch shape (F, W, P); ``wavelength`` has shape (1, W, 1).
    """
    num_w = lens.wavelength_um.shape[0]
    pupil = pupil.expand(tan_field.shape[0], num_w, pupil.shape[-2], 2)
    radius = epd / 2
    x = pupil[..., 0] * radius
    y = pupil[..., 1] * radius
    z = torch.zeros_like(x) + entrance_pupil_z
    target = torch.stack([x, y, z], -1)
    tan = tan_field[:, None, None]
    tan_x = None if tan_field_x is None else tan_field_x[:, None, None]
    if system.object_distance is None:
        if tan_x is None:
            cos = 1.0 / torch.sqrt(1.0 + tan * tan)
            d = torch.stack([torch.zeros_like(cos), tan * cos, cos], -1).expand_as(target)
        else:
            cos = 1.0 / torch.sqrt(1.0 + tan * tan + tan_x * tan_x)
            d = torch.stack([tan_x * cos, tan * cos, cos], -1).expand_as(target)
        pos = target
    else:
        z_obj = -system.object_distance
        h = -tan * (entrance_pupil_z - z_obj)
        hx = torch.zeros_like(h) if tan_x is None else -tan_x * (entrance_pupil_z - z_obj)
        obj = torch.stack([hx, h, torch.zeros_like(h) + z_obj], -1)
        d = target - obj
        d = d / torch.linalg.vector_norm(d, dim=-1, keepdim=True)
        pos = obj.expand_as(target)
    wavelength = torch.arange(num_w, device=pupil.device).view(1, num_w, 1)
    return Rays(pos=pos, dir=d, wavelength=wavelength)
