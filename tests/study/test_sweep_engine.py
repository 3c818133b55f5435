"""The sweep engine (lensopt.study.sweep): perturbed starts are deterministic and really move θ0 (start 0
is the spec itself); a 2-worker Dask LocalCluster gives the serial run's numbers to the last digit; the
best start is the minimum of the per-start results on disk; start 0 equals a plain ``optimize`` of a
spec edited by hand; a re-run computes nothing; another manifest is refused; a start that cannot run
is recorded as failed, not fatal."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

import lensopt.study.sweep as sw
from lensopt.analysis.spot import seed_esr
from lensopt.design import build_problem, optimize
from lensopt.errors import LensoptError
from lensopt.spec import build, load_spec
from lensopt.spec.io import dump_json
from lensopt.study.keys import parse_vary, set_key
from lensopt.study.sweep import Settings, perturbed_spec, run_sweep

COOKE = Path(__file__).resolve().parents[2] / "specs" / "cooke_triplet_opt.toml"
VARY = "optimize.solves[0].value=48.0,52.0"
SETTINGS = Settings(starts=2, sigma=0.05, steps=4, seed=0, esr_sampling="rings:4")


def tiny_text() -> str:
    """The Cooke spec with coarse optimization rays (rings:3): a fast, real optimization."""
    text = COOKE.read_text()
    assert 'sampling = "rings:8"' in text
    return text.replace('sampling = "rings:8"', 'sampling = "rings:3"')


def _spec(tmp: Path, text: str | None = None) -> tuple[Path, str]:
    path = tmp / "tiny.toml"
    path.write_text(text or tiny_text())
    return path, path.read_text()


def _run(out: Path, spec_path: Path, text: str, settings: Settings = SETTINGS, **kw: object) -> sw.SweepResult:
    return run_sweep(load_spec(spec_path), text, [parse_vary(VARY)], settings, out, plot=False, **kw)


@pytest.fixture(scope="module")
def serial(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, sw.SweepResult, Path, str]:
    tmp = tmp_path_factory.mktemp("sweep")
    spec_path, text = _spec(tmp)
    out = tmp / "serial"
    return out, _run(out, spec_path, text), spec_path, text


def _numbers(rec: dict) -> dict:
    return {k: v for k, v in rec.items() if k != "wall_s"}


def test_perturbation_is_deterministic_and_moves_theta() -> None:
    spec = load_spec(COOKE)
    st = Settings(starts=3, sigma=0.05)
    assert perturbed_spec(spec, 0, 0, st) is spec  # start 0 is the spec as written
    a, b = perturbed_spec(spec, 1, 1, st), perturbed_spec(spec, 1, 1, st)
    assert dump_json(a) == dump_json(b)
    assert dump_json(a) != dump_json(perturbed_spec(spec, 1, 2, st)) != dump_json(perturbed_spec(spec, 0, 1, st))
    theta0 = build_problem(spec).theta0
    theta1 = build_problem(a).theta0
    # Independent of the engine's code: the documented rule θ0 + σ·max(|θ0|, floor)·z, z from
    # numpy's default_rng([seed, point, start]); θ of the written-back spec reads it back.
    z = np.random.default_rng([0, 1, 1]).standard_normal(theta0.shape[0])
    want = theta0 + 0.05 * torch.clamp(theta0.abs(), min=0.1) * torch.from_numpy(z)
    torch.testing.assert_close(theta1, want, rtol=1e-12, atol=1e-12)
    assert bool((theta1 != theta0).all())
    rel = ((theta1 - theta0) / torch.clamp(theta0.abs(), min=0.1)).abs()
    assert 0.001 < float(rel.max()) < 0.3  # a few per cent, as σ = 0.05 asks


def test_dask_two_workers_equals_serial(serial: tuple[Path, sw.SweepResult, Path, str], tmp_path: Path) -> None:
    out, res, spec_path, text = serial
    assert res.complete and res.computed == 4 and res.skipped == 0
    dask = _run(tmp_path / "dask", spec_path, text, scheduler="local", workers=2)
    assert dask.complete and dask.computed == 4
    for key, rec in res.records.items():
        assert _numbers(dask.records[key]) == _numbers(rec)  # every number, to the last digit
    assert [{k: v for k, v in r.items() if k != "wall_s"} for r in dask.rows] == \
           [{k: v for k, v in r.items() if k != "wall_s"} for r in res.rows]
    for f in (out / "points").glob("*.lens.json"):
        assert (tmp_path / "dask" / "points" / f.name).read_bytes() == f.read_bytes()


def test_best_is_the_minimum_of_the_starts_on_disk(serial: tuple[Path, sw.SweepResult, Path, str]) -> None:
    out, res, _, _ = serial
    table = json.loads((out / "sweep.json").read_text())["points"]
    for row in table:
        recs = [json.loads((out / "points" / f"{row['point']}_{k}.json").read_text()) for k in range(2)]
        merits = [r["merit"] for r in recs if r["status"] == "finished"]
        assert row["best_merit"] == min(merits)
        k = next(r["start"] for r in recs if r["merit"] == min(merits))
        assert row["best_start"] == k and row["best_esr_um"] == recs[k]["esr_um"]
        assert (out / f"best_{row['point']}.json").read_bytes() == \
               (out / "points" / f"{row['point']}_{k}.lens.json").read_bytes()
        # The seed's measure of the best lens, beside the ESR: ``seed_esr`` of the lens file, computed here.
        model = build(load_spec(out / f"best_{row['point']}.json"))
        with torch.no_grad():
            want = 1e3 * float(seed_esr(model.lens, model.system))
        assert row["best_seed_esr_um"] == recs[k]["seed_esr_um"] == pytest.approx(want, rel=1e-12)
    csv_lines = (out / "sweep.csv").read_text().splitlines()
    assert csv_lines[0].startswith("point,optimize.solves[0].value,best_esr_um,best_merit,best_start")
    assert csv_lines[0].endswith(",wall_s,best_seed_esr_um")  # added last: the columns before keep their places
    assert len(csv_lines) == 3 and csv_lines[1].startswith("0,48.0,")


def test_start_zero_equals_plain_optimize_of_a_hand_edited_spec(serial: tuple[Path, sw.SweepResult, Path, str],
                                                                tmp_path: Path) -> None:
    out, res, _, _ = serial
    text = tiny_text()
    assert "value = 50.0 }]" in text
    spec_path, _ = _spec(tmp_path, text.replace("value = 50.0 }]", "value = 52.0 }]"))  # point 1, by hand
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as every sweep task does
    try:
        result = optimize(load_spec(spec_path), steps=4, seed=0)
    finally:
        torch.set_num_threads(threads)
    assert (out / "points" / "1_0.lens.json").read_text() == dump_json(result.spec)
    rec = res.records[(1, 0)]
    assert rec["steps"] == result.steps and rec["stop_reason"] == result.stop_reason
    assert rec["start_merit"] == result.start_merit


def test_rerun_computes_nothing_and_resumes_a_missing_task(serial: tuple[Path, sw.SweepResult, Path, str],
                                                           tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out, res, spec_path, text = serial
    calls: list[int] = []
    real = sw.optimize

    def counting(spec, **kw):  # noqa: ANN001, ANN202
        calls.append(1)
        return real(spec, **kw)

    monkeypatch.setattr(sw, "optimize", counting)
    again = _run(out, spec_path, text)
    assert calls == [] and again.skipped == 4 and again.computed == 0
    assert [r["best_merit"] for r in again.rows] == [r["best_merit"] for r in res.rows]
    # A run killed before task (0, 1) was written: only that task runs again.
    copy = tmp_path / "copy"
    copy.mkdir()
    (copy / "points").mkdir()
    (copy / "manifest.json").write_bytes((out / "manifest.json").read_bytes())
    for f in (out / "points").iterdir():
        if not f.name.startswith("0_1."):
            (copy / "points" / f.name).write_bytes(f.read_bytes())
    resumed = _run(copy, spec_path, text)
    assert len(calls) == 1 and resumed.computed == 1 and resumed.skipped == 3
    assert _numbers(resumed.records[(0, 1)]) == _numbers(res.records[(0, 1)])


def test_manifest_mismatch_is_refused_unless_restart(serial: tuple[Path, sw.SweepResult, Path, str],
                                                     tmp_path: Path) -> None:
    out, _, spec_path, text = serial
    copy = tmp_path / "m"
    copy.mkdir()
    (copy / "manifest.json").write_bytes((out / "manifest.json").read_bytes())
    other = Settings(starts=1, sigma=0.05, steps=3, seed=0, esr_sampling="rings:4")
    with pytest.raises(LensoptError, match="^--output: holds a sweep made with another spec"):
        _run(copy, spec_path, text, other)
    with pytest.raises(LensoptError, match="^--output: holds a sweep"):
        _run(copy, spec_path, text + "\n# edited\n")
    res = _run(copy, spec_path, text, other, restart=True)
    assert res.complete and res.computed == 2
    stray = tmp_path / "stray"
    stray.mkdir()
    (stray / "notes.txt").write_text("mine")
    with pytest.raises(LensoptError, match="not a sweep folder"):
        _run(stray, spec_path, text, other)


def test_unusable_start_is_recorded_as_failed(tmp_path: Path) -> None:
    spec_path, text = _spec(tmp_path)
    # σ = 2: start 1 of point 0 (z from default_rng([0, 0, 1])) puts the image distance below zero.
    st = Settings(starts=2, sigma=2.0, steps=2, seed=0, esr_sampling="rings:3")
    res = run_sweep(load_spec(spec_path), text, [parse_vary("optimize.solves[0].value=50.0")], st, tmp_path / "o",
                    plot=False)
    rec = res.records[(0, 1)]
    assert rec["status"] == "failed" and rec["reason"].startswith("the perturbed start is unusable: image distance")
    row = res.rows[0]
    assert row["starts_failed"] == 1 and row["starts_finished"] == 1 and row["best_start"] == 0
    assert not (tmp_path / "o" / "points" / "0_1.lens.json").exists()
    assert math.isfinite(row["best_merit"])


def test_bad_value_fails_before_any_work(tmp_path: Path) -> None:
    spec_path, text = _spec(tmp_path)
    spec = load_spec(spec_path)
    with pytest.raises(LensoptError, match="^--vary: surfaces\\[0\\].material=NOPE makes an unusable lens"):
        run_sweep(spec, text, [parse_vary("surfaces[0].material=SK16,NOPE")], SETTINGS, tmp_path / "x")
    assert not (tmp_path / "x").exists()
    assert set_key(spec, "optimize.solves[0].value", 48.0).optimize.solves[0].value == 48.0


def test_restored_objective_is_refused(tmp_path: Path) -> None:
    spec = load_spec(COOKE.parent / "cmount_4p_restored.toml")
    with pytest.raises(LensoptError, match="^optimize.objective: at optimize.steps=1: sweeps run the spot"):
        sw.expand_grid(spec, [parse_vary("optimize.steps=1")])


def test_perturbation_to_a_negative_glass_thickness_is_a_lensopt_error() -> None:
    # C-mount varies glass thicknesses; σ = 3 drives some of them below zero, which the spec cannot
    # hold: the start must fail as a LensoptError (recorded), never as a validation crash.
    spec = load_spec(COOKE.parent / "cmount_4p.toml")
    st = Settings(starts=6, sigma=3.0)
    outcomes = []
    for k in range(1, 6):
        try:
            perturbed_spec(spec, 0, k, st)
            outcomes.append("ok")
        except LensoptError as err:
            outcomes.append(str(err))
    assert any("glass element thickness" in o for o in outcomes), outcomes


def test_continuation_starts_each_point_from_the_previous_best_lens(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    spec_path, text = _spec(tmp_path)
    st = Settings(starts=1, steps=3, seed=0, esr_sampling="rings:3", continuation=True)
    vary = parse_vary("optimize.solves[0].value=52.0,48.0,46.0")
    seen: list[dict] = []
    real = sw.optimize

    def capturing(spec, **kw):  # noqa: ANN001, ANN202
        seen.append(json.loads(dump_json(spec)))
        return real(spec, **kw)

    monkeypatch.setattr(sw, "optimize", capturing)
    out = tmp_path / "walk"
    res = run_sweep(load_spec(spec_path), text, [vary], st, out, plot=False)
    assert res.complete and res.computed == 3 and len(seen) == 3
    base = json.loads(dump_json(load_spec(spec_path)))
    # Point 0 starts from the spec (value set), points 1 and 2 from the lens the point before wrote, its value set.
    assert seen[0]["surfaces"] == base["surfaces"] and seen[0]["optimize"]["solves"][0]["value"] == 52.0
    for i, value in ((1, 48.0), (2, 46.0)):
        before = json.loads((out / "points" / f"{i - 1}_0.lens.json").read_text())
        assert seen[i]["surfaces"] == before["surfaces"] != base["surfaces"]
        assert seen[i]["optimize"]["solves"][0]["value"] == value
        assert before["optimize"]["solves"][0]["value"] == [52.0, 48.0][i - 1]
    # The manifest says it is a continuation (a plain sweep of the same grid is refused in this folder), and a
    # run stopped after point 0 resumes there: point 1 from point 0's lens on disk, to the same numbers.
    with pytest.raises(LensoptError, match="^--output: holds a sweep"):
        run_sweep(load_spec(spec_path), text, [vary], Settings(starts=1, steps=3, seed=0, esr_sampling="rings:3"),
                  out, plot=False)
    copy = tmp_path / "copy"
    (copy / "points").mkdir(parents=True)
    (copy / "manifest.json").write_bytes((out / "manifest.json").read_bytes())
    for f in (out / "points").glob("0_0.*"):
        (copy / "points" / f.name).write_bytes(f.read_bytes())
    seen.clear()
    resumed = run_sweep(load_spec(spec_path), text, [vary], st, copy, plot=False)
    assert resumed.computed == 2 and resumed.skipped == 1 and len(seen) == 2
    for i in (1, 2):
        assert _numbers(resumed.records[(i, 0)]) == _numbers(res.records[(i, 0)])
        assert (copy / "points" / f"{i}_0.lens.json").read_bytes() == (out / "points" / f"{i}_0.lens.json").read_bytes()


def test_continuation_stops_where_a_point_has_no_finished_start(tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    spec_path, text = _spec(tmp_path)
    st = Settings(starts=1, steps=2, seed=0, esr_sampling="rings:3", continuation=True)

    def failing(spec, **kw):  # noqa: ANN001, ANN202
        raise LensoptError("no rays reach the image")

    monkeypatch.setattr(sw, "optimize", failing)
    res = run_sweep(load_spec(spec_path), text, [parse_vary("optimize.solves[0].value=50.0,48.0")], st,
                    tmp_path / "o", plot=False)
    assert res.records[(0, 0)]["reason"] == "no rays reach the image"
    assert res.records[(1, 0)] == {"point": 1, "start": 0, "status": "failed", "wall_s": 0.0,
                                   "reason": "the continuation stopped: point 0 has no finished start"}
    assert res.complete and [r["best_start"] for r in res.rows] == [None, None]
    with pytest.raises(LensoptError, match="^--continuation: a continuation walks along one key"):
        run_sweep(load_spec(spec_path), text, [parse_vary("optimize.solves[0].value=50.0"),
                                               parse_vary("optimize.steps=2,3")], st, tmp_path / "o2", plot=False)
    assert not (tmp_path / "o2").exists()
