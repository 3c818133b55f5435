"""The command line: ``trace --json`` and ``ray --json`` carry the library's numbers, plots write
complete files or nothing, bad input is one line and exit code 2."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from lensopt.analysis.spot import spot_stats
from lensopt.cli.app import app
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import PupilSampling
from tests.helpers import COOKE

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
runner = CliRunner()


@pytest.fixture(scope="module")
def trace_json():
    result = runner.invoke(app, ["trace", str(COOKE), "--json", "--sampling", "rings:12"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def test_trace_json_has_the_documented_keys(trace_json):
    fo_keys = {"efl", "bfl", "ffl", "epd", "entrance_pupil_z", "fnumber", "paraxial_image_height", "total_track"}
    assert fo_keys <= trace_json["first_order"].keys()
    assert trace_json["wavelengths_nm"] == [480.0, 550.0, 650.0]
    assert len(trace_json["fields"]) == 3
    for f in trace_json["fields"]:
        assert {"angle_deg", "rms_spot_radius_um", "rms_spot_radius_weighted_um", "centroid_y_mm",
                "chief_ray_y_mm", "failed_rays"} <= f.keys()
        assert len(f["rms_spot_radius_um"]) == 3
    assert len(trace_json["surfaces"]) == 6
    for s in trace_json["surfaces"]:
        assert {"type", "radius", "thickness", "conic", "asphere", "material", "index", "semi_diameter",
                "stop"} <= s.keys()
    assert [s["stop"] for s in trace_json["surfaces"]] == [False, False, True, False, False, False]


def test_trace_json_numbers_are_the_library_numbers(trace_json, cooke):
    lens, system = cooke.lens, cooke.system
    with torch.no_grad():
        fo = first_order(lens, system)
        bundle = trace_bundle(lens, system, PupilSampling.parse("rings:12").points(dtype=lens.dtype),
                              half_pupil=True)
        stats = spot_stats(bundle, system.wavelength_weights)
        chief = trace_bundle(lens, system, torch.zeros(1, 2, dtype=lens.dtype))
    for key, value in trace_json["first_order"].items():
        assert value == float(getattr(fo, key)), key
    for h, f in enumerate(trace_json["fields"]):
        assert f["angle_deg"] == pytest.approx([0.0, 14.0, 20.0][h], abs=1e-12)
        assert f["rms_spot_radius_weighted_um"] == 1e3 * float(stats.rms_radius[h])
        assert f["rms_spot_radius_um"] == [1e3 * float(v) for v in stats.rms_radius_w[h]]
        assert f["centroid_y_mm"] == float(stats.centroid[h, 1])
        assert f["chief_ray_y_mm"] == float(chief.result.pos[h, system.reference, 0, 1])
        assert f["failed_rays"] == 0
    # The prescription as traced (spec values; SK16 index at 550 nm from the catalog formula).
    radii = [22.01359, -435.76044, -22.21328, 20.29192, 79.68360, -18.39533]
    assert [s["radius"] for s in trace_json["surfaces"]] == pytest.approx(radii, rel=1e-15)
    assert trace_json["surfaces"][0]["index"] == [float(v) for v in lens.index[1]]
    # First-order sanity against the textbook design: EFL 50 mm at f/5 (EPD 10 mm).
    assert trace_json["first_order"]["efl"] == pytest.approx(50.0, abs=1e-3)


def test_trace_table_renders(trace_json):
    result = runner.invoke(app, ["trace", str(COOKE), "--sampling", "rings:12"])
    assert result.exit_code == 0, result.output
    assert "prescription" in result.stdout and "first-order data" in result.stdout
    weighted = trace_json["fields"][2]["rms_spot_radius_weighted_um"]
    assert f"{weighted:.4f}" in result.stdout
    assert "ray failures: none" in result.stdout


def test_ray_json_marginal_ray_matches_trace(cooke):
    """The on-axis marginal ray (0, 1) at the reference wavelength, surface by surface."""
    result = runner.invoke(app, ["ray", str(COOKE), "--field", "0", "--pupil", "0", "1", "--json"])
    assert result.exit_code == 0, result.output
    r = json.loads(result.stdout)
    lens, system = cooke.lens, cooke.system
    with torch.no_grad():
        b = trace_bundle(lens, system, torch.tensor([[0.0, 1.0]], dtype=lens.dtype),
                         rel_field=torch.zeros(1, dtype=lens.dtype), record=True)
    w = system.reference
    assert r["wavelength_nm"] == 550.0 and r["status"] == "ok"
    assert r["start"] == pytest.approx(b.rays.pos[0, w, 0].tolist(), abs=1e-12)
    assert r["start"][1] == pytest.approx(5.0, abs=1e-12)  # EPD/2
    for s, hit in enumerate(b.result.hits):
        row = r["surfaces"][s]
        assert [row[k] for k in "xyz"] == pytest.approx(hit.pos[0, w, 0].tolist(), abs=1e-12)
        assert [row[k] for k in "LMN"] == pytest.approx(hit.dir_out[0, w, 0].tolist(), abs=1e-12)
        cos_in = math.sqrt(float(hit.cos2_in[0, w, 0]))
        assert row["aoi_deg"] == pytest.approx(math.degrees(math.acos(cos_in)), abs=1e-9)
    assert [r["image"][k] for k in "xyz"] == pytest.approx(b.result.pos[0, w, 0].tolist(), abs=1e-12)


@pytest.mark.parametrize("kind", ["layout", "fans", "spots"])
def test_plot_commands_write_pngs(kind, tmp_path):
    out = tmp_path / "figs" / f"{kind}.png"
    extra = {"layout": ["--rays", "3"], "fans": ["--points", "11"], "spots": ["--sampling", "rings:6"]}[kind]
    result = runner.invoke(app, ["plot", kind, str(COOKE), "-o", str(out), "--dpi", "50", *extra])
    assert result.exit_code == 0, result.output
    data = out.read_bytes()
    assert data.startswith(PNG_MAGIC) and len(data) > 5000
    assert [p.name for p in out.parent.iterdir()] == [out.name]


def test_plot_with_chief_aiming(tmp_path):
    out = tmp_path / "spots.png"
    result = runner.invoke(app, ["plot", "spots", str(COOKE), "-o", str(out), "--aim", "chief",
                                 "--sampling", "grid:9", "--dpi", "50"])
    assert result.exit_code == 0, result.output
    assert out.read_bytes().startswith(PNG_MAGIC)


def test_plot_interrupted_while_writing_leaves_no_file(tmp_path, monkeypatch):
    """Ctrl-C in the middle of writing: exit code 130, neither the target nor a temporary file."""
    from matplotlib.figure import Figure

    def interrupted(self, path, **kwargs):
        Path(path).write_bytes(PNG_MAGIC + b"half")
        raise KeyboardInterrupt

    monkeypatch.setattr(Figure, "savefig", interrupted)
    result = runner.invoke(app, ["plot", "fans", str(COOKE), "-o", str(tmp_path / "fans.png"), "--points", "5"])
    assert result.exit_code == 130
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("args", "message"), [
    (["plot", "fans", str(COOKE), "-o", "{tmp}/fans.txt"], "--output: expected an image file name"),
    (["plot", "spots", str(COOKE), "-o", "{tmp}/s.png", "--sampling", "hex:3"], "--sampling: expected rings:N"),
    (["plot", "layout", str(COOKE), "-o", "{tmp}/l.png", "--aim", "sideways"], "--aim: must be none, chief or full"),
    (["plot", "layout", "{tmp}/missing.toml", "-o", "{tmp}/l.png"], "missing.toml: no such file"),
])
def test_plot_bad_input_is_one_line_and_exit_2(args, message, tmp_path):
    result = runner.invoke(app, [a.replace("{tmp}", str(tmp_path)) for a in args])
    assert result.exit_code == 2
    err = result.stderr.strip()
    assert message in err and len(err.splitlines()) == 1 and "Traceback" not in result.output
    assert list(tmp_path.iterdir()) == []
