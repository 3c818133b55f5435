"""Two-dimensional fields in tolerance trials (``[tolerance] fields``, issue 12).

- A rotationally symmetric lens gives the same ESR (and the same per-field spots) at ±x and ±y as at
  +y: the pupil samples turn with the field, so the rays of field (h, 0) are the rays of (0, h) turned
  by 90° — exact up to rounding.
- A lens with one y-decentered surface: the ±y fields differ (the lens is no longer symmetric about
  x), ±x stay mirror images; every field's centroid and RMS spot equal those of optiland (0.6.3), which
  launches its own rays for the normalized field (Hx, Hy) and pupil point (Px, Py) and traces them
  through its own coordinate systems: ≤ 1e-9 mm.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from lensopt.design.tolerance import tolerance_job
from lensopt.errors import LensoptError
from lensopt.spec import build, load_spec
from lensopt.spec.models import LensSpec
from lensopt.spec.tolerance import ToleranceSpec
from lensopt.tolerance.evaluate import evaluate
from lensopt.tolerance.monte_carlo import monte_carlo

ROOT = Path(__file__).resolve().parents[2]


def _model(single_wavelength: bool = False):
    spec = load_spec(ROOT / "specs" / "cooke_triplet.toml")
    if single_wavelength:
        data = spec.model_dump(exclude_none=True)
        data["spectrum"] = {"wavelengths_nm": [550.0], "weights": [1.0], "reference_nm": 550.0}
        spec = LensSpec.model_validate(data)
    return build(spec)


def _settings(fields, **kw) -> ToleranceSpec:
    base = {"items": [{"kind": "decenter_y", "limit": 0.1, "surfaces": [1]}], "compensator": "none",
            "sampling": "rings:8", "fields": fields}
    base.update(kw)
    return ToleranceSpec.model_validate(base)


@pytest.mark.parametrize(("compensator", "aim"), [("none", "none"), ("focus", "none"), ("focus", "chief")])
def test_symmetric_lens_same_esr_at_every_azimuth(compensator: str, aim: str) -> None:
    model = _model()
    values = torch.tensor([[0.0]], dtype=torch.float64)
    # A thickness tolerance keeps the lens symmetric (no placement: the +y run uses the half pupil).
    items = [{"kind": "thickness", "limit": 0.05, "surfaces": [0]}]
    y = tolerance_job(model, _settings("y", items=items, compensator=compensator, mtf_frequency=30.0, aim=aim))
    xy = tolerance_job(model, _settings("xy", items=items, compensator=compensator, mtf_frequency=30.0, aim=aim))
    assert y.setup.half and not xy.setup.half
    values = torch.tensor([[0.0], [0.04]], dtype=torch.float64)
    a, b = evaluate(y.setup, y.params(values)), evaluate(xy.setup, xy.params(values))
    assert torch.allclose(a["esr"], b["esr"], rtol=0, atol=1e-12)
    assert torch.allclose(a["focus_shift"], b["focus_shift"], rtol=0, atol=1e-12)
    # Fields of "xy": 0, then (0, ±h), (±h, 0) per system field: the same RMS spot and MTF four times.
    rel = model.system.rel_field
    assert xy.setup.field_xy.tolist()[:5] == [[0.0, 0.0], [0.0, rel[1]], [0.0, -rel[1]], [rel[1], 0.0],
                                              [-rel[1], 0.0]]
    for f in range(1, len(rel)):
        cols = slice(1 + 4 * (f - 1), 1 + 4 * f)
        for key in ("rms", "mtf_s", "mtf_t"):
            got = b[key][:, cols]
            assert torch.allclose(got, a[key][:, f:f + 1].expand_as(got), rtol=0, atol=1e-12), key
    assert torch.allclose(a["distortion"], b["distortion"], rtol=0, atol=1e-10)
    # The centroids turn with the field: (0, −h) at −ȳ, (h, 0) at (ȳ, 0).
    cy = a["centroid"][:, 1, 1]
    assert torch.allclose(b["centroid"][:, 2, 1], -cy, atol=1e-12)
    assert torch.allclose(b["centroid"][:, 3, 0], cy, atol=1e-12)
    assert b["centroid"][:, 3, 1].abs().max() < 1e-12


@pytest.mark.filterwarnings("ignore:paraxial ray tracing")
def test_decentered_lens_fields_match_optiland() -> None:
    pytest.importorskip("optiland")
    from optiland import optic as ol_optic
    from optiland.materials import IdealMaterial

    model = _model(single_wavelength=True)
    lens, system = model.lens, model.system
    fields = [[0.0, 1.0], [0.0, -1.0], [1.0, 0.0], [-1.0, 0.0], [0.6, 0.8]]
    job = tolerance_job(model, _settings(fields))
    dy = 0.1
    out = evaluate(job.setup, job.params(torch.tensor([[dy]], dtype=torch.float64)))
    rms, centroid = out["rms"][0].numpy(), out["centroid"][0].numpy()
    # The lens is not symmetric about x: the ±y fields differ by far more than rounding; ±x mirror.
    assert abs(rms[0] - rms[1]) > 1e-6  # 0.03 µm of 13.5 µm here: 10⁹ × rounding
    assert abs(centroid[0, 1] + centroid[1, 1]) > 1e-3
    assert rms[2] == pytest.approx(rms[3], abs=1e-12)
    assert centroid[2, 0] == pytest.approx(-centroid[3, 0], abs=1e-12)

    index = lens.index[:, 0].tolist()
    o = ol_optic.Optic()
    o.surfaces.add(index=0, radius=math.inf, thickness=math.inf, material=IdealMaterial(n=index[0]))
    for i in range(lens.num_surfaces):
        c = float(lens.curvature[i])
        kw = {"dy": dy} if i == 1 else {}
        o.surfaces.add(index=i + 1, radius=math.inf if c == 0 else 1.0 / c, thickness=float(lens.thickness[i]),
                       is_stop=(i == lens.stop), material=IdealMaterial(n=index[i + 1]), **kw)
    o.surfaces.add(index=lens.num_surfaces + 1)
    o.set_aperture("EPD", float(system.epd))
    o.fields.set_type("angle")
    o.fields.add(y=0.0)
    o.fields.add(y=system.field_max)
    o.wavelengths.add(value=float(lens.wavelength_um[0]), is_primary=True)
    pupil = job.setup.pupil.numpy()
    for f, (hx, hy) in enumerate(fields):
        # The pupil samples of field (hx, hy): the +y samples turned by the field's azimuth (here
        # tan θ_x : tan θ_y = tan(0.6·20°) : tan(0.8·20°), not 0.6 : 0.8).
        tx, ty = math.tan(math.radians(hx * system.field_max)), math.tan(math.radians(hy * system.field_max))
        sx, sy = tx / math.hypot(tx, ty), ty / math.hypot(tx, ty)
        px = pupil[:, 0] * sy + pupil[:, 1] * sx
        py = -pupil[:, 0] * sx + pupil[:, 1] * sy
        rays = o.trace_generic(hx, hy, np.ascontiguousarray(px), np.ascontiguousarray(py),
                               float(lens.wavelength_um[0]))
        xy = np.stack([np.asarray(rays.x), np.asarray(rays.y)], -1)
        c = xy.mean(0)
        r = math.sqrt(((xy - c) ** 2).sum(-1).mean())
        assert np.abs(centroid[f] - c).max() <= 1e-9, (f, centroid[f], c)
        assert abs(rms[f] - r) <= 1e-9, (f, rms[f], r)


def test_fields_setting_is_checked_and_monte_carlo_runs() -> None:
    with pytest.raises(ValueError):
        ToleranceSpec.model_validate({"profile": "s6.2", "fields": []})
    with pytest.raises(ValueError):
        ToleranceSpec.model_validate({"profile": "s6.2", "fields": "x"})
    model = _model()
    job = tolerance_job(model, _settings("xy", items=[{"kind": "decenter_y", "limit": 0.05},
                                                 {"kind": "tilt_x", "limit": 2.0}], compensator="focus"))
    mc = monte_carlo(job, 6, 0)
    assert mc.metrics["rms"].shape == (6, 9) and np.isfinite(mc.scalar).all()
    axis = tolerance_job(model, _settings([[0.0, 0.0]], items=[{"kind": "decenter_y", "limit": 0.05}]))
    out = evaluate(axis.setup, axis.params(torch.tensor([[0.0] * len(axis.tols)], dtype=torch.float64)))
    assert float(out["distortion"][0]) == 0.0 and torch.isfinite(out["esr"]).all()


def test_cli_fields_option() -> None:
    from lensopt.cli.tolerance import parse_fields

    assert parse_fields("xy") == "xy"
    assert parse_fields("0,1; 1,0;-0.5,0.5") == [(0.0, 1.0), (1.0, 0.0), (-0.5, 0.5)]
    with pytest.raises(LensoptError, match="--fields"):
        parse_fields("0,1;1")
    from typer.testing import CliRunner

    from lensopt.cli.app import app

    runner = CliRunner()
    cooke = str(ROOT / "specs" / "cooke_triplet.toml")
    args = ["tolerance", cooke, "--profile", "s6.2", "--trials", "4", "--scheduler", "serial", "--no-sensitivity",
            "--sampling", "rings:4", "--json"]
    r = runner.invoke(app, [*args, "--fields", "0,1;1,0"])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.stdout)
    assert rep["fields"] == [[0.0, 1.0], [1.0, 0.0]]
    # Symmetric lens (S6.2 has no decenters): the x field's spot is the y field's, so the ESR is too.
    r_y = json.loads(runner.invoke(app, [*args, "--fields", "0,1"]).stdout)
    assert rep["nominal"]["esr_um"] == pytest.approx(r_y["nominal"]["esr_um"], abs=1e-9)
    r = runner.invoke(app, [*args, "--fields", "0,1;x"])
    assert r.exit_code == 2 and "--fields" in r.output and len(r.output.strip().splitlines()) == 1
