"""Bad specs: the library raises ``SpecError``/``MaterialError`` with one line that starts with the spec
field a person must edit (``path.to.field: what is wrong (got X)``)."""

from __future__ import annotations

import copy
import json
import math
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from lensopt.errors import LensoptError, MaterialError, SpecError
from lensopt.spec import build, load_spec, parse_spec

BASE_TOML = """
name = "test doublet"

[system]
aperture = { epd = 10.0 }
field = { hfov_deg = 5.0, relative = [0.0, 0.7, 1.0] }

[spectrum]
wavelengths_nm = [486.1, 587.6, 656.3]
weights = [1.0, 1.0, 1.0]
reference_nm = 587.6

[[surfaces]]
type = "sphere"
radius = 61.5
thickness = 4.0
material = "N-BK7"
stop = true

[[surfaces]]
type = "sphere"
radius = -44.0
thickness = 2.5
material = "N-SF5"

[[surfaces]]
type = "sphere"
radius = -128.0
thickness = 95.0
"""

Mutation = Callable[[dict[str, Any]], None]


def _set(path: str, value: Any) -> Mutation:
    def mutate(d: dict[str, Any]) -> None:
        *parents, last = path.split(".")
        node: Any = d
        for p in parents:
            node = node[int(p)] if p.isdigit() else node[p]
        if value is _DELETE:
            del node[int(last) if last.isdigit() else last]
        else:
            node[int(last) if last.isdigit() else last] = value

    return mutate


_DELETE = object()


def _diffractive(d: dict[str, Any], base: dict[str, Any], design_nm: float | None) -> None:
    """Turn the last surface into a diffractive surface on ``base``."""
    surf = d["surfaces"][2]
    del surf["radius"]
    surf.update(type="diffractive", base=base, phase={"2": -1.0})
    if design_nm is not None:
        surf["design_wavelength_nm"] = design_nm

# (case id, mutation, error class, message prefix, words the message must contain)
CASES: list[tuple[str, Mutation, type[LensoptError], str, tuple[str, ...]]] = [
    ("unknown glass", _set("surfaces.0.material", "NBK7"), MaterialError, "surfaces[0].material: ",
     ("unknown glass 'NBK7'", "N-BK7 (schott)", "(got 'NBK7')")),
    ("unknown vendor glass", _set("surfaces.1.material", "ohara:N-SF5"), MaterialError, "surfaces[1].material: ",
     ("unknown glass", "ohara")),
    ("zero glass thickness", _set("surfaces.0.thickness", 0.0), SpecError, "surfaces[0].thickness: ",
     ("positive thickness", "(got 0.0)")),
    ("negative glass thickness", _set("surfaces.1.thickness", -1.0), SpecError, "surfaces[1].thickness: ",
     ("positive thickness", "(got -1.0)")),
    ("radius 0", _set("surfaces.2.radius", 0.0), SpecError, "surfaces[2].radius: ", ("non-zero", "(got 0.0)")),
    ("radius nan", _set("surfaces.2.radius", math.nan), SpecError, "surfaces[2].radius: ", ("(got nan)",)),
    ("thickness inf", _set("surfaces.2.thickness", math.inf), SpecError, "surfaces[2].thickness: ",
     ("finite", "(got inf)")),
    ("stop missing", _set("surfaces.0.stop", False), SpecError, "surfaces: ", ("stop = true",)),
    ("stop duplicated", _set("surfaces.2.stop", True), SpecError, "surfaces[2].stop: ", ("several surfaces [0, 2]",)),
    ("wavelength out of a catalog glass's range", _set("spectrum.wavelengths_nm", [486.1, 587.6, 2600.0]),
     MaterialError, "surfaces[0].material: ", ("2.6 µm", "outside the valid range", "N-BK7")),
    ("wavelength out of a model glass's range", lambda d: (
        d["surfaces"][0].update(material={"nd": 1.5, "vd": 60.0}), d["spectrum"].update(
            wavelengths_nm=[1200.0, 587.6, 656.3])), MaterialError, "surfaces[0].material: ", ("Hartmann",)),
    ("unknown top-level field", _set("lens", 1), SpecError, "lens: ", ("unknown field",)),
    ("unknown surface field", _set("surfaces.1.radiuss", 3.0), SpecError, "surfaces[1].radiuss: ",
     ("unknown field", "did you mean 'radius'")),
    ("unknown system field", _set("system.aperture.epdd", 3.0), SpecError, "system.aperture.epdd: ",
     ("did you mean 'epd'",)),
    # A field of another surface type: say which types have it (issue 29), not "did you mean 'conic'?".
    ("conic on a sphere", _set("surfaces.1.conic", -1.0), SpecError, "surfaces[1].conic: ",
     ('a sphere surface has no conic; set type = "conic" or "asphere"', "(got -1.0)")),
    ("coefficients on a conic", lambda d: d["surfaces"][1].update(type="conic", coefficients={"4": 1e-5}), SpecError,
     "surfaces[1].coefficients: ", ('a conic surface has no coefficients; set type = "asphere"',)),
    ("conic on a diffractive sphere base", lambda d: _diffractive(d, {"type": "sphere", "radius": -128.0, "conic": -1},
                                                                  587.6),
     SpecError, "surfaces[2].base.conic: ", ('a sphere base has no conic; set type = "conic" or "asphere"',)),
    ("radius as text", _set("surfaces.0.radius", "big"), SpecError, "surfaces[0].radius: ",
     ("valid number", "(got 'big')")),
    ("thickness as list", _set("surfaces.0.thickness", [1.0]), SpecError, "surfaces[0].thickness: ",
     ("valid number",)),
    ("material as number", _set("surfaces.0.material", 3), SpecError, "surfaces[0].material: ",
     ('"air"', "glass name", "nd", "(got 3)")),
    ("model glass nd too low", _set("surfaces.0.material", {"nd": 0.5, "vd": 50.0}), SpecError,
     "surfaces[0].material.nd: ", ("greater than 1", "(got 0.5)")),
    ("model glass unknown key", _set("surfaces.0.material", {"nd": 1.5, "vd": 50.0, "vdd": 3}), SpecError,
     "surfaces[0].material.vdd: ", ("unknown field",)),
    ("object neither infinity nor distance", _set("system.object", "far"), SpecError, "system.object: ",
     ('"infinity"', "distance", "(got 'far')")),
    ("object distance negative", _set("system.object", {"distance": -3.0}), SpecError,
     "system.object.distance: ", ("greater than 0",)),
    ("aperture as a number", _set("system.aperture", 5.0), SpecError, "system.aperture: ", ("table",)),
    ("aperture with both", _set("system.aperture", {"epd": 10.0, "fnumber": 4.0}), SpecError,
     "system.aperture: ", ("exactly one",)),
    ("surface type unknown", _set("surfaces.1.type", "toroid"), SpecError, "surfaces[1].type: ",
     ("plane, sphere, conic, asphere, diffractive", "(got 'toroid')")),
    ("surface type missing", _set("surfaces.1.type", _DELETE), SpecError, "surfaces[1].type: ", ("missing",)),
    ("surfaces empty", _set("surfaces", []), SpecError, "surfaces: ", ("at least 1",)),
    ("asphere key not a power", lambda d: d["surfaces"][2].update(type="asphere", coefficients={"x": 1.0}),
     SpecError, "surfaces[2].coefficients: ", ("powers", "(got 'x')")),
    ("asphere odd power", lambda d: d["surfaces"][2].update(type="asphere", coefficients={"5": 1.0}),
     SpecError, "surfaces[2].coefficients: ", ("even powers",)),
    ("weights length", _set("spectrum.weights", [1.0, 2.0]), SpecError, "spectrum.weights: ",
     ("one entry per wavelength", "3 wavelengths", "2 weights")),
    ("field weights length", _set("system.field.weights", [1.0]), SpecError, "system.field.weights: ",
     ("one entry per relative field",)),
    ("reference not in the list", _set("spectrum.reference_nm", 550.0), SpecError, "spectrum.reference_nm: ",
     ("one of wavelengths_nm", "(got 550.0)")),
    ("relative field above 1", _set("system.field.relative", [0.0, 1.2]), SpecError,
     "system.field.relative[1]: ", ("[0, 1]", "(got 1.2)")),
    ("relative field negative", _set("system.field.relative", [-0.5, 1.0]), SpecError,
     "system.field.relative[0]: ", ("(got -0.5)",)),
    ("hfov of 90 degrees", _set("system.field.hfov_deg", 90.0), SpecError, "system.field.hfov_deg: ",
     ("less than 90",)),
    ("negative wavelength", _set("spectrum.wavelengths_nm", [486.1, -587.6]), SpecError,
     "spectrum.wavelengths_nm[1]: ", ("positive",)),
    ("aim unknown", _set("system.aim", "sideways"), SpecError, "system.aim: ",
     ("'none', 'chief' or 'full'", "(got 'sideways')")),
    ("vary unknown", _set("surfaces.0.vary", ["conic"]), SpecError, "surfaces[0].vary: ", ("'conic'", "allowed")),
    ("diffractive without design wavelength", lambda d: _diffractive(d, {"type": "sphere", "radius": -128.0}, None),
     SpecError, "surfaces[2].design_wavelength_nm: ", ("missing",)),
    ("diffractive base radius 0", lambda d: _diffractive(d, {"type": "sphere", "radius": 0.0}, 587.6),
     SpecError, "surfaces[2].base.radius: ", ("non-zero", "(got 0.0)")),
    ("diffractive base type unknown", lambda d: _diffractive(d, {"type": "diffractive"}, 587.6),
     SpecError, "surfaces[2].base.type: ", ("plane, sphere, conic, asphere", "(got 'diffractive')")),
    ("spectrum missing", _set("spectrum", _DELETE), SpecError, "spectrum: ", ("required field is missing",)),
]


def _base() -> dict[str, Any]:
    return tomllib.loads(BASE_TOML)


def test_base_spec_is_valid() -> None:
    model = build(parse_spec(_base()))
    assert model.lens.num_surfaces == 3 and model.lens.stop == 0


@pytest.mark.parametrize(("mutate", "error", "prefix", "words"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_spec_names_the_field(mutate: Mutation, error: type[LensoptError], prefix: str,
                                  words: tuple[str, ...]) -> None:
    data = copy.deepcopy(_base())
    mutate(data)
    with pytest.raises(LensoptError) as info:
        build(parse_spec(data))
    assert type(info.value) is error, str(info.value)
    msg = str(info.value)
    assert msg.startswith(prefix), msg
    assert "\n" not in msg
    for w in words:
        assert w in msg, (w, msg)


def test_only_the_first_error_is_shown_with_a_count_of_the_rest() -> None:
    data = _base()
    data["surfaces"][0]["radius"] = 0.0
    data["surfaces"][2]["radius"] = "x"
    with pytest.raises(SpecError) as info:
        parse_spec(data)
    assert str(info.value) == ('surfaces[0].radius: must be non-zero (use inf or type = "plane" for a flat surface)'
                               " [+1 more] (got 0.0)")


def test_union_alternatives_are_not_counted_as_extra_errors() -> None:
    data = _base()
    data["surfaces"][0]["material"] = {"nd": 0.5, "vd": 50.0}
    with pytest.raises(SpecError) as info:
        parse_spec(data)
    assert "more]" not in str(info.value)


# ------------------------------------------------------------------------------------- files


def test_malformed_toml(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text('name = "x"\n[system\naperture = 1\n', encoding="utf-8")
    with pytest.raises(SpecError) as info:
        load_spec(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: malformed TOML: ")
    assert "line 2" in msg and "\n" not in msg


def test_malformed_json(tmp_path: Path) -> None:
    path = tmp_path / "bad.json"
    path.write_text('{"name": "x",', encoding="utf-8")
    with pytest.raises(SpecError, match=r"bad\.json: malformed JSON: "):
        load_spec(path)


def test_json_that_is_not_an_object(tmp_path: Path) -> None:
    path = tmp_path / "list.json"
    path.write_text("[1, 2]", encoding="utf-8")
    with pytest.raises(SpecError) as info:
        load_spec(path)
    assert str(info.value).startswith("spec: a spec must be a table") and "(got 'list')" in str(info.value)


def test_nonexistent_file(tmp_path: Path) -> None:
    path = tmp_path / "missing.toml"
    with pytest.raises(SpecError) as info:
        load_spec(path)
    assert str(info.value) == f"{path}: no such file"


def test_directory(tmp_path: Path) -> None:
    with pytest.raises(SpecError, match="is a directory"):
        load_spec(tmp_path)


def test_txt_file(tmp_path: Path) -> None:
    path = tmp_path / "lens.txt"
    path.write_text(BASE_TOML, encoding="utf-8")
    with pytest.raises(SpecError) as info:
        load_spec(path)
    assert str(info.value) == f"{path}: expected a .toml spec or a .json lens (got '.txt')"


def test_binary_file(tmp_path: Path) -> None:
    path = tmp_path / "lens.toml"
    path.write_bytes(b"\xff\xfe\x00binary")
    with pytest.raises(SpecError) as info:
        load_spec(path)
    assert str(info.value).startswith(f"{path}: not a UTF-8 text file")


def test_json_lens_roundtrip_keeps_infinite_radius(tmp_path: Path) -> None:
    # inf is allowed for a radius only (flat surface); JSON writes it as Infinity and reads it back.
    data = _base()
    data["surfaces"][2]["radius"] = math.inf
    path = tmp_path / "lens.json"
    path.write_text(json.dumps(data), encoding="utf-8")
    assert math.isinf(load_spec(path).surfaces[2].radius)
