"""Load and save lens specs: TOML (written by people) and JSON (written by lensopt), one schema.

Validation errors become one ``SpecError`` whose message names the field,
``surfaces[3].radius: must be non-zero (got 0.0)``.
"""

from __future__ import annotations

import difflib
import json
import tomllib
import typing
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

from lensopt.errors import SpecError
from lensopt.files import write_text_atomic
from lensopt.spec import models
from lensopt.spec.models import LensSpec

__all__ = ["load_spec", "parse_spec", "dump_json", "save_json", "format_loc", "load_tolerances"]


_MAX_STARTS = 8


def load_spec(path: str | Path) -> LensSpec:
    """Read a ``.toml`` spec or a ``.json`` lens; raise ``SpecError`` naming the bad field.

    A file may begin with ``start = "other.json"`` (a path relative to the file): the lens of that file
    (a spec or a lens, itself possibly with a ``start``) is the starting point and every top-level key
    of this file replaces the start's key of the same name, whole tables at a time (e.g. a polishing run
    is a ``start`` and a new ``[optimize]``).
    """
    try:
        return parse_spec(_load_data(Path(path), ()))
    except RecursionError:
        raise SpecError("nested too deeply to be a lens", path=str(path)) from None


def _load_data(path: Path, chain: tuple[Path, ...]) -> dict[str, Any]:
    """The plain data of a spec file, its ``start`` resolved (``chain``: the files that start from it)."""
    data = _read_data(path)
    if not isinstance(data, dict) or "start" not in data:
        return data
    start = data.pop("start")
    where = f"{path}: start"
    if not isinstance(start, str) or not start:
        raise SpecError("must be the path of a .toml spec or a .json lens, relative to this file", path=where,
                        got=start)
    target = (path.parent / start).resolve()
    if target in chain or target == path.resolve():
        raise SpecError("the files start from each other in a cycle", path=where, got=start)
    if len(chain) >= _MAX_STARTS:
        raise SpecError(f"more than {_MAX_STARTS} files start from each other", path=where, got=start)
    if not target.is_file():
        raise SpecError(f"no such file ({target}); write it first (e.g. with the lensopt optimize run this "
                        "file continues)", path=where, got=start)
    base = _load_data(target, (*chain, path.resolve()))
    if not isinstance(base, dict):
        raise SpecError("the start file is not a table of sections", path=where, got=start)
    return {**base, **data}


def _read_data(path: Path) -> Any:
    """The parsed TOML or JSON of ``path`` (no validation)."""
    if path.is_dir():
        raise SpecError("is a directory; expected a .toml spec or a .json lens file", path=str(path))
    if not path.is_file():
        raise SpecError("no such file", path=str(path))
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".json"):
        raise SpecError("expected a .toml spec or a .json lens", path=str(path), got=path.suffix)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise SpecError(f"not a UTF-8 text file ({err.reason} at byte {err.start})", path=str(path)) from None
    except OSError as err:
        raise SpecError(f"cannot read the file: {err.strerror}", path=str(path)) from None
    try:
        data = tomllib.loads(text) if suffix == ".toml" else json.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise SpecError(f"malformed TOML: {err}", path=str(path)) from None
    except json.JSONDecodeError as err:
        raise SpecError(f"malformed JSON: {err}", path=str(path)) from None
    except RecursionError:
        raise SpecError("nested too deeply to be a lens", path=str(path)) from None
    except ValueError as err:  # an integer of more than 4300 digits
        raise SpecError(f"unreadable number: {err}", path=str(path)) from None
    return data


def parse_spec(data: dict[str, Any]) -> LensSpec:
    """Validate a spec given as plain data (the parsed TOML/JSON)."""
    if not isinstance(data, dict):
        raise SpecError("a spec must be a table of sections (system, spectrum, surfaces, ...)", path="spec",
                        got=type(data).__name__)
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
    after_tag = False
    for part in loc:
        # A tag names the union member; "conic" is also a field of the conic member (conic.conic).
        if not isinstance(part, int) and _is_tag(part) and not (after_tag and part == "conic"):
            after_tag = True
            continue
        after_tag = False
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


_UNION_TAGS = {"plane", "sphere", "conic", "asphere", "diffractive", "str", "ModelGlassSpec", "TabulatedGlassSpec",
               "AgfGlassSpec", "ObjectSpec"}

#: What a value of a union field may be, for values that fit none of the alternatives.
_UNION_HINTS = {
    "material": 'must be "air", a catalog glass name such as "N-BK7", or a model glass { nd = 1.5168, vd = 64.17 }',
    "object": 'must be "infinity" or { distance = <mm from the object to surface 1> }',
}
#: Error types of a union alternative that does not fit the value's type at all.
_MISMATCH = {"string_type", "model_type", "dict_type", "model_attributes_type", "literal_error"}


def _is_tag(part: Any) -> bool:
    text = str(part)
    return part in _UNION_TAGS or text.startswith(("function-", "union[", "literal["))


def _kinds(union: Any) -> str:
    """``plane, sphere, …``: the ``type`` tags of a discriminated union of models."""
    members = typing.get_args(typing.get_args(union)[0])
    return ", ".join(typing.get_args(m.model_fields["type"].annotation)[0] for m in members)


def _other_kind_hint(loc: tuple[Any, ...], name: str) -> str | None:
    """For a field that another surface type has (``conic`` on a sphere): say so and which types to use."""
    if len(loc) < 2 or loc[-2] not in ("plane", "sphere", "conic", "asphere", "diffractive"):
        return None
    kind = str(loc[-2])
    members = {typing.get_args(m.model_fields["type"].annotation)[0]: m
               for m in typing.get_args(typing.get_args(models.BaseShape)[0])}
    members["diffractive"] = models.DiffractiveSurface
    have = [k for k, m in members.items() if name in m.model_fields]
    if not have:
        return None
    what = "base" if len(loc) >= 3 and loc[-3] == "base" else "surface"
    quoted = [f'"{k}"' for k in have]
    kinds = quoted[0] if len(quoted) == 1 else ", ".join(quoted[:-1]) + " or " + quoted[-1]
    return f"a {kind} {what} has no {name}; set type = {kinds} to give it one"


def _field_names() -> list[str]:
    names: set[str] = set()
    for obj in vars(models).values():
        if isinstance(obj, type) and issubclass(obj, BaseModel):
            names.update(obj.model_fields)
    return sorted(names)


def _is_mismatch(e: dict[str, Any]) -> bool:
    """An alternative of a union that the value does not fit at all (the str branch of a dict ...)."""
    return e["type"] in _MISMATCH and bool(e["loc"]) and _is_tag(e["loc"][-1])


def _drop_other_alternative(real: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """A material table is tried as a model glass, then as a tabulated glass: when one alternative has a
    real complaint, the other alternative's missing or unknown fields are noise, not further errors."""
    def in_union(e: dict[str, Any]) -> bool:
        return any(any(k in str(p) for k in ("ModelGlassSpec", "TabulatedGlassSpec", "AgfGlassSpec"))
                   for p in e["loc"])

    if any(in_union(e) and e["type"] not in ("missing", "extra_forbidden") for e in real):
        return [e for e in real if not (in_union(e) and e["type"] in ("missing", "extra_forbidden"))]
    return real


def _to_spec_error(err: ValidationError) -> SpecError:
    errors = err.errors(include_url=False)
    real = _drop_other_alternative([e for e in errors if not _is_mismatch(e)])
    first = real[0] if real else errors[0]
    loc = format_loc(tuple(first["loc"]))
    # Problems other than the first: real errors, plus unions that no alternative fits (their
    # mismatches are noise when another alternative of the same union reports a real error).
    real_locs = [format_loc(tuple(e["loc"])) for e in real]
    unfit = {format_loc(tuple(e["loc"])) for e in errors if _is_mismatch(e)}
    unfit = {u for u in unfit if not any(r == u or r.startswith((u + ".", u + "[")) for r in real_locs)}
    extra = len(real) + len(unfit) - 1

    kind = first["type"]
    msg = str(first["msg"])
    got = first.get("input", ...)
    for prefix in ("Value error, ", "Assertion failed, "):
        if msg.startswith(prefix):
            msg = msg[len(prefix):]
    if msg.startswith("@"):  # validators may name a sub-field: "@thickness: ..."
        sub, _, msg = msg[1:].partition(": ")
        loc = f"{loc}{'' if sub.startswith('[') else '.'}{sub}" if loc else sub
    if _is_mismatch(first):
        name = loc.rsplit(".", 1)[-1]
        msg = _UNION_HINTS.get(name, msg)
    elif kind == "union_tag_invalid":
        what = _kinds(models.BaseShape) if loc.endswith("base") else _kinds(models.SurfaceSpec)
        loc, msg, got = f"{loc}.type", f"unknown type; expected one of {what}", first["ctx"]["tag"]
    elif kind == "union_tag_not_found":
        what = _kinds(models.BaseShape) if loc.endswith("base") else _kinds(models.SurfaceSpec)
        loc, msg, got = f"{loc}.type", f"required field is missing; one of {what}", ...
    elif kind in ("model_type", "dict_type", "model_attributes_type"):
        msg = "must be a table of fields ({ key = value, ... } in TOML, an object in JSON)"
    elif kind == "missing":
        msg, got = "required field is missing", ...
    elif kind == "too_short":
        n = first["ctx"]["min_length"]
        msg, got = f"needs at least {n} entr{'y' if n == 1 else 'ies'}", ...
    elif kind == "extra_forbidden":
        name = loc.rsplit(".", 1)[-1]
        hint = _other_kind_hint(tuple(first["loc"]), name)
        close = difflib.get_close_matches(name, _field_names(), n=1)
        msg = hint or "unknown field" + (f"; did you mean {close[0]!r}?" if close else "")
    if first["loc"] and first["loc"][-1] == "[key]":  # a dict key that is not a power
        loc = format_loc(tuple(first["loc"][:-2]))
        msg, got = "keys must be even integer powers, e.g. 4, 6, 8", first["loc"][-2]
    if isinstance(got, dict | list) or "(got" in msg:
        got = ...
    if extra > 0:
        msg += f" [+{extra} more]"
    return SpecError(msg, path=loc or "spec", got=got)


def load_tolerances(path: str | Path) -> Any:
    """Read a ``--tolerances`` TOML file: a ``[tolerance]`` table (or its keys at the top level) →
    ``ToleranceSpec``; errors name ``tolerance.<field>``."""
    from lensopt.spec.tolerance import ToleranceSpec

    path = Path(path)
    if not path.is_file():
        raise SpecError("no such file", path=str(path))
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise SpecError(f"malformed TOML: {err}", path=str(path)) from None
    data = data.get("tolerance", data)
    try:
        return ToleranceSpec.model_validate(data)
    except ValidationError as err:
        first = err.errors()[0]
        where = format_loc(tuple(first["loc"]))
        raise SpecError(first["msg"], path="tolerance" + (f".{where}" if where else ""),
                        got=first.get("input")) from None
