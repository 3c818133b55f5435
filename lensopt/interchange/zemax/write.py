"""Write a lens as a Zemax OpticStudio sequential ``.zmx`` file (``lensopt export-zemax``).

What is written (ASCII text, which OpticStudio and the Python readers accept as well as UTF-16):

- ``MODE SEQ``, ``NAME``, ``UNIT MM …``; aperture ``ENPD`` (an EPD) or ``FNUM f 0`` (lensopt's
  f-number is Zemax's image-space F/#, EFL/EPD); ``RAIM`` (aiming off for ``aim = "none"``, real
  aiming otherwise); ``FTYP 0|2 0 nfields nwaves`` (angle or paraxial image height), ``XFLN``/``YFLN``,
  ``FWGN``; vignetting as ``VDYN``/``VCYN``/``VCXN`` (VCY = (superior + inferior)/2,
  VDY = (inferior − superior)/2, VCX = lateral; see ``zemax.system``); ``WAVM`` (µm) and ``PWAV``.
- ``SURF 0`` the object (``DISZ INFINITY`` or the distance); one ``SURF`` per lens surface with ``TYPE
  STANDARD`` (sphere, conic, plane), ``EVENASPH`` (``PARM 2…8`` = r⁴…r¹⁶) or ``BINARY_2`` (diffractive:
  ``PARM 0`` = order, the base asphere in ``PARM 1…8``, ``XDAT 1`` = terms, ``XDAT 2`` = normalization
  radius 1 mm so that ``XDAT 2+i`` = A_i = d_(2i) exactly), ``CURV`` = 1/R, ``CONI``, ``DISZ``, ``GLAS``,
  ``DIAM`` (semi-diameter), ``CLAP 0 r`` where lensopt clips, ``STOP``, ``COMM`` (label); the image
  surface last (the image defocus is added to the last gap).
- Glasses: catalog glasses by name with their vendor in ``GCAT``; model glasses and the plastics of
  Table S10 as ``GLAS ___BLANK 1 0 nd vd dPgF`` (Zemax's model glass; lensopt's Hartmann model gives
  slightly different indices away from the d line than Zemax's model); AGF glasses by name with the
  catalog file's stem in ``GCAT``. Tabulated glasses have no Zemax form and are refused.

Numbers are written in shortest round-trip form. What Zemax has no operand for (lensopt's material
names, exact relative fields, aiming steps, defocus, front aperture, sensor, RGB weights, vary lists,
design wavelengths) goes into ``NOTE 0 lensopt: {json}`` lines, read back only where they agree.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from lensopt.errors import SpecError
from lensopt.files import write_text_atomic
from lensopt.interchange.numbers import fmt_derived, fmt_exact
from lensopt.interchange.zemax.syntax import NOTE_PREFIX
from lensopt.materials import CatalogGlass, ModelGlass
from lensopt.materials.agf import AgfGlass
from lensopt.spec.build import build
from lensopt.spec.models import AgfGlassSpec, DiffractiveSurface, LensSpec, ModelGlassSpec, TabulatedGlassSpec

__all__ = ["export_zemax", "write_zemax"]

_MAX_POWER = 16  # EVENASPH / BINARY_2 PARM 8 is r^16


def _one_line(text: str) -> str:
    return " ".join(text.split())


def _num(x: float) -> str:
    return fmt_exact(x)


def export_zemax(spec: LensSpec) -> str:
    """The lens as the text of a Zemax ``.zmx`` file.

    Raises:
        SpecError: something the Zemax subset here cannot express (tabulated glasses, asphere terms
            beyond r¹⁶) or a lens that cannot be built.
    """
    model = build(spec)
    extras: dict[str, Any] = {"aim": spec.system.aim}
    if spec.system.aim_steps != 1:
        extras["aim_steps"] = spec.system.aim_steps
    if spec.system.front_aperture is not None:
        extras["front_aperture"] = spec.system.front_aperture.model_dump()
    if spec.sensor is not None:
        extras["sensor"] = spec.sensor.model_dump(mode="json", exclude_none=True)
    if spec.spectrum.rgb_weights is not None:
        extras["rgb_weights"] = spec.spectrum.rgb_weights
    extras["wavelengths_nm"] = list(spec.spectrum.wavelengths_nm)
    if spec.system.vignetting is not None:
        extras["vignetting"] = spec.system.vignetting.model_dump()
    if spec.image.defocus != 0:
        extras["defocus"] = spec.image.defocus
    glass_lines, gcat = _glasses(spec, model)
    lines = ["VERS 190513 80 123457", "MODE SEQ", f"NAME {_one_line(spec.name)}"]
    body = _system_lines(spec, gcat, extras)
    surfaces, surf_extras = _surface_lines(spec, glass_lines)
    body += surfaces
    if surf_extras:
        extras["surfaces"] = surf_extras
    notes = [f"NOTE 0 {NOTE_PREFIX} " + json.dumps({k: v}, separators=(",", ":")) for k, v in extras.items()]
    return "\n".join(lines + notes + body) + "\n"


def _system_lines(spec: LensSpec, gcat: list[str], extras: dict[str, Any]) -> list[str]:
    """Units, aperture, glass catalogs, ray aiming, fields (with vignetting factors) and wavelengths; the
    field data also go into ``extras``."""
    body = ["UNIT MM X W X CM MR CPMM"]
    ap = spec.system.aperture
    body.append(f"ENPD {_num(ap.epd)}" if ap.epd is not None else f"FNUM {_num(ap.fnumber)} 0")
    if gcat:
        body.append("GCAT " + " ".join(gcat))
    body.append(f"RAIM 0 {0 if spec.system.aim == 'none' else 2} 1 1 0 0 0 0 0")
    fld = spec.system.field
    top = fld.hfov_deg if fld.hfov_deg is not None else fld.image_height
    n_f, n_w = len(fld.relative), len(spec.spectrum.wavelengths_nm)
    body.append(f"FTYP {0 if fld.hfov_deg is not None else 2} 0 {n_f} {n_w} 0 0 0")
    body.append("XFLN " + " ".join("0" for _ in fld.relative))
    body.append("YFLN " + " ".join(fmt_derived(u * top) for u in fld.relative))
    extras["field"] = {"max": top, "relative": list(fld.relative)}
    if fld.weights is not None:
        body.append("FWGN " + " ".join(_num(w) for w in fld.weights))
    vig = spec.system.vignetting
    if vig is not None:
        body.append("VDXN " + " ".join("0" for _ in fld.relative))
        body.append("VDYN " + " ".join(fmt_derived((i - s) / 2) for s, i in zip(vig.superior, vig.inferior,
                                                                                 strict=True)))
        body.append("VCXN " + " ".join(_num(v) for v in vig.lateral))
        body.append("VCYN " + " ".join(fmt_derived((i + s) / 2) for s, i in zip(vig.superior, vig.inferior,
                                                                                 strict=True)))
    weights = spec.spectrum.weights_or_uniform
    for k, (w, wt) in enumerate(zip(spec.spectrum.wavelengths_nm, weights, strict=True), start=1):
        body.append(f"WAVM {k} {_num(w * 1e-3)} {_num(wt)}")
    body.append(f"PWAV {spec.spectrum.reference_index + 1}")
    return body


def _surface_lines(spec: LensSpec, glass_lines: list[str]) -> tuple[list[str], dict[str, Any]]:
    """The object surface, every surface (with the coordinate breaks of moved surfaces and elements) and
    the image surface; and the per-surface data only lensopt reads back (vary lists, materials, phases)."""
    body: list[str] = []
    obj = spec.system.object
    body += ["SURF 0", "  TYPE STANDARD", "  CURV 0",
             "  DISZ " + ("INFINITY" if obj == "infinity" else _num(obj.distance))]
    surf_extras: dict[str, Any] = {}
    last = len(spec.surfaces) - 1
    starts, ends = _elements(spec)
    number = 0
    for i, surf in enumerate(spec.surfaces):
        thickness = surf.thickness + (spec.image.defocus if i == last else 0.0)
        if i in starts:  # a moved element: the break before its first surface
            el = starts[i]
            number += 1
            body += _coordbrk(number, *el.decenter, *el.tilt_deg, 0, 0.0)
        moved = any(surf.decenter or (0.0,)) or any(surf.tilt_deg or (0.0,))
        dx, dy = surf.decenter or (0.0, 0.0)
        ax, ay = surf.tilt_deg or (0.0, 0.0)
        if moved:  # a coordinate break right before the surface: Zemax's basic decenter/tilt
            number += 1
            body += _coordbrk(number, dx, dy, ax, ay, 0, 0.0)
        number += 1
        returns = moved and surf.decenter_mode != "basic"
        closes = i in ends
        body += _surface(surf, number - 1, 0.0 if returns or closes else thickness, glass_lines[i],
                         path=f"surfaces[{i}]")
        if returns:  # decenter-and-return: the inverse break (order flag 1, negated values) carries the gap
            number += 1
            body += _coordbrk(number, -dx, -dy, -ax, -ay, 1, thickness)
        if closes:  # back along the moved axis to the element's first vertex, then the inverse break
            el = ends[i]
            inner = 0.0
            for k in range(el.surfaces[0], el.surfaces[1]):
                inner += spec.surfaces[k].thickness
            number += 2
            body += [f"SURF {number - 1}", "  TYPE STANDARD", "  CURV 0", f"  DISZ {_num(-inner)}"]
            if glass_lines[i]:
                body.append(f"  GLAS {glass_lines[i]}")
            body += _coordbrk(number, -el.decenter[0], -el.decenter[1], -el.tilt_deg[0], -el.tilt_deg[1], 1,
                              inner + thickness)
        extra: dict[str, Any] = {}
        if surf.vary:
            extra["vary"] = list(surf.vary)
        if not surf.is_air:
            extra["material"] = (surf.material if isinstance(surf.material, str)
                                 else surf.material.model_dump(mode="json", exclude_none=True))
        if isinstance(surf, DiffractiveSurface):
            extra["phase"] = {str(k): v for k, v in surf.phase.items()}
            extra["design_wavelength_nm"] = surf.design_wavelength_nm
        if extra:
            surf_extras[str(i + 1)] = extra
    body += [f"SURF {number + 1}", "  TYPE STANDARD", "  CURV 0", "  DISZ 0"]
    return body, surf_extras


def write_zemax(spec: LensSpec, path: str | Path) -> None:
    """Export ``spec`` to ``path`` atomically."""
    write_text_atomic(path, export_zemax(spec))


def _glasses(spec: LensSpec, model: Any) -> tuple[list[str], list[str]]:
    """The GLAS line of every surface ('' for air) and the GCAT catalog names."""
    out: list[str] = []
    gcat: list[str] = []
    for i, (surf, mat) in enumerate(zip(spec.surfaces, model.media[1:], strict=True)):
        if surf.is_air:
            out.append("")
            continue
        if isinstance(surf.material, TabulatedGlassSpec):
            raise SpecError("a tabulated glass has no Zemax form (no catalog formula, no model glass)",
                            path=f"surfaces[{i}].material")
        if isinstance(mat, ModelGlass) or isinstance(surf.material, ModelGlassSpec):
            dpgf = getattr(mat, "dpgf", 0.0)
            out.append(f"___BLANK 1 0 {_num(mat.nd)} {_num(mat.vd)} {_num(dpgf)} 0 0 0 0 0")
            continue
        if isinstance(mat, AgfGlass) and isinstance(surf.material, AgfGlassSpec):
            cat = mat.entry.catalog
        elif isinstance(mat, CatalogGlass):
            cat = mat.glass.vendor.upper()
        else:
            raise SpecError(f"material {mat.label} has no Zemax form", path=f"surfaces[{i}].material")
        if cat not in gcat:
            gcat.append(cat)
        out.append(f"{mat.name} 0 0 {_num(mat.nd)} {_num(mat.vd)} 0 0 0 0 0 0")
    return out, gcat


def _elements(spec: LensSpec) -> tuple[dict[int, Any], dict[int, Any]]:
    """Moved elements by first and by last surface; overlapping elements, and surface decenters inside an
    element, have no single Zemax form here and are refused."""
    starts: dict[int, Any] = {}
    ends: dict[int, Any] = {}
    taken: set[int] = set()
    for n, el in enumerate(spec.elements or []):
        if not (any(el.decenter) or any(el.tilt_deg)):
            continue
        first, last = el.surfaces
        inside = set(range(first, last + 1))
        if inside & taken:
            raise SpecError("overlapping moved elements cannot be written as Zemax coordinate breaks",
                            path=f"elements[{n}].surfaces")
        for k in inside:
            s = spec.surfaces[k]
            if any(s.decenter or (0.0,)) or any(s.tilt_deg or (0.0,)):
                raise SpecError("a decentered surface inside a moved element cannot be written as Zemax "
                                "coordinate breaks", path=f"surfaces[{k}].decenter")
        taken |= inside
        starts[first], ends[last] = el, el
    return starts, ends


def _coordbrk(number: int, dx: float, dy: float, ax: float, ay: float, order: int, thickness: float) -> list[str]:
    """A COORDBRK block: decenter (dx, dy) mm, tilts about x and y (degrees), order flag, thickness."""
    return [f"SURF {number}", "  TYPE COORDBRK", "  CURV 0", f"  PARM 1 {_num(dx)}", f"  PARM 2 {_num(dy)}",
            f"  PARM 3 {_num(ax)}", f"  PARM 4 {_num(ay)}", "  PARM 5 0", f"  PARM 6 {order}",
            f"  DISZ {_num(thickness)}"]


def _surface(surf: Any, i: int, thickness: float, glass: str, *, path: str) -> list[str]:
    """The SURF block of ``surf``, numbered i + 1; errors name the spec ``path``."""
    base = surf.base if isinstance(surf, DiffractiveSurface) else surf
    radius = getattr(base, "radius", math.inf)
    curv = 0.0 if math.isinf(radius) else 1.0 / radius
    coefficients = getattr(base, "coefficients", {})
    for power in coefficients:
        if power > _MAX_POWER:
            raise SpecError(f"Zemax's EVENASPH stops at r^16 (PARM 8); r^{power} cannot be exported",
                            path=f"{path}.coefficients", got=power)
    out = [f"SURF {i + 1}"]
    if surf.stop:
        out.append("  STOP")
    if surf.label:
        out.append(f"  COMM {_one_line(surf.label)}")
    if isinstance(surf, DiffractiveSurface):
        out.append("  TYPE BINARY_2")
    elif coefficients:
        out.append("  TYPE EVENASPH")
    else:
        out.append("  TYPE STANDARD")
    out.append(f"  CURV {_num(curv)}")
    if getattr(base, "conic", 0.0):
        out.append(f"  CONI {_num(base.conic)}")
    if isinstance(surf, DiffractiveSurface):
        out.append(f"  PARM 0 {surf.order}")
    if coefficients or isinstance(surf, DiffractiveSurface):
        out.append("  PARM 1 0")
        for k in range(2, 9):
            out.append(f"  PARM {k} {_num(coefficients.get(2 * k, 0.0))}")
    if isinstance(surf, DiffractiveSurface):
        terms = max(surf.phase) // 2 if surf.phase else 0
        out += [f"  XDAT 1 {terms}", "  XDAT 2 1"]
        for t in range(1, terms + 1):
            out.append(f"  XDAT {2 + t} {_num(surf.phase.get(2 * t, 0.0))}")
    out.append(f"  DISZ {_num(thickness)}")
    if glass:
        out.append(f"  GLAS {glass}")
    if surf.semi_diameter is not None:
        out.append(f"  DIAM {_num(surf.semi_diameter)} 1 0 0 1 \"\"")
        if surf.clip:
            out.append(f"  CLAP 0 {_num(surf.semi_diameter)} 0")
    return out
