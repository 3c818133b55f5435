"""Grazing incidence: rays at 89.9° to the surface normal, on a plane and on a sphere (closed-form
and Newton intersection). Expected directions come from Snell's law in angle form,
n sin i = n' sin i', worked out by hand below; values and gradients must be finite."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from lensopt.optics.trace import trace
from tests.hard_cases.hard_tools import collimated, counts, make_lens, make_rays, trace_checked

D = torch.float64
GRAZE = math.radians(89.9)
N_GLASS = 1.5


def test_plane_air_to_glass_at_89_9_degrees() -> None:
    lens = make_lens([{"kind": "plane", "t": 5.0}], index=[1.0, N_GLASS])
    start = torch.tensor([[0.0, 0.0, -0.01]], dtype=D)
    d = torch.tensor([[0.0, math.sin(GRAZE), math.cos(GRAZE)]], dtype=D)
    result, grads = trace_checked(lens, make_rays(start, d))
    assert counts(result) == {}
    # Snell: sin i' = sin(89.9°)/1.5, the ray keeps its plane of incidence.
    s = math.sin(GRAZE) / N_GLASS
    expected_dir = torch.tensor([0.0, s, math.sqrt(1 - s * s)], dtype=D)
    torch.testing.assert_close(result.dir[0], expected_dir, rtol=0, atol=1e-15)
    # Image height: 0.01 mm in air at tan 89.9°, then 5 mm in glass at tan i'.
    y = 0.01 * math.tan(GRAZE) + 5.0 * s / math.sqrt(1 - s * s)
    torch.testing.assert_close(result.pos[0], torch.tensor([0.0, y, 5.0], dtype=D), rtol=0, atol=1e-12)
    # d(image y)/dn' = 5 · d tan i'/dn' = 5 · (−sin(89.9°)/n'²) / cos³ i'  (index row 1 = the glass).
    cos_r = math.sqrt(1 - s * s)
    dy_dn = 5.0 * (-math.sin(GRAZE) / N_GLASS**2) / cos_r**3
    # The masked loss is |xy|² + Σ dir: d/dn' = 2 y dy/dn' + d(dir_y + dir_z)/dn'.
    ddir = (-math.sin(GRAZE) / N_GLASS**2) * (1 - s / cos_r)
    assert float(grads["index"][1, 0]) == pytest.approx(2 * y * dy_dn + ddir, rel=1e-12)


def test_glass_to_air_at_89_9_degrees_is_total_internal_reflection() -> None:
    # n sin i = 1.5 · sin 89.9° ≈ 1.49999 > 1: no refracted ray.
    lens = make_lens([{"kind": "plane", "t": 5.0}], index=[N_GLASS, 1.0])
    start = torch.tensor([[0.0, 0.0, -0.01]], dtype=D)
    d = torch.tensor([[0.0, math.sin(GRAZE), math.cos(GRAZE)]], dtype=D)
    result, _ = trace_checked(lens, make_rays(start, d))
    assert counts(result) == {"total internal reflection": 1}


@pytest.mark.parametrize("kind", ["sphere", "asphere"])
def test_sphere_hit_at_89_9_degrees(kind: str) -> None:
    # Collimated ray at height y = R sin i on a convex sphere (R = 10 mm, centre at z = R): the normal
    # at the hit point makes the angle i = 89.9° with the ray. Hit point (0, y, R − R cos i); after
    # refraction i' = asin(sin i / n) and the ray turns towards the axis by i − i'.
    radius = 10.0
    surf = {"kind": kind, "c": 1 / radius, "t": 15.0}  # image beyond the hit point at z ≈ 9.98
    if kind == "asphere":
        surf["a"] = [0.0]  # Newton path on the same sphere
    lens = make_lens([surf], index=[1.0, N_GLASS])
    y = radius * math.sin(GRAZE)
    result, _ = trace_checked(lens, collimated(torch.tensor([y], dtype=D), z=-1.0))
    assert counts(result) == {}
    hit = result.hits[0]
    torch.testing.assert_close(hit.pos[0], torch.tensor([0.0, y, radius - radius * math.cos(GRAZE)], dtype=D),
                               rtol=0, atol=1e-12)
    assert float(hit.cos2_in[0]) == pytest.approx(math.cos(GRAZE) ** 2, rel=1e-9)
    i_r = math.asin(math.sin(GRAZE) / N_GLASS)
    dev = GRAZE - i_r
    torch.testing.assert_close(hit.dir_out[0], torch.tensor([0.0, -math.sin(dev), math.cos(dev)], dtype=D),
                               rtol=0, atol=1e-12)
    # d(dir_y)/dc at fixed y: sin i = y c, di/dc = y / cos i (≈ 573 y at grazing), di'/dc =
    # cos i/(n cos i') di/dc, so d(−sin(i − i'))/dc = −cos(i − i') (1 − cos i/(n cos i')) y/cos i.
    ddy_dc = -math.cos(dev) * (1 - math.cos(GRAZE) / (N_GLASS * math.cos(i_r))) * y / math.cos(GRAZE)
    c = lens.curvature.clone().requires_grad_(True)
    out = trace(dataclasses.replace(lens, curvature=c), collimated(torch.tensor([y], dtype=D)), record=True)
    (dl,) = torch.autograd.grad(out.hits[0].dir_out[0, 1], c)
    assert float(dl[0]) == pytest.approx(ddy_dc, rel=1e-7)
