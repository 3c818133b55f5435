"""Surface profiles (seed S2.1.3–S2.1.4): sag, its slope, normals and diffractive phase gradients.

All profiles are functions of ``u = r² = x² + y²`` so that nothing divides by ``r`` (stable at the
vertex, r = 0). Units: lengths in mm, curvature in 1/mm, phase in radians.

Sag (S31, S33)::

    z(u) = c u / (1 + sqrt(1 − (1 + κ) c² u)) + Σ_i a_{2i} u^i        (i = 2, 3, …)

defined where ``1 − (1 + κ) c² u ≥ 0`` (everywhere when κ ≤ −1 or c = 0).
"""

from __future__ import annotations

import torch
from torch import Tensor

from lensopt.transforms import capturing

__all__ = ["sag", "phase_slope", "normal_from_slope", "normal_xyz", "conic_normal_xyz", "sag_domain"]


def sag_domain(u: Tensor, c: Tensor, k: Tensor) -> Tensor:
    """``1 − (1 + κ) c² u``: the sag is defined where this is ≥ 0.

    Args:
        u: (*) squared radial coordinate r², mm².
        c: () or broadcastable, curvature 1/mm.
        k: () or broadcastable, conic constant.
    """
    return 1.0 - (1.0 + k) * c * c * u


def sag(u: Tensor, c: Tensor, k: Tensor, asphere: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor]:
    """Sag ``z(u)``, its slope ``dz/du`` and the definition mask, with finite values everywhere.

    Args:
        u: (*) squared radial coordinate r², mm².
        c: curvature 1/mm, broadcastable to ``u``.
        k: conic constant, broadcastable to ``u``.
        asphere: (A,) even-asphere coefficients ``a4, a6, …, a_{2A+2}`` (mm^(1−2i)), or None.

    Returns:
        z: (*) sag in mm (placeholder value where undefined).
        dz_du: (*) slope with respect to u, 1/mm.
        defined: (*) bool, False where the conic square root would be negative.
    """
    q = sag_domain(u, c, k)
    defined = q >= 0
    # The square root never sees an argument below machine epsilon, so neither values nor
    # gradients become NaN or infinite on undefined rows or exactly at an ellipsoid's rim.
    floor = torch.finfo(u.dtype).eps
    root = torch.sqrt(torch.where(q > floor, q, floor))
    z = c * u / (1.0 + root)
    dz_du = c / (2.0 * root)
    if asphere is not None and asphere.shape[-1] > 0:
        z_a, dz_a = _even_polynomial(u, asphere, first_power=2)
        z = z + z_a
        dz_du = dz_du + dz_a
    return z, dz_du, defined


def phase_slope(u: Tensor, phase: Tensor) -> Tensor:
    """``dφ/du`` of the diffractive phase ``φ(r) = Σ_i d_{2i} r^{2i}`` (S35), i = 1, 2, ….

    Using ``dφ/du`` instead of ``dφ/dr`` keeps the phase gradient finite at r = 0 (S16–S17):
    ``∇φ = 2 (dφ/du) (x, y)``.

    Args:
        u: (*) r² in mm².
        phase: (D,) coefficients ``d2, d4, …`` in rad/mm^(2i).
    """
    _, slope = _even_polynomial(u, phase, first_power=1)
    return slope


def normal_from_slope(xy: Tensor, dz_du: Tensor) -> Tensor:
    """Unit surface normal ``∝ (−∂z/∂x, −∂z/∂y, 1)`` (S14), oriented towards +z.

    Args:
        xy: (*, 2) transverse coordinates, mm.
        dz_du: (*) sag slope with respect to u = r².

    Returns:
        (*, 3) unit normals.
    """
    return torch.stack(normal_xyz(xy[..., 0], xy[..., 1], dz_du), -1)


def conic_normal_xyz(x: Tensor, y: Tensor, z: Tensor, c: Tensor, k: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Unit normal of the conic ``c(x² + y²) + c(1 + κ) z² − 2z = 0`` at a point on it, towards +z.

    ``−∇F/2 = (−c x, −c y, 1 − (1 + κ) c z)``: no square root of the sag formula, finite at the rim
    of an ellipsoid (where the slope form diverges), and already unit length on a sphere.
    """
    nx, ny, nz = -c * x, -c * y, 1.0 - (1.0 + k) * c * z
    inv = torch.rsqrt(nx * nx + ny * ny + nz * nz)
    return nx * inv, ny * inv, nz * inv


def normal_xyz(x: Tensor, y: Tensor, dz_du: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """``normal_from_slope`` on components: (nx, ny, nz) of shape (*) from x, y and dz/du."""
    gx, gy = -2.0 * dz_du * x, -2.0 * dz_du * y
    inv = torch.rsqrt(1.0 + gx * gx + gy * gy)
    return gx * inv, gy * inv, inv


def _even_polynomial(u: Tensor, coeffs: Tensor, first_power: int) -> tuple[Tensor, Tensor]:
    """``p(u) = Σ_j coeffs[j] u^(first_power + j)`` and ``dp/du``.

    Eager: the powers of u in one running product and two matrix–vector products (a handful of
    operations whatever the number of coefficients: the eager trace is bound by the count of
    operations, not their size). Inside a captured graph (``torch.compile``, ``make_fx``): Horner's
    scheme, elementwise, which the compiler fuses into the trace's loop. The same values to rounding.
    """
    n = coeffs.shape[-1]
    if coeffs.dim() == 1 and not capturing():
        top = first_power + n - 1
        powers = torch.cat([torch.ones_like(u).unsqueeze(-1), u.unsqueeze(-1).expand(*u.shape, top)], -1).cumprod(-1)
        k = torch.arange(first_power, first_power + n, dtype=coeffs.dtype, device=coeffs.device)
        return powers[..., first_power:] @ coeffs, powers[..., first_power - 1:top] @ (k * coeffs)
    # Horner on q(u) = Σ_j coeffs[j] u^j, then p = u^first_power q, p' = u^(fp−1)(fp q + u q').
    q = torch.zeros_like(u)
    dq = torch.zeros_like(u)
    for j in range(n - 1, -1, -1):
        dq = dq * u + q
        q = q * u + coeffs[..., j]
    upow = u ** (first_power - 1) if first_power > 1 else torch.ones_like(u)
    value = upow * u * q
    slope = upow * (first_power * q + u * dq)
    return value, slope
