"""Load and save lens specs: TOML (written by people) and JSON (written by lensopt), one schema.

Validation errors become one ``SpecError`` whose message names the field,
``surfaces[3].radius: must be non-zero (got 0.0)``.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from lensopt.errors import SpecError
from lensopt.io.files import write_text_atomic
from lensopt.spec.models import LensSpec

__all__ = ["load_spec", "parse_spec", "dump_json", "save_json", "format_loc"]


def load_spec(path: str | Path) -> LensSpec:
    """Read a ``.toml`` spec or a ``.json`` lens; raise ``SpecError`` naming the bad field."""
    path = Path(path)
    if not path.is_file():
        raise SpecError("no such file", path=str(path))
    text = path.read_text(encoding="utf-8")
    suffix = path.suffix.lower()
    try:
        if suffix == ".toml":
            data = tomllib.loads(text)
        elif suffix == ".json":
            data = json.loads(text)
        else:
            raise SpecError("expected a .toml spec or a .json lens", path=str(path), got=path.suffix)
    except tomllib.TOMLDecodeError as err:
        raise SpecError(f"malformed TOML: {err}", path=str(path)) from None
    except json.JSONDecodeError as err:
        raise SpecError(f"malformed JSON: {err}", path=str(path)) from None
    return parse_spec(data)


def parse_spec(data: dict[str, Any]) -> LensSpec:
    """Validate a spec given as plain data (the parsed TOML/JSON)."""
    try:
        return LensSpec.model_validate(data)
    except ValidationError as err:
        raise _to_spec_error(err) from None


def dump_json(spec: LensSpec) -> str:
    """The lens as JSON text (inf radii as ``Infinity``, which Python's json reads back)."""
    return spec.model_dump_json(indent=2, exclude_none=True) + "\n"


def save_json(spec: LensSpec, path: str | Path) -> None:
    """Write the lens as JSON atomically."""
    write_text_atomic(path, dump_json(spec))


def format_loc(loc: tuple[Any, ...]) -> str:
    """``('surfaces', 3, 'sphere', 'radius')`` → ``surfaces[3].radius`` (union tags dropped)."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in _UNION_TAGS or str(part).startswith(("function-", "union[", "literal[")):
            continue
        else:
            out += f".{part}" if out else str(part)
    return out


_UNION_TAGS = {"plane", "sphere", "conic", "asphere", "diffractive", "str", "ModelGlassSpec", "TabulatedGlassSpec",
               "ObjectSpec"}


def _to_spec_error(err: ValidationError) -> SpecError:
    errors = err.errors(include_url=False)
    first = _most_specific(errors)
    loc = format_loc(tuple(first["loc"]))
    msg = str(first["msg"])
    for prefix in ("Value error, ", "Assertion failed, "):
        if msg.startswith(prefix):
            msg = msg[len(prefix):]
    if msg.startswith("@"):  # validators may name a sub-field: "@thickness: ..."
        sub, _, msg = msg[1:].partition(": ")
        loc = f"{loc}{'' if sub.startswith('[') else '.'}{sub}" if loc else sub
    got = first.get("input", ...)
    if first["type"] in ("missing", "model_type", "dict_type") or isinstance(got, dict | list) or "(got" in msg:
        got = ...
    extra = len(errors) - 1
    if extra and first["type"] != "union_tag_invalid":
        msg += f" [+{extra} more]"
    if first["type"] == "extra_forbidden":
        msg = "unknown field"
    if first["type"] == "missing":
        msg = "required field is missing"
    return SpecError(msg, path=loc or "spec", got=got)


def _most_specific(errors: list[dict[str, Any]]) -> dict[str, Any]:
    """Prefer errors that are not the catch-all alternatives of a union (``material`` as str/dict)."""
    candidates = [e for e in errors if not any(str(p) in ("str", "literal['infinity']") for p in e["loc"])]
    if not candidates:
        return errors[0]
    # A material dict is tried as a model glass, then as a tabulated glass: report the alternative
    # with a real complaint rather than the other one's missing/unknown fields.
    if any("TabulatedGlassSpec" in str(p) for e in candidates for p in e["loc"]):
        real = [e for e in candidates if e["type"] not in ("missing", "extra_forbidden")]
        if real:
            return real[0]
    return candidates[0]
