"""Ray initialization (S1.3.1): pupil sampling schemes and object-space ray bundles.

Relative pupil coordinates (px, py) lie in the unit disc and are scaled by EPD/2 on the paraxial
entrance pupil plane. Off-axis bundles travel upward (+y) in object space, so by symmetry about the
meridional (y–z) plane the ``rings`` and ``gauss`` schemes sample only the half pupil x ≥ 0 (Figure S1).

Schemes (``PupilSampling.parse``):

==================  ======  ==========================================================================
``rings:N``         N²      seed Figure S1: equal-area rings, jittered (seeded); what the seed optimizes
``rings:N:nojitter``N²      the same rings, not rotated
``grid:N``          ≈πN²/4  N×N cell-centred grid clipped to the disc, full pupil
``gauss:N``         2N²     N Gauss–Legendre radii (weight r dr) × 2N midpoint angles on (0, π): a
                            product quadrature with **unequal** weights (``PupilSampling.weights``),
                            exponentially convergent for a smooth pupil (the reference of
                            ``qa.accuracy``); symmetric in py, so an on-axis centroid is 0
==================  ======  ==========================================================================

``gauss`` rays do not stand for equal pupil areas: only the statistics that read
``Bundle.pupil_weights`` (spot sizes, centroids, distortion, relative illumination) may use it, so a
caller opts in with ``parse(..., weighted=True)``; PSFs and the optimizer's ray sets use equal weights.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from lensopt.engine import Engine
from lensopt.errors import SpecError
from lensopt.optics.lens import Lens, System
from lensopt.optics.trace import Rays

__all__ = ["PupilSampling", "DEFAULT_REPORT_SAMPLING", "pupil_rings", "pupil_grid", "pupil_gauss", "fan", "launch"]

DEFAULT_REPORT_SAMPLING = "gauss:16"
"""Pupil sampling of the reporting commands (``trace``, ``check``, the ``sweep`` tables, the ``optimize``
summary): 512 rays per field and wavelength (``rings:24`` traces 576); ESR within 1e-5 of the converged
quadrature on every shipped lens (``lensopt accuracy``; ``rings:24`` is 0.03–2.7 % off)."""


@dataclass(frozen=True)
class PupilSampling:
    """A pupil sampling scheme (see the module doc): ``rings:N`` (seed Figure S1, jittered, half pupil),
    ``rings:N:nojitter``, ``grid:N`` (full pupil) or ``gauss:N`` (weighted quadrature, half pupil)."""

    kind: str
    n: int
    jitter: bool = True
    seed: int = 0

    @classmethod
    def parse(cls, text: str, *, seed: int = 0, path: str = "sampling", weighted: bool = False) -> PupilSampling:
        """``weighted``: the caller passes ``weights()`` on (``trace_bundle(pupil_weights=...)``), so
        ``gauss:N`` is accepted; elsewhere it is refused with a message saying why."""
        m = re.fullmatch(r"(rings|grid|gauss):(\d+)(:nojitter)?", text.strip())
        if not m or int(m.group(2)) < 1 or (m.group(1) != "rings" and m.group(3)):
            allowed = "rings:N, rings:N:nojitter, grid:N or gauss:N" if weighted else \
                "rings:N, rings:N:nojitter or grid:N"
            raise SpecError(f"expected {allowed} with N ≥ 1", path=path, got=text)
        if m.group(1) == "gauss" and not weighted:
            raise SpecError("gauss:N weights its rays unequally, which only spot statistics use; here give "
                            "rings:N, rings:N:nojitter or grid:N", path=path, got=text)
        return cls(kind=m.group(1), n=int(m.group(2)), jitter=m.group(3) is None, seed=seed)

    @property
    def half(self) -> bool:
        """Whether only the half pupil x ≥ 0 is sampled (x̄ = 0 by symmetry)."""
        return self.kind in ("rings", "gauss")

    @property
    def count(self) -> int:
        """Rays per field and wavelength (``grid``: before clipping to the disc, an upper bound)."""
        return 2 * self.n**2 if self.kind == "gauss" else self.n**2

    def points(self, *, dtype: torch.dtype, device: torch.device | None = None, engine: Engine | None = None) -> Tensor:
        """(P, 2) relative pupil coordinates; refused (``LensoptError``) beyond the engine's memory budget."""
        (engine or Engine()).require(64 * self.count, f"{self} pupil sampling ({self.count:,} points)",
                                     lower="N of rings:N / grid:N / gauss:N")
        if self.kind == "rings":
            return pupil_rings(self.n, jitter=self.jitter, seed=self.seed, dtype=dtype, device=device)
        if self.kind == "gauss":
            return pupil_gauss(self.n, dtype=dtype, device=device)[0]
        return pupil_grid(self.n, dtype=dtype, device=device)

    def weights(self, *, dtype: torch.dtype, device: torch.device | None = None) -> Tensor | None:
        """(P,) pupil-area weights of ``points`` (mean 1), or None where every ray weighs the same."""
        if self.kind != "gauss":
            return None
        return pupil_gauss(self.n, dtype=dtype, device=device)[1]

    def __str__(self) -> str:
        suffix = ":nojitter" if self.kind == "rings" and not self.jitter else ""
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


def pupil_gauss(n: int, *, dtype: torch.dtype, device: torch.device | None = None) -> tuple[Tensor, Tensor]:
    """``gauss:N``: Gauss–Legendre radii r_i (i = 1..N, weight r dr on [0, 1]) × midpoint angles
    ψ_j = π(j + ½)/(2N) (j = 0..2N − 1) on the half pupil x ≥ 0, px = r sin ψ, py = r cos ψ.

    With the mirror x → −x the angles are the periodic trapezoid rule on the full circle, so the product
    rule integrates a smooth pupil function exponentially fast (``qa.accuracy``'s reference uses the
    same nodes). The angles come in pairs ψ, π − ψ built as exact mirrors py → −py, so an on-axis
    bundle's centroid is 0 to rounding.

    Returns:
        points: (2N², 2) (px, py), ring by ring from the centre.
        weights: (2N²,) pupil-area weights w_i·(π/2N), scaled to mean 1.
    """
    x, w = np.polynomial.legendre.leggauss(n)
    r = (x + 1.0) / 2.0
    wr = w / 2.0 * r  # ∫₀¹ f r dr
    psi = math.pi * (np.arange(n) + 0.5) / (2 * n)  # the upper quarter; the lower one mirrors it
    sin, cos = np.sin(psi), np.cos(psi)
    px = np.concatenate([sin, sin[::-1]])
    py = np.concatenate([cos, -cos[::-1]])
    pts = np.stack([r[:, None] * px[None, :], r[:, None] * py[None, :]], -1).reshape(-1, 2)
    wts = np.repeat(wr, 2 * n)
    wts = wts / wts.mean()
    return (torch.from_numpy(pts).to(dtype=dtype, device=device),
            torch.from_numpy(wts).to(dtype=dtype, device=device))


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
