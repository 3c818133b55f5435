"""Fuzzing every command with hypothesis: mutated TOML specs, arbitrary and mutated JSON lenses, CODE V
text, image files and command-line arguments (the contract is checked by ``conftest.invoke``).

Counts per test are chosen so that ``make test`` runs ≥ 1000 examples in well under 2 minutes (every
command: trace, ray, plot *, simulate, optimize, import/export CODE V and Zemax, and bad input of check,
accuracy and tolerance).
"""

from __future__ import annotations

import copy
import json
import re
import tempfile
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from tests.fuzz.fuzz_harness import BASE, BASE_TEXT, fuzz_settings, invoke

COOKE = BASE  # valid input of every command: a small lens (fast), see fuzz_harness.BASE_TEXT
COOKE_TEXT = BASE_TEXT
COOKE_DATA = tomllib.loads(COOKE_TEXT)
# Lines "key = value" of the spec whose value a mutation replaces.
ASSIGN = [m for m in re.finditer(r"^(\s*[A-Za-z_]+\s*=\s*)(.+)$", COOKE_TEXT, flags=re.M)]

NASTY_TOML = ["0", "-0.0", "1e308", "-1e308", "1e-308", "5e-324", "nan", "-nan", "inf", "-inf", "1e999", '"text"',
              '"1e999"', '"yes"', "true", "false", "[]", "{}", "[1, 2]", "[[1]]", "9" * 30, "-" + "9" * 30,
              '"N-BK7"', '"air"', '"NOPE-GLASS"', "{ nd = 1.5, vd = 60.0 }", "{ nd = 0.5, vd = 1e9 }",
              "{ epd = -1 }", "{ fnumber = 0 }", "{ hfov_deg = 89.999 }", "{ image_height = 1e-300 }",
              "[0.0, 0.0, 0.0]", "[-1.0]", "[1e308, 1e308]", '"infinity"', "{ distance = 0 }", "''", '"\\u0000"']
SCALARS = st.one_of(
    st.sampled_from(NASTY_TOML),
    st.floats(-100, 100, allow_nan=False).map(repr),  # plausible numbers: lenses that trace, or nearly
    st.floats(allow_nan=False, allow_infinity=False, width=64).map(repr),
    st.integers(min_value=-(10**20), max_value=10**20).map(str),
)


def _tmp() -> Path:
    return Path(tempfile.mkdtemp(prefix="lensopt-fuzz-"))


@st.composite
def mutated_toml(draw: st.DrawFn) -> str:
    text = COOKE_TEXT
    picks = draw(st.lists(st.integers(0, len(ASSIGN) - 1), min_size=1, max_size=3, unique=True))
    for i in sorted(picks, reverse=True):  # from the end, so earlier offsets stay valid
        m = ASSIGN[i]
        value = draw(SCALARS)
        text = text[:m.start(2)] + value + text[m.end(2):]
    if draw(st.integers(0, 9)) == 0:  # sometimes also break the structure
        cut = draw(st.integers(0, len(text)))
        text = text[:cut] + draw(st.sampled_from(["[", "]", "=", "\n[[surfaces]]\n", "\x00", '"', "\n[system]\n"])) \
            + text[cut:]
    return text


@fuzz_settings(350)
@given(text=mutated_toml(), command=st.sampled_from(["trace"] * 6 + ["ray", "export-codev"]))
def test_fuzz_toml_specs(text: str, command: str) -> None:
    folder = _tmp()
    spec = folder / "lens.toml"
    spec.write_text(text, encoding="utf-8")
    if command == "trace":
        invoke(["trace", spec, "--sampling", "rings:2", "--json"], folder, json_out=True)
    elif command == "ray":
        invoke(["ray", spec, "--json"], folder, json_out=True)
    else:
        invoke(["export-codev", spec, "-o", folder / "x.seq"], folder)


def _leaves(obj: Any, path: tuple = ()) -> list[tuple]:
    if isinstance(obj, dict):
        return [p for k, v in obj.items() for p in _leaves(v, (*path, k))] + [path]
    if isinstance(obj, list):
        return [p for i, v in enumerate(obj) for p in _leaves(v, (*path, i))] + [path]
    return [path]


LEAVES = [p for p in _leaves(COOKE_DATA) if p]
JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.floats(width=64) | st.integers(-(10**30), 10**30) | st.text(max_size=12)
    | st.sampled_from([1e308, -1e308, 0.0, "1e999", "air", "SK16", "sphere", "plane", "asphere", "conic"]),
    lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=8), kids, max_size=4),
    max_leaves=8,
)


@st.composite
def mutated_json(draw: st.DrawFn) -> str:
    data = copy.deepcopy(COOKE_DATA)
    for path in draw(st.lists(st.sampled_from(LEAVES), min_size=1, max_size=3)):
        parent = data
        try:
            for key in path[:-1]:
                parent = parent[key]
            action = draw(st.integers(0, 5))
            if action == 0 and isinstance(parent, dict):
                parent.pop(path[-1], None)
            else:
                parent[path[-1]] = draw(JSON_VALUES)
        except (KeyError, IndexError, TypeError):
            continue
    return json.dumps(data, allow_nan=True)


@fuzz_settings(300)
@given(text=st.one_of(mutated_json(), mutated_json(), JSON_VALUES.map(lambda v: json.dumps(v, allow_nan=True)),
                      st.text(max_size=50)))
def test_fuzz_json_lenses(text: str) -> None:
    folder = _tmp()
    lens = folder / "lens.json"
    lens.write_text(text, encoding="utf-8")
    invoke(["trace", lens, "--sampling", "rings:2", "--json"], folder, json_out=True)


CODEV_LINES = ["RDM;LEN", "TITLE 'fuzz'", "EPD 25.0", "EPD -1", "EPD 1e308", "DIM M", "DIM I", "DIM X", "WL 587.6",
               "WL 486.1 587.6 656.3", "WL -5", "REF 1", "REF 9", "WTW 1", "XAN 0.0", "YAN 0.0 10.0 20.0", "YAN 89.9",
               "SO 0.0 0.1e14", "SO 0 1e308", "S 61.47 6.0 NBK7_SCHOTT", "S -44.64 2.5 NSF5_SCHOTT",
               "S -129.94 95.95", "S 0 0", "S 1e-300 1e300", "S nan 1", "S 10 1 NOPE_GLASS", "S 10 1 1.5:60",
               "  STO", "  CIR 12.0", "  CIR -1", "  K -1.0", "  A 1e-5", "  ASP", "  PIM", "SI 0.0 0.0", "GO",
               "PIM", "STO S1", "XYZ 1 2 3", "", "!", "S", "S 10", "FNO 4", "FNO 0", "CA", "  SLB \"x\""]


@fuzz_settings(200)
@given(lines=st.lists(st.one_of(st.sampled_from(CODEV_LINES), st.text(max_size=20)), min_size=0, max_size=25))
def test_fuzz_codev_import(lines: list[str]) -> None:
    folder = _tmp()
    seq = folder / "lens.seq"
    seq.write_text("\n".join(lines) + "\n", encoding="utf-8")
    code, _, _ = invoke(["import-codev", seq, "-o", folder / "lens.json"], folder)
    if code == 0:  # what was imported must trace (or be refused in one line)
        invoke(["trace", folder / "lens.json", "--sampling", "rings:2", "--json"], folder, json_out=True)


ZEMAX_LINES = ["VERS 140730 73 26155", "MODE SEQ", "MODE NSC", "NAME fuzz", "UNIT MM X W X CM MR CPMM", "UNIT IN",
               "FNUM 2.1 0", "ENPD 10", "ENPD -1", "ENPD 1e308", "FTYP 0 0 3 3 0 0 0", "FTYP 3 0 3 3 0 0 0",
               "FTYP 9 9", "YFLN 0 8.0 13.6", "YFLN 0 89.99", "XFLN 0 0 0", "WAVM 1 0.55 1", "WAVM 2 -1 1",
               "WAVM 1 nan 1", "PWAV 1", "PWAV 9", "GCAT SCHOTT", "SURF 0", "SURF 1", "SURF 2", "SURF 3", "SURF 99",
               "  TYPE STANDARD", "  TYPE EVENASPH", "  TYPE COORDBRK", "  TYPE TOROIDAL", "  CURV 0.02",
               "  CURV 0.0 0 0 0 0 \"\"", "  CURV 1e308", "  CURV nan", "  DISZ 5", "  DISZ INFINITY", "  DISZ -1e308",
               "  GLAS N-BK7 0 0 1.5 60", "  GLAS NOPE 0 0 0 0", "  GLAS MIRROR", "  DIAM 5", "  DIAM -3", "  STOP",
               "  CONI -1", "  CONI inf", "  PARM 1 0.5", "  PARM 99 1", "  PARM 2", "  SQAP 1 1", "  FLAP 0 5 0",
               "  PZUP 1 1 0 0", "  MIRR 2 0", "SURF", "CURV", "", "GLAS", "TOL TOFF"]


@fuzz_settings(120)
@given(lines=st.lists(st.one_of(st.sampled_from(ZEMAX_LINES), st.text(max_size=20)), min_size=0, max_size=30),
       utf16=st.booleans())
def test_fuzz_zemax_import(lines: list[str], utf16: bool) -> None:
    folder = _tmp()
    zmx = folder / "lens.zmx"
    zmx.write_bytes("\r\n".join(lines).encode("utf-16" if utf16 else "utf-8", errors="replace"))
    code, _, _ = invoke(["import-zemax", zmx, "-o", folder / "lens.json"], folder)
    if code == 0:
        invoke(["trace", folder / "lens.json", "--sampling", "rings:2", "--json"], folder, json_out=True)


NUM_TEXT = st.one_of(st.sampled_from(["0", "-1", "1e308", "-1e308", "nan", "inf", "-inf", "1e-320", "89.9999",
                                      "90", "x", "", "9" * 40, "-" + "9" * 25, "0x10", "1_000"]),
                     st.floats(-100, 100, allow_nan=False).map(lambda v: f"{v:.3g}"))
SAMPLING = st.sampled_from(["rings:1", "rings:2", "rings:3:nojitter", "grid:3", "rings:0", "grid:0", "rings:-1",
                            "rings", "hex:3", "rings:2:jitter", "grid:2:nojitter", "rings:99999999999", "",
                            " rings:2 "])
AIM = st.sampled_from(["none"] * 8 + ["chief", "full", "sideways", "", "NONE"])  # aiming is slow: rarely


@st.composite
def cli_args(draw: st.DrawFn, folder: Path) -> tuple[list[str], bool]:
    """(arguments, whether stdout is JSON) for one command with adversarial options."""
    command = draw(st.sampled_from(["trace", "trace", "trace", "ray", "ray", "ray", "plot-layout", "plot-fans",
                                    "plot-spots", "plot-field", "plot-psf", "plot-mtf", "export-codev", "export-zemax",
                                    "optimize", "check", "accuracy", "tolerance", "usage"]))
    lens = str(draw(st.sampled_from([COOKE, COOKE, folder / "missing.toml", folder, folder / "x.txt"])))
    suffix = draw(st.sampled_from([".png", ".svg", ".xyz", "", ".json", ".seq", "/"]))
    out = str(folder / f"out{suffix}")
    if command == "trace":
        args = ["trace", lens, "--sampling", draw(SAMPLING), "--aim", draw(AIM), "--json"]
        if draw(st.booleans()):
            args += ["--aim-steps", draw(NUM_TEXT)]
        if draw(st.booleans()):
            args += ["--seed", draw(NUM_TEXT)]
        return args, True
    if command == "ray":
        return ["ray", lens, "--field", draw(NUM_TEXT), "--pupil", draw(NUM_TEXT), draw(NUM_TEXT),
                "--wavelength", draw(NUM_TEXT), "--aim", draw(AIM), "--json"], True
    if command.startswith("plot-"):
        kind = command[5:]
        dpi = draw(st.sampled_from(["30", "20", "x", "1e9", "-5", "0", "1201"]))
        args = ["plot", kind, lens, "-o", out, "--dpi", dpi]
        if kind in ("spots", "field"):
            args += ["--sampling", draw(SAMPLING)]
        if kind == "psf":
            args += ["--rays", draw(SAMPLING), "--pitch-um", draw(NUM_TEXT)]
        if kind == "mtf":
            args += ["--method", draw(st.sampled_from(["heuristic", "nope", ""])), "--max-frequency", draw(NUM_TEXT)]
        return args, False
    if command in ("export-codev", "export-zemax"):
        return [command, lens, "-o", out], False
    # Long-running commands get bad input only (a real run is their own tests' business).
    if command == "check":
        return ["check", lens, "--baseline", draw(st.sampled_from([lens, str(folder / "x.txt"), out])), "--json"], True
    if command == "accuracy":
        return ["accuracy", lens, "--target", draw(st.sampled_from(["x", "-1%", "", "%", "1e999%x"])), "--knobs",
                draw(st.sampled_from(["nope", "rings,nope", ""])), "--json"], True
    if command == "tolerance":
        return ["tolerance", lens, "--metric", draw(st.sampled_from(["bogus", "", "esr2"])), "--trials",
                draw(st.sampled_from(["-1", "x", "0"])), "--scheduler", "serial", "--json"], True
    if command == "optimize":  # bad input only: a real run is the signal tests' business
        return ["optimize", lens, "-o", out, "--steps", draw(st.sampled_from(["0", "-1", "x"])), "-q"], False
    words = draw(st.lists(st.sampled_from(["--bogus", "-x", "trace", "plot", "nope", "--json", "--", "-o", "--seed",
                                           "--max-memory", "0", "1Q", "--version", "--help"]), max_size=4))
    return words, False


@fuzz_settings(150)
@given(data=st.data())
def test_fuzz_cli_arguments(data: st.DataObject) -> None:
    folder = _tmp()
    (folder / "x.txt").write_text("not a lens")
    args, json_out = data.draw(cli_args(folder))
    # Plots of valid input are slow: keep those examples, but at the cheapest resolution.
    invoke(args, folder, json_out=json_out)


def _image(path: Path, arr: np.ndarray) -> None:
    import OpenImageIO as oiio

    h, w, c = arr.shape
    fmt = oiio.UINT8 if arr.dtype == np.uint8 else oiio.FLOAT
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(w, h, c, fmt))
    assert out.write_image(np.ascontiguousarray(arr))
    out.close()


@st.composite
def images(draw: st.DrawFn) -> tuple[str, np.ndarray]:
    h, w = draw(st.integers(1, 24)), draw(st.integers(1, 24))
    c = draw(st.sampled_from([1, 2, 3, 4, 5]))
    if draw(st.booleans()):
        values = draw(st.sampled_from([0, 255, 128]))
        return ".png", np.full((h, w, min(c, 4)), values, np.uint8)
    special = draw(st.sampled_from([0.0, 1.0, -1.0, 1e30, np.nan, np.inf, -np.inf, 0.5]))
    arr = np.full((h, w, c), draw(st.floats(0, 2)), np.float32)
    arr[draw(st.integers(0, h - 1)), draw(st.integers(0, w - 1)), 0] = special
    return ".exr", arr


@fuzz_settings(40)
@given(img=images(), region=st.sampled_from([None, "center", "corner", "full", "nan,0,10,10", "0,0,-1,1",
                                             "0,0,1e308,1e308", "tile:0,0/2x2", "tile:5,5/2x2", "x"]),
       extra=st.sampled_from([[], ["--plan"], ["--effects=-convolution,-distortion,-ri"], ["--overlap", "1.5"],
                              ["--grid", "2x2"], ["--grid", "0x3"], ["--kernel", "nope"], ["--effects", "+bogus"],
                              ["--effects", "noise=nan"]]))
def test_fuzz_images(img: tuple[str, np.ndarray], region: str | None, extra: list[str]) -> None:
    folder = _tmp()
    suffix, arr = img
    path = folder / f"scene{suffix}"
    _image(path, arr)
    args = ["simulate", COOKE, path, "-o", folder / f"out{suffix}", "--rays", "rings:2", "--json", *extra]
    if region is not None:
        args += ["--region", region]
    invoke(args, folder, json_out=True)
