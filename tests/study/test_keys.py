"""Dotted keys into a spec and ``--vary`` values (lensopt.study.keys): set values land in the built lens,
the input is untouched, every bad key or value is a LensoptError naming --vary."""

from __future__ import annotations

from pathlib import Path

import pytest

from lensopt.errors import LensoptError
from lensopt.spec import build, load_spec
from lensopt.study.keys import get_key, parse_key, parse_vary, set_key

COOKE = Path(__file__).resolve().parents[2] / "specs" / "cooke_triplet_opt.toml"


def test_parse_key() -> None:
    assert parse_key("optimize.solves[0].value") == ["optimize", "solves", 0, "value"]
    assert parse_key("surfaces[-1].thickness") == ["surfaces", -1, "thickness"]
    for bad in ("", "surfaces[x].thickness", "a..b", "3d"):
        with pytest.raises(LensoptError, match="^--vary"):
            parse_key(bad)


def test_get_and_set_values_land_in_the_lens() -> None:
    spec = load_spec(COOKE)
    # The file says: [optimize] solves = [{ type = "efl", surface = -1, value = 50.0 }]; surfaces[3] thickness 4.75041
    assert get_key(spec, "optimize.solves[0].value") == 50.0
    assert get_key(spec, "surfaces[3].thickness") == 4.75041
    s2 = set_key(spec, "surfaces[3].thickness", 5.5)
    assert float(build(s2).lens.thickness[3]) == 5.5
    assert spec.surfaces[3].thickness == 4.75041  # the input is not changed
    s3 = set_key(spec, "system.field.hfov_deg", 15.0)
    assert s3.system.field.hfov_deg == 15.0
    s4 = set_key(spec, "optimize.solves[-1].value", 48.0)
    assert s4.optimize.solves[0].value == 48.0
    assert set_key(spec, "optimize.steps", 7).optimize.steps == 7
    assert set_key(spec, "surfaces[0].material", "F2").surfaces[0].material == "F2"


@pytest.mark.parametrize(("key", "value", "words"), [
    ("surfaces[9].thickness", 1.0, "out of range"),
    ("surfaces[1].thick", 1.0, "thickness"),  # unknown field: the schema suggests the right one
    ("surfaces[0].thickness", -1.0, "positive"),  # a glass element needs a positive thickness
    ("optimize.solves[0]", 1.0, "is a table"),
    ("optimize.solve[0].value", 48.0, "has no 'solve'"),
    ("system.field.hfov_deg", "abc", "number"),
    ("name.x", 1.0, "not a table"),
])
def test_set_key_errors_name_vary(key: str, value: object, words: str) -> None:
    with pytest.raises(LensoptError) as err:
        set_key(load_spec(COOKE), key, value)
    assert str(err.value).startswith("--vary: ") and words in str(err.value)
    assert "\n" not in str(err.value)


def test_parse_vary_lists_and_ranges() -> None:
    v = parse_vary("optimize.solves[0].value=19.4,20.0,20.7")
    assert v.key == "optimize.solves[0].value" and v.values == (19.4, 20.0, 20.7)
    # inclusive range, without binary noise (0.75 + 3·0.05 would be 0.9000000000000001)
    assert parse_vary("k=0.75:0.90:0.05").values == (0.75, 0.8, 0.85, 0.9)
    assert parse_vary("optimize.steps=10:30:10").values == (10.0, 20.0, 30.0)
    # a descending range (a continuation's walk): TR 0.85 → 0.80 of the 25.9 mm telephoto in 4 stages
    assert parse_vary("k=22.015:20.72:-0.32375").values == (22.015, 21.69125, 21.3675, 21.04375, 20.72)
    assert parse_vary("surfaces[0].material=SK16,schott:N-BK7").values == ("SK16", "schott:N-BK7")
    assert parse_vary("optimize.steps=5,7").values == (5, 7)
    for bad in ("k", "k=", "k=1,,2", "k=1,1", "k=2:1:0.5", "k=1:2:-0.5", "k=0:1:0", "=1,2"):
        with pytest.raises(LensoptError, match="^--vary"):
            parse_vary(bad)
