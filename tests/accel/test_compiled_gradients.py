"""Gradients through ``compiled_trace``: reverse mode (through the compiled graph) and forward mode
(``torch.func.jvp`` and ``forward_ad`` duals) equal the eager trace's.

Oracle: the eager ``trace``'s derivatives, themselves checked against fourth-order finite differences
in ``test_gradients.py``. The lens is small on purpose (three spheres, one clipping aperture): the
compile of forward + backward graphs is what this test pays for: ~45 s of CPU with a cold Inductor
cache (measured on the loaded 2-core machine), so it is marked slow (``make test-slow``).
"""

from __future__ import annotations

import dataclasses

import pytest
import torch
from torch import Tensor

from lensopt.accel import compiled
from lensopt.accel.compiled import clear_compiled_cache, compiled_trace
from lensopt.optics.trace import Rays, trace
from lensopt.spec import build, parse_spec

DOUBLET = {
    "name": "cemented doublet",
    "system": {"aperture": {"epd": 10.0}, "field": {"hfov_deg": 5.0, "relative": [0.0, 1.0]}, "object": "infinity"},
    "spectrum": {"wavelengths_nm": [486.1, 587.6, 656.3], "reference_nm": 587.6},
    "surfaces": [
        {"type": "sphere", "radius": 30.0, "thickness": 4.0, "material": "N-BK7", "stop": True},
        {"type": "sphere", "radius": -25.0, "thickness": 2.0, "material": "N-SF5"},
        {"type": "sphere", "radius": -90.0, "thickness": 45.0, "semi_diameter": 5.4, "clip": True},
    ],
}


def _rays(n: int = 300) -> Rays:
    g = torch.Generator().manual_seed(3)
    xy = (torch.rand(n, 2, generator=g, dtype=torch.float64) * 2 - 1) * 5.5
    ang = torch.deg2rad(torch.rand(n, generator=g, dtype=torch.float64) * 6.0)
    d = torch.stack([torch.zeros_like(ang), torch.sin(ang), torch.cos(ang)], -1)
    pos = torch.cat([xy, torch.full((n, 1), -1.0, dtype=torch.float64)], -1)
    return Rays(pos=pos, dir=d, wavelength=torch.randint(0, 3, (n,), generator=g))


@pytest.fixture(autouse=True)
def _fresh_cache():
    clear_compiled_cache()
    yield
    clear_compiled_cache()


def _image(tracer, lens, rays: Rays, curvature: Tensor, thickness: Tensor, index: Tensor) -> Tensor:
    """(n, 2) image x, y of the valid rays (0 for the clipped ones) as a function of lens tensors."""
    r = tracer(dataclasses.replace(lens, curvature=curvature, thickness=thickness, index=index), rays)
    return torch.where(r.valid[:, None], r.pos[:, :2], 0.0)


def _compiled(lens, rays):
    return compiled_trace(lens, rays, fallback=False)


def _rel(a: Tensor, b: Tensor) -> float:
    return float((a - b).abs().max() / b.abs().max())


@pytest.mark.slow  # compiles a forward and a backward graph: ~45 s of CPU with a cold Inductor cache
def test_reverse_and_forward_mode_equal_eager() -> None:
    lens = build(parse_spec(DOUBLET)).lens
    rays = _rays()
    primals = (lens.curvature, lens.thickness, lens.index)
    g = torch.Generator().manual_seed(0)
    tangents = tuple(torch.randn(p.shape, generator=g, dtype=p.dtype) for p in primals)
    weights = torch.randn(rays.pos.shape[0], 2, generator=g, dtype=torch.float64)

    def loss(tracer):
        leaves = [p.clone().requires_grad_() for p in primals]
        out = (weights * _image(tracer, lens, rays, *leaves)).sum()
        return torch.autograd.grad(out, leaves)

    eager_grads = loss(trace)
    with torch.no_grad():
        eager_img = _image(trace, lens, rays, *primals)
    valid = int((eager_img != 0).any(-1).sum())
    assert 100 < valid < rays.pos.shape[0]  # some rays are clipped: the masks are exercised

    # Reverse mode through the compiled graph (fallback=False: a compile failure fails the test).
    comp_grads = loss(_compiled)
    for ge, gc in zip(eager_grads, comp_grads, strict=True):
        assert bool(ge.abs().max() > 0)
        assert _rel(gc, ge) <= 1e-12
    assert compiled._EAGER not in compiled._cache.values()

    # Forward mode, torch.func.jvp: same primal and tangent as eager.
    out_e, tan_e = torch.func.jvp(lambda *p: _image(trace, lens, rays, *p), primals, tangents)
    out_c, tan_c = torch.func.jvp(lambda *p: _image(_compiled, lens, rays, *p), primals, tangents)
    assert _rel(out_c, out_e) <= 1e-12
    assert bool(tan_e.abs().max() > 0)
    assert _rel(tan_c, tan_e) <= 1e-12

    # Forward mode, forward_ad duals (torch.compile alone would return the tangent as None).
    import torch.autograd.forward_ad as fwad

    with fwad.dual_level():
        duals = [fwad.make_dual(p, t) for p, t in zip(primals, tangents, strict=True)]
        tan_d = fwad.unpack_dual(_image(_compiled, lens, rays, *duals)).tangent
    assert tan_d is not None
    assert _rel(tan_d, tan_e) <= 1e-12

    # Forward mode did not mark the structure as uncompilable: a plain call still runs compiled.
    assert compiled._EAGER not in compiled._cache.values()
