"""``lensopt simulate`` and ``lensopt plot psf`` from the command line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from lensopt.cli.app import app

ROOT = Path(__file__).resolve().parents[2]
COOKE = str(ROOT / "specs" / "cooke_triplet.toml")
COFFEE = str(ROOT / "lensopt" / "imaging" / "data" / "coffee.png")
runner = CliRunner()


def test_plan_json_has_the_promised_keys_and_runs_nothing(tmp_path: Path) -> None:
    out = tmp_path / "never.png"
    r = runner.invoke(app, ["simulate", COOKE, COFFEE, "-o", str(out), "--region", "corner", "--plan", "--json"])
    assert r.exit_code == 0, r.output
    plan = json.loads(r.stdout)
    for key in ("channels", "wavelengths_nm", "fields_deg", "psf_grid", "diffraction", "effects"):
        assert key in plan
    assert plan["channels"] == ["R", "G", "B"] and len(plan["psf_grid"]) == 2
    assert set(plan["diffraction"]) == {"on", "reason"}
    assert all({"on", "reason"} <= set(e) for e in plan["effects"].values())
    assert not out.exists()


def test_simulate_writes_an_image_and_reports_stages(tmp_path: Path) -> None:
    from lensopt.imaging.io import read_image, write_image

    img, info = read_image(COFFEE)
    small = tmp_path / "gray.png"
    write_image(small, img[:100, :150, :1], info)
    out = tmp_path / "out.png"
    r = runner.invoke(app, ["simulate", COOKE, str(small), "-o", str(out), "--region", "corner", "--rays",
                            "rings:8", "--json", "--score"])
    assert r.exit_code == 0, r.output
    res = json.loads(r.stdout)
    assert res["plan"]["channels"] == ["Y"]
    assert {"pilot trace", "trace + PSFs", "PSF grid", "convolution"} <= set(res["timings"])
    assert res["output_encoding"] == "uint8 sRGB" and res["input_encoding"].startswith("sRGB 8-bit")
    back, binfo = read_image(out)
    assert back.shape == (100, 150, 1)
    assert 20 < res["metrics"]["psnr_db"] < 60 and not np.array_equal(back, img[:100, :150, :1])
    r2 = runner.invoke(app, ["simulate", COOKE, str(small), "-o", str(out), "--region", "corner", "--rays",
                             "rings:8"])
    assert r2.exit_code == 0 and "plan — Cooke triplet" in r2.stdout and "wrote" in r2.stderr
    assert "PSNR" not in r2.stdout  # scored only when asked (--score or --reference)
    r3 = runner.invoke(app, ["simulate", COOKE, str(small), "-o", str(out), "--region", "corner", "--rays",
                             "rings:8", "--json"])
    assert r3.exit_code == 0 and json.loads(r3.stdout)["metrics"] is None


def test_errors_are_one_line_with_exit_code_2(tmp_path: Path) -> None:
    r = runner.invoke(app, ["simulate", COOKE, COFFEE, "-o", str(tmp_path / "x.png"), "--region", "1,2"])
    assert r.exit_code == 2 and "--region:" in r.stderr
    r = runner.invoke(app, ["simulate", COOKE, COFFEE, "--effects", "sparkle", "--plan"])
    assert r.exit_code == 2 and "--effects:" in r.stderr
    r = runner.invoke(app, ["simulate", COOKE, COFFEE])
    assert r.exit_code == 2 and "--output" in r.stderr
    r = runner.invoke(app, ["simulate", COOKE, COFFEE, "--plan", "--kernel", "gauss"])
    assert r.exit_code == 2 and "--kernel:" in r.stderr
    r = runner.invoke(app, ["simulate", COOKE, COFFEE, "--plan", "--rays", "many"])
    assert r.exit_code == 2 and "--rays:" in r.stderr
    spec = tmp_path / "nosensor.toml"
    spec.write_text("\n".join(line for line in Path(COOKE).read_text().splitlines()
                              if not line.startswith(("[sensor]", "pixel_pitch_um", "resolution"))))
    r = runner.invoke(app, ["simulate", str(spec), COFFEE, "--plan"])
    assert r.exit_code == 2 and "sensor:" in r.stderr
    assert not list(tmp_path.glob("*.png"))


def test_plot_psf_writes_a_figure(tmp_path: Path) -> None:
    out = tmp_path / "psf.png"
    r = runner.invoke(app, ["plot", "psf", COOKE, "-o", str(out), "--rays", "rings:8", "--sqrt"])
    assert r.exit_code == 0, r.output
    assert out.stat().st_size > 10_000 and out.read_bytes()[:4] == b"\x89PNG"
