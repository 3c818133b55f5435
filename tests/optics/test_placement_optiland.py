"""Decentered and tilted surfaces and elements against an independent tracer (optiland 0.6.3).

Oracle: optiland places every surface with its own ``CoordinateSystem`` (origin x, y, z; rotations
rx, ry, rz; optionally a ``reference_cs`` it is nested in) and traces rays by localize → intersect →
refract → globalize (``optiland/coordinate_system.py``, ``surfaces/standard_surface.py``). Its
``globalize`` applies ``rotate_x(rx)`` then ``rotate_y(ry)`` then the translation, i.e.
``p = T + Ry(ry) Rx(rx) p_local``; lensopt's convention is α about x, then β about the *new* y,
``Rx(α) Ry(β)``, which optiland expresses exactly as a CS with ``ry = β`` nested in one with
``rx = α`` (checked on a case with both angles). Each case builds the geometry in optiland's own terms
(absolute positions for decenter-and-return, nested frames for the basic mode and for a tilted
element), traces exactly lensopt's object-space rays (full-pupil grid, every field and wavelength)
and compares image intercepts in the image surface's own frame: ≤ 1e-9 mm (issue 12).
"""

from __future__ import annotations

import dataclasses
import math
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import torch

pytest.importorskip("optiland")

from optiland import optic as ol_optic  # noqa: E402
from optiland.coordinate_system import CoordinateSystem  # noqa: E402
from optiland.materials import IdealMaterial  # noqa: E402
from optiland.rays import RealRays  # noqa: E402

from lensopt.errors import LensoptError  # noqa: E402
from lensopt.optics.bundle import trace_bundle  # noqa: E402
from lensopt.optics.placement import Placement, no_placement  # noqa: E402
from lensopt.optics.sampling import pupil_grid  # noqa: E402
from lensopt.spec import build, load_spec  # noqa: E402
from lensopt.spec.io import parse_spec  # noqa: E402

pytestmark = [
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
    pytest.mark.filterwarnings("ignore:.*:numba.core.errors.NumbaIRAssumptionWarning"),
]

SPEC = Path(__file__).resolve().parents[2] / "specs" / "cooke_triplet.toml"
TOL_MM = 1e-9
DEG = math.pi / 180


@cache
def _model():
    return build(load_spec(SPEC))


def _cs(x=0.0, y=0.0, z=0.0, rx=0.0, ry=0.0, ref=None) -> CoordinateSystem:
    """A frame ``T + Rx(rx) Ry(ry)`` (lensopt's order) as optiland's nested coordinate systems."""
    outer = CoordinateSystem(x=x, y=y, z=z, rx=rx, reference_cs=ref)
    return CoordinateSystem(ry=ry, reference_cs=outer) if ry else outer


def _optiland(lens, w: int, frames: list[CoordinateSystem]) -> ol_optic.Optic:
    """The lens at wavelength ``w`` with lensopt's indices, surface s placed in ``frames[s]``
    (S surfaces, then the image surface)."""
    index = lens.index[:, w].tolist()
    o = ol_optic.Optic()
    o.surfaces.add(index=0, radius=math.inf, thickness=math.inf, material=IdealMaterial(n=index[0]))
    for i in range(lens.num_surfaces):
        c = float(lens.curvature[i])
        o.surfaces.add(index=i + 1, radius=math.inf if c == 0 else 1.0 / c, thickness=float(lens.thickness[i]),
                       is_stop=(i == lens.stop), material=IdealMaterial(n=index[i + 1]))
    o.surfaces.add(index=lens.num_surfaces + 1)
    for i, cs in enumerate(frames):
        o.surfaces.surfaces[i + 1].geometry.cs = cs
    return o


def _compare(placement: Placement, frames: list[CoordinateSystem]) -> float:
    """Max |lensopt − optiland| image intercept (image frame), mm, over a full-pupil grid."""
    model = _model()
    lens = dataclasses.replace(model.lens, placement=placement)
    bundle = trace_bundle(lens, model.system, pupil_grid(11, dtype=torch.float64))
    assert bool(bundle.result.valid.all())
    ours = bundle.result.pos.numpy()
    worst = 0.0
    for w in range(lens.wavelength_um.shape[0]):
        o = _optiland(lens, w, frames)
        shape = bundle.result.pos[:, w].shape
        pos = bundle.rays.pos[:, w].expand(shape).reshape(-1, 3).numpy()
        d = bundle.rays.dir[:, w].expand(shape).reshape(-1, 3).numpy()
        t = np.minimum(0.0, (-1.0 - pos[:, 2]) / d[:, 2])
        pos = pos + t[:, None] * d
        n = pos.shape[0]
        rays = RealRays(*(np.ascontiguousarray(a) for a in (*pos.T, *d.T)), np.ones(n),
                        np.full(n, float(lens.wavelength_um[w])))
        o.surfaces.trace(rays)
        frames[-1].localize(rays)  # image intercepts in the image surface's own x, y
        theirs = np.stack([np.asarray(rays.x), np.asarray(rays.y)], -1).reshape(*shape[:-1], 2)
        assert np.all(np.isfinite(theirs))
        worst = max(worst, float(np.abs(ours[:, w, :, :2] - theirs).max()))
    return worst


def _nominal_z(lens) -> list[float]:
    return lens.vertex_z().tolist()


def _placement(num: int, **changes) -> Placement:
    p = no_placement(num, dtype=torch.float64)
    return dataclasses.replace(p, **changes)


def test_surface_decenter_return() -> None:
    lens = _model().lens
    z = _nominal_z(lens)
    p = _placement(lens.num_surfaces)
    p.decenter[2] = torch.tensor([0.05, 0.1], dtype=torch.float64)
    frames = [_cs(z=zi) for zi in z]
    frames[2] = _cs(x=0.05, y=0.1, z=z[2])
    assert _compare(p, frames) <= TOL_MM


def test_surface_tilt_return_both_axes() -> None:
    lens = _model().lens
    z = _nominal_z(lens)
    p = _placement(lens.num_surfaces)
    p.tilt[3] = torch.tensor([0.5 * DEG, -0.3 * DEG], dtype=torch.float64)
    p.decenter[3] = torch.tensor([0.0, -0.02], dtype=torch.float64)
    frames = [_cs(z=zi) for zi in z]
    frames[3] = _cs(y=-0.02, z=z[3], rx=0.5 * DEG, ry=-0.3 * DEG)
    assert _compare(p, frames) <= TOL_MM


def test_surface_tilt_basic_moves_later_surfaces() -> None:
    """Basic mode: the axis follows surface 1's tilt, later surfaces (and the image) sit on it."""
    lens = _model().lens
    z = _nominal_z(lens)
    p = _placement(lens.num_surfaces, basic=(False, True) + (False,) * (lens.num_surfaces - 2))
    p.tilt[1] = torch.tensor([0.2 * DEG, 0.1 * DEG], dtype=torch.float64)
    p.decenter[1] = torch.tensor([0.03, 0.0], dtype=torch.float64)
    frames = [_cs(z=zi) for zi in z]
    tilted = _cs(x=0.03, z=z[1], rx=0.2 * DEG, ry=0.1 * DEG)
    frames[1] = tilted
    for s in range(2, len(z)):
        frames[s] = CoordinateSystem(z=z[s] - z[1], reference_cs=tilted)
    assert _compare(p, frames) <= TOL_MM


def test_element_decenter_and_tilt() -> None:
    """Element = surfaces 2..3 (the middle lens), moved about the vertex of surface 2 and returned."""
    lens = _model().lens
    z = _nominal_z(lens)
    p = _placement(lens.num_surfaces, groups=((2, 3),),
                   group_decenter=torch.tensor([[0.02, -0.04]], dtype=torch.float64),
                   group_tilt=torch.tensor([[0.3 * DEG, 0.2 * DEG]], dtype=torch.float64))
    frames = [_cs(z=zi) for zi in z]
    pivot = _cs(x=0.02, y=-0.04, z=z[2], rx=0.3 * DEG, ry=0.2 * DEG)
    frames[2] = pivot
    frames[3] = CoordinateSystem(z=z[3] - z[2], reference_cs=pivot)
    assert _compare(p, frames) <= TOL_MM


def test_zero_placement_equals_symmetric_path() -> None:
    """A placement of zeros goes through the frame transforms and must give the fast path's numbers."""
    model = _model()
    pupil = pupil_grid(7, dtype=torch.float64)
    fast = trace_bundle(model.lens, model.system, pupil).result.pos
    lens = dataclasses.replace(model.lens, placement=no_placement(model.lens.num_surfaces, dtype=torch.float64))
    placed = trace_bundle(lens, model.system, pupil).result.pos
    assert torch.allclose(fast, placed, rtol=0, atol=1e-12)


def test_spec_fields_build_the_placement() -> None:
    """``decenter``/``tilt_deg``/``decenter_mode`` per surface and ``[[elements]]`` reach the Lens
    (degrees → radians); a spec without them keeps the symmetric fast path (placement None)."""
    from pydantic import ValidationError

    spec = load_spec(SPEC)
    assert build(spec).lens.placement is None
    data = spec.model_dump(exclude_none=True)
    data["surfaces"][2].update(decenter=(0.05, 0.1), tilt_deg=(0.5, 0.0), decenter_mode="basic")
    data["elements"] = [{"surfaces": (2, 3), "tilt_deg": (0.0, 0.2)}]
    placed = build(parse_spec(data)).lens.placement
    assert placed is not None and placed.basic[2] and not placed.basic[1]
    assert placed.decenter[2].tolist() == [0.05, 0.1]
    assert abs(float(placed.tilt[2, 0]) - 0.5 * DEG) < 1e-15
    assert placed.groups == ((2, 3),) and abs(float(placed.group_tilt[0, 1]) - 0.2 * DEG) < 1e-15
    data["elements"] = [{"surfaces": (2, 30)}]
    with pytest.raises((LensoptError, ValidationError)):
        parse_spec(data)


def test_two_dimensional_fields_rotate_on_a_symmetric_lens() -> None:
    """A field along x on a rotationally symmetric lens is the y field turned by 90° (invariant): the
    centroid of field (u, 0) is (ȳ, 0) where ȳ is that of field (0, u), on a full-pupil grid that the
    turn maps onto itself."""
    model = _model()
    u = torch.tensor([0.0, 0.7, 1.0], dtype=torch.float64)
    pupil = pupil_grid(9, dtype=torch.float64)
    along_y = trace_bundle(model.lens, model.system, pupil, rel_field=u)
    along_x = trace_bundle(model.lens, model.system, pupil, rel_field=torch.zeros_like(u), rel_field_x=u)
    wy = along_y.result.pos[..., :2].mean(2)  # (F, W, 2)
    wx = along_x.result.pos[..., :2].mean(2)
    assert torch.allclose(wx[..., 0], wy[..., 1], atol=1e-12) and torch.allclose(wx[..., 1], wy[..., 0], atol=1e-12)
    # And a decentered lens is traced on the full pupil even from a half-pupil sampling.
    lens = dataclasses.replace(model.lens, placement=no_placement(model.lens.num_surfaces, dtype=torch.float64))
    half = torch.tensor([[0.5, 0.2]], dtype=torch.float64)
    b = trace_bundle(lens, model.system, half, half_pupil=True)
    assert not b.half_pupil and b.pupil.shape[-2] == 2
