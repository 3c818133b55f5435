"""Read a CODE V sequence file into a lens spec (``lensopt import-codev``).

Reads the subset ``export_codev`` writes plus: ``RDM N`` (curvatures, also CODE V's default when a
file has no ``RDM``), ``FNO``/``NA``/``NAO``,
``YOB``/``YIM``, ``DIM C``/``DIM I`` (converted to mm), fictitious glasses (``516800.641700``, six-digit
codes: lensopt's Hartmann model glass with normal partial dispersion), private catalogs (exact at
their wavelengths, a cubic spline between), ``SI`` defocus, surface commands qualified by ``Sk``.
Solves and variable codes (``CCY``, ``THC``, ``PIM``, …) are ignored with one warning listing them;
so are commands lensopt does not model. Reflective (``REFL``), decentered/tilted surfaces and curved
images raise a ``SpecError`` (exit code 2).

CODE V conventions taken: an object distance ≥ 1e10 is infinite; ``YAN`` is the object-space chief
ray angle to the paraxial entrance pupil (also for finite objects), ``YIM`` the paraxial image height;
``YOB`` h becomes the angle atan(h/(d + z_EP)); ``FNO`` is EFL/EPD for an infinite object in air and
the working f-number otherwise; ``NA``/``NAO`` give the paraxial marginal slope tan(asin(NA/n)) (as
rayoptics' ``na2slp``). Files without lensopt's comments get ``aim = "chief"`` (CODE V aims real rays
at the stop). HCO coefficients: see ``codev.write``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lensopt.errors import SpecError
from lensopt.interchange.codev.materials import PrivateGlass, resolve_glass
from lensopt.interchange.codev.syntax import Command, split_commands
from lensopt.interchange.codev.system import system_from_codev

__all__ = ["CodevImport", "import_codev", "read_codev", "SOLVE_COMMANDS", "INFINITE_OBJECT"]

#: An object at this distance (file units) or farther is at infinity.
INFINITE_OBJECT = 1e10
#: Solve and variable codes: ignored (lensopt's solves live in its optimizer).
SOLVE_COMMANDS = frozenset(
    "CCY CCX THC GLC KC AC BC CC DC EC FC GC HC JC HCC PIM PUY PUX PIY PIX PCY PCX PUI PUC PIC PCI".split())
_UNITS = {"M": 1.0, "MM": 1.0, "C": 10.0, "CM": 10.0, "I": 25.4, "IN": 25.4}
_LETTERS = {"A": 4, "B": 6, "C": 8, "D": 10, "E": 12, "F": 14, "G": 16, "H": 18, "J": 20}
_SYSTEM = frozenset("EPD FNO NA NAO XAN YAN XOB YOB XIM YIM XRI YRI WTF VUY VLY VUX VLX WL WTW REF".split())
_SILENT = frozenset(("LEN",))
_IGNORED = frozenset("TEM PRE INI CWL WID CUF DER ADY ADX DAR BEN REV RMD EDG SPH".split())


@dataclass
class CodevImport:
    """The imported lens and the warnings the import produced (one line each)."""

    spec: Any
    warnings: list[str]


@dataclass
class _Surface:
    line: int
    value: float  # radius (RDM Y) or curvature (RDM N), file units
    thickness: float
    glass: str | None
    radius_mode: bool
    stop: bool = False
    label: str | None = None
    cir: float | None = None
    kind: str = "sphere"
    conic: float | None = None
    coefficients: dict[int, float] = field(default_factory=dict)
    doe: bool = False
    order: int = 1
    hwl: float | None = None
    hco: dict[int, float] = field(default_factory=dict)

    def radius(self) -> float:
        if self.radius_mode:
            return math.inf if self.value == 0 else self.value
        return math.inf if self.value == 0 else 1.0 / self.value


@dataclass
class _State:
    source: str
    radius_mode: bool = False  # CODE V's default without RDM: curvatures (as rayoptics reads them)
    scale: float = 1.0
    name: str = "lens"
    system: dict[str, tuple[Command, list[float]]] = field(default_factory=dict)
    private: dict[str, PrivateGlass] = field(default_factory=dict)
    private_wl: list[float] | None = None
    in_private: bool = False
    obj: _Surface | None = None
    surfaces: list[_Surface] = field(default_factory=list)
    image: _Surface | None = None
    current: _Surface | None = None
    solves: list[str] = field(default_factory=list)
    ignored: list[str] = field(default_factory=list)
    done: bool = False


def read_codev(path: str | Path) -> CodevImport:
    """Import the ``.seq`` file at ``path``.

    Raises:
        SpecError: unreadable file, unsupported content, bad numbers or glasses (the message names
            the file, the line and what is wrong).
    """
    path = Path(path)
    if not path.is_file():
        raise SpecError("no such file", path=str(path))
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as err:
        raise SpecError(f"cannot read: {err}", path=str(path)) from None
    return import_codev(text, source=str(path))


def import_codev(text: str, *, source: str = "seq") -> CodevImport:
    """Import the text of a ``.seq`` file; see the module doc for what is understood."""
    seq = split_commands(text, source=source)
    st = _State(source)
    for cmd in seq.commands:
        if st.done:
            break
        try:
            _command(st, cmd)
        except IndexError:  # a command without the values it needs ("A" with no coefficient)
            raise _err(st, cmd, f"{cmd.name} needs more values") from None
    if not st.surfaces:
        raise SpecError("no surfaces (S lines) between SO and SI", path=source)
    warnings: list[str] = []
    if st.solves:
        warnings.append("ignored CODE V solves and variable codes: " + ", ".join(_unique(st.solves)))
    if st.ignored:
        warnings.append("ignored CODE V commands lensopt does not model: " + ", ".join(_unique(st.ignored)))
    surfaces = _surfaces(st, seq.extras, warnings)
    spec = system_from_codev(st.name, st.system, st.scale, _object_distance(st), surfaces,
                             _defocus(st), seq.extras, warnings, source=source)
    return CodevImport(spec, warnings)


def _unique(items: list[str]) -> list[str]:
    return list(dict.fromkeys(items))


def _err(st: _State, cmd: Command, message: str) -> SpecError:
    return SpecError(f"line {cmd.line} ({' '.join(cmd.tokens)[:60]}): {message}", path=st.source)


def _number(st: _State, cmd: Command, token: str) -> float:
    try:
        return float(token.replace("D", "e").replace("d", "e"))
    except ValueError:
        raise _err(st, cmd, f"expected a number, got {token!r}") from None


def _numbers(st: _State, cmd: Command, tokens: tuple[str, ...]) -> list[float]:
    return [_number(st, cmd, t) for t in tokens]


def _target(st: _State, cmd: Command) -> tuple[_Surface | None, tuple[str, ...]]:
    """The surface a surface command applies to (an ``Sk``/``SO``/``SI`` qualifier, else the current
    one) and the remaining arguments."""
    args = cmd.args
    if args and args[0][:1].upper() == "S" and (args[0][1:].isdigit() or args[0][1:].upper() in ("O", "I")):
        q = args[0][1:].upper()
        surf = st.obj if q == "O" else st.image if q == "I" else (
            st.surfaces[int(q) - 1] if 0 < int(q) <= len(st.surfaces) else None)
        if surf is None:
            raise _err(st, cmd, f"no surface {args[0]}")
        return surf, args[1:]
    return st.current, args


def _command(st: _State, cmd: Command) -> None:
    name = cmd.name
    if st.in_private:
        if name == "END":
            st.in_private = False
        elif name == "PWL":
            st.private_wl = _numbers(st, cmd, cmd.args)
        else:
            st.private[cmd.tokens[0].upper()] = PrivateGlass(cmd.tokens[0], cmd.line, st.private_wl,
                                                             list(cmd.args))
        return
    if name in ("RDM",):
        st.radius_mode = not (cmd.args and cmd.args[0].upper().startswith("N"))
    elif name in ("TIT", "TITLE"):
        st.name = " ".join(cmd.args).strip() or st.name
    elif name == "DIM":
        unit = cmd.args[0].upper() if cmd.args else "M"
        if unit not in _UNITS:
            raise _err(st, cmd, "unknown unit; expected M, C or I")
        st.scale = _UNITS[unit]
    elif name in _SYSTEM:
        st.system[name] = (cmd, _numbers(st, cmd, cmd.args))
    elif name == "PRV":
        st.in_private = True
    elif name == "GO":
        st.done = True
    elif name in ("SO", "SI") or (name[0] == "S" and (name[1:].isdigit() or name == "S")):
        _surface_line(st, cmd)
    elif name in SOLVE_COMMANDS:
        st.solves.append(name)
    else:
        _surface_command(st, cmd)


def _surface_line(st: _State, cmd: Command) -> None:
    args = cmd.args
    if len(args) < 2:
        raise _err(st, cmd, "a surface line needs a radius (or curvature) and a thickness")
    value, thickness = _number(st, cmd, args[0]), _number(st, cmd, args[1])
    glass = args[2] if len(args) > 2 else None
    if glass is not None and glass.upper() == "REFL":
        raise _err(st, cmd, "mirrors (REFL) are not supported yet: lensopt traces refractive systems only")
    surf = _Surface(cmd.line, value, thickness, glass, st.radius_mode)
    if cmd.name == "SO":
        st.obj = surf
    elif cmd.name == "SI":
        st.image = surf
    else:
        st.surfaces.append(surf)
    st.current = surf


def _surface_command(st: _State, cmd: Command) -> None:
    name = cmd.name
    surf, args = _target(st, cmd)
    if name in ("RDY", "CUY", "THI") and args and not _is_number(args[0]):
        st.solves.append(f"{name} {args[0].upper()}")
        return
    if name in _SILENT:
        return
    if name in _IGNORED or surf is None:
        st.ignored.append(name)
        return
    if name == "STO":
        surf.stop = True
    elif name == "SLB":
        surf.label = " ".join(args) or None
    elif name == "CIR":
        quals = {a.upper() for a in args if not _is_number(a)}
        if quals & {"EDG", "OBS", "HOL"}:
            st.ignored.append(f"CIR {'/'.join(sorted(quals))}")
        else:
            surf.cir = _number(st, cmd, args[-1])
    elif name == "CON":
        surf.kind = "conic" if surf.kind == "sphere" else surf.kind
    elif name == "ASP":
        surf.kind = "asphere"
    elif name == "K":
        surf.conic = _number(st, cmd, args[0])
    elif name in _LETTERS:
        surf.coefficients[_LETTERS[name]] = _number(st, cmd, args[0])
    elif name in ("RDY", "CUY"):
        surf.value, surf.radius_mode = _number(st, cmd, args[0]), name == "RDY"
    elif name == "THI":
        surf.thickness = _number(st, cmd, args[0])
    elif name in ("XDE", "YDE", "ZDE", "ADE", "BDE", "CDE"):
        if any(v != 0 for v in _numbers(st, cmd, args)):
            raise _err(st, cmd, "decentered or tilted surfaces are not supported (lensopt is rotationally "
                                "symmetric)")
    elif name in ("DIF", "HOR", "HWL", "HCT", "HCO"):
        _diffractive(st, cmd, surf, args)
    else:
        st.ignored.append(name)


def _is_number(token: str) -> bool:
    try:
        float(token.replace("D", "e").replace("d", "e"))
    except ValueError:
        return False
    return True


def _diffractive(st: _State, cmd: Command, surf: _Surface, args: tuple[str, ...]) -> None:
    name = cmd.name
    if name == "DIF":
        kind = args[0].upper() if args else ""
        if kind != "DOE":
            raise _err(st, cmd, f"only DIF DOE (phase polynomial) diffractive surfaces are supported (got "
                                f"{kind or 'nothing'})")
        surf.doe = True
    elif name == "HOR":
        order = _number(st, cmd, args[0])
        if order != int(order):
            raise _err(st, cmd, "diffraction order must be an integer")
        surf.order = int(order)
    elif name == "HWL":
        surf.hwl = _number(st, cmd, args[0])
    elif name == "HCT":
        if not args or args[0].upper() != "R":
            raise _err(st, cmd, "only rotationally symmetric phase (HCT R) is supported")
    elif name == "HCO":
        if len(args) < 2 or args[0][:1].upper() != "C" or not args[0][1:].isdigit():
            raise _err(st, cmd, "expected HCO Ck value")
        surf.hco[int(args[0][1:])] = _number(st, cmd, args[1])


def _object_distance(st: _State) -> float | None:
    if st.obj is None:
        return None
    if st.obj.glass is not None and st.obj.glass.upper() != "AIR":
        raise SpecError(f"line {st.obj.line}: object space must be air (got {st.obj.glass})", path=st.source)
    if st.obj.thickness >= INFINITE_OBJECT:
        return None
    if not st.obj.thickness > 0:
        raise SpecError(f"line {st.obj.line}: the object distance must be positive (got {st.obj.thickness})",
                        path=st.source)
    return st.obj.thickness * st.scale


def _defocus(st: _State) -> float:
    if st.image is None:
        return 0.0
    if st.image.value != 0:
        raise SpecError(f"line {st.image.line}: curved image surfaces are not supported (got "
                        f"{'radius' if st.image.radius_mode else 'curvature'} {st.image.value})", path=st.source)
    return st.image.thickness * st.scale


def _surfaces(st: _State, extras: dict[str, Any], warnings: list[str]) -> list[dict[str, Any]]:
    """Surface dicts of the spec (lengths in mm)."""
    scale = st.scale
    surf_extras = extras.get("surfaces", {}) if isinstance(extras.get("surfaces"), dict) else {}
    out: list[dict[str, Any]] = []
    stop_found = any(s.stop for s in st.surfaces)
    if not stop_found:
        warnings.append("no STO in the file: surface 1 is taken as the aperture stop")
    for i, s in enumerate(st.surfaces):
        extra = surf_extras.get(str(i + 1), {})
        extra = extra if isinstance(extra, dict) else {}
        path = f"surfaces[{i}]"
        radius = s.radius() * scale
        base: dict[str, Any]
        if s.kind == "asphere" or s.coefficients:
            base = {"type": "asphere", "radius": radius, "conic": s.conic or 0.0,
                    "coefficients": {str(p): c * scale ** (1 - p) for p, c in s.coefficients.items()}}
        elif s.kind == "conic" or s.conic is not None:
            base = {"type": "conic", "radius": radius, "conic": s.conic or 0.0}
        elif math.isinf(radius):
            base = {"type": "plane"}
        else:
            base = {"type": "sphere", "radius": radius}
        surf: dict[str, Any] = {"thickness": s.thickness * scale,
                                "material": resolve_glass(s.glass, st.private, extra.get("material"),
                                                          extras.get("glasses"), path=path, line=s.line,
                                                          source=st.source)}
        if s.doe:
            surf |= _doe(st, s, extra, path)
            surf["base"] = base
        else:
            surf |= base
        if s.cir is not None:
            surf["semi_diameter"] = s.cir * scale
        surf["stop"] = s.stop or (not stop_found and i == 0)
        if s.label:
            surf["label"] = s.label
        for key in ("clip", "vary"):
            if key in extra:
                surf[key] = extra[key]
        out.append(surf)
    return out


def _doe(st: _State, s: _Surface, extra: dict[str, Any], path: str) -> dict[str, Any]:
    if s.hwl is None or not s.hwl > 0:
        raise SpecError(f"line {s.line}: a DIF DOE surface needs a construction wavelength HWL (nm)",
                        path=st.source)
    lam0_mm = s.hwl * 1e-6
    # HCO Ck: OPD at HWL in lens units, coefficient of r^(2k): φ = 2π/λ0 · OPD (see codev.write).
    phase = {2 * k: c * st.scale ** (1 - 2 * k) * 2.0 * math.pi / lam0_mm for k, c in sorted(s.hco.items())}
    exact = extra.get("phase")
    if isinstance(exact, dict) and _same_phase(exact, phase):
        phase = {int(k): float(v) for k, v in exact.items()}
    return {"type": "diffractive", "phase": {str(k): v for k, v in phase.items()},
            "design_wavelength_nm": s.hwl, "order": s.order}


def _same_phase(exact: dict[str, Any], phase: dict[int, float]) -> bool:
    try:
        ex = {int(k): float(v) for k, v in exact.items()}
    except (TypeError, ValueError):
        return False
    if set(ex) != set(phase):
        return False
    return all(abs(ex[k] - phase[k]) <= 1e-12 * max(abs(phase[k]), abs(ex[k])) for k in ex)
