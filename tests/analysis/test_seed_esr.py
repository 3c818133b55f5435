"""The seed's ESR measure (``analysis.spot.seed_esr``): 11 equally spaced fields with equal weights and a
dense full-pupil grid, whatever the spec's own fields, field weights and sampling are."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import torch

from lensopt.analysis.report import seed_esr_um
from lensopt.analysis.spot import SEED_FIELDS, seed_esr, spot_stats
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build, load_spec

ROOT = Path(__file__).resolve().parents[2]
LENS = ROOT / "lenses" / "cooke_triplet_opt.json"


def test_the_measure_ignores_the_specs_fields_and_weights() -> None:
    model = build(load_spec(LENS), dtype=torch.float64)
    system = model.system
    with torch.no_grad():
        esr = seed_esr(model.lens, system)
        other = dataclasses.replace(system, rel_field=(0.0, 0.9), field_weights=(5.0, 1.0))
        assert float(seed_esr(model.lens, other)) == float(esr)
        # By hand: the RMS spot radius of each of the 11 fields on the 61 × 61 grid, then the root of
        # their plain mean square (equal field weights).
        pupil = PupilSampling.parse("grid:61").points(dtype=torch.float64)
        radii = []
        for u in torch.linspace(0, 1, SEED_FIELDS, dtype=torch.float64):
            b = trace_bundle(model.lens, system, pupil, rel_field=u.reshape(1))
            radii.append(float(spot_stats(b, system.wavelength_weights).rms_radius[0]))
    assert abs(float(esr) - (sum(r * r for r in radii) / len(radii)) ** 0.5) <= 1e-12 * float(esr)
    # A spec optimized on a coarse sample reports a different number of its own: the measures differ.
    own = spot_stats(trace_bundle(model.lens, system, PupilSampling.parse("rings:3").points(dtype=torch.float64)),
                     system.wavelength_weights).effective_radius
    assert abs(float(own) - float(esr)) > 1e-6 * float(esr)



def test_the_reported_value_is_the_issues_number_and_null_for_a_dead_lens(tmp_path: Path) -> None:
    model = build(load_spec(ROOT / "lenses" / "cmount_4p.json"), dtype=torch.float64)
    with torch.no_grad():
        mm = float(seed_esr(model.lens, model.system))
    reported = seed_esr_um(model)
    assert reported == 1e3 * mm
    # Issue 25's table ("lensopt now", C-mount 4P: 13.43 µm), to the third decimal it was measured at.
    assert abs(reported - 13.438) <= 1e-3
    # A lens whose rays all fail (gaps of 900 m) has no spot to measure: None, not the 0 of a masked mean.
    text = (ROOT / "specs" / "cooke_triplet.toml").read_text()
    dead = re.sub(r"^thickness = .*$", "thickness = 9e5", text, flags=re.M)
    assert dead != text
    (tmp_path / "dead.toml").write_text(dead)
    assert seed_esr_um(build(load_spec(tmp_path / "dead.toml"))) is None
