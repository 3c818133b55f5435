"""The fuzz harness: every generated input goes through a real ``lensopt`` command in-process (typer's
CliRunner) and must keep the contract — exit 0 or 2, never a traceback or an internal error (exit 70),
a bad input as one line ``error: …``, JSON output without NaN/Infinity, no temp file left behind, no hang
(each example gets ``HANG_S`` seconds).

``make test`` runs a fixed number of derandomized examples (≥ 1000 in all); ``LENSOPT_FUZZ_SCALE=N``
multiplies every count (``make test-fuzz-long``); ``LENSOPT_FUZZ_REPORT=path`` writes the tally as JSON.
"""

from __future__ import annotations

import json
import os
import signal
import tempfile
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
import typer.testing as typer_testing
from hypothesis import HealthCheck, settings
from typer.testing import CliRunner

from lensopt.cli.app import app

_build = typer_testing._get_command

ROOT = Path(__file__).resolve().parents[2]
#: The lens the fuzzers start from: small (fast to trace) but with every kind of section a spec has.
BASE_TEXT = """\
name = "fuzz doublet"

[system]
aperture = { epd = 8.0 }
field = { hfov_deg = 3.0, relative = [0.0, 1.0], weights = [1.0, 0.5] }
object = "infinity"
aim = "none"

[spectrum]
wavelengths_nm = [486.1, 587.6]
weights = [1.0, 2.0]
reference_nm = 587.6

[sensor]
pixel_pitch_um = 5.0
resolution = [640, 480]

[[surfaces]]
type = "sphere"
radius = 51.5
thickness = 4.0
material = "N-BK7"
stop = true
semi_diameter = 6.0

[[surfaces]]
type = "conic"
radius = -51.5
conic = -0.5
thickness = 2.0
material = { nd = 1.62, vd = 36.4 }

[[surfaces]]
type = "plane"
thickness = 45.0

[image]
defocus = 0.0
"""
BASE = Path(tempfile.mkdtemp(prefix="lensopt-fuzz-base-")) / "base.toml"
BASE.write_text(BASE_TEXT, encoding="utf-8")
SCALE = float(os.environ.get("LENSOPT_FUZZ_SCALE", "1"))
HANG_S = 60
TALLY: Counter[str] = Counter()
runner = CliRunner()
# typer rebuilds the click command for every invoke (~50 ms); the fuzzers build it once (see invoke).
_COMMAND = typer_testing._get_command(app)


def fuzz_settings(examples: int) -> settings:
    """Fixed seed (derandomize), no deadline (the machine may be loaded; hangs are caught by an alarm)."""
    return settings(max_examples=max(1, int(examples * SCALE)), derandomize=True, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                           HealthCheck.data_too_large, HealthCheck.filter_too_much])


class Hang(Exception):
    pass


def _alarm(signum: int, frame: Any) -> None:
    raise Hang(f"no answer within {HANG_S} s")


def _no_nan(text: str) -> None:
    raise ValueError(f"NaN or Infinity in JSON output: {text}")


def invoke(args: list[Any], folder: Path | None = None, *, json_out: bool = False) -> tuple[int, str, str]:
    """Run ``lensopt ARGS`` and check the contract; returns (exit code, stdout, stderr)."""
    args = [str(a) for a in args]
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(HANG_S)
    typer_testing._get_command = lambda a: _COMMAND if a is app else _build(a)  # type: ignore[assignment]
    try:
        r = runner.invoke(app, args)
    finally:
        typer_testing._get_command = _build
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    out, err = r.stdout, r.stderr
    TALLY["inputs"] += 1
    where = f"lensopt {' '.join(args)!r}\nstdout: {out[-2000:]}\nstderr: {err[-2000:]}"
    if r.exception is not None and not isinstance(r.exception, SystemExit):
        TALLY["tracebacks"] += 1
        raise AssertionError(f"uncaught {type(r.exception).__name__}: {r.exception}\n{where}") from r.exception
    if "Traceback" in out + err or r.exit_code == 70 or "internal error" in err:
        TALLY["tracebacks"] += 1
        raise AssertionError(f"traceback or internal error\n{where}")
    if "no answer within" in err:
        TALLY["hangs"] += 1
        raise AssertionError(f"hang\n{where}")
    assert r.exit_code in (0, 2), f"exit code {r.exit_code}\n{where}"
    TALLY[f"exit {r.exit_code}"] += 1
    if r.exit_code == 2:  # exactly one error line, after any warning lines
        lines = err.strip().splitlines()
        assert lines and lines[-1].startswith("error: "), f"no error line\n{where}"
        assert all(ln.startswith("warning: ") for ln in lines[:-1]), f"not one line\n{where}"
    if r.exit_code == 0 and json_out:
        try:
            json.loads(out, parse_constant=_no_nan)
        except ValueError:
            TALLY["nan_outputs"] += 1
            raise
    if folder is not None:
        left = [p.name for p in folder.iterdir() if ".part" in p.name]
        assert not left, f"temp files left: {left}\n{where}"
    return r.exit_code, out, err


@pytest.fixture(scope="session", autouse=True)
def _report() -> Any:
    yield
    path = os.environ.get("LENSOPT_FUZZ_REPORT")
    if path:
        Path(path).write_text(json.dumps(dict(TALLY), indent=2) + "\n", encoding="utf-8")
