"""Vignetting factors (S1.3.2, S19–S20): reshape the unit entrance-pupil disc per field and wavelength.

With V_i, V_s, V_l the blocked fractions of the inferior (lower, −y), superior (upper, +y) and lateral
pupil halves::

    x' = (1 − V_l) x,     y' = (1 − (V_i + V_s)/2) y + (V_i − V_s)/2

so that the pupil spans y' ∈ [−1 + V_i, 1 − V_s], as the seed's text says ("V_i = 1, V_s = 0: light
passes through the centre and top, blocked between bottom and centre") and as CODE V's VLY/VUY do.
The printed S20 has the last term as (V_s − V_i)/2, which contradicts that text; we follow the text.
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = [
    "apply_vignetting",
    "factors_to_ellipse",
    "ellipse_to_factors",
    "compose_factors",
    "front_aperture_disc",
    "clip_ellipse_to_disc",
    "outside_front_aperture",
]


def apply_vignetting(pupil: Tensor, factors: Tensor) -> Tensor:
    """Apply S19–S20 (sign of S20's offset as in the seed's text, see the module doc) to pupil coordinates.

    Args:
        pupil: (F, W, P, 2) relative pupil coordinates.
        factors: (F, W, 3) or broadcastable (e.g. (F, 1, 3)) factors (V_i, V_s, V_l).

    Returns:
        (F, W, P, 2) reshaped pupil coordinates (differentiable in the factors).
    """
    v_i, v_s, v_l = (factors[..., k].unsqueeze(-1) for k in range(3))
    x = (1.0 - v_l) * pupil[..., 0]
    y = (1.0 - 0.5 * (v_i + v_s)) * pupil[..., 1] + 0.5 * (v_i - v_s)
    return torch.stack([x, y], -1)


# ----------------------------------------------------------------------- pupil regions (ellipses)
#
# A vignetted pupil is an ellipse centred on the meridional axis: centre y_c, semi-axes a (x) and b (y),
# in relative entrance-pupil units. S19–S20 are the map (x, y) ↦ (a x, y_c + b y) of the unit disc, with
#   V_i = 1 + y_c − b,   V_s = 1 − y_c − b,   V_l = 1 − a.


def factors_to_ellipse(factors: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """(…, 3) factors (V_i, V_s, V_l) → ellipse (y_c, a, b), each (…)."""
    v_i, v_s, v_l = factors.unbind(-1)
    return 0.5 * (v_i - v_s), 1.0 - v_l, 1.0 - 0.5 * (v_i + v_s)


def ellipse_to_factors(y_c: Tensor, a: Tensor, b: Tensor) -> Tensor:
    """Ellipse (y_c, a, b) → (…, 3) factors (V_i, V_s, V_l); the inverse of ``factors_to_ellipse``."""
    y_c, a, b = torch.broadcast_tensors(y_c, a, b)
    return torch.stack([1.0 + y_c - b, 1.0 - y_c - b, 1.0 - a], -1)


def compose_factors(outer: Tensor, inner: Tensor) -> Tensor:
    """Factors ``inner`` taken relative to the pupil ``outer`` (e.g. fixed factors relative to the
    aimed pupil, as CODE V applies VUY/VLY with ray aiming on): the composition of the two maps."""
    yo, ao, bo = factors_to_ellipse(outer)
    yi, ai, bi = factors_to_ellipse(inner)
    return ellipse_to_factors(yo + bo * yi, ao * ai, bo * bi)


def front_aperture_disc(
    distance: float, diameter: float, tan_field: Tensor, *, epd: Tensor, entrance_pupil_z: Tensor,
    object_distance: float | None = None,
) -> tuple[Tensor, Tensor]:
    """The opening of an object-space aperture seen in relative entrance-pupil coordinates.

    A ray launched through the pupil point (x, y) (``sampling.launch``) passes the aperture plane at
    z = ``distance`` inside the opening exactly when x² + (y − c)² ≤ ρ². Infinite object (rays of slope
    tan θ): c = tan θ (z_EP − d) / (EPD/2), ρ = (D/2) / (EPD/2). Finite object at distance L before
    surface 1: the rays fan out from the object point, which scales both by (z_EP + L) / (d + L).

    Args:
        tan_field: (F,) chief-ray slopes.
        epd, entrance_pupil_z: () paraxial entrance pupil diameter and position, mm (differentiable).

    Returns:
        centre c: (F,) and radius ρ: () or (F,), relative pupil units, differentiable.
    """
    r_ep = epd / 2
    scale = torch.ones_like(entrance_pupil_z)
    if object_distance is not None:
        scale = (entrance_pupil_z + object_distance) / (distance + object_distance)
    centre = tan_field * (entrance_pupil_z - distance) * scale / r_ep
    return centre, 0.5 * diameter * scale / r_ep


def clip_ellipse_to_disc(
    ellipse: tuple[Tensor, Tensor, Tensor], centre: Tensor, radius: Tensor, lateral: str = "inscribed"
) -> tuple[tuple[Tensor, Tensor, Tensor], Tensor]:
    """The ellipse that replaces pupil ``ellipse`` once the disc (``centre``, ``radius``) clips it.

    The y extent is exact: [max(y_c − b, c − ρ), min(y_c + b, c + ρ)]. The x semi-axis follows
    ``lateral``: ``inscribed`` gives the widest ellipse of that y extent lying inside both the pupil
    ellipse and the disc (so no launched ray falls outside; S1.3.2's front aperture), ``extent`` the
    widest x of the intersection (CODE V's convention; the ellipse then pokes out near the corners).

    Args:
        ellipse: (y_c, a, b), broadcastable tensors.
        centre, radius: the disc, broadcastable to the ellipse tensors.

    Returns:
        ((y_c, a, b), blocked): the clipped ellipse (finite everywhere, a point where nothing passes)
        and a bool mask of the entries where the intersection is empty.
    """
    y_c, a, b = torch.broadcast_tensors(*ellipse, centre, radius)[:3]
    centre, radius = torch.broadcast_tensors(centre, radius, y_c)[:2]
    lo = torch.maximum(y_c - b, centre - radius)
    hi = torch.minimum(y_c + b, centre + radius)
    blocked = hi <= lo
    hi_safe = torch.where(blocked, lo, hi)
    new_c, new_b = 0.5 * (lo + hi_safe), 0.5 * (hi_safe - lo)
    regions = ((y_c, a, b), (centre, radius, radius))
    if lateral == "inscribed":
        new_a = torch.minimum(*[_inscribed_width(new_c, new_b, lo, hi_safe, r) for r in regions])
    elif lateral == "extent":
        new_a = _widest_chord(regions, lo, hi_safe)
    else:
        raise ValueError(f"lateral must be 'inscribed' or 'extent', got {lateral!r}")
    new_a = torch.where(blocked, torch.zeros_like(new_a), new_a)
    return (new_c, new_a, new_b), blocked


def _sqrt0(x: Tensor) -> Tensor:
    """sqrt(max(x, 0)) with a zero (not infinite) derivative where x ≤ 0."""
    pos = x > torch.finfo(x.dtype).tiny
    return torch.where(pos, torch.sqrt(torch.where(pos, x, torch.ones_like(x))), torch.zeros_like(x))


def _inscribed_width(y0: Tensor, b: Tensor, lo: Tensor, hi: Tensor, container: tuple[Tensor, Tensor, Tensor]) -> Tensor:
    """Largest x semi-axis a of the ellipse (centre y0, y semi-axis b, spanning [lo, hi]) that stays
    inside the axis-aligned ellipse ``container`` = (y_k, A, B), which contains its y extent.

    Scaling x by B/A turns the container into a circle of radius B. The ellipse x² = a'²(1 − u²/b²),
    u = y − y0, stays inside x² + (u + δ)² ≤ B² (δ = y0 − y_k) while k = a'²/b² ≤ the larger root of
    b² k² + (δ² − b² − B²) k + B² = 0, i.e. k = (b² + B² − δ² + √(PQ)) / 2b² with
    P = (B − b − |δ|)(B − b + |δ|), Q = (B + b)² − δ². P = 0 when both touch at an end of the y extent
    (the extent [lo, hi] lies inside the container's, [y_k − B, y_k + B]).
    """
    y_k, big_a, big_b = container
    delta = y0 - y_k
    # B − max(|hi − y_k|, |lo − y_k|) (= B − b − |δ|) as the smaller gap between the extent and the
    # container's edges: exactly 0 where the extent ends on an edge (hi is y_k + B itself, or lo is
    # y_k − B), as it does for the pupil ellipse and for a held ray. Written as B − |hi − y_k| it is
    # ±eps there, and √(P Q) turns that into noise of √eps (1e-9 in the pupil factors).
    # A held ray ends the extent on the disc's edge up to rounding (its height comes from another
    # computation): gaps within rounding of the edges are that same tangency, snapped to 0.
    gap = torch.minimum((y_k + big_b) - hi, lo - (y_k - big_b))
    gap = torch.where(gap.abs() <= 64 * torch.finfo(gap.dtype).eps * (y_k.abs() + big_b), torch.zeros_like(gap), gap)
    p = gap * (big_b - b + delta.abs())
    q = (big_b + b) ** 2 - delta**2
    tiny = torch.finfo(b.dtype).tiny
    b_safe = b.clamp_min(tiny**0.25)
    k = (b**2 + big_b**2 - delta**2 + _sqrt0(p * q)) / (2.0 * b_safe**2)
    return big_a / big_b * b * _sqrt0(k)


def _widest_chord(regions: tuple[tuple[Tensor, Tensor, Tensor], ...], lo: Tensor, hi: Tensor) -> Tensor:
    """max over y ∈ [lo, hi] of the half-width of the intersection of two axis-aligned ellipses.

    Each half-width² A²(1 − (y − y_k)²/B²) is concave, so their minimum peaks at one ellipse's centre
    or where the two are equal (a quadratic in y); the maximum over those candidates is exact.
    """
    (y1, a1, b1), (y2, a2, b2) = regions
    p1, p2 = (a1 / b1) ** 2, (a2 / b2) ** 2
    qa = p2 - p1
    qb = 2.0 * (p1 * y1 - p2 * y2)
    qc = a1**2 - a2**2 - p1 * y1**2 + p2 * y2**2
    root = _sqrt0(qb**2 - 4.0 * qa * qc)
    sign = torch.where(qb >= 0, torch.ones_like(qb), -torch.ones_like(qb))
    s = -0.5 * (qb + sign * root)

    def div(n: Tensor, d: Tensor) -> Tensor:
        ok = d.abs() > torch.finfo(d.dtype).eps
        return torch.where(ok, n / torch.where(ok, d, torch.ones_like(d)), torch.zeros_like(n))

    best = torch.zeros_like(lo)
    for y in (y1, y2, div(s, qa), div(qc, s)):
        y = torch.minimum(torch.maximum(y, lo), hi)
        w2 = torch.minimum(a1**2 - p1 * (y - y1) ** 2, a2**2 - p2 * (y - y2) ** 2)
        best = torch.maximum(best, _sqrt0(w2))
    return best


def outside_front_aperture(pos: Tensor, dir: Tensor, distance: float, diameter: float) -> Tensor:
    """(*B) bool: object-space rays (pos, dir: (*B, 3)) that meet the plane z = ``distance`` outside the
    opening of diameter ``diameter`` (with a relative tolerance of 1e-9 on the radius²)."""
    dz = dir[..., 2]
    safe = torch.where(dz.abs() > torch.finfo(dz.dtype).eps, dz, torch.ones_like(dz))
    t = (distance - pos[..., 2]) / safe
    x = pos[..., 0] + t * dir[..., 0]
    y = pos[..., 1] + t * dir[..., 1]
    r2 = (0.5 * diameter) ** 2
    return (x * x + y * y > r2 * (1.0 + 1e-9)) | (dz.abs() <= torch.finfo(dz.dtype).eps)
