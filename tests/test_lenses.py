"""The resolved lenses shipped in ``lenses/`` (written by ``lensopt optimize``), held to the numbers they
were made for, so that a change to the tracer or the optimizer that would break them shows here.

- ``cooke_triplet_opt.json``: the classic Cooke triplet (``specs/cooke_triplet.toml``, an independent
  published prescription) with radii and airspaces optimized at EFL 50 mm: smaller spot than the classic.
- ``cmount_4p.json``: the seed's C-mount study (S6.1) from the crude start of ``specs/cmount_4p.toml``:
  effective spot radius within 10 % of the seed's 12.9 µm (Table S15), the S6.1 requirements met, real
  glasses of the seed's Ohara recommended catalog.
- ``cmount_4p_multistart.json``: the best ESR of 20 starts of the same C-mount design (``lensopt sweep``, σ 0.05
  and 0.2, benchmarks/README.md, optimize): the same minimum as ``cmount_4p.json`` (same glasses,
  radii within 7 %), 0.02 % smaller ESR, the S6.1 requirements met.
- ``cmount_4p_raw.json``: the C-mount study's image-driven row (S6.2, Table S15 "raw image quality"),
  LM on GTRA from ``cmount_4p.json`` (``specs/cmount_4p_raw.toml``): higher held-out raw PSNR than the
  spot-optimized lens while its ESR grows, the S6.1 requirements still met, the same real glasses.
- ``cmount_4p_restored.json``: Table S15's restored row (``benchmarks/e2e/table_s15.py --polish --ship``: 100 joint
  lens + network steps of ``specs/cmount_4p_restored.toml`` from ``cmount_4p.json``, then the raw lens's polish
  to the 2 % distortion limit); S6.1 and its network in ``tests/restore/test_shipped_networks.py``.
- ``telephoto_5p_tr080.json`` and ``telephoto_5p1_middle_tr075.json``: the seed's telephoto study (S4) and
  its hybrid 5P+1 (middle) (S4.2.2), each from its crude start by the seed's procedure (S4.2.1: free plastics,
  then bound) at half the seed's 10,000 steps. The 5P: the TR sweep's TR 0.85 point (``lensopt sweep
  specs/telephoto_5p_tr080.toml --vary 'optimize.solves[0].value=…,22.015,…' --steps 5000``), its fields set
  to the seed's 11, walked to TR 0.80 (``lensopt sweep … --continuation --steps 300`` over TTL 21.6913,
  21.3675, 21.0438, 20.72), its fields set back to the spec's 5 (benchmarks/README.md, studies; the direct
  5000-step run from the crude start gives 3.06 µm). The hybrid: ``lensopt optimize
  specs/telephoto_5p1_middle_tr075.toml --steps 5000`` (converged at 3751), then 1000 steps ``--full-weight`` and
  400 with the ray-angle group at weight 100 and 59.8° (the lens's own ``[optimize]``): every Table S8
  requirement met on a dense ray sample, Table S10 plastics; their ESRs (2.90 and 4.80 µm) are above the
  seed's (≈ 1.75 and ≈ 2.6 µm). The hybrid has its phase on its own plane between E4 and E5, as its spec and
  the seed's design.
- ``microscope_8p_wd12.json``: the seed's microscope objective study (S5) after a 2400-step run (1200 with
  free glasses, 1200 bound) from the crude start of ``specs/microscope_8p_wd12_alt.toml`` (alternating
  positive and negative elements; the first start, ``specs/microscope_8p_wd12.toml``, reached 6.63 µm),
  then 1500 and 3 × 3000 more steps at full constraint weight (benchmarks/studies/full_weight_spec.py): every
  Table S12 requirement met on a dense ray sample, recommended Ohara glasses; ESR 3.57 µm against the
  seed's ≈ 0.85 µm (benchmarks/README.md, studies).
- ``microscope_8p_wd12_wavefront.json``: that lens after 244 more LM steps (240 CPU s) on the wavefront merit
  (``specs/microscope_8p_wd12_wavefront.toml``'s); held in ``tests/test_lens_wavefront.py``.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from lensopt.analysis.report import trace_report
from lensopt.analysis.requirements import check_requirements, failed, table_s8
from lensopt.materials import design_catalog
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build, dump_json, load_spec
from tests.helpers import microscope_table_s12

ROOT = Path(__file__).resolve().parents[1]
LENSES = sorted(p for p in (ROOT / "lenses").glob("*.json") if p.name != "check_baseline.json")  # not a lens
RINGS24 = PupilSampling.parse("rings:24")


def _report(path: Path) -> dict:
    return trace_report(build(load_spec(path)), RINGS24)


@pytest.mark.parametrize("path", LENSES, ids=[p.name for p in LENSES])
def test_a_shipped_lens_is_a_resolved_lens_that_traces(path: Path) -> None:
    spec = load_spec(path)
    assert dump_json(spec) == path.read_text()  # exactly what lensopt writes: re-saving changes nothing
    rep = trace_report(build(spec), RINGS24)
    assert all(f["failed_rays"] == 0 for f in rep["fields"])


def test_the_optimized_cooke_triplet_beats_the_classic_prescription() -> None:
    classic = _report(ROOT / "specs" / "cooke_triplet.toml")
    opt = _report(ROOT / "lenses" / "cooke_triplet_opt.json")
    assert opt["first_order"]["efl"] == pytest.approx(50.0, rel=1e-9)  # the EFL solve
    # The merit is the field-weighted spot size, so the ESR falls (12.50 → 12.12 µm when written);
    # single fields may trade (the axis grows 5.0 → 5.7 µm while 14° shrinks 16.4 → 15.3 µm).
    assert opt["effective_spot_radius_um"] < 0.99 * classic["effective_spot_radius_um"]


def test_the_cmount_study_reaches_the_seed_spot_size_with_its_requirements_met() -> None:
    # Seed S6.1 / Table S15: ESR 12.9 µm for this design problem; the issue asks for ≤ 10 % above it.
    path = ROOT / "lenses" / "cmount_4p.json"
    model = build(load_spec(path))
    rep = trace_report(model, RINGS24)
    assert rep["effective_spot_radius_um"] <= 1.10 * 12.9
    fo = rep["first_order"]
    assert fo["efl"] == pytest.approx(28.0, rel=1e-3)  # solved at 550 nm; the report is at the reference
    assert fo["fnumber"] == pytest.approx(2.0, rel=1e-3)
    _cmount_requirements(model, rep)


def test_the_cmount_multistart_lens_is_the_best_start_and_meets_s61() -> None:
    # lensopt sweep specs/cmount_4p.toml --vary 'optimize.solves[0].value=28.0' --starts 8 --perturb 0.2
    # --scheduler serial, start 5 (benchmarks/optimize/results_cmount_multistart.json): every start that finished ends
    # in the shipped lens's basin; this one has the smallest ESR, a hair under cmount_4p.json's.
    model = build(load_spec(ROOT / "lenses" / "cmount_4p_multistart.json"))
    rep = trace_report(model, RINGS24)
    assert rep["effective_spot_radius_um"] == pytest.approx(13.9556, rel=1e-4)  # when written
    assert rep["effective_spot_radius_um"] < _report(ROOT / "lenses" / "cmount_4p.json")["effective_spot_radius_um"]
    fo = rep["first_order"]
    assert fo["efl"] == pytest.approx(28.0, rel=1e-3) and fo["fnumber"] == pytest.approx(2.0, rel=1e-3)
    _cmount_requirements(model, rep)


def _cmount_requirements(model, rep: dict) -> None:  # noqa: ANN001
    # The S6.1 requirements, measured here on every traced ray of a dense grid plus the pupil rim (not
    # with the optimizer's own residuals): glass 1–5 mm, airspaces ≥ 0.25 mm, image clearance ≥ 20 mm,
    # angles of incidence/refraction ≤ 60°, |distortion| ≤ 2 %.
    grid = PupilSampling.parse("grid:41").points(dtype=torch.float64)
    phi = torch.linspace(0, 2 * math.pi, 65, dtype=torch.float64)[:-1]
    pupil = torch.cat([grid, torch.stack([phi.cos(), phi.sin()], -1)])
    b = trace_bundle(model.lens, model.system, pupil, record=True)
    ok = b.result.valid
    assert bool(ok.all())
    z = [h.pos[..., 2] for h in b.result.hits] + [b.result.pos[..., 2]]
    for i, surf in enumerate(model.spec.surfaces):
        tz = z[i + 1] - z[i]
        if i == len(model.spec.surfaces) - 1:
            assert float(tz.min()) >= 20.0
        elif surf.material == "air":
            assert float(tz.min()) >= 0.25
        else:
            assert 1.0 <= float(tz.min()) and float(tz.max()) <= 5.0
    cos2 = torch.stack([torch.stack([h.cos2_in, h.cos2_out]) for h in b.result.hits])
    assert math.degrees(math.acos(math.sqrt(float(cos2.min())))) <= 60.0
    assert max(abs(f["distortion_percent"]) for f in rep["fields"]) <= 2.0
    ohara = set(design_catalog("ohara-recommended").names)
    glasses = [s.material for s in model.spec.surfaces if s.material != "air"]
    assert len(glasses) == 4 and all(isinstance(g, str) and g.split(":")[-1] in ohara for g in glasses)


def test_the_raw_cmount_lens_images_better_than_the_spot_lens(cmount) -> None:
    # Seed Table S15: the raw-image-quality lens gains 0.7 dB of pre-restoration PSNR (26.2 → 26.9 dB on
    # DIV2K) while its ESR grows (12.9 → 15.5 µm). Here: held-out dead-leaves patches rendered as in the
    # run (benchmarks/e2e/run_cmount_raw.py, numbers in benchmarks/README.md), same patches for both lenses.
    from lensopt.design import build_problem

    raw_path = ROOT / "lenses" / "cmount_4p_raw.json"
    raw = build_problem(load_spec(raw_path))
    spot = cmount
    before = raw.image.held_out_psnr(spot.lens, count=8)
    after = raw.image.held_out_psnr(raw.setup.lens, count=8)
    # 13.736 → 14.189 dB on these 8 patches when written (32 patches in the run: 13.854 → 14.337 dB).
    assert before == pytest.approx(13.736, abs=0.02)
    assert after > before + 0.4
    model = build(load_spec(raw_path))
    rep = trace_report(model, RINGS24)
    assert rep["effective_spot_radius_um"] > _report(ROOT / "lenses" / "cmount_4p.json")["effective_spot_radius_um"]
    assert rep["first_order"]["efl"] == pytest.approx(28.0, rel=1e-3)
    _cmount_requirements(model, rep)


@pytest.mark.parametrize(("name", "ttl", "esr_um"), [("telephoto_5p_tr080", 20.72, 2.903),
                                                     ("telephoto_5p1_middle_tr075", 19.425, 4.797)])
def test_the_telephoto_study_lenses_meet_table_s8(name: str, ttl: float, esr_um: float) -> None:
    # Table S8 with Table S11's thresholds, measured on a dense ray sample (a 31² pupil grid and 64 rim
    # rays at 11 fields, every wavelength, with the front aperture and full aiming), not with the
    # optimizer's residuals: elements 0.25–4 mm, edge/centre 1/3–3, air ≥ 0.1 mm, flange (E5 back to the
    # sensor, across the IR filter) ≥ 5.1 mm, normals ≤ 30°, angles ≤ 60°, |distortion| ≤ 2 %,
    # relative illumination ≥ 70 %, Table S10 plastics, image height 5.1 mm, TTL = TR × 25.9 mm.
    spec = load_spec(ROOT / "lenses" / f"{name}.json")
    model = build(spec)
    glass = [s for s in spec.surfaces if not s.is_air and not (s.label or "").startswith("IR")]
    filt = [s.label for s in spec.surfaces].index("IR filter front")  # the hybrid's DOE plane moves it by one
    assert filt == (12 if name == "telephoto_5p1_middle_tr075" else 11)
    checks = check_requirements(model.lens, model.system,
                                table_s8(flange_from=filt - 1, filter_gap=filt, total_track=ttl),
                                glass_gaps=[not s.is_air for s in spec.surfaces],
                                materials=[s.material for s in glass], grid=31)
    assert failed(checks) == [], [c for c in checks if not c.ok]
    assert len(glass) == 5 and spec.system.front_aperture is not None
    # The ESR when written (rings:24), above the seed's (benchmarks/README.md, studies).
    assert trace_report(model, RINGS24)["effective_spot_radius_um"] == pytest.approx(esr_um, rel=1e-3)


def test_the_microscope_study_lens_meets_table_s12() -> None:
    # Table S12 with Table S14's thresholds on a dense ray sample: elements 1–4 mm, edge/centre 1/3–3,
    # air ≥ 0.5 mm, normals ≤ 30°, angles ≤ 60°, |distortion| ≤ 2 %, recommended Ohara glasses, EFL
    # 10 mm at f/1.25 (EPD 8 mm), WD (last gap) 12 mm, 8 spherical elements.
    spec = load_spec(ROOT / "lenses" / "microscope_8p_wd12.json")
    model, glass, checks = microscope_table_s12(spec)
    assert failed(checks) == [], [c for c in checks if not c.ok]
    assert len(glass) == 8 and all(s.type == "sphere" for s in spec.surfaces if s.type != "plane")
    assert spec.surfaces[-1].thickness == 12.0 and spec.surfaces[0].stop
    rep = trace_report(model, RINGS24)
    assert rep["first_order"]["fnumber"] == pytest.approx(1.25, rel=1e-6)
    assert rep["effective_spot_radius_um"] == pytest.approx(3.565, rel=1e-3)  # when written; the seed: ≈ 0.85


def test_the_raw_cmount_lens_is_made_by_two_specs_in_the_repo(tmp_path: Path) -> None:
    # lenses/cmount_4p_raw.json = specs/cmount_4p_raw.toml (stage 1, the 54 steps of the recorded run,
    # benchmarks/e2e/results_cmount_raw.json) then specs/stages/cmount_4p_raw_polish.toml (stage 2: 4 steps with the
    # distortion weight 1000 and max_percent 1.95, benchmarks/e2e/results_cmount_raw_polish.json). The
    # 1-hour stage 1 is not re-run here: its output is stood in for by the shipped lens, which shows that
    # the polish spec starts from stage 1's output file and that its settings are the ones the shipped
    # lens records in its [optimize] (what `lensopt optimize` writes).
    import json

    stage1 = load_spec(ROOT / "specs" / "cmount_4p_raw.toml")
    record = json.loads((ROOT / "benchmarks" / "e2e" / "results_cmount_raw.json").read_text())
    polish_record = json.loads((ROOT / "benchmarks" / "e2e" / "results_cmount_raw_polish.json").read_text())
    assert stage1.optimize.steps == record["steps"] == 54
    assert stage1.surfaces == load_spec(ROOT / "lenses" / "cmount_4p.json").surfaces  # starts from the spot lens
    polish_file = ROOT / "specs" / "stages" / "cmount_4p_raw_polish.toml"  # needs stage 1, so not in specs/
    text = polish_file.read_text()
    assert 'start = "../../out/cmount_4p_raw_stage1.json"' in text
    assert "lensopt optimize specs/cmount_4p_raw.toml -o out/cmount_4p_raw_stage1.json --seed 0" in text
    (tmp_path / "specs" / "stages").mkdir(parents=True)
    (tmp_path / "out").mkdir()
    (tmp_path / "specs" / "stages" / polish_file.name).write_text(text)
    shipped = load_spec(ROOT / "lenses" / "cmount_4p_raw.json")
    (tmp_path / "out" / "cmount_4p_raw_stage1.json").write_text(dump_json(shipped))
    polish = load_spec(tmp_path / "specs" / "stages" / polish_file.name)
    assert polish.optimize == shipped.optimize
    assert polish.optimize.steps == polish_record["steps"] == 4
    assert polish.optimize.constraints.distortion.weight == 1000.0
    assert polish.optimize.constraints.distortion.max_percent == 1.95
    # stage 2 changes only the distortion group and the step count of stage 1's [optimize]
    same = stage1.optimize.model_copy(update={"steps": 4, "constraints": stage1.optimize.constraints.model_copy(
        update={"distortion": polish.optimize.constraints.distortion})})
    assert polish.optimize == same
