"""The resolved lenses shipped in ``lenses/`` (written by ``lensopt optimize``), held to the numbers they
were made for, so that a change to the tracer or the optimizer that would break them shows here.

- ``cooke_triplet_opt.json``: the classic Cooke triplet (``specs/cooke_triplet.toml``, an independent
  published prescription) with radii and airspaces optimized at EFL 50 mm: smaller spot than the classic.
- ``cmount_4p.json``: the seed's C-mount study (S6.1) from the crude start of ``specs/cmount_4p.toml``:
  effective spot radius within 10 % of the seed's 12.9 µm (Table S15), the S6.1 requirements met, real
  glasses of the seed's Ohara recommended catalog.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from lensopt.analysis.report import trace_report
from lensopt.materials import design_catalog
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build, dump_json, load_spec

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
