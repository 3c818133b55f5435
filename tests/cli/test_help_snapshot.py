"""The command line's surface as a recorded copy: the ``--help`` text of every command and subcommand and the
top-level keys of every ``--json`` output (issue 26: the CLI moved into ``lensopt/cli/`` with behaviour
unchanged; the copy was recorded on the code before the move).

The help is rendered at a fixed width (``COLUMNS=100``) so that the copy does not depend on the terminal.
The JSON runs use the smallest settings (one step, a few rays, a 48×32 image); warmup's compilation is
replaced by a stand-in that writes a file, as in tests/cli/test_warmup.py.

Regenerate after an intended change of the CLI: ``python tests/cli/test_help_snapshot.py --write``.
"""

from __future__ import annotations

import json
import sys
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from lensopt.cli.app import app

ROOT = Path(__file__).resolve().parents[2]
SNAPSHOT = Path(__file__).resolve().parent / "data" / "help_snapshot.json"
COOKE = ROOT / "specs" / "cooke_triplet.toml"
COOKE_OPT = ROOT / "specs" / "cooke_triplet_opt.toml"
ENV = {"COLUMNS": "100", "LINES": "40", "TERMINAL_WIDTH": "100", "NO_COLOR": "1"}
runner = CliRunner()

# The tiny network of the restoration commands (the Cooke triplet's 3 wavelengths → RGB).
TINY_RESTORE = {"width": 4, "encoder_blocks": [1, 1], "middle_blocks": 1, "decoder_blocks": [1, 1],
                "train": {"batch": 2, "patch": 32, "steps": 1, "checkpoint_every": 1, "validate_every": 1,
                          "validation_patches": 2}}


def _invoke(args: list[str]) -> Any:
    r = runner.invoke(app, args, env=ENV, prog_name="lensopt")
    assert r.exit_code == 0, (args, r.output)
    return r


def help_texts() -> dict[str, str]:
    """``lensopt … --help`` for the root, every group and every command (walked from the app itself)."""
    out: dict[str, str] = {}

    def walk(cmd: Any, path: list[str]) -> None:
        out[" ".join(["lensopt", *path, "--help"])] = _invoke([*path, "--help"]).stdout
        if hasattr(cmd, "list_commands"):
            ctx = cmd.make_context("lensopt", [], resilient_parsing=True)
            for name in cmd.list_commands(ctx):
                walk(cmd.get_command(ctx, name), [*path, name])

    walk(typer.main.get_command(app), [])
    out["lensopt plot"] = _invoke(["plot"]).stdout  # no subcommand: the group's help
    return out


def _tiny_restore_lens(tmp: Path) -> Path:
    data = tomllib.loads(COOKE.read_text())
    data["sensor"]["resolution"] = [640, 480]
    data["restore"] = TINY_RESTORE
    path = tmp / "tiny_restore.json"
    path.write_text(json.dumps(data))
    return path


def _tiny_joint_spec(tmp: Path) -> Path:
    data = tomllib.loads(COOKE.read_text())
    data["sensor"]["resolution"] = [640, 480]
    data["surfaces"][0]["vary"] = ["radius"]
    data["optimize"] = {"objective": "restored", "sampling": "rings:3", "steps": 1,
                        "image": {"patch": 32, "batch": 2, "psf_size": 9, "fields": 3, "sampling": "rings:4",
                                  "validation": 2, "noise": 0.005}}
    data["restore"] = {"width": 4, "encoder_blocks": [1, 1], "decoder_blocks": [1, 1],
                       "train": {"checkpoint_every": 1, "validate_every": 0}}
    path = tmp / "tiny_joint.json"
    path.write_text(json.dumps(data))
    return path


def _image(tmp: Path) -> Path:
    """A 48×32 8-bit RGB scene."""
    import OpenImageIO as oiio

    path = tmp / "scene.png"
    arr = (np.arange(32 * 48 * 3, dtype=np.uint32).reshape(32, 48, 3) * 37 % 256).astype(np.uint8)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(48, 32, 3, oiio.UINT8)) and out.write_image(arr)
    out.close()
    return path


def json_keys(tmp: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, list[str]]:
    """The top-level keys of each command's ``--json`` output, in the order printed."""
    from lensopt.accel import aot

    monkeypatch.setenv("TORCHINDUCTOR_CACHE_DIR", str(tmp / "inductor"))

    def fake_build(lens: Any, *, record: bool = False, upto: Any = None, newton_iterations: int = 12) -> float:
        path = aot.package_path(lens, record=record)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"stand-in")
        return 1.5

    monkeypatch.setattr(aot, "build_package", fake_build)
    image = _image(tmp)
    tiny = _tiny_restore_lens(tmp)
    ck = tmp / "irm"
    cooke, cooke_opt = str(COOKE), str(COOKE_OPT)
    runs: dict[str, list[str]] = {
        "trace": ["trace", cooke, "--sampling", "rings:4", "--json"],
        "trace --mtf": ["trace", cooke, "--sampling", "rings:4", "--mtf", "10,20", "--json"],
        "trace --wavefront --seidel": ["trace", cooke, "--sampling", "rings:4", "--wavefront", "--seidel",
                                       "--pupil-grid", "8", "--json"],
        "ray": ["ray", cooke, "--json"],
        "simulate --plan": ["simulate", cooke, str(image), "--plan", "--json"],
        "simulate": ["simulate", cooke, str(image), "-o", str(tmp / "sim.png"), "--rays", "rings:4", "--score",
                     "--json"],
        "check": ["check", str(ROOT / "lenses" / "cooke_triplet_opt.json"), "--baseline",
                  str(ROOT / "lenses" / "check_baseline.json"), "--json"],
        "accuracy": ["accuracy", cooke, "--knobs", "grid", "--repeats", "1", "--json"],
        "train-irm": ["train-irm", str(tiny), "-o", str(ck), "--steps", "1", "--fields", "3", "--psf-size", "9",
                      "--sampling", "rings:4", "--json"],
        "evaluate": ["evaluate", str(tiny), "--count", "1", "--patch", "32", "--rays", "rings:4", "--json"],
        "evaluate --irm": ["evaluate", str(tiny), "--count", "1", "--patch", "32", "--rays", "rings:4", "--irm",
                           str(ck), "--json"],
        "tolerance": ["tolerance", cooke, "--profile", "s6.2", "--trials", "2", "--scheduler", "serial",
                      "--sampling", "rings:4", "--json"],
        "optimize": ["optimize", cooke_opt, "-o", str(tmp / "opt.json"), "--steps", "1", "--quiet", "--json"],
        "optimize (restored)": ["optimize", str(_tiny_joint_spec(tmp)), "-o", str(tmp / "joint.json"), "--steps", "1",
                                "--quiet", "--json"],
        "sweep": ["sweep", cooke_opt, "--vary", "optimize.solves[0].value=50.0", "--steps", "1", "--scheduler",
                  "serial", "--esr-sampling", "rings:3", "-o", str(tmp / "sweep"), "--quiet", "--json"],
        "warmup": ["warmup", cooke, "--json"],
    }
    return {name: list(json.loads(_invoke(args).stdout)) for name, args in runs.items()}


def snapshot(tmp: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    return {"help": help_texts(), "json_keys": json_keys(tmp, monkeypatch)}


def test_help_and_json_keys_match_the_recorded_copy(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    recorded = json.loads(SNAPSHOT.read_text(encoding="utf-8"))
    now = snapshot(tmp_path, monkeypatch)
    assert sorted(now["help"]) == sorted(recorded["help"]), "commands added or removed"
    for cmd, text in recorded["help"].items():
        assert now["help"][cmd] == text, cmd
    assert now["json_keys"] == recorded["json_keys"]


if __name__ == "__main__":  # python tests/cli/test_help_snapshot.py --write
    import tempfile

    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python tests/cli/test_help_snapshot.py --write")
    with tempfile.TemporaryDirectory() as d, pytest.MonkeyPatch.context() as mp:
        data = snapshot(Path(d), mp)
    SNAPSHOT.parent.mkdir(exist_ok=True)
    SNAPSHOT.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    print(f"wrote {SNAPSHOT}: {len(data['help'])} help texts, {len(data['json_keys'])} JSON outputs")
