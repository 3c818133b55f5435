"""Bad input on the command line: one line on stderr (``error: path.to.field: what is wrong (got X)``),
nothing on stdout, no traceback, exit code 2."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from lensopt.cli.app import app

GOOD = """
name = "cli test singlet"
[system]
aperture = { epd = 8.0 }
field = { hfov_deg = 3.0, relative = [0.0, 1.0] }
[spectrum]
wavelengths_nm = [486.1, 587.6, 656.3]
reference_nm = 587.6
[[surfaces]]
type = "sphere"
radius = 51.5
thickness = 4.0
material = "N-BK7"
stop = true
[[surfaces]]
type = "sphere"
radius = -51.5
thickness = 49.0
"""


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    out = {}
    for name, text in {
        "good.toml": GOOD,
        "bad_glass.toml": GOOD.replace('"N-BK7"', '"N-BK77"'),
        "bad_syntax.toml": GOOD.replace("[system]", "[system"),
        "zero_radius.toml": GOOD.replace("radius = 51.5", "radius = 0.0"),
        "lens.txt": GOOD,
    }.items():
        (tmp_path / name).write_text(text, encoding="utf-8")
        out[name] = tmp_path / name
    (tmp_path / "binary.toml").write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff")
    out["binary.toml"] = tmp_path / "binary.toml"
    out["missing.toml"] = tmp_path / "missing.toml"
    return out


CASES = [
    (["trace", "{missing.toml}"], "{missing.toml}: no such file"),
    (["trace", "{lens.txt}"], "{lens.txt}: expected a .toml spec or a .json lens (got '.txt')"),
    (["trace", "{bad_syntax.toml}"], "{bad_syntax.toml}: malformed TOML: "),
    (["trace", "{binary.toml}"], "{binary.toml}: not a UTF-8 text file"),
    (["trace", "{bad_glass.toml}"], "surfaces[0].material: unknown glass 'N-BK77'; close matches: N-BK7"),
    (["trace", "{zero_radius.toml}"], "surfaces[0].radius: must be non-zero"),
    (["trace", "{good.toml}", "--sampling", "ring:5"], "--sampling: expected rings:N"),
    (["trace", "{good.toml}", "--sampling", "rings:0"], "--sampling: "),
    (["trace", "{good.toml}", "--sampling", "grid:7:nojitter"], "--sampling: "),
    (["trace", "{good.toml}", "--aim", "fully"], "--aim: must be none, chief or full (got 'fully')"),
    (["ray", "{good.toml}", "--aim", "real"], "--aim: must be none, chief or full (got 'real')"),
    (["ray", "{good.toml}", "--field", "95"], "--field: "),
    (["ray", "{good.toml}", "--field", "inf"], "--field: "),
    (["ray", "{good.toml}", "--pupil", "nan", "0"], "--pupil: "),
    (["ray", "{good.toml}", "--pupil", "0", "1.5"],
     "--pupil: relative pupil coordinates must lie within the unit circle, px² + py² ≤ 1 (1 is the pupil edge) "
     "(got '0 1.5')"),
    (["ray", "{good.toml}", "--pupil", "0.8", "0.7"], "--pupil: relative pupil coordinates must lie within"),
    (["ray", "{good.toml}", "--wavelength", "-5"], "--wavelength: must be a positive wavelength in nm"),
    (["ray", "{good.toml}", "--wavelength", "inf"], "--wavelength: "),
    (["ray", "{missing.toml}"], "{missing.toml}: no such file"),
]


@pytest.mark.parametrize(("args", "expected"), CASES, ids=[" ".join(a).replace("{", "").replace("}", "")
                                                             for a, _ in CASES])
def test_bad_input_gives_one_line_and_exit_code_2(files: dict[str, Path], args: list[str], expected: str) -> None:
    def fill(text: str) -> str:
        for name, path in files.items():
            text = text.replace("{" + name + "}", str(path))
        return text

    argv = [fill(a) for a in args]
    result = CliRunner().invoke(app, argv)
    assert result.exit_code == 2, (result.exit_code, result.stdout, result.stderr, result.exception)
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: " + fill(expected)), lines[0]
    assert "Traceback" not in result.stderr


def test_good_input_runs(files: dict[str, Path]) -> None:
    result = CliRunner().invoke(app, ["ray", str(files["good.toml"]), "--field", "3", "--pupil", "0", "1", "--json"])
    assert result.exit_code == 0, result.stderr
    assert '"status": "ok"' in result.stdout
