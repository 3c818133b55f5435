"""The eager trace in cache-sized chunks (``trace.CHUNK_RAYS``, taken when nothing needs gradients)
gives the one-pass trace's numbers bit for bit, including its shortcuts (selects whose condition
holds for every ray, a quadric's far root that no ray needs).

Oracle: the one-pass eager trace (validated against optiland elsewhere). Elementwise IEEE arithmetic
does not depend on how the rays are split, so the results must be *equal*, not close; the chunk
size is made small here so that a few thousand rays give many chunks.
"""

import pytest
import torch

# MIXED: every code path of the trace (Newton, spheres, a hyperboloid, clipping, a diffractive surface,
# TIR, misses, Newton failures), shared with the compiled-trace tests.
from lensopt.optics import trace as trace_mod
from lensopt.optics.trace import REASONS, Rays, trace
from lensopt.spec import build, parse_spec
from tests.helpers import MIXED

SPHERES = {  # all rays pass: the shortcut branches (every select's condition true) are taken
    "name": "doublet",
    "system": {"aperture": {"epd": 10.0}, "field": {"hfov_deg": 5.0, "relative": [0.0, 1.0]}, "object": "infinity"},
    "spectrum": {"wavelengths_nm": [486.1, 587.6, 656.3], "reference_nm": 587.6},
    "surfaces": [
        {"type": "sphere", "radius": 60.0, "thickness": 4.0, "material": "N-BK7", "stop": True},
        {"type": "sphere", "radius": -45.0, "thickness": 2.0, "material": "N-SF5"},
        {"type": "sphere", "radius": -200.0, "thickness": 95.0},
    ],
}


def _rays(n: int, spread: float, max_deg: float) -> Rays:
    g = torch.Generator().manual_seed(3)
    xy = (torch.rand(n, 2, generator=g, dtype=torch.float64) * 2 - 1) * spread
    ang = torch.deg2rad(torch.rand(n, generator=g, dtype=torch.float64) * max_deg)
    d = torch.stack([torch.zeros_like(ang), torch.sin(ang), torch.cos(ang)], -1)
    pos = torch.cat([xy, torch.full((n, 1), -2.0, dtype=torch.float64)], -1)
    return Rays(pos=pos, dir=d, wavelength=torch.randint(0, 3, (n,), generator=g))


def _fields(r) -> list[torch.Tensor]:
    out = [r.pos, r.dir, r.status, r.backtrack] + ([] if r.failed_at is None else [r.failed_at])
    for h in r.hits:
        out += [h.pos, h.dir_in, h.dir_out, h.normal, h.t, h.cos2_in, h.cos2_out]
    return out


@pytest.mark.parametrize("spec, spread, max_deg", [(MIXED, 9.0, 60.0), (SPHERES, 4.0, 5.0)])
@pytest.mark.parametrize("record", [False, True])
def test_chunked_trace_equals_one_pass(monkeypatch, spec, spread, max_deg, record) -> None:
    lens = build(parse_spec(spec)).lens
    rays = _rays(5003, spread, max_deg)  # not a multiple of the chunk: a short last chunk
    one_pass = trace(lens, rays, record=record)  # below 2 chunks at the default size: one pass
    assert not trace_mod._chunked(lens, rays, rays.pos)
    monkeypatch.setattr(trace_mod, "CHUNK_RAYS", 512)
    assert trace_mod._chunked(lens, rays, rays.pos)
    chunked = trace(lens, rays, record=record)
    if spec is MIXED:  # the case really fails rays for every reason
        assert {int(v) for v in one_pass.status.unique()} >= {int(r) for r in REASONS if r.name != "BLOCKED"}
    else:
        assert bool(one_pass.valid.all())
    for a, b in zip(_fields(one_pass), _fields(chunked), strict=True):
        assert a.shape == b.shape and a.dtype == b.dtype
        assert torch.equal(a, b)


def test_batch_shape_kept(monkeypatch) -> None:
    """A (F, W, P) batch with a broadcast wavelength index comes back in its own shape."""
    lens = build(parse_spec(SPHERES)).lens
    flat = _rays(2 * 3 * 700, 4.0, 5.0)
    rays = Rays(flat.pos.reshape(2, 3, 700, 3), flat.dir.reshape(2, 3, 700, 3), torch.arange(3).reshape(1, 3, 1))
    one_pass = trace(lens, rays)
    monkeypatch.setattr(trace_mod, "CHUNK_RAYS", 256)
    chunked = trace(lens, rays)
    assert chunked.pos.shape == (2, 3, 700, 3) and chunked.status.shape == (2, 3, 700)
    assert torch.equal(one_pass.pos, chunked.pos) and torch.equal(one_pass.status, chunked.status)


def test_no_chunks_when_gradients_are_needed(monkeypatch) -> None:
    """Autograd and forward mode see the one-pass trace (the optimizer's path is unchanged)."""
    lens = build(parse_spec(SPHERES)).lens
    rays = _rays(3000, 4.0, 5.0)
    monkeypatch.setattr(trace_mod, "CHUNK_RAYS", 256)
    c = lens.curvature.clone().requires_grad_(True)
    import dataclasses

    lens_g = dataclasses.replace(lens, curvature=c)
    assert not trace_mod._chunked(lens_g, rays, rays.pos)
    with torch.no_grad():
        assert trace_mod._chunked(lens_g, rays, rays.pos)

    def image_y(curv: torch.Tensor) -> torch.Tensor:
        lens_f = dataclasses.replace(lens, curvature=curv)
        assert not trace_mod._chunked(lens_f, rays, rays.pos)
        return trace(lens_f, rays).pos[:, 1]

    torch.func.jvp(image_y, (lens.curvature,), (torch.ones_like(lens.curvature),))
