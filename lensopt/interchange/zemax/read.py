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
- System data: see :mod:`lensopt.interchange.zemax.system`; the file's syntax:
  :mod:`lensopt.interchange.zemax.syntax`.

Data lensopt keeps but Zemax has no operand for are written by ``export_zemax`` into ``NOTE`` lines
(``NOTE 0 lensopt: {json}``); they are read back only where they agree with the Zemax data.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lensopt.errors import LensoptError, SpecError
from lensopt.interchange.zemax.materials import material, range_warnings
from lensopt.interchange.zemax.syntax import INFINITE_OBJECT, MERIT, ZFile, ZSurface, parse_zmx
from lensopt.interchange.zemax.system import system_from_zemax
from lensopt.materials.agf import decode_text, read_agf

__all__ = ["ZemaxImport", "read_zemax", "import_zemax"]

#: Where a coordinate break's dummy surface keeps its Zemax values until the surfaces are complete.
_CB_KEY = "_zemax_coordbrk"


@dataclass
class ZemaxImport:
    """The imported lens and the warnings the import produced (one line each)."""

    spec: Any
    warnings: list[str]


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
        if name == MERIT:
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
    decenter and a tilt, are refused (except as the second break of a decenter-and-return pair, which
    :func:`_return_pair` reads first).
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
                            "decenter_mode": "basic", "label": s.comment or f"COORDBRK {s.number}",
                            _CB_KEY: (dx, dy, ax, ay, order, s.thickness)}
    if dx or dy:
        surf["decenter"] = [dx * scale, dy * scale]
    if ax or ay:
        surf["tilt_deg"] = [ax, ay]
    return surf


def _return_pair(out: list[dict[str, Any]], s: ZSurface, scale: float) -> bool:
    """Zemax's decenter-and-return: a break (order 0, no thickness), one surface with no thickness, and this
    break with order flag 1 and exactly the negated decenters/tilts, which undoes the first. The surface
    then gets lensopt's ``return`` decenter/tilt and this break's thickness (what ``export_zemax`` writes)."""
    if len(out) < 2 or s.parm.get(6, 0.0) == 0 or s.parm.get(5, 0.0) != 0:
        return False
    first, surface = out[-2].get(_CB_KEY), out[-1]
    if first is None or _CB_KEY in surface or surface["thickness"] != 0 or first[4] != 0 or first[5] != 0:
        return False
    if tuple(-s.parm.get(k, 0.0) for k in range(1, 5)) != tuple(first[:4]):
        return False
    dx, dy, ax, ay = first[:4]
    del out[-2]
    surface["thickness"] = s.thickness * scale
    surface["decenter_mode"] = "return"
    if dx or dy:
        surface["decenter"] = [dx * scale, dy * scale]
    if ax or ay:
        surface["tilt_deg"] = [ax, ay]
    return True


def _element_return(out: list[dict[str, Any]], s: ZSurface, scale: float) -> dict[str, Any] | None:
    """Zemax's tilted/decentered element: a break (order 0, no thickness) before surfaces first..last (the
    last without thickness), a plane dummy going back −L along the moved axis (L = the element's inner
    thicknesses), and this break with order flag 1 and the negated values, carrying L + the gap after the
    element. Returns lensopt's element placement (surfaces removed from ``out`` accordingly), or None."""
    if s.parm.get(6, 0.0) == 0 or s.parm.get(5, 0.0) != 0 or len(out) < 3:
        return None
    back = tuple(-s.parm.get(k, 0.0) for k in range(1, 5))
    j = next((k for k in range(len(out) - 3, -1, -1) if _CB_KEY in out[k]), None)
    if j is None:
        return None
    first, group, dummy = out[j][_CB_KEY], out[j + 1:-1], out[-1]
    if first[4] != 0 or first[5] != 0 or tuple(first[:4]) != back or not group:
        return None
    if dummy.get("type") != "plane" or dummy.get("label") or any(_CB_KEY in g for g in group):
        return None
    inner = 0.0
    for g in group[:-1]:
        inner += g["thickness"]
    if group[-1]["thickness"] != 0 or dummy["thickness"] != -inner:
        return None
    group[-1]["thickness"] = s.thickness * scale + dummy["thickness"]
    del out[-1]
    del out[j]
    dx, dy, ax, ay = first[:4]
    return {"surfaces": [j, j + len(group) - 1], "decenter": [dx * scale, dy * scale], "tilt_deg": [ax, ay]}


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
            if _return_pair(out, s, scale):
                warnings.append(f"surface {s.number}: coordinate-break pair imported as a decenter-and-return of "
                                "the surface between them")
                continue
            element = _element_return(out, s, scale)
            if element is not None:
                zf.elements.append(element)
                plain -= 1  # the element's return dummy is no lensopt surface
                warnings.append(f"surface {s.number}: coordinate-break pair imported as a rigid decenter/tilt "
                                f"of the element of surfaces {element['surfaces'][0]}..{element['surfaces'][1]}")
                continue
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
    for surf in out:
        surf.pop(_CB_KEY, None)
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
