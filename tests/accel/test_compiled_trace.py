"""``compiled_trace`` (torch.compile) gives the eager ``trace``'s numbers and failure statuses.

Oracle: the eager ``trace`` itself (validated against optiland elsewhere); the compiled graph must
reproduce it to rounding (it compiles ``trace_kernel``, the same trace with fewer operations per ray,
and Inductor may contract a*b + c into an FMA and reorder short sums), so every status code is
identical and float64 intercepts agree to 2e-14 of their size (+ 2e-14 mm): ≤ 1e-12 mm out to 50 mm;
the worst ray here, at 75° to the axis 88 mm out after four refractions, 1.4e-12 mm (50 ulps).
"""

import dataclasses
import logging

import pytest
import torch

from lensopt.accel import compiled
from lensopt.accel.compiled import clear_compiled_cache, compiled_trace
from lensopt.optics.trace import REASONS, Rays, Status, trace
from lensopt.spec import build, parse_spec
from tests.helpers import MIXED
from tests.helpers import mixed_rays as _rays


def _close(a: torch.Tensor, b: torch.Tensor, rtol: float = 2e-14) -> bool:
    """|a − b| ≤ rtol (1 + |b|) on every row of (*, 3) vectors (a few dozen ulps of the coordinates)."""
    return bool(((a - b).abs().amax(-1) <= rtol * (1.0 + b.abs().amax(-1))).all())


@pytest.fixture(autouse=True)
def _fresh_cache():
    clear_compiled_cache()
    yield
    clear_compiled_cache()


@pytest.mark.slow  # 27 s with a cold Inductor cache (issue 14: ≤ 20 s a test); the recorded variant below stays
def test_compiled_equals_eager_with_every_failure_reason() -> None:
    lens = build(parse_spec(MIXED)).lens
    rays = _rays()
    eager = trace(lens, rays)
    # The case really covers every reason, and enough rays get through.
    for reason in REASONS:
        if reason == Status.BLOCKED:  # set by optics.bundle (front aperture), never by trace itself
            continue
        assert int((eager.status == reason).sum()) > 0, REASONS[reason]
    assert int((eager.status == Status.OK).sum()) > 150
    assert bool(eager.backtrack.any())

    # fallback=False: a compilation failure or graph break (fullgraph) fails this test.
    comp = compiled_trace(lens, rays, fallback=False)
    assert torch.equal(comp.status, eager.status)
    assert torch.equal(comp.backtrack, eager.backtrack)
    assert comp.pos.dtype == torch.float64
    assert torch.isfinite(comp.pos).all() and torch.isfinite(comp.dir).all()
    assert _close(comp.pos, eager.pos)
    assert (comp.dir - eager.dir).abs().max() <= 1e-12

    # New tensor values, same structure: the cached function serves them with the new numbers.
    moved = dataclasses.replace(lens, thickness=lens.thickness + 0.1)
    eager2, comp2 = trace(moved, rays), compiled_trace(moved, rays, fallback=False)
    assert not torch.allclose(eager2.pos, eager.pos)
    assert torch.equal(comp2.status, eager2.status)
    assert _close(comp2.pos, eager2.pos)
    assert len(compiled._cache) == 1
    # The kernel skips the far root on the sphere, the plane and the asphere's slot (Newton there),
    # not on the hyperboloid (κ = −2.5): tests/optics/test_trace_kernel.py shows why it must not.
    assert next(iter(compiled._cache))[-1] == (True, True, False, True)


def test_falls_back_to_eager_when_compilation_fails(monkeypatch, caplog) -> None:
    def broken_compile(fn, **kwargs):
        def run(*args):
            raise RuntimeError("no C++ compiler")
        return run

    monkeypatch.setattr(compiled.torch, "compile", broken_compile)
    lens = build(parse_spec(MIXED)).lens
    rays = _rays(50)
    with caplog.at_level(logging.WARNING, logger="lensopt.accel.compiled"):
        out = compiled_trace(lens, rays)
    eager = trace(lens, rays)
    assert torch.equal(out.pos, eager.pos) and torch.equal(out.status, eager.status)
    assert "no C++ compiler" in caplog.text
    with pytest.raises(RuntimeError, match="no C\\+\\+ compiler"):
        clear_compiled_cache()
        compiled_trace(lens, rays, fallback=False)


def test_component_major_rays_keep_their_values_and_skip_the_copy() -> None:
    from lensopt.accel.compiled import _component_major, component_major_rays

    g = torch.Generator().manual_seed(1)
    pos = torch.randn(5, 7, 3, generator=g, dtype=torch.float64)
    d = torch.nn.functional.normalize(torch.randn(5, 7, 3, generator=g, dtype=torch.float64) + torch.tensor(
        [0.0, 0.0, 4.0], dtype=torch.float64), dim=-1)
    rays = Rays(pos, d, torch.zeros(5, 7, dtype=torch.long))
    cm = component_major_rays(rays)
    assert torch.equal(cm.pos, pos) and torch.equal(cm.dir, d)
    assert cm.pos.movedim(-1, 0).is_contiguous() and not pos.movedim(-1, 0).is_contiguous()
    assert _component_major(cm.pos) is cm.pos  # already component-major: no copy


SINGLET = {
    "name": "singlet",
    "system": {"aperture": {"epd": 12.0}, "field": {"hfov_deg": 10.0, "relative": [0.0, 1.0]}, "object": "infinity"},
    "spectrum": {"wavelengths_nm": [486.1, 587.6, 656.3], "reference_nm": 587.6},
    "surfaces": [{"type": "sphere", "radius": 15.0, "thickness": 4.0, "material": "N-BK7", "stop": True},
                 {"type": "sphere", "radius": -40.0, "thickness": 30.0}],
}


def test_compiled_singlet_equals_eager_with_its_failures() -> None:
    # The default suite's torch.compile check (15 s with a cold Inductor cache; the every-path lens
    # above and below takes 23-27 s cold, so it runs in the slow set): a spherical singlet, recorded,
    # on rays of which some miss the front sphere or are totally reflected at the back one.
    lens = build(parse_spec(SINGLET)).lens
    rays = _rays(200)
    eager = trace(lens, rays, record=True)
    comp = compiled_trace(lens, rays, record=True, fallback=False)
    assert torch.equal(comp.status, eager.status) and torch.equal(comp.failed_at, eager.failed_at)
    assert len({int(v) for v in eager.status.unique()}) >= 2  # valid rays and at least one failure reason
    ok = eager.valid
    assert ok.sum() > 50
    assert _close(comp.pos[ok], eager.pos[ok]) and _close(comp.dir[ok], eager.dir[ok])
    for h_c, h_e in zip(comp.hits, eager.hits, strict=True):
        assert _close(h_c.pos[ok], h_e.pos[ok])


@pytest.mark.slow  # 23 s with a cold Inductor cache (issue 14: ≤ 20 s a test); the singlet above stays
def test_compiled_record_keeps_the_hits_and_failure_surfaces() -> None:
    # record=True (what the optimizer's constraints and failure margins read): per-surface hits and
    # the surface where each ray failed, as eager.
    lens = build(parse_spec(MIXED)).lens
    rays = _rays(200)
    eager = trace(lens, rays, record=True)
    comp = compiled_trace(lens, rays, record=True, fallback=False)
    assert torch.equal(comp.failed_at, eager.failed_at)
    assert bool((eager.failed_at >= 0).any()) and bool((eager.failed_at < 0).any())
    assert len(comp.hits) == len(eager.hits) == lens.num_surfaces
    for h_c, h_e in zip(comp.hits, eager.hits, strict=True):
        ok = eager.valid
        assert _close(h_c.pos[ok], h_e.pos[ok])
        assert (h_c.cos2_out[ok] - h_e.cos2_out[ok]).abs().max() <= 1e-12
    assert trace(lens, rays).failed_at is None  # the plain trace skips the bookkeeping
