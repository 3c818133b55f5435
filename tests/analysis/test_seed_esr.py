"""The seed's ESR measure (``analysis.spot.seed_esr``): 11 equally spaced fields with equal weights and a
dense full-pupil grid, whatever the spec's own fields, field weights and sampling are."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch

from lensopt.analysis.spot import SEED_FIELDS, seed_esr, spot_stats
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build, load_spec

LENS = Path(__file__).resolve().parents[2] / "lenses" / "cooke_triplet_opt.json"


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
