"""Read a Zemax OpticStudio sequential ``.zmx`` file into a lens spec (``lensopt import-zemax``).

Understood (everything else is listed in one warning line per item, or refused with exit code 2
where the lens would be wrong without it):

- Text in UTF-16 (what OpticStudio writes) or ASCII/UTF-8/Latin-1; ``UNIT`` MM, CM, IN, METER.
- Surfaces ``STANDARD`` (``CURV``, ``CONI``), ``EVENASPH`` (``PARM 2…8`` = r⁴…r¹⁶; a non-zero r²
  term ``PARM 1`` is refused: lensopt's asphere has none), ``BINARY_2`` (an even asphere base plus the
  rotationally symmetric phase Φ = M Σ A_i ρ^(2i), ρ = r/R: ``PARM 0`` = order M, ``XDAT 1`` = number
  of terms, ``XDAT 2`` = R, ``XDAT 3…`` = A_i in radians → lensopt's diffractive surface with
  ``order`` M and phase d_(2i) = A_i / R^(2i); lensopt's deflection m λ/(2π) ∇φ is Zemax's
  λ/(2π) ∇Φ), ``COORDBRK`` (see :func:`coordinate_break`), ``STOP``, ``DISZ`` (``INFINITY``),
  ``DIAM`` (semi-diameter, kept as ``semi_diameter`` without clipping, as Zemax does not clip on
  it), ``CLAP`` (circular aperture: ``semi_diameter`` with ``clip = true``), ``FLAP`` (floating
  aperture: clips at the semi-diameter).
- Glasses: ``GLAS NAME`` looked up first in the AGF catalogs given (``catalogs``), then in lensopt's
  catalogs (the vendors of ``GCAT`` first); ``GLAS ___BLANK 1 0 nd vd dpgf`` (a model glass) →
  lensopt's Hartmann model glass (nd, vd, ΔPgF). ``MIRROR`` is refused (refractive systems only).
- System data: see :mod:`lensopt.io.zemax_system`.

Data lensopt keeps but Zemax has no operand for are written by ``export_zemax`` into ``NOTE`` lines
(``NOTE 0 lensopt: {json}``); they are read back only where they agree with the Zemax data.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lensopt.errors import LensoptError, SpecError
from lensopt.io.zemax_materials import material, range_warnings
from lensopt.io.zemax_system import system_from_zemax
from lensopt.materials.agf import decode_text, read_agf

__all__ = ["ZemaxImport", "read_zemax", "import_zemax", "NOTE_PREFIX", "INFINITE_OBJECT", "UNITS"]

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
_MERIT = "merit function / tolerance data"


@dataclass
class ZemaxImport:
    """The imported lens and the warnings the import produced (one line each)."""

    spec: Any
    warnings: list[str]


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

    def last(self, key: str) -> tuple[int, list[str]] | None:
        items = self.system.get(key)
        return items[-1] if items else None


def read_zemax(path: str | Path, *, catalogs: list[str | Path] | tuple[str | Path, ...] = ()) -> ZemaxImport:
    """Import the ``.zmx`` file at ``path``, with glasses looked up first in the AGF ``catalogs``.

    Raises:
        SpecError: unreadable or binary file, unsupported content, unknown glass (one line naming the
            file, the line and what is wrong).
    """
    path = Path(path)
    if not path.is_file():
        raise SpecError("no such file", path=str(path))
    try:
        data = path.read_bytes()
    except OSError as err:
        raise SpecError(f"cannot read: {err.strerror}", path=str(path)) from None
    try:
        text = decode_text(data, source=str(path))
    except LensoptError as err:
        raise SpecError(err.message, path=str(path)) from None
    return import_zemax(text, source=str(path), catalogs=catalogs)


def import_zemax(text: str, *, source: str = "zmx",
                 catalogs: list[str | Path] | tuple[str | Path, ...] = ()) -> ZemaxImport:
    """Import the text of a ``.zmx`` file; see the module doc for what is understood."""
    for c in catalogs:
        try:
            read_agf(c)
        except LensoptError as err:
            raise SpecError(err.message, path=f"--catalog {c}") from None
    try:
        return _import(text, source, catalogs)
    except (ValueError, OverflowError, IndexError, KeyError, ZeroDivisionError) as err:
        raise SpecError(f"malformed file ({type(err).__name__}: {err})", path=source) from None


def _import(text: str, source: str, catalogs: Any) -> ZemaxImport:
    zf = parse_zmx(text, source=source)
    warnings: list[str] = []
    extras = _extras(zf, warnings)
    zf.extras = extras
    if len(zf.surfaces) < 3:
        raise SpecError(f"only {len(zf.surfaces)} SURF block(s): a lens needs an object, at least one surface "
                        "and an image (truncated file?)", path=source)
    surfaces = _lens_surfaces(zf, catalogs, extras, warnings)
    obj = zf.surfaces[0]
    image = zf.surfaces[-1]
    if obj.glass is not None and obj.glass[0].upper() != "AIR":
        raise SpecError(f"line {obj.glass_line}: object space must be air (got {obj.glass[0]})", path=source)
    if obj.curv != 0:
        raise SpecError(f"line {obj.line}: a curved object surface is not supported", path=source)
    if image.curv != 0:
        raise SpecError(f"line {image.line}: curved image surfaces are not supported (CURV {image.curv:g})",
                        path=source)
    if image.type != "STANDARD":
        raise SpecError(f"line {image.line}: the image surface must be STANDARD (got {image.type})", path=source)
    distance = obj.thickness * zf.scale
    object_distance = None if not math.isfinite(distance) or distance >= INFINITE_OBJECT else distance
    if object_distance is not None and not object_distance > 0:
        raise SpecError(f"line {obj.line}: the object distance must be positive (got {obj.thickness:g})",
                        path=source)
    warnings += zf.notices
    for name, count in zf.ignored.items():
        if name == _MERIT:
            warnings.append(f"ignored the merit function and tolerance data ({count} lines)")
            continue
        warnings.append(f"ignored Zemax operand {name} ({count} line{'s' if count > 1 else ''}): lensopt does "
                        "not model it")
    try:
        spec = system_from_zemax(zf, surfaces, object_distance, extras, warnings)
    except LensoptError as err:
        if "outside the valid range" in err.message:
            raise SpecError(f"{err}; lensopt's catalog data stop there: give the glass's AGF catalog with "
                            "--catalog FILE.agf to extrapolate it with a warning", path=source) from None
        raise
    range_warnings(spec, warnings)
    return ZemaxImport(spec, warnings)


# ----------------------------------------------------------------------------------------- parsing


def _num(tokens: list[str], i: int, line: int, source: str, default: float | None = None) -> float:
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


def _index(tokens: list[str], i: int, line: int, source: str, default: int | None = None) -> int:
    value = _num(tokens, i, line, source, None if default is None else float(default))
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
            current = ZSurface(_index(tokens, 1, number, source, default=len(zf.surfaces)), number)
            zf.surfaces.append(current)
            in_merit = False
            continue
        if op == "MNUM" and len(tokens) > 1 and _is_number(tokens[1]) and float(tokens[1]) > 1:
            zf.notices.append(f"the file has {int(float(tokens[1]))} configurations (MNUM): only the nominal one "
                              "is imported")
        if op == "ENVD" and len(tokens) > 2 and _is_number(tokens[1]) and _is_number(tokens[2]) and (
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
        zf.ignored[_MERIT] = merit_lines
    return zf


def _surface_operand(zf: ZFile, s: ZSurface, op: str, tokens: list[str], line: int, raw: str) -> None:
    src = zf.source
    if op == "TYPE":
        s.type = tokens[1].upper() if len(tokens) > 1 else "STANDARD"
        s.type_line = line
    elif op == "CURV":
        s.curv = _num(tokens, 1, line, src)
    elif op == "CONI":
        s.conic = _num(tokens, 1, line, src)
    elif op == "DISZ":
        s.thickness = _num(tokens, 1, line, src)
    elif op == "PARM":
        s.parm[_index(tokens, 1, line, src)] = _num(tokens, 2, line, src)
    elif op == "XDAT":
        s.xdat[_index(tokens, 1, line, src)] = _num(tokens, 2, line, src)
    elif op == "GLAS":
        s.glass, s.glass_line = tokens[1:], line
    elif op == "STOP":
        s.stop = True
    elif op == "DIAM":
        s.diam = _num(tokens, 1, line, src)
    elif op == "CLAP":
        s.clap = (_num(tokens, 1, line, src, 0.0), _num(tokens, 2, line, src))
    elif op == "FLAP":
        s.flap = True
        if len(tokens) > 2:
            s.diam = _num(tokens, 2, line, src)
    elif op == "IGNR" and len(tokens) > 1 and tokens[1] not in ("0", "0.0"):
        s.ignored.append("IGNR (Zemax skips this surface when tracing; lensopt traces it)")
    elif op == "COMM":
        s.comment = raw.strip()[4:].strip() or None
    elif op in _APERTURE_IGNORED:
        values = [t for t in tokens[1:] if _is_number(t)]
        if any(float(v) != 0 for v in values):
            s.ignored.append(f"{op} ({_APERTURE_IGNORED[op]})")


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _extras(zf: ZFile, warnings: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for note in zf.notes:
        try:
            data = json.loads(note)
        except json.JSONDecodeError:
            warnings.append("ignored a malformed lensopt NOTE line")
            continue
        if isinstance(data, dict):
            out.update(data)
    return out


# ---------------------------------------------------------------------------------------- surfaces


def coordinate_break(zf: ZFile, s: ZSurface, medium: Any, scale: float) -> dict[str, Any] | None:
    """The single hook for ``COORDBRK`` surfaces: None for a break that moves nothing (its thickness is
    added to the previous gap), else a dummy plane surface in the current medium that carries the break
    as lensopt's ``basic`` decenter/tilt (the axis follows, as in Zemax) and the break's thickness.

    Zemax: ``PARM 1``/``2`` decenter x/y, ``PARM 3``/``4``/``5`` tilt about x/y/z (degrees), ``PARM 6``
    order flag (0: decenter, then tilt x, then about the new y, then z). lensopt's placement is the same
    (decenter, then α about x, then β about the new y); a tilt about z, and order flag 1 with both a
    decenter and a tilt, are refused.
    """
    dx, dy, ax, ay, az = (s.parm.get(k, 0.0) for k in range(1, 6))
    order = s.parm.get(6, 0.0)
    where = f"line {s.line}: surface {s.number} (COORDBRK)"
    if az != 0:
        raise SpecError(f"{where}: a tilt about z ({az:g}°) is not supported (lensopt tilts about x and y)",
                        path=zf.source)
    if order != 0 and (dx or dy) and (ax or ay):
        raise SpecError(f"{where}: order flag {order:g} (tilt before decenter) with both a decenter and a tilt "
                        "is not supported", path=zf.source)
    if not (dx or dy or ax or ay):
        return None
    surf: dict[str, Any] = {"type": "plane", "thickness": s.thickness * scale, "material": medium,
                            "decenter_mode": "basic", "label": s.comment or f"COORDBRK {s.number}"}
    if dx or dy:
        surf["decenter"] = [dx * scale, dy * scale]
    if ax or ay:
        surf["tilt_deg"] = [ax, ay]
    return surf


def _lens_surfaces(zf: ZFile, catalogs: Any, extras: dict[str, Any], warnings: list[str]) -> list[dict[str, Any]]:
    scale = zf.scale
    src = zf.source
    surf_extras = extras.get("surfaces") if isinstance(extras.get("surfaces"), dict) else {}
    gcat = [t.upper() for _, tokens in zf.system.get("GCAT", []) for t in tokens[1:]]
    out: list[dict[str, Any]] = []
    plain = 0  # non-COORDBRK blocks so far: the key of export_zemax's per-surface NOTE data
    lens = zf.surfaces[1:-1]
    if not any(s.stop for s in lens):
        warnings.append("no STOP in the file: surface 1 is taken as the aperture stop (Zemax's default)")
    for s in lens:
        if s.type == "COORDBRK":
            if s.stop:
                raise SpecError(f"line {s.line}: the stop is on a coordinate break", path=src)
            medium = out[-1]["material"] if out else "air"
            dummy = coordinate_break(zf, s, medium, scale)
            if dummy is None and not out:  # before the first surface: keep its gap as a dummy plane
                dummy = {"type": "plane", "thickness": s.thickness * scale, "material": "air"}
            if dummy is not None:
                warnings.append(f"surface {s.number}: coordinate break imported as a dummy plane surface with a "
                                "basic decenter/tilt (the axis follows)")
                out.append(dummy)
                continue
            warnings.append(f"surface {s.number}: coordinate break with zero decenters and tilts imported as a "
                            "plain gap")
            out[-1]["thickness"] += s.thickness * scale
            continue
        i = len(out)
        plain += 1
        extra = surf_extras.get(str(plain), {}) if isinstance(surf_extras, dict) else {}
        extra = extra if isinstance(extra, dict) else {}
        surf = _surface(zf, s, scale, catalogs, gcat, extra, warnings)
        surf["stop"] = s.stop or (not any(t.stop for t in lens) and i == 0)
        out.append(surf)
        for item in s.ignored:
            warnings.append(f"surface {s.number}: ignored {item}")
    if not out:
        raise SpecError("no lens surfaces between the object and the image", path=src)
    return out


def _base(zf: ZFile, s: ZSurface, scale: float, first_parm: int) -> dict[str, Any]:
    radius = math.inf if s.curv == 0 else 1.0 / s.curv * scale
    if s.parm.get(first_parm, 0.0) != 0:
        raise SpecError(f"line {s.line}: surface {s.number} ({s.type}) has an r² term (PARM {first_parm} = "
                        f"{s.parm[first_parm]:g}); lensopt's asphere starts at r⁴", path=zf.source)
    coefficients = {}
    for k in range(first_parm + 1, first_parm + 8):
        v = s.parm.get(k, 0.0)
        if v != 0:
            power = 2 * (k - first_parm + 1)
            coefficients[str(power)] = v * scale ** (1 - power)
    if coefficients:
        return {"type": "asphere", "radius": radius, "conic": s.conic, "coefficients": coefficients}
    if s.conic != 0:
        return {"type": "conic", "radius": radius, "conic": s.conic}
    if math.isinf(radius):
        return {"type": "plane"}
    return {"type": "sphere", "radius": radius}


def _surface(zf: ZFile, s: ZSurface, scale: float, catalogs: Any, gcat: list[str], extra: dict[str, Any],
             warnings: list[str]) -> dict[str, Any]:
    src = zf.source
    where = f"line {s.type_line or s.line}: surface {s.number}"
    if s.type in ("STANDARD", "EVENASPH"):
        base = _base(zf, s, scale, 1)
        surf: dict[str, Any] = dict(base)
    elif s.type == "BINARY_2":
        base = _base(zf, s, scale, 1)
        surf = {"type": "diffractive", "base": base, **_binary2(zf, s, scale, extra, where)}
    else:
        usable = s.curv == 0 and s.conic == 0 and not any(s.parm.values()) and not any(s.xdat.values())
        if not usable:
            raise SpecError(f"{where}: TYPE {s.type} is not supported (lensopt imports STANDARD, EVENASPH, "
                            "BINARY_2 and COORDBRK)", path=src)
        warnings.append(f"surface {s.number}: TYPE {s.type} with no curvature and all parameters zero imported as "
                        "a plane surface")
        surf = {"type": "plane"}
    surf["thickness"] = s.thickness * scale
    if not math.isfinite(surf["thickness"]):
        raise SpecError(f"line {s.line}: surface {s.number} has an infinite thickness", path=src)
    surf["material"] = material(zf, s, catalogs, gcat, extra, warnings)
    if s.clap is not None:
        rmin, rmax = s.clap
        if rmin > 0:
            warnings.append(f"surface {s.number}: ignored the inner radius {rmin:g} of the annular aperture CLAP")
        surf["semi_diameter"] = rmax * scale
        surf["clip"] = True
    elif s.flap and s.diam:
        surf["semi_diameter"] = s.diam * scale
        surf["clip"] = True
    elif s.diam:
        surf["semi_diameter"] = s.diam * scale
    if s.comment:
        surf["label"] = s.comment
    for key in ("vary",):
        if key in extra:
            surf[key] = extra[key]
    return surf


def _binary2(zf: ZFile, s: ZSurface, scale: float, extra: dict[str, Any], where: str) -> dict[str, Any]:
    order = s.parm.get(0, 1.0)
    if order != int(order):
        raise SpecError(f"{where}: BINARY_2 diffraction order must be an integer (got {order:g})", path=zf.source)
    terms = int(s.xdat.get(1, 0))
    radius = s.xdat.get(2, 1.0) * scale
    if terms and not radius > 0:
        raise SpecError(f"{where}: BINARY_2 normalization radius must be positive", path=zf.source)
    phase = {}
    for i in range(1, terms + 1):
        a = s.xdat.get(2 + i, 0.0)
        if a != 0:
            phase[2 * i] = a / radius ** (2 * i)
    exact = extra.get("phase")
    if isinstance(exact, dict):
        try:
            ex = {int(k): float(v) for k, v in exact.items()}
        except (TypeError, ValueError):
            ex = {}
        if set(ex) == set(phase) and all(abs(ex[k] - phase[k]) <= 1e-12 * max(abs(ex[k]), 1e-300) for k in ex):
            phase = ex
    out: dict[str, Any] = {"phase": {str(k): v for k, v in phase.items()}, "order": int(order)}
    wl = extra.get("design_wavelength_nm")
    if isinstance(wl, int | float) and wl > 0:
        out["design_wavelength_nm"] = float(wl)
    return out
