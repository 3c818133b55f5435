"""The command line of the designer's analyses (issue 28): ``trace --wavefront/--seidel`` (JSON keys, numbers
that obey the closed-form relations between them, tables that fit 80 columns), every ``plot`` command of
the analyses writing a PNG, bad input as one line and exit 2 with no file written, and the analyses' rows
of ``lensopt accuracy`` showing their error and time.

Independent checks of the JSON numbers (not a copy of the code path):
- Maréchal's estimate is exp(−(2πσ)²) of the RMS printed beside it (closed form);
- the Seidel totals are the sums of the per-surface rows, W040 = S_I/8 and W220P = S_IV/4 in waves of the
  reference wavelength (Welford eq. 8.23);
- the RMS wavefront error equals an RMS computed here with numpy from ``analysis.wavefront.wavefront`` on
  the same cell-centred grid (piston and tilt removed by numpy's least squares, not by ``remove_tilt``);
- Zernike numbering: Fringe and Noll start at 1, ANSI at 0; the Fringe and Noll spherical term
  coefficients differ by the normalization sqrt(5) (Z9 edge amplitude vs Z11 RMS of the (4, 0) term),
  to the accuracy of a 16×16 grid.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from rich.console import Console
from typer.testing import CliRunner

from lensopt.analysis.wavefront import map_grid, wavefront
from lensopt.cli.app import app
from lensopt.spec import build, load_spec

ROOT = Path(__file__).resolve().parents[2]
COOKE = ROOT / "specs" / "cooke_triplet.toml"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
runner = CliRunner()

WAVE_KEYS = {"wavelength_nm", "rms_waves", "pv_waves", "rms_chief_waves", "pv_chief_waves", "strehl_psf",
             "strehl_marechal", "zernike_waves", "zernike_residual_rms_waves", "rays"}


def _json(args: list[str]) -> dict:
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)


@pytest.fixture(scope="module")
def wf_json() -> dict:
    return _json(["trace", str(COOKE), "--sampling", "rings:4", "--wavefront", "--seidel", "--pupil-grid", "16",
                  "--json"])


def test_wavefront_json_keys(wf_json) -> None:
    wf = wf_json["wavefront"]
    assert set(wf) == {"convention", "pupil_grid", "wavelengths_nm", "reference_nm", "zernike", "fields"}
    assert wf["pupil_grid"] == 16 and wf["wavelengths_nm"] == [480.0, 550.0, 650.0] and wf["reference_nm"] == 550.0
    assert set(wf["zernike"]) == {"ordering", "normalization", "numbers", "nm"}
    assert wf["zernike"]["ordering"] == "fringe" and wf["zernike"]["numbers"] == list(range(1, 38))
    assert len(wf["fields"]) == 3
    for f in wf["fields"]:
        assert set(f) == {"relative", "angle_deg", "wavelengths"}
        assert [w["wavelength_nm"] for w in f["wavelengths"]] == wf["wavelengths_nm"]
        for w in f["wavelengths"]:
            assert set(w) == WAVE_KEYS and len(w["zernike_waves"]) == 37 and w["rays"] > 0
    assert [f["relative"] for f in wf["fields"]] == [0.0, 0.7, 1.0]
    assert wf["fields"][2]["angle_deg"] == pytest.approx(20.0, abs=1e-9)


def test_wavefront_json_numbers_obey_their_relations(wf_json) -> None:
    for f in wf_json["wavefront"]["fields"]:
        for w in f["wavelengths"]:
            assert w["strehl_marechal"] == pytest.approx(math.exp(-((2 * math.pi * w["rms_waves"]) ** 2)), rel=1e-12)
            assert 0.0 < w["strehl_psf"] <= 1.0
            assert w["rms_waves"] <= w["rms_chief_waves"] + 1e-15  # removing tilt too cannot raise the RMS
            assert w["pv_waves"] >= w["rms_waves"]  # zero-mean residual: max ≥ 0 ≥ min, |W| ≤ max − min
    ref_axis = wf_json["wavefront"]["fields"][0]["wavelengths"][1]
    assert ref_axis["zernike_waves"][1] == pytest.approx(0.0, abs=1e-9)  # on axis: no tilt x (symmetry)


def test_wavefront_rms_matches_an_independent_numpy_fit(wf_json) -> None:
    m = build(load_spec(COOKE))
    pts, inside = map_grid(16, dtype=torch.float64)
    with torch.no_grad():
        wf = wavefront(m.lens, m.system, pts[inside])
    p = pts[inside].numpy()
    basis = np.stack([np.ones(len(p)), p[:, 0], p[:, 1]], -1)
    for fi, f in enumerate(wf_json["wavefront"]["fields"]):
        for wi, w in enumerate(f["wavelengths"]):
            ok = wf.valid[fi, wi].numpy()
            y = wf.opd[fi, wi].numpy()[ok]
            coef = np.linalg.lstsq(basis[ok], y, rcond=None)[0]
            resid = y - basis[ok] @ coef
            assert w["rms_waves"] == pytest.approx(float(np.sqrt(np.mean(resid**2))), rel=1e-9)
            assert w["pv_waves"] == pytest.approx(float(resid.max() - resid.min()), rel=1e-9)
            assert w["rays"] == int(ok.sum())


def test_zernike_orderings_number_and_normalize_as_stated() -> None:
    base = ["trace", str(COOKE), "--sampling", "rings:4", "--wavefront", "--pupil-grid", "16", "--json"]
    fringe = _json([*base, "--zernike", "fringe"])["wavefront"]
    noll = _json([*base, "--zernike", "noll"])["wavefront"]
    ansi = _json([*base, "--zernike", "ansi"])["wavefront"]
    assert noll["zernike"]["numbers"][0] == 1 and ansi["zernike"]["numbers"][0] == 0
    assert noll["zernike"]["nm"][10] == [4, 0] and fringe["zernike"]["nm"][8] == [4, 0]
    assert ansi["zernike"]["nm"][12] == [4, 0]
    z9 = fringe["fields"][0]["wavelengths"][1]["zernike_waves"][8]
    z11 = noll["fields"][0]["wavelengths"][1]["zernike_waves"][10]
    z12 = ansi["fields"][0]["wavelengths"][1]["zernike_waves"][12]
    # The first 37 terms of each ordering are different sets, and on a 16×16 grid the sampled terms are only
    # nearly orthogonal, so the same (4, 0) term's coefficient agrees to ~1e-4, not to rounding; the scale
    # between the unnormalized Fringe and the RMS-normalized Noll/ANSI term is sqrt(5) (N = sqrt(n + 1)).
    assert z11 == pytest.approx(z12, rel=1e-3)
    assert z9 / z11 == pytest.approx(math.sqrt(5.0), rel=1e-3)


def test_seidel_json_keys_and_relations(wf_json) -> None:
    sd = wf_json["seidel"]
    assert set(sd) == {"wavelength_nm", "color_wavelengths_nm", "lagrange_invariant_mm", "total_mm", "total_waves",
                       "total_transverse_mm", "surfaces_mm", "surfaces_waves"}
    assert list(sd["total_mm"]) == ["S_I", "S_II", "S_III", "S_IV", "S_V", "C_I", "C_II"]
    assert list(sd["total_waves"]) == ["W040", "W131", "W222", "W220P", "W311", "W020", "W111"]
    assert len(sd["surfaces_mm"]) == 6 and sd["color_wavelengths_nm"] == [480.0, 650.0]
    for k in sd["total_mm"]:
        assert sd["total_mm"][k] == pytest.approx(sum(s[k] for s in sd["surfaces_mm"]), rel=1e-12, abs=1e-15)
    lam_mm = sd["wavelength_nm"] * 1e-6
    assert sd["total_waves"]["W040"] == pytest.approx(sd["total_mm"]["S_I"] / 8 / lam_mm, rel=1e-12)
    assert sd["total_waves"]["W220P"] == pytest.approx(sd["total_mm"]["S_IV"] / 4 / lam_mm, rel=1e-12)


def test_trace_tables_fit_80_columns(monkeypatch) -> None:
    import lensopt.cli.trace_analyses as ta

    wide = Console(width=300, record=True, color_system=None)  # no wrapping: the tables' natural width shows
    monkeypatch.setattr(ta, "console", wide)
    r = runner.invoke(app, ["trace", str(COOKE), "--sampling", "rings:4", "--wavefront", "--seidel",
                            "--pupil-grid", "8", "--wide", "--zernike", "noll"])
    assert r.exit_code == 0, r.output
    text = wide.export_text()
    lines = text.splitlines()
    assert max(len(line.rstrip()) for line in lines) <= 80, max(lines, key=len)
    assert "Strehl PSF" in text and "Maréchal" in text and "Z11" in text and "W040" in text and "S_IV" in text
    assert sum("550" in line for line in lines) >= 6  # --wide: every wavelength has rows (3 fields × 2 tables)


BAD_TRACE = [
    (["--wavefront", "--zernike", "zemax"], "--zernike: must be one of fringe, noll, ansi"),
    (["--wavefront", "--pupil-grid", "2"], "--pupil-grid"),
]


@pytest.mark.parametrize("extra,message", BAD_TRACE)
def test_trace_bad_options_are_one_line(extra, message) -> None:
    r = runner.invoke(app, ["trace", str(COOKE), "--sampling", "rings:4", *extra])
    assert r.exit_code == 2
    errors = [line for line in r.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], r.stderr


SMOKE = {
    "opd": ["--points", "9", "--wavelength", "480,650"],
    "wavefront": ["--samples", "12", "--field", "0,1", "--zernike", "noll", "--terms", "15"],
    "field-curves": ["--samples", "5"],
    "focal-shift": ["--samples", "9"],
    "encircled": ["--sampling", "rings:6", "--field", "0.5", "--wavelength", "550", "--ensquared"],
    "mtf-field": ["--sampling", "rings:6", "--samples", "3", "--frequencies", "20,40"],
    "through-focus": ["--sampling", "rings:6", "--samples", "3", "--field", "0", "--focus-range", "50"],
}


@pytest.mark.parametrize("kind", list(SMOKE))
def test_plot_analysis_commands_write_pngs(kind, tmp_path) -> None:
    out = tmp_path / f"{kind}.png"
    r = runner.invoke(app, ["plot", kind, str(COOKE), "-o", str(out), "--dpi", "40", *SMOKE[kind]])
    assert r.exit_code == 0, r.output
    assert out.read_bytes()[:8] == PNG_MAGIC
    assert f"wrote {out}" in r.stderr


def test_plot_encircled_diffraction_and_defaults_run(tmp_path) -> None:
    out = tmp_path / "ee.png"
    r = runner.invoke(app, ["plot", "encircled", str(COOKE), "-o", str(out), "--dpi", "40", "--method", "diffraction",
                            "--field", "0", "--samples", "48", "--sampling", "rings:6"])
    assert r.exit_code == 0, r.output
    assert out.read_bytes()[:8] == PNG_MAGIC


BAD_PLOT = [
    (["opd", "--field", "1.5"], "--field: relative field must lie in [0, 1] (1 = the full field, 20°)"),
    (["wavefront", "--field", "0,-0.2"], "--field: relative field must lie in [0, 1]"),
    (["encircled", "--field", "nan"], "--field: relative field must lie in [0, 1]"),
    (["through-focus", "--field", "2"], "--field: relative field must lie in [0, 1]"),
    (["opd", "--field", "0,x"], "--field: expected comma-separated numbers"),
    (["mtf-field", "--frequencies", "0"], "--frequencies: spatial frequency must be > 0 cycles/mm (got 0.0)"),
    (["mtf-field", "--frequencies", "10,-5"], "--frequencies: spatial frequency must be > 0 cycles/mm (got -5.0)"),
    (["through-focus", "--frequencies", "0"], "--frequencies: spatial frequency must be > 0"),
    (["through-focus", "--focus-range", "0"], "--focus-range: must be a positive half-width in µm"),
    (["opd", "--wavelength", "500"], "--wavelength: not a wavelength of the spec; one of 480, 550, 650 nm"),
    (["wavefront", "--wavelength", "587.6"], "--wavelength: not a wavelength of the spec"),
    (["wavefront", "--wavelength", "480,550"], "--wavelength: expected one wavelength in nm"),
    (["encircled", "--wavelength", "700"], "--wavelength: not a wavelength of the spec"),
    (["wavefront", "--zernike", "zemax"], "--zernike: must be one of fringe, noll, ansi"),
    (["wavefront", "--terms", "40"], "--terms: the Fringe set has 37 terms"),
    (["wavefront", "--samples", "8", "--zernike", "noll", "--terms", "60"], "--terms: more terms than the 52 pupil"),
    (["encircled", "--method", "fft"], "--method: must be geometric or diffraction"),
    (["encircled", "--center", "peak"], "--center: must be one of centroid, chief"),
    (["mtf-field", "--method", "fft"], "--method: must be one of heuristic, geometric, reference"),
    (["mtf-field", "--sampling", "hex:3"], "--sampling: expected rings:N"),
    (["field-curves", "--aim", "sideways"], "--aim: must be none, chief or full"),
    (["focal-shift", "--samples", "1"], "--samples"),
]


@pytest.mark.parametrize("args,message", BAD_PLOT, ids=[" ".join(a) for a, _ in BAD_PLOT])
def test_plot_analysis_bad_input_is_one_line_exit_2_and_no_file(args, message, tmp_path) -> None:
    out = tmp_path / "fig.png"
    r = runner.invoke(app, ["plot", args[0], str(COOKE), "-o", str(out), *args[1:]])
    assert r.exit_code == 2, r.output
    errors = [line for line in r.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], r.stderr
    assert "Traceback" not in r.output
    assert list(tmp_path.iterdir()) == []  # nothing written, not even a temporary file


def test_plot_analysis_bad_output_suffix(tmp_path) -> None:
    r = runner.invoke(app, ["plot", "opd", str(COOKE), "-o", str(tmp_path / "fig.txt")])
    assert r.exit_code == 2 and "--output: expected an image file name" in r.stderr


def test_accuracy_table_shows_each_analysis_error_and_time(monkeypatch) -> None:
    from lensopt.cli import qa

    data = _json(["accuracy", str(COOKE), "--knobs", "field_curves,focal_shift,seidel", "--repeats", "1", "--json"])
    rec = Console(width=300, record=True, color_system=None)
    monkeypatch.setattr(qa, "console", rec)
    qa._render_accuracy(data)
    text = rec.export_text()
    rows = [line for line in text.splitlines() if line.strip().startswith(("│ field_curves", "│ focal_shift",
                                                                           "│ seidel"))]
    points = data["points"]
    assert {p["knob"] for p in points} == {"field_curves", "focal_shift", "seidel"}
    for p in points:
        (err,) = p["errors"].values()
        row = next(r for r in rows if f" {p['setting']} " in r and p["knob"] in r)
        assert f"{err:.2e}" in row and f"{p['time_s']:.4f}" in row
    for knob in ("field_curves", "focal_shift"):  # the reference setting's time on its own row
        ref = data["reference"]["analyses"][knob]
        assert any(f"reference: {ref['reference']}" in r and f"{ref['time_s']:.4f}" in r for r in rows)
    assert "ESR err" not in text  # no spot knob asked for: no empty spot table
