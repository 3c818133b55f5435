"""The design procedure (``lensopt.study.procedure``, ``lensopt design``): rounds of starts until the best
agree, basin hopping from the best lenses, the distinct minima, resume, and one-line errors.

The starts are real optimizations of the Cooke triplet on a coarse sample (a few steps each); the rules
under test (agreement, grouping, the basin keep rule) are checked against the records on disk, written
by the starts themselves."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from lensopt.analysis.spot import seed_esr
from lensopt.errors import LensoptError
from lensopt.spec import build, load_spec, parse_spec
from lensopt.study.procedure import ProcedureSettings, agreement, minima, run_procedure

COOKE = Path(__file__).resolve().parents[2] / "specs" / "cooke_triplet_opt.toml"


def _spec(tmp: Path) -> tuple[Path, str]:
    text = COOKE.read_text().replace('sampling = "rings:8"', 'sampling = "rings:3"')
    path = tmp / "tiny.toml"
    path.write_text(text)
    return path, text


def test_multistart_rounds_resume_and_minima(tmp_path: Path) -> None:
    path, text = _spec(tmp_path)
    spec = load_spec(path)
    out = tmp_path / "run"
    st = ProcedureSettings(starts=2, rounds=2, steps=3, agree=1e-9, esr_sampling="rings:3")
    events = []
    res = run_procedure(spec, text, st, out, callback=events.append)
    names = sorted(r["name"] for r in res.records)
    assert names == ["0_0", "0_1", "0_2", "0_3"] and res.rounds == 2
    assert not res.agreed and res.stop_reason == "2 rounds without agreement"
    assert [e.kind for e in events].count("round") == 2
    doc = json.loads((out / "design.json").read_text())
    on_disk = {r["name"]: r for r in doc["starts"]}
    best = min(on_disk.values(), key=lambda r: r["merit"])
    assert doc["best"] == best["name"] == res.best["name"]
    assert (out / "best.json").read_text() == (out / "points" / f"{best['name']}.lens.json").read_text()
    # Minima: the finished starts by merit, best first; each start in exactly one group.
    merits = [m["merit"] for m in res.minima]
    assert merits == sorted(merits) and sum(m["count"] for m in res.minima) == 4
    # Each minimum reports its best start's ESR on the seed's measure, that of the lens on disk (computed here).
    for m in doc["minima"]:
        model = build(load_spec(out / "points" / f"{m['best']}.lens.json"))
        with torch.no_grad():
            want = 1e3 * float(seed_esr(model.lens, model.system))
        assert m["seed_esr_um"] == on_disk[m["best"]]["seed_esr_um"] == pytest.approx(want, rel=1e-12)
    # Resume with one more round: the four starts are read back, two more run.
    again = run_procedure(spec, text, ProcedureSettings(starts=2, rounds=3, steps=3, agree=1e-9,
                                                        esr_sampling="rings:3"), out, callback=events.append)
    assert sorted(r["name"] for r in again.records) == names + ["0_4", "0_5"]
    skipped = [e for e in events[len(events) - 2 * 3 - 3:] if e.kind == "skipped"]
    assert len(skipped) == 4
    # Other settings (another perturbation) are refused in the same folder.
    with pytest.raises(LensoptError, match="^--output: holds a design run made with another spec"):
        run_procedure(spec, text, ProcedureSettings(starts=2, rounds=1, steps=3, sigma=0.2), out)


def test_agreement_rule_and_grouping_on_records() -> None:
    recs = [{"name": f"0_{i}", "round": 0, "start": i, "status": "finished", "merit": m}
            for i, m in enumerate([1.00, 1.015, 1.3, 2.0])]
    recs.append({"name": "0_4", "round": 0, "start": 4, "status": "failed", "merit": None})
    count, best = agreement(recs, 0.02)
    assert (count, best["name"]) == (2, "0_0")
    assert agreement(recs, 0.01)[0] == 1
    groups = minima(recs, 0.02)
    assert [(g["best"], g["count"]) for g in groups] == [("0_0", 2), ("0_2", 1), ("0_3", 1)]


def test_basin_hopping_starts_from_the_best_and_keeps_only_better_hops(tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    import lensopt.study.sweep as sw

    path, text = _spec(tmp_path)
    spec = load_spec(path)
    out = tmp_path / "basin"
    st = ProcedureSettings(method="basin", starts=2, rounds=3, steps=3, hop_sigma=0.02, agree=1e-12,
                           esr_sampling="rings:3")
    weights: list[bool] = []
    real = sw.optimize

    def recording(spec, **kw):  # noqa: ANN001, ANN202
        weights.append(kw["full_weight"])
        return real(spec, **kw)

    monkeypatch.setattr(sw, "optimize", recording)
    res = run_procedure(spec, text, st, out)
    by = {r["name"]: r for r in res.records}
    assert set(by) == {"0_0", "0_1", "1_1", "2_1", "1_2", "2_2"}
    # Round 0's starts run the spec's schedules; the four hops continue bound lenses at full weight.
    assert weights == [False, False, True, True, True, True]
    # Round 0's two starts seed the chains, best first; a hop's lens is the chain's lens in the next
    # round only when its merit is lower (the hop's start lens is the perturbed chain lens).
    first = sorted(["0_0", "0_1"], key=lambda n: by[n]["merit"])
    for chain, seed_name in ((1, first[0]), (2, first[1])):
        kept = by[seed_name]["merit"]
        hop1 = by[f"{chain}_1"]
        if hop1["status"] == "finished" and hop1["merit"] < kept:
            kept = hop1["merit"]
        assert res.best["merit"] <= kept
    assert res.best["merit"] == min(r["merit"] for r in by.values() if r["status"] == "finished")


def test_bad_settings_are_one_line_errors(tmp_path: Path) -> None:
    path, text = _spec(tmp_path)
    spec = load_spec(path)
    for settings, where in ((ProcedureSettings(method="anneal"), "--method"),
                            (ProcedureSettings(agree=-1.0), "--agree"),
                            (ProcedureSettings(budget_cpu_h=0.0), "--budget-cpu-h")):
        with pytest.raises(LensoptError, match=f"^{where}:"):
            run_procedure(spec, text, settings, tmp_path / "x")
    data = json.loads(json.dumps(spec.model_dump(mode="json")))
    data["optimize"]["objective"] = "restored"
    data.setdefault("sensor", {"pixel_pitch_um": 2.0, "resolution": [64, 64]})
    with pytest.raises(LensoptError, match="^optimize.objective:"):
        run_procedure(parse_spec(data), text, ProcedureSettings(), tmp_path / "y")
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
