"""Tolerance runs: batched = per-trial, hard cases (failed rays, compensator out of range), statistics
against hand computations, worst trials written back as lenses, serial = Dask LocalCluster."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from lensopt.design.tolerance import tolerance_job, trial_spec
from lensopt.spec import build, load_spec
from lensopt.spec.tolerance import ToleranceSpec
from lensopt.tolerance.evaluate import EvalSetup, evaluate
from lensopt.tolerance.job import nominal_metrics, run_trials
from lensopt.tolerance.model import Tolerance, draw, nominal_params
from lensopt.tolerance.monte_carlo import monte_carlo, yield_table
from lensopt.tolerance.sensitivity import moments, sensitivity
from tests.helpers import CMOUNT


def _model(path: Path = CMOUNT):
    return build(load_spec(path))


def _job(model, **kw):
    data = {"profile": "s6.2", "sampling": "rings:4", "chunk": 4}
    data.update(kw)
    return tolerance_job(model, ToleranceSpec.model_validate(data))


def test_s62_profile_on_the_cmount() -> None:
    """S6.2's set: 8 curvatures (±0.1 %), 4 airspaces (±0.02 mm), 4 thicknesses (±0.01 mm), 4 glasses ×
    (index ±0.0005, Abbe ±0.5 %); the back focus is the compensator."""
    job = _job(_model())
    kinds = [(t.kind, t.limit) for t in job.tols]
    assert kinds.count(("curvature", 0.1)) == 8
    assert kinds.count(("thickness", 0.02)) == 4 and kinds.count(("thickness", 0.01)) == 4
    assert kinds.count(("index", 0.0005)) == 4 and kinds.count(("abbe", 0.5)) == 4
    assert all(t.target != job.lens.num_surfaces - 1 for t in job.tols if t.kind == "thickness")


def test_batched_equals_one_trial_at_a_time() -> None:
    job = _job(_model())
    values = draw(list(job.tols), 5, seed=3)
    batched = evaluate(job.setup, job.params(values))
    for k in range(5):
        one = evaluate(job.setup, job.params(values[k:k + 1]))
        for key in ("esr", "rms", "focus_shift", "distortion"):
            assert torch.allclose(batched[key][k], one[key][0], rtol=1e-12, atol=1e-15), key


def test_abbe_and_index_changes_follow_their_definitions() -> None:
    """Abbe +x %: V_d = (n_d − 1)/(n_F − n_C) scales by (1 + x/100) with n_d fixed (checked on the
    glass's own F, C, d indices); index +Δ: every wavelength moves by Δ; both together compose."""
    model = _model()
    job = _job(model)
    t_abbe = next(i for i, t in enumerate(job.tols) if t.kind == "abbe")
    t_ind = next(i for i, t in enumerate(job.tols) if t.kind == "index" and t.target == job.tols[t_abbe].target)
    s = job.tols[t_abbe].target
    mat = model.media[s + 1]
    lines = torch.tensor([0.5875618, 0.4861327, 0.6562725], dtype=torch.float64)  # d, F, C
    nd, nf, nc = mat.index(lines).tolist()
    n0 = model.lens.index[s + 1]
    for dv, dn in ((0.5, 0.0), (0.0, 0.0005), (0.5, 0.0005)):
        values = torch.zeros(1, len(job.tols), dtype=torch.float64)
        values[0, t_abbe], values[0, t_ind] = dv, dn
        n1 = job.params(values).index[0, s + 1]
        # The same map applied to the d, F, C lines gives V_d × (1 + dv/100) and n_d + dn:
        f = 1 + dv / 100
        d1, f1, c1 = (nd + dn + (x - nd) / f for x in (nd, nf, nc))
        assert d1 == pytest.approx(nd + dn, abs=1e-15)
        assert (d1 - dn - 1) / (f1 - c1) == pytest.approx((nd - 1) / (nf - nc) * f, rel=1e-12)
        assert torch.allclose(n1, nd + dn + (n0 - nd) / f, atol=1e-14)


def test_huge_tolerances_fail_rays_never_nan() -> None:
    model = _model()
    job = tolerance_job(model, ToleranceSpec.model_validate({
        "items": [{"kind": "curvature", "limit": 400.0}, {"kind": "airspace", "limit": 8.0},
                  {"kind": "decenter_y", "limit": 3.0, "surfaces": [3]}],
        "sampling": "rings:4", "chunk": 8}))
    mc = monte_carlo(job, 16, seed=1)
    assert mc.stats["trials_with_failed_rays"] > 0
    assert (mc.metrics["failed_rays"] > 0).sum() == mc.stats["trials_with_failed_rays"]
    for key, v in mc.metrics.items():
        assert not np.isnan(np.asarray(v, dtype=float)).any(), key
    assert not np.isnan(mc.scalar).any()
    # A trial that lost every ray of some field sorts as the worst (inf), not as a perfect lens (0).
    rms = mc.metrics["rms"]
    assert np.all(rms > 0)


def test_compensator_out_of_range_is_reported() -> None:
    model = _model()
    job = tolerance_job(model, ToleranceSpec.model_validate({
        "items": [{"kind": "airspace", "limit": 0.5, "surfaces": [2]}], "sampling": "rings:4",
        "focus_range": 0.01}))
    out = run_trials(job, torch.tensor([[0.0], [0.5]], dtype=torch.float64))
    assert bool(out["compensator_ok"][0]) and not bool(out["compensator_ok"][1])
    assert abs(out["focus_shift"][1]) == pytest.approx(0.01)
    assert np.isfinite(out["esr"]).all()


def test_compensator_without_rays_is_reported() -> None:
    """Every ray lost: no focus can be solved for; reported, metric infinite, nothing NaN."""
    model = _model()
    job = tolerance_job(model, ToleranceSpec.model_validate({
        "items": [{"kind": "decenter_y", "limit": 100.0, "surfaces": [1]}], "sampling": "rings:4"}))
    out = run_trials(job, torch.tensor([[100.0]], dtype=torch.float64))
    assert not bool(out["compensator_ok"][0])
    assert math.isinf(float(out["esr"][0]))
    assert not np.isnan(out["focus_shift"]).any()


def test_yield_table_matches_order_statistics() -> None:
    v = np.arange(1.0, 101.0)  # 1..100
    rows = yield_table(v, higher_is_better=False)
    assert [r["value"] for r in rows] == [50.0, 80.0, 90.0, 95.0, 99.0]
    for r in rows:
        assert r["ci_low"] <= r["value"] <= r["ci_high"]
    # 50 %: n p = 50, half-width 1.96·sqrt(25) = 9.8 → ranks 40..60 (1-based, floor/ceil) → values 40, 60.
    assert (rows[0]["ci_low"], rows[0]["ci_high"]) == (40.0, 60.0)
    high = yield_table(v, higher_is_better=True)
    assert high[0]["value"] == 51.0 and high[2]["value"] == 11.0


def test_distribution_moments() -> None:
    """Uniform on ±a: a²/3, a⁴/5; normal σ = a/2: σ², 3σ⁴; truncated at ±2σ, against numeric integrals."""
    assert moments("uniform", 2.0) == pytest.approx((4 / 3, 16 / 5))
    assert moments("normal", 2.0) == pytest.approx((1.0, 3.0))
    x = np.linspace(-2, 2, 400001)
    pdf = np.exp(-x * x / 2)
    pdf /= np.trapezoid(pdf, x)
    e2, e4 = np.trapezoid(x**2 * pdf, x), np.trapezoid(x**4 * pdf, x)
    assert moments("truncnormal", 2.0) == pytest.approx((e2, e4), rel=1e-6)  # σ = 1, cut at ±2σ
    vals = draw([Tolerance("thickness", 0, 0.3, "truncnormal")], 20000, seed=0).numpy()
    assert np.abs(vals).max() <= 0.3 and float(vals.var()) == pytest.approx(moments("truncnormal", 0.3)[0],
                                                                              rel=0.05)


def test_sensitivity_and_worst_trial_roundtrip(tmp_path: Path) -> None:
    model = _model()
    job = _job(model)
    nominal = nominal_metrics(job)
    rows, target = sensitivity(job, nominal)
    assert len(rows) == len(job.tols)
    assert all(rows[i].worst >= rows[i + 1].worst for i in range(len(rows) - 1))
    # Inverse sensitivity: the quadratic fit through ±limit gives the target change at ±inverse.
    for r in rows[:5]:
        if math.isfinite(r.inverse):
            x = r.inverse
            reached = [abs(r.linear * sx + r.quadratic * sx * sx) for sx in (x, -x)]
            assert min(abs(v - target) for v in reached) <= 1e-9 * target
    mc = monte_carlo(job, 6, seed=2)
    k = mc.worst(1)[0]
    spec = trial_spec(model, job.params(torch.from_numpy(mc.values[k:k + 1])), float(mc.metrics["focus_shift"][k]),
                      name="worst")
    rebuilt = build(spec)
    p, _ = nominal_params(rebuilt.lens)
    setup = EvalSetup(rebuilt.lens, rebuilt.system, None, job.setup.pupil, job.setup.half, compensate="none")
    esr = float(evaluate(setup, p)["esr"][0]) * 1e3
    assert esr == pytest.approx(float(mc.scalar[k]), rel=1e-9)


def test_same_seed_serial_and_two_worker_local_cluster() -> None:
    pytest.importorskip("distributed")
    job = _job(_model(), chunk=3)
    serial = monte_carlo(job, 8, seed=5)
    dask = monte_carlo(job, 8, seed=5, scheduler="local", workers=2)
    np.testing.assert_array_equal(serial.values, dask.values)
    for key in serial.metrics:
        np.testing.assert_allclose(serial.metrics[key], dask.metrics[key], rtol=1e-13, atol=0)
    assert [r["value"] for r in serial.yields] == pytest.approx([r["value"] for r in dask.yields], rel=1e-13)


def _one_variable_cmount():
    """The C-mount with a single spec variable: the radius of surface 7 (an LM compensator)."""
    from lensopt.spec.io import parse_spec

    data = load_spec(CMOUNT).model_dump(exclude_none=True)
    for i, surf in enumerate(data["surfaces"]):
        surf["vary"] = ["radius"] if i == 7 else []
    return build(parse_spec(data))


def test_lm_compensator_never_worse_than_focus_and_reports_convergence() -> None:
    model = _one_variable_cmount()
    base = {"profile": "s6.2", "sampling": "rings:3"}
    values = draw(list(_job(model, **base).tols), 2, seed=7) * 4
    focus = run_trials(_job(model, **base), values)
    lm_job = _job(model, **base, compensator="lm", lm_steps=6)
    assert lm_job.setup.lm_vars == (("curvature", 7),)
    lm = run_trials(lm_job, values)
    # LM starts from the focus-compensated lens and accepts only steps that lower the ESR.
    assert np.all(lm["esr"] <= focus["esr"] * (1 + 1e-12))
    assert np.any(lm["esr"] < focus["esr"] * (1 - 1e-4))
    assert lm["compensator_ok"].all()  # one variable, 6 steps: converged
    one = run_trials(_job(model, **base, compensator="lm", lm_steps=1), values)
    assert not one["compensator_ok"].any()  # one damped step does not converge: reported, not raised
    # The written trial carries the LM offset: rebuilt and traced, it has the trial's ESR.
    k = int(np.argmax(lm["esr"]))
    spec = trial_spec(model, lm_job.params(values[k:k + 1]), float(lm["focus_shift"][k]), name="t",
                      lm_vars=lm_job.setup.lm_vars, lm_offsets=lm["lm_offsets"][k])
    rebuilt = build(spec)
    p, _ = nominal_params(rebuilt.lens)
    setup = EvalSetup(rebuilt.lens, rebuilt.system, None, lm_job.setup.pupil, lm_job.setup.half, compensate="none")
    assert float(evaluate(setup, p)["esr"][0]) == pytest.approx(float(lm["esr"][k]), rel=1e-9)


def test_mtf_metric_equals_the_analysis_mtf() -> None:
    """The per-trial MTF (vmapped, half pupil with the mirrored half folded in) is lensopt.analysis.mtf's
    heuristic MTF of the same lens and rays."""
    from lensopt.analysis.mtf import lens_mtf

    model = _model()
    job = _job(model, compensator="none", mtf_frequency=40.0, sampling="rings:6")
    out = run_trials(job, torch.zeros(1, len(job.tols), dtype=torch.float64))
    ref = lens_mtf(model.lens, model.system, torch.tensor([40.0], dtype=torch.float64), sampling="rings:6")
    assert np.allclose(out["mtf_s"][0], ref.sagittal[:, 0].numpy(), rtol=0, atol=1e-12)
    assert np.allclose(out["mtf_t"][0], ref.tangential[:, 0].numpy(), rtol=0, atol=1e-12)
