"""Dotted keys into a spec (``optimize.solves[1].value``, ``surfaces[3].thickness``) and ``--vary``
values: read a key, set it (the spec is validated again), expand ``KEY=V1,V2`` and ``KEY=A:B:STEP``.

The spec is edited as the plain data of its JSON form and validated again by ``parse_spec``, so a
value the spec rejects fails exactly as it would in a file; every error names ``--vary``.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from typing import Any

from lensopt.errors import LensoptError
from lensopt.spec.io import dump_json, parse_spec
from lensopt.spec.models import LensSpec

__all__ = ["Vary", "parse_key", "parse_vary", "get_key", "set_key", "format_value"]

_PART = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[-?\d+\])*)$")
_INDEX = re.compile(r"\[(-?\d+)\]")
Value = int | float | str | bool


@dataclass(frozen=True)
class Vary:
    """One swept key and its values (in the order given)."""

    key: str
    values: tuple[Value, ...]


def parse_key(key: str, *, option: str = "--vary") -> list[str | int]:
    """``surfaces[3].thickness`` → ``["surfaces", 3, "thickness"]``."""
    parts: list[str | int] = []
    if not key:
        raise LensoptError("empty key; expected e.g. surfaces[3].thickness", path=option, got=key)
    for piece in key.split("."):
        m = _PART.match(piece)
        if m is None:
            raise LensoptError("not a key: expected names and [index]es joined by dots, e.g. "
                               "optimize.solves[0].value", path=option, got=key)
        parts.append(m.group(1))
        parts += [int(i) for i in _INDEX.findall(m.group(2))]
    return parts


def _walk(data: Any, parts: list[str | int], key: str, option: str) -> Any:
    node = data
    done = ""
    for p in parts:
        if isinstance(p, int):
            if not isinstance(node, list):
                raise LensoptError(f"{done or 'the spec'} is not a list", path=option, got=key)
            if not -len(node) <= p < len(node):
                raise LensoptError(f"{done} has {len(node)} entries; index {p} is out of range", path=option,
                                   got=key)
            node = node[p]
            done += f"[{p}]"
        else:
            if not isinstance(node, dict) or p not in node:
                where = done or "the spec"
                have = ", ".join(sorted(node)) if isinstance(node, dict) else type(node).__name__
                raise LensoptError(f"{where} has no {p!r} (it has: {have})", path=option, got=key)
            node = node[p]
            done += f".{p}" if done else p
    return node


def _data(spec: LensSpec) -> dict[str, Any]:
    return json.loads(dump_json(spec))


def get_key(spec: LensSpec, key: str, *, option: str = "--vary") -> Any:
    """The value at ``key`` in the spec's JSON form."""
    return _walk(_data(spec), parse_key(key, option=option), key, option)


def set_key(spec: LensSpec, key: str, value: Value, *, option: str = "--vary") -> LensSpec:
    """A new spec with ``key`` set to ``value``, validated again (the input is not changed).

    The last name may be a field the spec leaves unset (e.g. ``optimize.steps``); the schema then
    decides whether it exists. Raises ``LensoptError`` naming ``option``.
    """
    parts = parse_key(key, option=option)
    data = _data(spec)
    parent = _walk(data, parts[:-1], key, option)
    last = parts[-1]
    if isinstance(last, int):
        _walk(parent, [last], key, option)
    elif not isinstance(parent, dict):
        raise LensoptError(f"{key.rsplit('.', 1)[0]} is not a table", path=option, got=key)
    old = parent[last] if isinstance(last, int) or last in parent else None
    if isinstance(old, dict | list):
        raise LensoptError(f"{key} is a {'table' if isinstance(old, dict) else 'list'}; vary a single value "
                           "inside it", path=option, got=key)
    parent[last] = value
    try:
        return parse_spec(data)
    except LensoptError as err:
        raise LensoptError(f"{key}={format_value(value)} is rejected by the spec: {err}", path=option) from None


def format_value(v: Value) -> str:
    return repr(v) if isinstance(v, float) else str(v)


def _scalar(text: str) -> Value:
    t = text.strip()
    low = t.lower()
    if low in ("true", "false"):
        return low == "true"
    try:
        return int(t)
    except ValueError:
        pass
    try:
        v = float(t)
    except ValueError:
        return t
    if low in ("inf", "+inf", "-inf", "infinity", "-infinity"):
        return v
    return v if math.isfinite(v) else t


def _range(text: str, option: str) -> tuple[float, ...]:
    try:
        a, b, step = (float(x) for x in text.split(":"))
    except ValueError:
        raise LensoptError("a range is START:STOP:STEP with numbers, e.g. 0.75:0.90:0.05", path=option,
                           got=text) from None
    if not all(math.isfinite(x) for x in (a, b, step)) or step == 0 or (b - a) * step < 0:
        raise LensoptError("a range needs START ≤ STOP and STEP > 0, or START ≥ STOP and STEP < 0 (a descending "
                           "walk)", path=option, got=text)
    n = math.floor((b - a) / step + 1e-9)
    if n >= 10_000:
        raise LensoptError("a range of more than 10000 values", path=option, got=text)
    # round away the binary noise of a + k·step (0.75 + 3·0.05 = 0.9000000000000001)
    digits = max(_decimals(a), _decimals(step))
    return tuple(round(a + k * step, digits) for k in range(n + 1))


def _decimals(x: float) -> int:
    text = repr(x)
    if "e" in text:
        return 15
    return len(text.split(".")[1]) if "." in text else 0


def parse_vary(text: str, *, option: str = "--vary") -> Vary:
    """``KEY=V1,V2,…`` or ``KEY=START:STOP:STEP`` (inclusive; STEP < 0 descends) → ``Vary``. Values are ints, floats,
    true/false or strings (material names)."""
    key, sep, rest = text.partition("=")
    key = key.strip()
    if not sep or not rest.strip():
        raise LensoptError("expected KEY=V1,V2,... or KEY=START:STOP:STEP", path=option, got=text)
    parse_key(key, option=option)
    parts = rest.split(":")
    if "," not in rest and len(parts) == 3 and all(_is_number(x) for x in parts):
        values: tuple[Value, ...] = _range(rest, option)
    else:
        items = rest.split(",")
        if any(not x.strip() for x in items):
            raise LensoptError("an empty value in the list", path=option, got=text)
        values = tuple(_scalar(x) for x in items)
    if len(set(map(repr, values))) != len(values):
        raise LensoptError("a value appears twice", path=option, got=text)
    return Vary(key, values)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
