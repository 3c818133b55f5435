"""The differential ray trace (``optics.differential``) against forward-mode AD of the trace itself.

Reference: ``torch.func.jacfwd`` of ``trace(lens(θ), rays(θ), record=True)``, where θ holds every
entry of the lens tensors (curvatures, conics, asphere and phase coefficients, thicknesses, indices)
and two ray parameters (a shift of the launch heights and a tilt of the directions), so that every
input the local derivatives take (per ray: position, direction, the two indices; per surface: the
prescription and the vertex) carries a tangent. The values must be the trace's own (same step
function); the tangents agree with jacfwd to rounding: ≤ 1e-12 of each field's largest tangent.
"""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import pytest
import torch

from lensopt.optics.bundle import trace_bundle
from lensopt.optics.differential import HIT_FIELDS, supported, trace_with_tangents
from lensopt.optics.trace import Rays, trace
from lensopt.spec import build, parse_spec

ROOT = Path(__file__).resolve().parents[2]
NAMES = ("curvature", "conic", "asphere", "phase", "thickness", "index")


def _setup(path: Path, pupil_scale: float = 1.0):  # noqa: ANN202
    model = build(parse_spec(tomllib.loads(path.read_text())), dtype=torch.float64)
    lens = model.lens
    pupil = torch.tensor([[0.0, 0.0], [0.0, 0.6], [0.0, -0.9], [0.7, 0.2], [0.5, -0.5]], dtype=torch.float64)
    with torch.no_grad():
        b = trace_bundle(lens, model.system, pupil_scale * pupil)
    pos0, dir0 = torch.broadcast_tensors(b.rays.pos, b.rays.dir)
    sizes = [getattr(lens, n).numel() for n in NAMES]

    def lens_of(theta: torch.Tensor):  # noqa: ANN202
        parts = torch.split(theta[:sum(sizes)], sizes)
        shaped = {n: p.reshape(getattr(lens, n).shape) for n, p in zip(NAMES, parts, strict=True)}
        return dataclasses.replace(lens, **shaped)

    def rays_of(theta: torch.Tensor) -> Rays:
        shift, tilt = theta[-2], theta[-1]
        pos = pos0 + shift * torch.tensor([0.0, 1.0, 0.0], dtype=pos0.dtype)
        d = dir0 + tilt * torch.tensor([1.0, 0.0, 0.0], dtype=dir0.dtype)
        return Rays(pos, d / torch.linalg.vector_norm(d, dim=-1, keepdim=True), b.rays.wavelength)

    theta = torch.cat([getattr(lens, n).reshape(-1) for n in NAMES] + [torch.zeros(2, dtype=torch.float64)])
    return lens_of, rays_of, theta


def _tangents(lens_of, rays_of, theta):  # noqa: ANN001, ANN202
    lens, rays = lens_of(theta), rays_of(theta)
    jl = torch.func.jacfwd(lambda t: tuple(getattr(lens_of(t), n) for n in NAMES))(theta)
    jr = torch.func.jacfwd(lambda t: (rays_of(t).pos, rays_of(t).dir))(theta)
    lens_dot = dataclasses.replace(lens, **dict(zip(NAMES, jl, strict=True)))
    return lens, rays, lens_dot, Rays(jr[0], jr[1], rays.wavelength)


CASES = {
    "telephoto (even aspheres, plastics, IR filter)": (ROOT / "specs" / "telephoto_5p_tr080.toml", 1.0),
    "hybrid triplet (sphere, conic, asphere, diffractive)": (ROOT / "tests" / "data" / "hybrid_triplet.toml", 1.0),
    "Cooke triplet, pupil overfilled (rays fail)": (ROOT / "specs" / "cooke_triplet.toml", 4.0),
}


@pytest.mark.parametrize("case", list(CASES))
def test_tangents_equal_forward_mode_of_the_trace(case: str) -> None:
    path, scale = CASES[case]
    lens_of, rays_of, theta = _setup(path, scale)
    lens, rays, lens_dot, rays_dot = _tangents(lens_of, rays_of, theta)
    assert supported(lens)
    result, dot = trace_with_tangents(lens, rays, lens_dot, rays_dot)
    ref = trace(lens, rays, record=True)
    # The values are the trace's: the same step function.
    assert torch.equal(result.status, ref.status) and torch.equal(result.failed_at, ref.failed_at)
    assert torch.equal(result.pos, ref.pos) and torch.equal(result.dir, ref.dir)

    def fields(t):  # noqa: ANN001, ANN202
        r = trace(lens_of(t), rays_of(t), record=True)
        return (r.pos, r.dir) + tuple(getattr(h, f) for h in r.hits for f in sorted(HIT_FIELDS))

    jac = torch.func.jacfwd(fields)(theta)
    got = (dot.pos, dot.dir) + tuple(getattr(h, f) for h in dot.hits for f in sorted(HIT_FIELDS))
    valid = ref.valid
    if case.startswith("Cooke"):
        assert 0 < int(valid.sum()) < valid.numel()  # some rays fail: their rows are held too
    for k, (want, have) in enumerate(zip(jac, got, strict=True)):  # every ray, failed ones too
        scale_k = float(want.abs().max()) or 1.0
        assert float((want - have).abs().max()) <= 1e-12 * scale_k, (k, float((want - have).abs().max()), scale_k)


def test_only_the_requested_hit_fields_get_tangents() -> None:
    lens_of, rays_of, theta = _setup(ROOT / "specs" / "cooke_triplet.toml")
    lens, rays, lens_dot, rays_dot = _tangents(lens_of, rays_of, theta)
    _, full = trace_with_tangents(lens, rays, lens_dot, rays_dot)
    _, part = trace_with_tangents(lens, rays, lens_dot, rays_dot, hit_fields=lambda r: ("cos2_out", "pos"))
    for h_full, h_part in zip(full.hits, part.hits, strict=True):
        assert h_part.normal is None and h_part.t is None and h_part.dir_out is None
        assert torch.equal(h_part.cos2_out, h_full.cos2_out) and torch.equal(h_part.pos, h_full.pos)
    assert torch.equal(part.pos, full.pos) and torch.equal(part.dir, full.dir)
    # No recorded field at all (every constraint quiet): the ray's tangents keep their bits.
    _, bare = trace_with_tangents(lens, rays, lens_dot, rays_dot, hit_fields=())
    assert all(h.pos is None and h.cos2_in is None for h in bare.hits)
    assert torch.equal(bare.pos, full.pos) and torch.equal(bare.dir, full.dir)


@pytest.mark.parametrize("case", list(CASES))
def test_hit_fields_asked_for_at_some_surfaces_get_tangents_there_alone(case: str) -> None:
    # (field, surface) pairs: that field's tangents at that surface alone (a ramp term's active blocks
    # read a few hits); a bare name: every surface; a surface beyond the lens: nothing. The same numbers
    # as the full set's: bit for bit where the chain's batched product runs on BLAS either way; a small
    # one (rows × 8 × N < 400: the Cooke case's single row) takes ATen's plain loop, to rounding. The
    # ray's own tangents keep their bits.
    path, scale = CASES[case]
    lens_of, rays_of, theta = _setup(path, scale)
    lens, rays, lens_dot, rays_dot = _tangents(lens_of, rays_of, theta)
    _, full = trace_with_tangents(lens, rays, lens_dot, rays_dot)
    S = lens.num_surfaces
    wanted = [("pos", 1), ("normal", S - 1), ("pos", S - 1), "cos2_in", ("t", S + 3)]
    _, part = trace_with_tangents(lens, rays, lens_dot, rays_dot, hit_fields=wanted, first=True)
    expect = {(f, s): f == "cos2_in" or (f, s) in wanted for f in HIT_FIELDS for s in range(S)}
    assert sum(expect.values()) == S + 3
    for (f, s), there in expect.items():
        have, want = getattr(part.hits[s], f), getattr(full.hits[s], f)
        assert (have is not None) == there, (f, s)
        if there:
            want = want.movedim(-1, 0)
            small = case.startswith("Cooke")
            assert torch.equal(have, want) or small and torch.allclose(have, want, rtol=1e-14, atol=0), (f, s)
    assert torch.equal(part.pos, full.pos.movedim(-1, 0)) and torch.equal(part.dir, full.dir.movedim(-1, 0))


@pytest.mark.parametrize("case", list(CASES))
def test_tangents_variables_first_are_the_same_numbers(case: str) -> None:
    # ``first=True`` (stage C's layout: (N, *B, …), contiguous) chains each recorded field by itself:
    # the same bits as the default layout's tangents (held against jacfwd above), moved.
    path, scale = CASES[case]
    lens_of, rays_of, theta = _setup(path, scale)
    lens, rays, lens_dot, rays_dot = _tangents(lens_of, rays_of, theta)
    for wanted in (HIT_FIELDS, ("dir_in", "t", "normal")):
        _, dot = trace_with_tangents(lens, rays, lens_dot, rays_dot, hit_fields=wanted)
        _, top = trace_with_tangents(lens, rays, lens_dot, rays_dot, hit_fields=wanted, first=True)
        pairs = [(dot.pos, top.pos), (dot.dir, top.dir)]
        pairs += [(getattr(h, f), getattr(g, f)) for h, g in zip(dot.hits, top.hits, strict=True) for f in HIT_FIELDS]
        for a, b in pairs:
            if a is None:
                assert b is None
                continue
            assert b.is_contiguous() and b.shape == (a.shape[-1], *a.shape[:-1])
            assert torch.equal(b, a.movedim(-1, 0))


def test_a_placed_lens_is_refused() -> None:
    from lensopt.optics.placement import no_placement

    lens_of, rays_of, theta = _setup(ROOT / "specs" / "cooke_triplet.toml")
    lens, rays, lens_dot, rays_dot = _tangents(lens_of, rays_of, theta)
    placed = dataclasses.replace(lens, placement=no_placement(lens.num_surfaces, dtype=torch.float64))
    assert not supported(placed)
    with pytest.raises(ValueError, match="placement"):
        trace_with_tangents(placed, rays, lens_dot, rays_dot)


@pytest.mark.parametrize("case", list(CASES))
def test_attached_stop_hit_is_the_trace_to_the_stop_in_value_and_derivative(case: str) -> None:
    # The aiming solves' attached final steps trace to the stop through ``attached_stop_hit``: the values
    # of the plain trace, the derivatives by its explicit partials (``stop_partials``). Reference: the
    # plain ``stop_hit`` of the attached lens and rays under jacfwd (forward mode through every step).
    from lensopt.optics.aiming import attached_stop_hit, stop_hit

    path, scale = CASES[case]
    lens_of, rays_of, theta = _setup(path, scale)
    lens, rays = lens_of(theta), rays_of(theta)
    x0, y0, hit0 = stop_hit(lens, rays)
    x1, y1, hit1 = attached_stop_hit(lens, rays)  # no derivatives: the plain trace itself
    assert torch.equal(x0, x1) and torch.equal(y0, y1) and torch.equal(hit0.status, hit1.status)

    def via(fn):  # noqa: ANN001, ANN202
        def f(t):  # noqa: ANN001, ANN202
            x, y, _ = fn(lens_of(t), rays_of(t))
            return (x, y), (x, y)
        return f

    jac_ref, (xr, yr) = torch.func.jacfwd(via(stop_hit), has_aux=True)(theta)
    jac, (xa, ya) = torch.func.jacfwd(via(attached_stop_hit), has_aux=True)(theta)
    assert torch.equal(xa, x0) and torch.equal(ya, y0) and torch.equal(xr, x0)  # values keep their bits
    valid = hit0.valid
    if case.startswith("Cooke"):
        assert 0 < int(valid.sum()) < valid.numel()  # some rays are lost before the stop: not compared
    for want, have in zip(jac_ref, jac, strict=True):
        want, have = want[valid], have[valid]
        scale_k = float(want.abs().max())
        assert scale_k > 0
        assert float((want - have).abs().max()) <= 1e-12 * scale_k


@pytest.mark.parametrize("case", list(CASES))
def test_stop_partials_trace_is_the_trace_to_the_stop(case: str) -> None:
    # ``stop_partials`` returns the trace to the stop it differentiates (``attached_stop_hit`` takes its
    # values from there instead of tracing again): bit for bit ``trace(…, upto=stop)``, the rays lost
    # before the stop (overfilled Cooke) and their status included; its partials are those of the stop
    # hits, held against jacfwd above.
    from lensopt.optics.differential import stop_partials

    path, scale = CASES[case]
    lens_of, rays_of, theta = _setup(path, scale)
    lens, rays = lens_of(theta), rays_of(theta)
    ref = trace(lens, rays, upto=lens.stop)
    hit, partials = stop_partials(lens, rays)
    for name in ("pos", "dir", "status", "backtrack"):
        assert torch.equal(getattr(hit, name), getattr(ref, name)), name
    assert hit.failed_at is None and partials.shape[:-1] == (*ref.status.shape, 3)
    if case.startswith("Cooke"):
        assert 0 < int(ref.valid.sum()) < ref.valid.numel()


def test_attached_stop_hit_under_vmap_is_the_plain_trace_without_a_fallback_loop() -> None:
    # Lens values batched by a vmap (tolerance trials): the partials' trace has no batching rule for its
    # in-place products, so ``attached_stop_hit`` traces plainly there: the same numbers as ``stop_hit`` per
    # sample to rounding, and no "performance drop" warning (torch's per-sample fallback).
    import warnings

    from lensopt.optics.aiming import attached_stop_hit, stop_hit

    lens_of, rays_of, theta = _setup(*CASES["telephoto (even aspheres, plastics, IR filter)"])
    thetas = torch.stack([theta, theta * (1 + 1e-3), theta * (1 - 1e-3)])

    def via(fn):  # noqa: ANN001, ANN202
        return lambda t: fn(lens_of(t), rays_of(t))[:2]

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the fallback's UserWarning would fail here
        xb, yb = torch.func.vmap(via(attached_stop_hit))(thetas)
    for k in range(thetas.shape[0]):
        x, y = via(stop_hit)(thetas[k])
        # (batched kernels may sum in another order than the per-sample trace: rounding only)
        torch.testing.assert_close(xb[k], x, rtol=1e-12, atol=1e-12)
        torch.testing.assert_close(yb[k], y, rtol=1e-12, atol=1e-12)
