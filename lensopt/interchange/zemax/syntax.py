"""Zemax ``.zmx`` syntax: the operands of a sequential file, split into system operands and ``SURF``
blocks with their numbers read (no optics here: :mod:`lensopt.interchange.zemax.read` turns them into
a lens spec).

A ``.zmx`` file is one operand per line: a four-letter name and its tokens. lensopt keeps its own data
that Zemax has no operand for in ``NOTE`` lines (``NOTE 0 lensopt: {json}``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from lensopt.errors import SpecError

__all__ = ["NOTE_PREFIX", "INFINITE_OBJECT", "UNITS", "MERIT", "ZSurface", "ZFile", "parse_zmx", "number", "index",
           "is_number"]

#: Prefix of the NOTE lines carrying lensopt's own data.
NOTE_PREFIX = "lensopt:"
#: An object distance (mm) at or beyond this is infinite.
INFINITE_OBJECT = 1e10
#: UNIT tokens -> millimetres.
UNITS = {"MM": 1.0, "CM": 10.0, "IN": 25.4, "METER": 1000.0, "M": 1000.0}
#: Surface operands: those read here, plus those whose content the file already resolved (pickups, variable
#: flags) or that do not change the traced rays (display, coatings, thermal data, mechanical semi-diameter).
_SURFACE_OPS = frozenset("TYPE CURV CONI PARM XDAT DISZ GLAS DIAM STOP CLAP FLAP OBDC SQAP ELAP OBSC SCBD "
                         "COMM FIMP HIDE MIRR SLAB POPS MEMA VPAR VCRV VDSZ VCON VXDT PZUP COAT TCE IGNR".split())
_SYSTEM_OPS = frozenset("NAME UNIT ENPD FNUM OBNA FLOA FTYP XFLN YFLN XFLD YFLD FWGN VDXN VDYN VCXN VCYN VANN "
                        "WAVM WAVL WWGT PWAV GCAT MODE RAIM NOTE".split())
#: Operands with no effect on the traced lens (display, file, environment bookkeeping).
_SILENT = frozenset("VERS PFIL LANG ENVD GFAC PUSH SDMA OMMA ROPD PICB POLS GLRS GSTD NSCD COFN HYPR BLNK "
                    "ZVCY ZVDY ZVCX ZVDX MNUM MOFF TOL DMFS".split())
#: Surface operands that change the lens but that lensopt does not model: ignored with a warning.
_APERTURE_IGNORED = {"SQAP": "rectangular aperture", "ELAP": "elliptical aperture", "OBSC": "obscuration",
                     "OBDC": "aperture decenter", "SCBD": "coordinate return / tilt-decenter data"}
MERIT = "merit function / tolerance data"
@dataclass
class ZSurface:
    """One ``SURF`` block as read (file units)."""

    number: int
    line: int
    type: str = "STANDARD"
    type_line: int = 0
    curv: float = 0.0
    conic: float = 0.0
    thickness: float = 0.0
    glass: list[str] | None = None
    glass_line: int = 0
    parm: dict[int, float] = field(default_factory=dict)
    xdat: dict[int, float] = field(default_factory=dict)
    stop: bool = False
    diam: float | None = None
    clap: tuple[float, float] | None = None
    flap: bool = False
    comment: str | None = None
    ignored: list[str] = field(default_factory=list)


@dataclass
class ZFile:
    """The parsed file: system operands (name -> list of token lists with line numbers), surfaces, notes."""

    source: str
    system: dict[str, list[tuple[int, list[str]]]] = field(default_factory=dict)
    surfaces: list[ZSurface] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    ignored: dict[str, int] = field(default_factory=dict)
    scale: float = 1.0
    extras: dict[str, Any] = field(default_factory=dict)
    notices: list[str] = field(default_factory=list)
    elements: list[dict[str, Any]] = field(default_factory=list)

    def last(self, key: str) -> tuple[int, list[str]] | None:
        items = self.system.get(key)
        return items[-1] if items else None

def number(tokens: list[str], i: int, line: int, source: str, default: float | None = None) -> float:
    if i >= len(tokens):
        if default is not None:
            return default
        raise SpecError(f"line {line}: {tokens[0]} needs a value at position {i}", path=source)
    t = tokens[i]
    if t.upper() in ("INFINITY", "INF"):
        return math.inf
    try:
        value = float(t.replace(",", "."))
    except ValueError:
        raise SpecError(f"line {line}: {tokens[0]}: expected a number, got {t!r}", path=source) from None
    if not math.isfinite(value):
        raise SpecError(f"line {line}: {tokens[0]}: expected a finite number, got {t!r}", path=source)
    return value


def index(tokens: list[str], i: int, line: int, source: str, default: int | None = None) -> int:
    value = number(tokens, i, line, source, None if default is None else float(default))
    if value != int(value):
        raise SpecError(f"line {line}: {tokens[0]}: expected an integer, got {tokens[i]!r}", path=source)
    return int(value)


def parse_zmx(text: str, *, source: str) -> ZFile:
    """Split the text into system operands and SURF blocks (no interpretation beyond numbers)."""
    zf = ZFile(source)
    current: ZSurface | None = None
    in_merit = False
    merit_lines = 0
    for number, raw in enumerate(text.splitlines(), start=1):
        tokens = raw.split()
        if not tokens:
            continue
        op = tokens[0].upper()
        if op == "SURF":
            current = ZSurface(index(tokens, 1, number, source, default=len(zf.surfaces)), number)
            zf.surfaces.append(current)
            in_merit = False
            continue
        if op == "MNUM" and len(tokens) > 1 and is_number(tokens[1]) and float(tokens[1]) > 1:
            zf.notices.append(f"the file has {int(float(tokens[1]))} configurations (MNUM): only the nominal one "
                              "is imported")
        if op == "ENVD" and len(tokens) > 2 and is_number(tokens[1]) and is_number(tokens[2]) and (
                float(tokens[1]) != 20.0 or float(tokens[2]) != 1.0):
            zf.notices.append(f"ignored the environment ENVD {tokens[1]} °C, {tokens[2]} atm: indices are taken at "
                              "the catalogs' reference conditions (20 °C, 1 atm)")
        if op in ("DMFS", "TOL", "MNUM", "BLNK") or in_merit:
            in_merit = op not in _SYSTEM_OPS or in_merit
            if op not in ("BLNK",):
                merit_lines += 1
            current = None
            continue
        if op == "NOTE":
            body = raw.strip()[4:].strip()
            first, _, rest = body.partition(" ")
            if first.lstrip("-").isdigit():
                body = rest
            if body.startswith(NOTE_PREFIX):
                zf.notes.append(body[len(NOTE_PREFIX):].strip())
            continue
        if current is not None and op in _SURFACE_OPS:
            _surface_operand(zf, current, op, tokens, number, raw)
            continue
        if op in _SYSTEM_OPS:
            zf.system.setdefault(op, []).append((number, tokens))
            if op == "UNIT":
                unit = tokens[1].upper() if len(tokens) > 1 else "MM"
                if unit not in UNITS:
                    raise SpecError(f"line {number}: unknown UNIT {tokens[1] if len(tokens) > 1 else ''!r}; "
                                    f"expected {', '.join(UNITS)}", path=source)
                zf.scale = UNITS[unit]
            elif op == "MODE" and (len(tokens) < 2 or tokens[1].upper() != "SEQ"):
                raise SpecError(f"line {number}: only sequential files (MODE SEQ) can be imported", path=source)
            continue
        if op in _SILENT:
            continue
        zf.ignored[op] = zf.ignored.get(op, 0) + 1
    if merit_lines:
        zf.ignored[MERIT] = merit_lines
    return zf


def _surface_operand(zf: ZFile, s: ZSurface, op: str, tokens: list[str], line: int, raw: str) -> None:
    src = zf.source
    if op == "TYPE":
        s.type = tokens[1].upper() if len(tokens) > 1 else "STANDARD"
        s.type_line = line
    elif op == "CURV":
        s.curv = number(tokens, 1, line, src)
    elif op == "CONI":
        s.conic = number(tokens, 1, line, src)
    elif op == "DISZ":
        s.thickness = number(tokens, 1, line, src)
    elif op == "PARM":
        s.parm[index(tokens, 1, line, src)] = number(tokens, 2, line, src)
    elif op == "XDAT":
        s.xdat[index(tokens, 1, line, src)] = number(tokens, 2, line, src)
    elif op == "GLAS":
        s.glass, s.glass_line = tokens[1:], line
    elif op == "STOP":
        s.stop = True
    elif op == "DIAM":
        s.diam = number(tokens, 1, line, src)
    elif op == "CLAP":
        s.clap = (number(tokens, 1, line, src, 0.0), number(tokens, 2, line, src))
    elif op == "FLAP":
        s.flap = True
        if len(tokens) > 2:
            s.diam = number(tokens, 2, line, src)
    elif op == "IGNR" and len(tokens) > 1 and tokens[1] not in ("0", "0.0"):
        s.ignored.append("IGNR (Zemax skips this surface when tracing; lensopt traces it)")
    elif op == "COMM":
        s.comment = raw.strip()[4:].strip() or None
    elif op in _APERTURE_IGNORED:
        values = [t for t in tokens[1:] if is_number(t)]
        if any(float(v) != 0 for v in values):
            s.ignored.append(f"{op} ({_APERTURE_IGNORED[op]})")


def is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True
