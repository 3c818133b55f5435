"""Hard pupil cases: a field the front aperture blocks entirely, a stop smaller than the beam, aiming
that cannot converge. Each gives finite outputs, a plain reason and no exception (library and CLI)."""

import json
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from lensopt.analysis.field import field_summary
from lensopt.analysis.spot import spot_stats
from lensopt.cli.app import app
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.optics.trace import Status
from lensopt.spec import build, parse_spec
from tests.helpers import cooke_data

F64 = torch.float64
RINGS = PupilSampling.parse("rings:6")


def _cooke(**system: object) -> dict:
    data = cooke_data()
    data["system"].update(system)
    return data


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "lens.json"
    path.write_text(json.dumps(data))
    return path


def _cli(path: Path, *args: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, ["trace", str(path), "--sampling", "rings:6", *args])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    return result.exit_code, result.output


# A 2 mm hole 40 mm in front of the lens: on axis it passes a thin central beam; at 14° and 20° its image
# on the entrance pupil (centre tan θ (z_EP + 40) / 5 ≥ 2.6 pupil radii up, radius 0.2) misses the pupil.
BLOCKING = {"front_aperture": {"distance": -40.0, "diameter": 2.0}}


def test_front_aperture_blocking_whole_fields() -> None:
    m = build(parse_spec(_cooke(**BLOCKING)))
    curv = m.lens.curvature.clone().requires_grad_()
    lens = m.lens.__class__(**{**m.lens.__dict__, "curvature": curv})
    b = trace_bundle(lens, m.system, RINGS.points(dtype=F64), half_pupil=True)
    status = b.result.status
    assert bool((status[1:] == Status.BLOCKED).all())
    assert bool((status[0] == Status.OK).any())
    stats = spot_stats(b, m.system.wavelength_weights)
    assert bool(torch.isfinite(stats.rms_radius).all()) and bool(torch.isfinite(b.vignetting).all())
    (g,) = torch.autograd.grad(stats.effective_radius, curv)
    assert bool(torch.isfinite(g).all())
    s = field_summary(m.lens, m.system, RINGS)
    assert s.ri_three_ray[1:].tolist() == [0.0, 0.0] and s.ri_std[1:].tolist() == [0.0, 0.0]
    assert sum("front aperture blocks the whole beam" in n for n in s.notes) == 2


def test_front_aperture_blocking_cli(tmp_path: Path) -> None:
    code, out = _cli(_write(tmp_path, _cooke(**BLOCKING)), "--json")
    assert code == 0
    r = json.loads(out)
    assert r["fields"][2]["distortion_percent"] is None  # nothing reaches the image: nothing to measure
    assert r["fields"][2]["relative_illumination"] == {"three_ray": 0.0, "std": 0.0}  # and no light
    assert r["fields"][2]["failures"] == {"blocked by front aperture": r["fields"][2]["rays"]}
    assert any("front aperture blocks the whole beam" in n for n in r["notes"])


def test_stop_smaller_than_the_beam(tmp_path: Path) -> None:
    data = _cooke()
    data["surfaces"][2].update(semi_diameter=2.0, clip=True)
    m = build(parse_spec(data))
    s = field_summary(m.lens, m.system, RINGS)
    assert bool(torch.isfinite(s.distortion).all()) and bool(torch.isfinite(s.ri_std).all())
    assert any("smaller than the axial beam" in n for n in s.notes)
    code, out = _cli(_write(tmp_path, data))
    assert code == 0
    assert "clipped by aperture" in out and "smaller than the axial beam" in out


def test_aiming_that_cannot_converge(tmp_path: Path) -> None:
    # The Cooke triplet at a 50° half field with full aiming: at 35° every ray is lost to TIR inside
    # the lens, at 50° even the chief ray cannot reach the stop.
    data = _cooke(aim="full", field={"hfov_deg": 50.0, "relative": [0.0, 0.7, 1.0]})
    m = build(parse_spec(data))
    with torch.no_grad():
        b = trace_bundle(m.lens, m.system, RINGS.points(dtype=F64), half_pupil=True, aim_steps=2)
    pa = b.pupil_aim
    assert bool(pa.converged[0].all()) and not bool(pa.converged[1:].any())
    for t in (pa.factors, pa.residual_mm, b.aim.offset, b.result.pos, b.result.dir):
        assert bool(torch.isfinite(t).all())
    code, out = _cli(_write(tmp_path, data), "--aim-steps", "2", "--json")
    assert code == 0
    notes = json.loads(out)["notes"]
    assert any("full aiming not converged after 2 step(s)" in n and "do not reach the stop" in n for n in notes)


@pytest.mark.parametrize(("args", "message"), [
    (["--aim", "sideways"], "--aim: must be none, chief or full (got 'sideways')"),
    (["--aim-steps", "0"], "--aim-steps: must be an integer from 1 to 100 (got 0)"),
])
def test_bad_aim_options(tmp_path: Path, args: list[str], message: str) -> None:
    code, out = _cli(_write(tmp_path, _cooke()), *args)
    assert code == 2
    assert message in out


def test_front_aperture_spec_errors() -> None:
    from lensopt.errors import SpecError

    with pytest.raises(SpecError, match=r"^system\.front_aperture\.diameter: "):
        parse_spec(_cooke(front_aperture={"distance": 1.0, "diameter": -2.0}))
    with pytest.raises(SpecError, match=r"^system\.front_aperture\.distance: the aperture must lie after the object"):
        parse_spec(_cooke(front_aperture={"distance": -600.0, "diameter": 2.0}, object={"distance": 500.0}))
    with pytest.raises(SpecError, match=r"^system\.aim: "):
        parse_spec(_cooke(aim="sideways"))
