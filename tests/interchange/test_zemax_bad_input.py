"""Bad or partly unsupported .zmx input: one warning line per ignored item and the lens still imported when
the rest is usable; otherwise one SpecError line (exit code 2 from the CLI), nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from lensopt.cli.app import app
from lensopt.errors import SpecError
from lensopt.interchange.zemax.read import import_zemax, read_zemax

DATA = Path(__file__).resolve().parents[1] / "data" / "zemax"
LENS1 = (DATA / "optiland_lens1.zmx").read_text()


def _edit(old: str, new: str) -> str:
    assert old in LENS1
    return LENS1.replace(old, new, 1)


def test_utf16_file_reads_like_ascii(tmp_path: Path) -> None:
    p = tmp_path / "lens1_utf16.zmx"
    p.write_bytes(LENS1.encode("utf-16"))  # with a BOM, as OpticStudio writes
    q = tmp_path / "lens1_utf16le.zmx"
    q.write_bytes(LENS1.encode("utf-16-le"))  # without a BOM
    ref = read_zemax(DATA / "optiland_lens1.zmx").spec
    assert read_zemax(p).spec == ref
    assert read_zemax(q).spec == ref


def test_binary_file_is_refused(tmp_path: Path) -> None:
    p = tmp_path / "lens.zmx"
    p.write_bytes(bytes(range(256)) * 8)
    with pytest.raises(SpecError, match="binary"):
        read_zemax(p)


def test_truncated_file_is_refused_with_a_reason() -> None:
    text = LENS1[: LENS1.index("SURF 2")]  # object and one surface, no image
    with pytest.raises(SpecError, match="truncated"):
        import_zemax(text)


def test_truncated_wavelength_list_warns() -> None:
    text = _edit("WAVM 3 0.65627250000000004 1\n", "")
    result = import_zemax(text)
    assert any("declares 3 wavelengths" in w for w in result.warnings)
    assert len(result.spec.spectrum.wavelengths_nm) == 2


def test_unsupported_surface_type_with_power_is_refused() -> None:
    text = _edit("SURF 3\n  TYPE STANDARD", "SURF 3\n  TYPE TOROIDAL\n  PARM 1 30")
    with pytest.raises(SpecError, match="TYPE TOROIDAL is not supported"):
        import_zemax(text)


def test_unsupported_dummy_surface_imports_with_one_warning() -> None:
    # The flat stop surface written as a (powerless) TILTSURF-like unknown type: usable, one warning.
    text = _edit("SURF 5\n  STOP\n  TYPE STANDARD", "SURF 5\n  STOP\n  TYPE USERSURF")
    result = import_zemax(text)
    lines = [w for w in result.warnings if "USERSURF" in w]
    assert len(lines) == 1 and "plane" in lines[0]
    assert result.spec.surfaces[4].type == "plane"


def test_ignored_operands_are_one_warning_line_each() -> None:
    text = _edit("SURF 2\n", "SURF 2\n  OBSC 0 2.0 0\n  SQAP 3 2 0\n").replace("PWAV 2\n", "PWAV 2\nFOOB 1 2\nFOOB 3\n")
    warnings = import_zemax(text).warnings
    assert sum("OBSC" in w for w in warnings) == 1
    assert sum("SQAP" in w for w in warnings) == 1
    assert sum("FOOB" in w and "2 lines" in w for w in warnings) == 1


def test_unknown_glass_without_catalog_is_refused() -> None:
    text = _edit("GLAS N-SF2 1 0", "GLAS UNOBTAINIUM-7 1 0")
    with pytest.raises(SpecError, match="unknown glass 'UNOBTAINIUM-7'.*--catalog"):
        import_zemax(text)


def test_mirror_and_coordinate_break_are_refused() -> None:
    with pytest.raises(SpecError, match="mirror"):
        import_zemax(_edit("GLAS N-SF2 1 0 1.6476432085037231 33.838470458984375", "GLAS MIRROR 0 0"))
    text = _edit("SURF 5\n  STOP", "SURF 5\n  TYPE COORDBRK\n  PARM 5 5.0\n  DISZ 0\nSURF 6\n  STOP")
    text = text.replace("SURF 6\n  TYPE STANDARD\n  CURV 0.039", "SURF 7\n  TYPE STANDARD\n  CURV 0.039")
    with pytest.raises(SpecError, match="COORDBRK.*tilt about z"):
        import_zemax(text)


def test_real_file_without_stop_size_is_refused() -> None:
    # DeepLens wrote FLOA (float by stop size) without the stop's semi-diameter; optiland refuses it too.
    with pytest.raises(SpecError, match="FLOA"):
        read_zemax(DATA / "deeplens_ef35mm_f2.0.zmx")


def test_cli_exit_codes_and_no_partial_output(tmp_path: Path) -> None:
    runner = CliRunner()
    out = tmp_path / "lens.json"
    bad = tmp_path / "bad.zmx"
    bad.write_text(_edit("GLAS N-SF2 1 0", "GLAS UNOBTAINIUM-7 1 0"))
    res = runner.invoke(app, ["import-zemax", str(bad), "-o", str(out)])
    assert res.exit_code == 2
    assert "UNOBTAINIUM-7" in res.output and len(res.output.strip().splitlines()) == 1
    assert not out.exists()
    res = runner.invoke(app, ["import-zemax", str(DATA / "rayoptics_US00583336-2-scaled.zmx"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert res.output.count("warning:") >= 3 and out.exists()
    zmx = tmp_path / "back.zmx"
    res = runner.invoke(app, ["export-zemax", str(out), "-o", str(zmx)])
    assert res.exit_code == 0 and zmx.exists()


def test_environment_and_configurations_are_one_warning_each() -> None:
    text = LENS1.replace("MODE SEQ\n", "MODE SEQ\nENVD 35 1 0\n").replace("SURF 8\n", "MNUM 3 1\nSURF 8\n")
    warnings = import_zemax(text).warnings
    assert sum("ENVD 35" in w for w in warnings) == 1
    assert sum("3 configurations" in w for w in warnings) == 1
    assert not any("ENVD" in w for w in import_zemax(LENS1.replace("MODE SEQ\n", "MODE SEQ\nENVD 20 1 0\n")).warnings)


def test_catalog_glass_outside_its_range_points_to_agf(tmp_path: Path) -> None:
    text = _edit("WAVM 3 0.65627250000000004 1", "WAVM 3 3.5 1")  # 3.5 µm: beyond Schott's data
    with pytest.raises(SpecError, match="outside the valid range.*--catalog"):
        import_zemax(text)


def test_truncated_or_garbled_files_fail_with_one_line_only() -> None:
    # Every truncation of a real file (at a line end and in mid-line) and random garbled numbers either
    # import or raise the one-line LensoptError; nothing else escapes (IndexError, ValueError, ...).
    import random

    from lensopt.errors import LensoptError

    lines = LENS1.splitlines(keepends=True)
    texts = ["".join(lines[:k]) for k in range(1, len(lines))]
    texts += ["".join(lines[:k]) + lines[k][: len(lines[k]) // 2] for k in range(1, len(lines))]
    rnd = random.Random(0)
    for _ in range(60):
        ls = list(lines)
        i = rnd.randrange(len(ls))
        tokens = ls[i].split()
        if len(tokens) > 1:
            tokens[rnd.randrange(1, len(tokens))] = rnd.choice(["x", "-1", "0", "1e400", "nan"])
            ls[i] = " ".join(tokens) + "\n"
            texts.append("".join(ls))
    for text in texts:
        try:
            import_zemax(text)
        except LensoptError as err:
            assert "\n" not in str(err)
