"""Issue 17 regressions, one or more per category: parsing limits, output paths, images, sizes, numbers,
dead lenses, signals, usage errors, help, determinism, CI progress, --version, startup, newcomer details.

The contract (README, "Errors and exit codes"): bad input is one line ``error: …`` on stderr and exit 2,
never a traceback; Ctrl-C 130, SIGTERM 143; failed quantities are null / "—", never 0.
"""

from __future__ import annotations

import json
import math
import os
import re
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from lensopt.cli.app import app
from lensopt.spec import load_spec
from tests.helpers import COOKE, COOKE_OPT

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()
ENV = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}


def run(*args: str) -> tuple[int, str, str]:
    r = runner.invoke(app, [str(a) for a in args])
    return r.exit_code, r.stdout, r.stderr


def assert_one_line_error(code: int, out: str, err: str, expect: str) -> None:
    assert code == 2, (code, out, err)
    assert err.startswith("error: ") and len(err.strip().splitlines()) == 1, err
    assert expect in err, err
    assert "Traceback" not in out + err and "╭" not in err


def cooke_text(**subs: str) -> str:
    text = COOKE.read_text(encoding="utf-8")
    for old, new in subs.items():
        assert old in text, old
        text = text.replace(old, new, 1)
    return text


def write(tmp: Path, name: str, text: str) -> Path:
    p = tmp / name
    p.write_text(text, encoding="utf-8")
    return p


# ----------------------------------------------------------------------------------- parsing limits


def test_huge_integer_and_deep_nesting_are_one_line(tmp_path: Path) -> None:
    big = write(tmp_path, "big.json", '{"name": "x", "a": ' + "9" * 5000 + "}")
    assert_one_line_error(*run("trace", big), "unreadable number")
    deep = write(tmp_path, "deep.json", "[" * 100_000 + "]" * 100_000)
    assert_one_line_error(*run("trace", deep), "nested too deeply")
    deep_toml = write(tmp_path, "deep.toml", "a = " + "[" * 100_000 + "]" * 100_000)
    assert_one_line_error(*run("trace", deep_toml), "nested too deeply")


@pytest.mark.parametrize("seed", [2**64, -1, 10**30])
def test_seed_beyond_64_bits(seed: int) -> None:
    assert_one_line_error(*run("trace", COOKE, "--seed", seed), "--seed")
    assert_one_line_error(*run("tolerance", COOKE, "--profile", "s6.2", "--trials", "2", "--seed", seed), "--seed")


# ------------------------------------------------------------------------------------- output paths


@pytest.mark.parametrize(("args", "expect"), [
    (["plot", "layout", COOKE, "-o", "/proc/x.png"], "cannot write in /proc"),
    (["plot", "layout", COOKE, "-o", "{tmp}"], "--output"),
    (["plot", "fans", COOKE, "-o", "{tmp}/dir.png"], "is a directory"),
    (["plot", "spots", COOKE, "-o", "{tmp}/file.txt/x.png"], "is a file, not a folder"),
    (["plot", "psf", COOKE, "-o", "{tmp}/x.xyz"], "--output: expected an image file name ending in .png"),
    (["export-codev", COOKE, "-o", "{tmp}/x.json"], "ending in .seq"),
    (["optimize", COOKE_OPT, "-o", "{tmp}/file.txt/x.json"], "is a file, not a folder"),
])
def test_output_paths_checked_before_work(tmp_path: Path, args: list, expect: str) -> None:
    (tmp_path / "dir.png").mkdir()
    (tmp_path / "file.txt").write_text("x")
    (tmp_path / "dir.png" / "keep").write_text("x")
    before = sorted(p.name for p in tmp_path.rglob("*"))
    assert_one_line_error(*run(*[str(a).replace("{tmp}", str(tmp_path)) for a in args]), expect)
    assert sorted(p.name for p in tmp_path.rglob("*")) == before  # nothing written, no temp files


# ------------------------------------------------------------------------------------------- images


def _write_image(path: Path, arr: np.ndarray) -> Path:
    import OpenImageIO as oiio

    h, w, c = arr.shape
    fmt = oiio.UINT8 if arr.dtype == np.uint8 else oiio.FLOAT
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(w, h, c, fmt)) and out.write_image(arr)
    out.close()
    return path


SIM = ["--rays", "rings:4", "--region", "center", "--json", "--score"]


def test_one_pixel_image_simulates_with_ssim_null(tmp_path: Path) -> None:
    img = _write_image(tmp_path / "one.png", np.full((1, 1, 3), 128, np.uint8))
    code, out, err = run("simulate", COOKE, img, "-o", tmp_path / "o.png", *SIM)
    assert code == 0, err
    m = json.loads(out)["metrics"]
    assert m["ssim"] is None and math.isfinite(m["psnr_db"])  # not measurable, said so; never NaN


def test_nan_pixels_refused_and_negative_light_clamped(tmp_path: Path) -> None:
    a = np.full((16, 24, 3), 0.5, np.float32)
    a[3, 4, 1] = np.nan
    nan = _write_image(tmp_path / "nan.exr", a)
    assert_one_line_error(*run("simulate", COOKE, nan, "-o", tmp_path / "o.exr", *SIM), "NaN or infinite")
    assert not (tmp_path / "o.exr").exists()
    a[3, 4, 1] = -0.5
    neg = _write_image(tmp_path / "neg.exr", a)
    code, out, err = run("simulate", COOKE, neg, "-o", tmp_path / "o.exr", *SIM)
    assert code == 0 and "warning: " in err and "1 negative pixel values set to 0" in err
    m = json.loads(out)["metrics"]
    assert math.isfinite(m["psnr_db"]) and math.isfinite(m["ssim"])


@pytest.mark.parametrize(("channels", "named"), [(4, "channel A not simulated"), (5, "channels A, ")])
def test_extra_channels_are_named(tmp_path: Path, channels: int, named: str) -> None:
    img = _write_image(tmp_path / "x.exr", np.full((16, 24, channels), 0.25, np.float32))
    code, _, err = run("simulate", COOKE, img, "-o", tmp_path / "o.exr", *SIM)
    assert code == 0 and named in err


def test_pass_through_has_no_numpy_warning_and_no_infinity(tmp_path: Path) -> None:
    img = _write_image(tmp_path / "flat.png", np.full((16, 24, 3), 100, np.uint8))
    code, out, err = run("simulate", COOKE, img, "-o", tmp_path / "o.png", "--effects=-convolution,-distortion,-ri",
                         *SIM)
    assert code == 0 and "Warning" not in err and "Infinity" not in out and "NaN" not in out
    assert json.loads(out)["metrics"]["psnr_db"] is None  # identical images: PSNR is infinite → null
    code, out, _ = run("simulate", COOKE, img, "-o", tmp_path / "o.png", "--effects=-convolution,-distortion,-ri",
                       "--rays", "rings:4", "--region", "center", "--score")
    assert code == 0 and "PSNR ∞ (identical)" in out


# -------------------------------------------------------------------------------------------- sizes


@pytest.mark.parametrize(("args", "expect"), [
    (["trace", COOKE, "--sampling", "rings:3000"], "lower the pupil sampling"),
    (["trace", COOKE, "--sampling", "grid:1000000"], "lower N of rings:N / grid:N"),
    (["--max-memory", "1M", "trace", COOKE], "over the memory budget of 1.05 MB"),
    (["--max-memory", "200M", "plot", "spots", COOKE, "-o", "{tmp}/s.png", "--sampling", "rings:300"],
     "tracing 810,000 rays needs about 1.04 GB, over the memory budget of 210 MB; lower the pupil sampling"),
])
def test_memory_budget_refuses_with_what_to_lower(tmp_path: Path, args: list, expect: str) -> None:
    peak0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    assert_one_line_error(*run(*[str(a).replace("{tmp}", str(tmp_path)) for a in args]), expect)
    # Refused before allocating: this process's peak resident memory grew by far less than the request.
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak0 < 512 * 1024


def test_image_and_grid_budget(tmp_path: Path) -> None:
    img = _write_image(tmp_path / "x.png", np.full((100, 150, 3), 90, np.uint8))
    # 100 × 150 px × 240 B/px ≈ 3.6 MB > 1 MB: refused from the header, before the pixels are read.
    code, out, err = run("--max-memory", "1M", "simulate", COOKE, img, "-o", tmp_path / "o.png", *SIM)
    assert_one_line_error(code, out, err, "simulating a 150×100 image needs about 3.6 MB")
    code, out, err = run("simulate", COOKE, img, "-o", tmp_path / "o.png", "--grid", "100000x100000", *SIM)
    assert_one_line_error(code, out, err, "--grid: a 100000x100000 PSF grid needs about")
    assert not (tmp_path / "o.png").exists()
    assert_one_line_error(*run("--max-memory", "lots", "trace", COOKE), "--max-memory")


def test_budget_default_is_half_the_machine(monkeypatch: pytest.MonkeyPatch) -> None:
    from lensopt.cli.common import make_engine
    from lensopt.engine import Engine, parse_size

    monkeypatch.delenv("LENSOPT_MAX_MEMORY", raising=False)
    pages = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    assert Engine().budget <= 0.5 * pages + 1 and make_engine().budget == Engine().budget
    assert parse_size("1.5G") == int(1.5 * 2**30) and parse_size("512M") == 512 * 2**20
    monkeypatch.setenv("LENSOPT_MAX_MEMORY", "2K")  # read by the CLI when it makes a command's engine
    assert make_engine().budget == 2048 and Engine().budget != 2048


# ------------------------------------------------------------------------------------------ numbers


@pytest.mark.parametrize(("subs", "expect"), [
    ({"thickness = 3.25896": "thickness = 1e308"}, "surfaces[0].thickness: "),
    ({"radius = 22.01359": 'radius = "1e999"'}, "surfaces[0].radius: must be a valid number, not text"),
    ({"stop = true": 'stop = "yes"'}, "surfaces[2].stop: must be true or false, not text"),
    ({'type = "sphere"\nradius = 22.01359': 'type = "conic"\nradius = 22.01359\nconic = inf'},
     "surfaces[0].conic: "),
])
def test_bad_numbers_name_their_field(tmp_path: Path, subs: dict, expect: str) -> None:
    assert_one_line_error(*run("trace", write(tmp_path, "x.toml", cooke_text(**subs))), expect)


def test_bad_numbers_in_options_and_solves(tmp_path: Path) -> None:
    img = _write_image(tmp_path / "x.png", np.full((16, 24, 3), 90, np.uint8))
    assert_one_line_error(*run("simulate", COOKE, img, "-o", tmp_path / "o.png", "--region", "nan,0,10,10"),
                          "--region: region numbers must be finite")
    sensor = cooke_text(**{"pixel_pitch_um = 7.2": "pixel_pitch_um = 1e308"})
    assert_one_line_error(*run("trace", write(tmp_path, "s.toml", sensor)), "sensor.pixel_pitch_um: ")
    opt = COOKE_OPT.read_text(encoding="utf-8")
    assert 'type = "efl"' in opt
    bad = opt.replace('type = "efl", surface = -1, value = 50.0', 'type = "efl", surface = -1, value = 1e308')
    assert bad != opt
    assert_one_line_error(*run("optimize", write(tmp_path, "e.toml", bad), "-o", tmp_path / "o.json"),
                          "value: must be positive and at most 1e6 mm")


# -------------------------------------------------------------------------------------- dead lenses


def test_dead_lens_is_null_and_dash_never_zero(tmp_path: Path) -> None:
    text = re.sub(r"^thickness = .*$", "thickness = 9e5", COOKE.read_text(encoding="utf-8"), flags=re.M)
    dead = write(tmp_path, "dead.toml", text)
    code, out, _ = run("trace", dead, "--json")
    assert code == 0
    r = json.loads(out)
    assert r["effective_spot_radius_um"] is None
    for f in r["fields"]:
        assert f["failed_rays"] == f["rays"] and f["failures"]  # the reason
        assert f["rms_spot_radius_um"] == [None, None, None] and f["rms_spot_radius_weighted_um"] is None
        assert f["centroid_y_mm"] is None and f["relative_illumination"]["three_ray"] is None
    code, out, _ = run("trace", dead)
    assert code == 0 and "effective spot radius: —" in out and "0.0000 µm" not in out


def test_ray_after_a_failure_prints_no_numbers(tmp_path: Path) -> None:
    # A pupil past the edge is refused (px² + py² ≤ 1); a 60° field fails by total internal reflection.
    code, out, _ = run("ray", COOKE, "--field", "60", "--aim", "none", "--json")
    r = json.loads(out)
    assert code == 0 and r["status"] == "total internal reflection" and r["failed_at_surface"] is not None
    k = r["failed_at_surface"]
    for s in r["surfaces"]:
        if s["surface"] < k:  # before the failure: a real ray, unit direction vector
            assert abs(math.hypot(s["L"], s["M"], s["N"]) - 1) < 1e-12
        else:  # the failing surface keeps where the ray met it (TIR: no refracted direction), later ones nothing
            assert s["L"] is None and (s["x"] is None) == (s["surface"] > k)
    assert all(v is None for v in r["image"].values())
    code, out, _ = run("ray", COOKE, "--field", "60", "--aim", "none")
    assert f"total internal reflection at surface {k}" in out and "—" in out


def test_three_ray_illumination_is_nan_not_zero_when_its_rays_fail() -> None:
    import torch

    from lensopt.analysis.illumination import THREE_RAY_PUPIL, relative_illumination_three_ray
    from lensopt.optics.bundle import trace_bundle
    from lensopt.spec import build, parse_spec

    data = load_spec(COOKE).model_dump()
    data["system"]["aperture"] = {"epd": 40.0}  # the marginal rays of the three miss surface 1 on axis
    m = build(parse_spec(data))
    with torch.no_grad():
        b = trace_bundle(m.lens, m.system, torch.tensor(THREE_RAY_PUPIL, dtype=m.lens.dtype))
        ri = relative_illumination_three_ray(b, m.system.reference)
    assert not bool(b.result.valid[0, m.system.reference].all())
    assert bool(torch.isnan(ri).all())  # the axis reference fails: no field can be normalized; never 0


# ------------------------------------------------------------------------------ usage errors and help


def test_usage_errors_are_one_line() -> None:
    for args in (["trace", COOKE, "--bogus"], ["trace"], ["plot", "layout", COOKE], ["trace", COOKE, "--seed", "x"],
                 ["nosuchcommand"]):
        code, out, err = run(*args)
        assert code == 2 and len(err.strip().splitlines()) == 1 and err.startswith("error: "), (args, err)
        assert "╭" not in err and "Usage:" not in err


def test_help_is_plain_and_complete() -> None:
    for args in (["--help"], ["optimize", "--help"], ["plot", "--help"], ["plot", "psf", "--help"],
                 ["trace", "--help"], ["simulate", "--help"]):
        code, out, _ = run(*args)
        assert code == 0 and "<bool>" not in out and "…" not in out and "..." not in out.split("Commands:")[-1], args
    assert "field" in run("plot", "--help")[1] and "--dpi" in run("plot", "psf", "--help")[1]
    assert "with vary lists and an optimize section." in " ".join(run("optimize", "--help")[1].split())


def test_version() -> None:
    from lensopt import __version__

    code, out, _ = run("--version")
    assert code == 0 and out.strip() == f"lensopt {__version__}"


def test_wrote_goes_to_stderr_everywhere(tmp_path: Path) -> None:
    for args in (["plot", "layout", COOKE, "-o", tmp_path / "l.png"], ["export-codev", COOKE, "-o", tmp_path / "c.seq"],
                 ["plot", "psf", COOKE, "-o", tmp_path / "p.png", "--rays", "rings:4", "--dpi", "40"]):
        code, out, err = run(*args)
        assert code == 0 and "wrote" in err and "wrote" not in out, args


def test_plan_json_has_no_float_noise(tmp_path: Path) -> None:
    img = _write_image(tmp_path / "x.png", np.full((16, 24, 3), 90, np.uint8))
    code, out, _ = run("simulate", COOKE, img, "--plan", "--json")
    assert code == 0 and '"pixel_pitch_um": 7.2,' in out.replace("\n", "").replace("  ", "")


def test_help_imports_no_torch() -> None:
    code = ("import sys\nsys.argv = ['lensopt', '--help']\nfrom lensopt.cli.app import app\n"
            "try:\n    app()\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in ('torch', 'numpy', 'pydantic', 'matplotlib', 'scipy') if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=60)
    assert r.returncode == 0 and r.stdout.strip().splitlines()[-1] == "[]", r.stdout + r.stderr


# ------------------------------------------------------------------------------------------ progress


def test_progress_is_plain_lines_when_not_a_terminal(tmp_path: Path) -> None:
    from lensopt.cli.optimize import LiveProgress
    from lensopt.optim.driver import Progress

    lines = []

    class FakeConsole:
        is_terminal = False

        def print(self, text: str, **_: object) -> None:
            lines.append(text)

    live = LiveProgress(FakeConsole(), interval_s=3600.0)  # type: ignore[arg-type]
    with live:
        for k in range(1, 6):
            live(Progress(k, 5, "fixed glasses", 1.0 / k, 1e-3, 10.0 / k, k, 0, True, {"tra": 1.0}, 1.0, "", 0.1 * k))
    steps = [ln for ln in lines if ln.startswith("step ")]
    assert steps[0].startswith("step 1/5 [fixed glasses] merit 1.000000e+00, ESR 10.000 µm")
    assert steps[-1].startswith("step 5/5 ") and len(steps) == 2  # first, then the last (interval not reached)


# ------------------------------------------------------------------------------------------- signals


def _spawn(*args: str, env: dict | None = None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "lensopt", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env or ENV)


def _wait_for(proc: subprocess.Popen, text: str, timeout: float) -> str:
    """Read stderr lines until one contains ``text``."""
    seen = ""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        line = proc.stderr.readline()
        seen += line
        if text in line or (not line and proc.poll() is not None):
            return seen
    return seen


def _check_lens_dir(folder: Path, name: str) -> None:
    assert [p.name for p in folder.iterdir() if p.name.startswith(".")] == []  # no temp files left
    spec = load_spec(folder / name)  # a complete, valid lens
    assert spec.surfaces


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGTERM, 143),
                                           pytest.param(signal.SIGINT, 130, marks=pytest.mark.slow)])
def test_signal_during_optimize_saves_the_best_lens(tmp_path: Path, sig: int, code: int) -> None:
    proc = _spawn("optimize", str(COOKE_OPT), "-o", str(tmp_path / "x.json"), "--steps", "1000", "--json",
                  env={**ENV, "OMP_NUM_THREADS": "1"})
    seen = _wait_for(proc, "step 1/1000", 120)
    assert "step 1/1000" in seen, seen
    time.sleep(0.5)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err
    assert "Traceback" not in err
    s = json.loads(out)
    assert s["interrupted"] and s["output"] == str(tmp_path / "x.json") and s["steps"] >= 1
    _check_lens_dir(tmp_path, "x.json")


# Signals at every moment of a run (startup, command, exit): tests/cli/test_signals.py.


# --------------------------------------------------------------------------------------- determinism


def test_optimize_is_bit_identical_with_1_and_2_threads() -> None:
    """torch's intra-op thread count (what OMP_NUM_THREADS sets) must not change the optimizer's path: before
    the fix, 6 LM steps on the Cooke problem already gave different radii with 1 and 2 threads."""
    import torch

    from lensopt.design import optimize
    from lensopt.spec import dump_json

    threads = torch.get_num_threads()
    out = []
    try:
        for n in (1, 2):
            torch.set_num_threads(n)
            out.append(dump_json(optimize(load_spec(COOKE_OPT), steps=6).spec))
    finally:
        torch.set_num_threads(threads)
    assert out[0] == out[1]


@pytest.mark.slow
def test_timeout_term_leaves_a_valid_cmount_lens(tmp_path: Path) -> None:
    """``timeout -s TERM 20 lensopt optimize specs/cmount_4p.toml -o x.json`` (the issue's CI case)."""
    cmd = ["timeout", "--preserve-status", "-s", "TERM", "20", sys.executable, "-m", "lensopt", "optimize",
           str(ROOT / "specs" / "cmount_4p.toml"), "-o", str(tmp_path / "x.json")]
    r = subprocess.run(cmd, capture_output=True, text=True, env=ENV, timeout=300)
    assert r.returncode == 143 and "Traceback" not in r.stderr, r.stderr
    _check_lens_dir(tmp_path, "x.json")


def test_telephoto_layout_carries_its_front_aperture(cooke, tmp_path: Path) -> None:
    from lensopt.analysis.layout import layout
    from lensopt.spec import build

    spec = load_spec(ROOT / "specs" / "telephoto_plastic.toml")
    fa = spec.system.front_aperture
    assert layout(build(spec), rays_per_field=3).front_aperture == (fa.distance, fa.diameter / 2)
    assert layout(cooke, rays_per_field=3).front_aperture is None
