"""The LM Jacobian by stages (``optim.jacobian``) equals ``torch.func.jacfwd`` of the residual function.

The reference is ``Problem.jacobian_jacfwd``: forward-mode AD through the whole of ℓ(θ), which
tests/optim/test_jacobian.py holds against reverse mode and central differences. The staged Jacobian
must agree to rounding on the study specs (full aiming with a front aperture, even aspheres, a
diffractive surface, glass variables, solves, every constraint group) and on a start where rays fail
(the ray-failure term reads every hit field then).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
import torch

from lensopt.design import build_problem
from lensopt.spec import parse_spec

SPECS = Path(__file__).resolve().parents[2] / "specs"


def _study(name: str) -> dict:
    """A study spec with a small sample (three fields, rings:2): the suite stays fast."""
    data = tomllib.loads((SPECS / name).read_text())
    data["system"]["field"]["relative"] = [0.0, 0.6, 1.0]
    data["optimize"]["sampling"] = "rings:2"
    return data


def _assert_equal_by_group(p, J: torch.Tensor, ref: torch.Tensor) -> None:  # noqa: ANN001
    for name, sl in p.slices.items():
        scale = float(ref[sl].abs().max()) if ref[sl].numel() else 0.0
        err = float((J[sl] - ref[sl]).abs().max()) if ref[sl].numel() else 0.0
        assert err <= 1e-11 * max(scale, 1e-300), (name, err, scale)


@pytest.mark.parametrize("name", ["telephoto_5p_tr080.toml", "telephoto_5p1_middle_tr075.toml",
                                  "microscope_8p_wd12.toml", "cmount_4p.toml"])
def test_staged_jacobian_equals_jacfwd_on_the_studies(name: str) -> None:
    p = build_problem(parse_spec(_study(name)))
    theta = p.theta0 * (1 + 1e-3 * torch.linspace(-1, 1, p.num_variables, dtype=torch.float64))
    ref, r_ref = p.jacobian_jacfwd(theta)
    J, r = p.jacobian(theta)
    assert torch.equal(r, r_ref)
    _assert_equal_by_group(p, J, ref)
    assert float(ref.abs().max()) > 0


def test_staged_jacobian_with_failed_rays(make_cooke) -> None:  # noqa: ANN001
    data = make_cooke(sampling="rings:3", constraints={"ray_angle": {"max_deg": 40.0}})
    data["system"]["aperture"] = {"epd": 4.0 * data["system"]["aperture"]["epd"]}  # overfilled: TIR and misses
    for s in data["surfaces"][:-1]:
        s["vary"] = ["radius", "thickness"]
    p = build_problem(parse_spec(data))
    theta = p.theta0
    failed, total, _ = p.failure_summary(theta)
    assert 0 < failed < total
    ref, r_ref = p.jacobian_jacfwd(theta)
    J, r = p.jacobian(theta)
    assert torch.equal(r, r_ref)
    _assert_equal_by_group(p, J, ref)
    assert float(J[p.slices["ray_failure"]].abs().max()) > 0  # the failure margins have a gradient


def test_reusing_the_aiming_solves_of_an_evaluation_changes_no_bit() -> None:
    # LM evaluates ℓ at a trial θ before it asks for J there: the Jacobian reuses that evaluation's
    # detached aiming solves. A function of θ alone: the same bits as a Jacobian computed afresh.
    data = _study("telephoto_5p_tr080.toml")
    theta = build_problem(parse_spec(data)).theta0 * (1 + 1e-4)
    fresh = build_problem(parse_spec(data))
    J0, r0 = fresh.jacobian(theta)
    p = build_problem(parse_spec(data))
    p.evaluate(theta)
    assert p.solved_shape(theta) is not None and p.solved_shape(theta * (1 + 1e-15)) is None
    J1, r1 = p.jacobian(theta)
    assert torch.equal(J0, J1) and torch.equal(r0, r1)


def test_ramp_terms_differentiate_their_active_rows_alone() -> None:
    # Ramp terms enter stage C as constants; the derivatives of their active rows (margin ≥ 0 on a valid
    # ray) are taken on those rays alone. Against jacfwd over the whole ℓ: every other row exactly 0,
    # the active rows to rounding, ℓ bit for bit. At the C-mount start no ray-angle or ray-path row is
    # active (their hit fields are not differentiated at all); a tighter ray-angle limit makes some so.
    data = _study("cmount_4p.toml")
    p = build_problem(parse_spec(data))
    theta = p.theta0
    lens, _ = p.lens(theta)
    plan = p.ramp_plan(theta, lens, p.bundle(lens))
    assert {"ray_path", "ray_angle"} <= set(plan.given) and not plan.ramps
    assert not {"cos2_in", "cos2_out", "pos"} & {f for f, _ in plan.fields}
    for max_deg, some in ((59.9, False), (20.0, True)):
        data["optimize"]["constraints"]["ray_angle"]["max_deg"] = max_deg
        p = build_problem(parse_spec(data))
        lens, _ = p.lens(theta)
        plan = p.ramp_plan(theta, lens, p.bundle(lens))
        active = {r.name: r.rows for r in plan.ramps}
        assert ("ray_angle" in active) == some
        ref, r_ref = p.jacobian_jacfwd(theta)
        J, r = p.jacobian(theta)
        assert torch.equal(r, r_ref)
        for name in plan.given:
            block, want = J[p.slices[name]], ref[p.slices[name]]
            rows = active.get(name, torch.zeros(0, dtype=torch.long))
            off = torch.ones(block.shape[0], dtype=torch.bool)
            off[rows] = False
            assert torch.equal(block[off], torch.zeros_like(block[off])) and torch.equal(want[off], block[off])
            if rows.numel():
                assert float(want[rows].abs().max()) > 0
        _assert_equal_by_group(p, J, ref)
        if some:  # some rows, not all: the active rows alone were differentiated
            sl = p.slices["ray_angle"]
            assert 0 < active["ray_angle"].numel() < sl.stop - sl.start


def test_a_ramp_at_exactly_zero_is_active() -> None:
    # clamp_min's derivative passes at margin = 0: such a row is not quiet; failed rays do not count.
    from lensopt.optim.residuals import inactive

    valid = torch.tensor([True, True, False])
    assert inactive(torch.tensor([-1.0, -1e-300, 5.0], dtype=torch.float64), valid)
    assert not inactive(torch.tensor([-1.0, 0.0, 5.0], dtype=torch.float64), valid)
    assert not inactive(torch.tensor([-1.0, -0.0, 5.0], dtype=torch.float64), valid)
    x = torch.tensor([0.0, -1.0, -0.0], dtype=torch.float64)
    _, dot = torch.func.jvp(lambda v: torch.clamp_min(v, 0.0), (x,), (torch.ones_like(x),))
    assert dot.tolist() == [1.0, 0.0, 1.0]


def test_staged_jacobian_behind_a_vignetting_front_aperture() -> None:
    # tests/data/telephoto_vignetted.toml: the front aperture cuts V_i ≈ 0.45 at the edge of the field,
    # full aiming holds the bottom ray on its edge (4 steps). Its aiming solves' final steps are
    # differentiated through ``aiming.attached_stop_hit`` in both Jacobians; the staged one must
    # still equal jacfwd of the whole residual function.
    data = tomllib.loads((Path(__file__).resolve().parents[1] / "data" / "telephoto_vignetted.toml").read_text())
    data["system"]["field"]["relative"] = [0.0, 0.6, 1.0]
    data["optimize"] = {"sampling": "rings:2"}
    for s in data["surfaces"][:6]:
        s["vary"] = ["radius", "thickness"] if "radius" in s else ["thickness"]
    p = build_problem(parse_spec(data))
    theta = p.theta0 * (1 + 1e-4 * torch.linspace(-1, 1, p.num_variables, dtype=torch.float64))
    shape = p.launch(p.lens(theta)[0]).shape
    assert shape.full is not None and bool(shape.full.held.any())  # a held ray: the aperture's edge
    ref, r_ref = p.jacobian_jacfwd(theta)
    J, r = p.jacobian(theta)
    assert torch.equal(r, r_ref)
    _assert_equal_by_group(p, J, ref)
    assert float(ref.abs().max()) > 0


def test_rays_cut_before_stage_c_equal_rays_cut_inside() -> None:
    # ``staged_jacobian(…, rays=)`` cuts the trace and its tangents to the rays before stage C (plain
    # index copies), or takes views when they are all the rays in order. Either must give the bits of
    # cutting the dual bundle inside stage C (``take_rays`` there), for a subset, a reordering and all.
    from lensopt.optim.jacobian import staged_jacobian, take_rays

    p = build_problem(parse_spec(_study("cmount_4p.toml")))
    theta = p.theta0 * (1 + 1e-4 * torch.linspace(-1, 1, p.num_variables, dtype=torch.float64))
    n = p.launch(p.lens(theta)[0]).rays.pos.shape[:-1].numel()
    fields = ("normal", "pos", "cos2_out")

    def read(result):  # noqa: ANN001, ANN202 - the cut trace's differentiated fields, flattened
        hits = result.hits
        return torch.cat([result.pos.reshape(-1), result.dir.reshape(-1), hits[1].normal.reshape(-1),
                          hits[2].pos.reshape(-1), hits[-1].cos2_out.reshape(-1)])

    def jac(rays: torch.Tensor, before: bool) -> tuple[torch.Tensor, torch.Tensor]:
        def terms_of(t, lens, bundle, cut):  # noqa: ANN001, ANN202
            if not before:
                assert cut is None
                cut = take_rays(bundle, rays)
            return torch.cat([t * 2.0, read(cut.result)])

        return staged_jacobian(theta, lens_of=lambda t: p.lens(t)[0], launch_of=lambda lens: p.launch(lens),
                               terms_of=terms_of, hit_fields=lambda lens, bundle: fields, system=p.system,
                               rays=(lambda: rays) if before else (lambda: None))

    g = torch.Generator().manual_seed(0)
    for rays in (torch.randperm(n, generator=g)[: n // 3].sort().values, torch.randperm(n, generator=g),
                 torch.arange(n)):
        J_in, r_in = jac(rays, before=False)
        J, r = jac(rays, before=True)
        assert J.shape == (p.num_variables + rays.numel() * 13, p.num_variables)
        assert torch.equal(r, r_in) and torch.equal(J, J_in)
        assert float(J[p.num_variables:].abs().max()) > 0


def test_ramp_margins_on_some_blocks_are_those_blocks_of_all() -> None:
    # The Jacobian takes a ramp term's margins on the blocks with an active row alone (``Term.margin``'s
    # ``blocks``): they must be the same numbers, and the same derivatives, as those blocks of all the
    # margins. The telephoto study has gaps, a span, interfaces and aspheres; at its start the plan
    # takes a strict subset of each term's blocks (so test_staged_jacobian_equals_jacfwd_on_the_studies
    # holds the cut margins against jacfwd of the whole ℓ).
    from lensopt.optim.terms import term

    p = build_problem(parse_spec(_study("telephoto_5p_tr080.toml")))
    theta = p.theta0
    lens, _ = p.lens(theta)
    bundle = p.bundle(lens)
    plan = p.ramp_plan(theta, lens, bundle)
    g = torch.Generator().manual_seed(1)
    for name in ("ray_path", "ray_angle", "surface_normal"):
        margin = term(name).margin
        whole = margin(p.term_setup, lens, bundle, None)
        assert name != "ray_path" or whole.shape[0] == lens.num_surfaces + 1  # the gaps and the span
        some = torch.randperm(whole.shape[0], generator=g)[:3].sort().values.tolist()
        for blocks in ([0], [whole.shape[0] - 1], some, list(range(whole.shape[0]))):
            assert torch.equal(margin(p.term_setup, lens, bundle, blocks), whole[blocks]), (name, blocks)
    for ramp in plan.ramps:
        assert ramp.margin(lens, bundle).shape[0] < term(ramp.name).margin(p.term_setup, lens, bundle, None).shape[0]
    # Only the hits those blocks read are differentiated (``Term.reads_at``): a few of each field.
    for f in ("pos", "normal"):
        assert 0 < len({s for g, s in plan.fields if g == f}) < lens.num_surfaces - 2
    # The derivatives too: jvp along one direction of θ through the lens and the trace.
    direction = torch.linspace(-1, 1, p.num_variables, dtype=torch.float64)

    def margins(t: torch.Tensor, blocks: list[int] | None) -> torch.Tensor:
        lens_t, _ = p.lens(t)
        return term("ray_path").margin(p.term_setup, lens_t, p.bundle(lens_t), blocks)

    _, whole_dot = torch.func.jvp(lambda t: margins(t, None), (theta,), (direction,))
    blocks = [0, 5, lens.num_surfaces - 1, lens.num_surfaces]
    _, some_dot = torch.func.jvp(lambda t: margins(t, blocks), (theta,), (direction,))
    assert torch.equal(some_dot, whole_dot[blocks]) and float(some_dot.abs().max()) > 0


@pytest.mark.parametrize("ramps", [False, True])
def test_rows_placed_after_stage_c_are_the_whole_residual_functions(ramps: bool) -> None:
    # Stage C leaves the ramp terms out (their rows of ℓ come from the plan, their rows of J are 0 but
    # for the active ones, ``place_rows``). Without a ramp term J is stage C's as it is; with ramp terms
    # between other terms (ray angle and surface normal before distortion and illumination) every
    # term's rows must land in its block: ℓ bit for bit, J to rounding against jacfwd, and J laid out
    # variables first as stage C gives it (what LM's column norms and row selection read).
    from tests.helpers import small_problem_data

    data = small_problem_data()
    if ramps:
        data["optimize"]["constraints"] |= {"ray_angle": {"max_deg": 25.0}, "surface_normal": {"max_deg": 20.0}}
    p = build_problem(parse_spec(data))
    theta = p.theta0 * (1 + 1e-3 * torch.linspace(-1, 1, p.num_variables, dtype=torch.float64))
    lens, _ = p.lens(theta)
    plan = p.ramp_plan(theta, lens, p.bundle(lens))
    assert bool(plan.given) == ramps and (len(plan.ramps) == 2) == ramps
    ref, r_ref = p.jacobian_jacfwd(theta)
    J, r = p.jacobian(theta)
    assert torch.equal(r, r_ref)
    _assert_equal_by_group(p, J, ref)
    assert J.T.is_contiguous()
    for name in ("tra", "distortion", "relative_illumination"):
        assert float(ref[p.slices[name]].abs().max()) > 0, name


@pytest.mark.parametrize("max_deg", [20.0, 89.0])
def test_a_problem_of_ramp_terms_alone(make_cooke, max_deg: float) -> None:  # noqa: ANN001
    # No TRA, no failure term: every row is a ray-angle row. With none active (89°) stage C has no row
    # at all; J is still (M, N), all 0, as jacfwd's.
    data = make_cooke(tra={"weight": 0.0}, constraints={"ray_failure": {"weight": 0.0},
                                                         "ray_angle": {"max_deg": max_deg}})
    for s in (0, 2, 4):
        data["surfaces"][s]["vary"] = ["radius"]
    p = build_problem(parse_spec(data))
    assert list(p.slices) == ["ray_angle"]
    ref, r_ref = p.jacobian_jacfwd(p.theta0)
    J, r = p.jacobian(p.theta0)
    assert J.shape == ref.shape == (p.size, 3) and torch.equal(r, r_ref)
    _assert_equal_by_group(p, J, ref)
    assert (float(ref.abs().max()) > 0) == (max_deg < 45)
