"""Write a lens as a CODE V sequence file (``lensopt export-codev``).

What is written, and the CODE V conventions used:

- ``RDM Y`` (radii, not curvatures), ``LEN``, ``TITLE``, ``DIM M`` (millimetres).
- Aperture: ``EPD``, or ``FNO`` for an f-number with an infinite object in air (CODE V's FNO is then
  EFL/EPD); a finite-conjugate f-number is written as the EPD it implies.
- Fields: ``YAN`` (degrees, also for finite objects: CODE V's object angle of the chief ray to the
  paraxial entrance pupil, which is lensopt's angle field) or ``YIM`` (paraxial image height), ``WTF``.
- Vignetting factors (S19–S20): ``VUY`` = superior, ``VLY`` = inferior, ``VUX`` = ``VLX`` = lateral.
- ``WL`` (nm), ``WTW``, ``REF``; ``SO 0 1e10`` for an infinite object, else the object distance.
- One ``S radius thickness material`` line per surface, then each modifier on its own line: ``STO``,
  ``SLB``, ``CIR`` (semi-diameter), ``CON``/``ASP`` with ``K`` and ``A``…``J`` (r⁴…r²⁰),
  ``DIF DOE``/``HOR``/``HWL``/``HCT R``/``HCO Ck``; ``SI 0 defocus``; ``GO``.
- Diffractive phase: CODE V's HCO coefficients are optical path in lens units at the construction
  wavelength HWL, OPD(r) = Σ C_k r^(2k), i.e. φ = (2π/λ0) Σ C_k r^(2k) in radians; a ray of order m at
  wavelength λ is deflected by m (λ/λ0) ∇OPD. Sources: rayoptics ``oprops/doe.py``
  (``DiffractiveElement.phase``: ``out_dir = in_dir + order·(λ/λ0)·∇W``, after Wang et al.,
  doi:10.1117/1.600780) and the CODE V ↔ Zemax conversion C_2i = A_i λ/(2π σ^2i)
  (opticsrealm.com, "Diffraction coefficients: converting from CODE V to Zemax and back"). lensopt's
  phase is in radians with deflection m λ/(2π) ∇φ, so C_k = d_2k · λ0 / (2π) with λ0 in mm, and both
  give the paraxial power −2 m C_1 λ/λ0 = −m λ d_2/π (no sign change).
- Glasses: catalog glasses by their CODE V names (``NBK7_SCHOTT``); model glasses, plastics, tabulated
  glasses and, with ``private_catalog``, every glass as a private catalog (``PRV``/``PWL``/``'NAME'
  n1 … nk``/``END``) with the indices lensopt computes at the lens wavelengths (at least 4 wavelengths:
  the Fraunhofer lines are added where fewer), as the seed does (S1.3.4).

Numbers lensopt stores are written exactly (shortest round-trip form); numbers computed for CODE V
(field values, HCO, a derived EPD) with 14 significant digits (see ``codev.syntax``). What CODE V has
no command for (ray aiming, exact relative fields, the lensopt definition of private glasses, clip
and vary flags, sensor, RGB weights) goes into ``! lensopt:`` comment lines that the importer reads
back only when they agree with the CODE V data.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from lensopt import __version__
from lensopt.errors import SpecError
from lensopt.files import write_text_atomic
from lensopt.interchange.codev.names import codev_glass_name, private_name
from lensopt.interchange.codev.syntax import EXTRAS_PREFIX
from lensopt.interchange.numbers import fmt_derived, fmt_exact
from lensopt.materials import LINE_C_UM, LINE_D_UM, LINE_F_UM, LINE_G_UM, CatalogGlass, Material
from lensopt.optics.paraxial import first_order
from lensopt.spec.build import Model, build
from lensopt.spec.models import DiffractiveSurface, LensSpec, ModelGlassSpec, TabulatedGlassSpec

__all__ = ["export_codev", "write_codev", "ASPHERE_LETTERS", "MIN_PRIVATE_WAVELENGTHS", "phase_to_hco"]

#: CODE V asphere coefficient commands for r⁴, r⁶, …, r²⁰.
ASPHERE_LETTERS: dict[int, str] = {4: "A", 6: "B", 8: "C", 10: "D", 12: "E", 14: "F", 16: "G", 18: "H", 20: "J"}
#: Readers need at least this many private-catalog wavelengths (CODE V fits a dispersion curve).
MIN_PRIVATE_WAVELENGTHS = 4
#: Wavelengths (nm) added to a private catalog when the lens has fewer than four: F, d, C, g lines.
_EXTRA_NM = tuple(round(w * 1e3, 4) for w in (LINE_F_UM, LINE_D_UM, LINE_C_UM, LINE_G_UM))


def phase_to_hco(d: float, power: int, design_wavelength_nm: float) -> float:
    """CODE V HCO coefficient (mm^(1−power), OPD at HWL) of the lensopt phase term d·r^power (radians)."""
    del power  # the conversion is the same for every power: OPD = φ λ0 / (2π)
    return d * (design_wavelength_nm * 1e-6) / (2.0 * math.pi)


@dataclass
class _Private:
    name: str
    spec_material: Any
    material: Material


def export_codev(spec: LensSpec, *, private_catalog: bool = False) -> str:
    """The lens as the text of a CODE V ``.seq`` file.

    Args:
        spec: the lens.
        private_catalog: write every glass as a private catalog entry (indices computed by lensopt at
            the lens wavelengths), not only model, plastic and tabulated glasses.

    Raises:
        SpecError: the lens uses something CODE V's sequence subset here cannot express (asphere
            terms beyond r²⁰) or cannot be built.
    """
    model = build(spec)
    fo = first_order(model.lens, model.system)
    names, privates = _materials(model, private_catalog)
    extras: dict[str, Any] = {"aim": spec.system.aim}
    if spec.system.aim_steps != 1:
        extras["aim_steps"] = spec.system.aim_steps
    if spec.system.front_aperture is not None:  # an object-space aperture: no CODE V command here
        extras["front_aperture"] = spec.system.front_aperture.model_dump()
    lines = [f"! CODE V sequence file written by lensopt {__version__}: {spec.name}"]
    ref_nm = spec.spectrum.wavelengths_nm[spec.spectrum.reference_index]
    lines.append(
        f"! lensopt first-order data at {ref_nm:g} nm: EFL {float(fo.efl):.10g} BFL {float(fo.bfl):.10g} "
        f"EPD {float(fo.epd):.10g} f/# {float(fo.fnumber):.10g} paraxial image height "
        f"{float(fo.paraxial_image_height):.10g} total track {float(fo.total_track):.10g}")
    lines += ["RDM Y", "LEN", f"TITLE '{_quote(spec.name)}'", "DIM M"]
    lines += _aperture(spec, float(fo.epd), model)
    if lines[-1].startswith("EPD") and spec.system.aperture.fnumber is not None:
        extras["aperture"] = {"fnumber": spec.system.aperture.fnumber}
    field_lines, field_extras = _fields(spec)
    lines += field_lines
    extras["field"] = field_extras
    lines += _spectrum(spec)
    if privates:
        lines += _private_catalog(spec, privates)
        extras["glasses"] = {p.name: _material_json(p.spec_material) for p in privates}
    obj = spec.system.object
    lines.append("SO 0 1e10" if obj == "infinity" else f"SO 0 {fmt_exact(obj.distance)}")
    surface_extras: dict[str, Any] = {}
    for i, surf in enumerate(spec.surfaces):
        lines += _surface(surf, names[i], path=f"surfaces[{i}]")
        extra = {k: v for k, v in (("clip", surf.clip), ("vary", surf.vary)) if v}
        if isinstance(surf.material, str) and not surf.is_air:
            extra["material"] = surf.material
        if isinstance(surf, DiffractiveSurface):
            extra["phase"] = {str(k): v for k, v in surf.phase.items()}
        if extra:
            surface_extras[str(i + 1)] = extra
    lines.append(f"SI 0 {fmt_exact(spec.image.defocus)}")
    lines.append("GO")
    if surface_extras:
        extras["surfaces"] = surface_extras
    if spec.sensor is not None:
        extras["sensor"] = spec.sensor.model_dump(mode="json", exclude_none=True)
    if spec.spectrum.rgb_weights is not None:
        extras["rgb_weights"] = spec.spectrum.rgb_weights
    extra_lines = [EXTRAS_PREFIX + json.dumps({k: v}, separators=(", ", ": ")) for k, v in extras.items()]
    return "\n".join(lines[:2] + extra_lines + lines[2:]) + "\n"


def write_codev(spec: LensSpec, path: str | Path, *, private_catalog: bool = False) -> None:
    """Export ``spec`` to ``path`` atomically (no half-written file on error)."""
    write_text_atomic(path, export_codev(spec, private_catalog=private_catalog))


def _quote(text: str) -> str:
    return text.replace("'", "").replace('"', "").replace("\n", " ")


def _aperture(spec: LensSpec, epd: float, model: Model) -> list[str]:
    ap = spec.system.aperture
    if ap.epd is not None:
        return [f"EPD {fmt_exact(ap.epd)}"]
    image_in_air = bool(torch.all(model.lens.index[-1] == 1.0))
    if spec.system.object == "infinity" and image_in_air:
        return [f"FNO {fmt_exact(ap.fnumber)}"]
    return [f"EPD {fmt_derived(epd)}"]


def _fields(spec: LensSpec) -> tuple[list[str], dict[str, Any]]:
    fld = spec.system.field
    if fld.hfov_deg is not None:
        cmd, top = "YAN", fld.hfov_deg
    else:
        cmd, top = "YIM", fld.image_height
    lines = [f"{cmd} " + " ".join(fmt_derived(u * top) for u in fld.relative)]
    if fld.weights is not None:
        lines.append("WTF " + " ".join(fmt_exact(w) for w in fld.weights))
    vig = spec.system.vignetting
    if vig is not None:
        lines.append("VUY " + " ".join(fmt_exact(v) for v in vig.superior))
        lines.append("VLY " + " ".join(fmt_exact(v) for v in vig.inferior))
        lines.append("VUX " + " ".join(fmt_exact(v) for v in vig.lateral))
        lines.append("VLX " + " ".join(fmt_exact(v) for v in vig.lateral))
    return lines, {"max": top, "relative": list(fld.relative)}


def _spectrum(spec: LensSpec) -> list[str]:
    sp = spec.spectrum
    lines = ["WL " + " ".join(fmt_exact(w) for w in sp.wavelengths_nm)]
    if sp.weights is not None:
        lines.append("WTW " + " ".join(fmt_exact(w) for w in sp.weights))
    lines.append(f"REF {sp.reference_index + 1}")
    return lines


def _materials(model: Model, private_catalog: bool) -> tuple[list[str], list[_Private]]:
    """CODE V material token of every surface ('' for air) and the private glasses to define."""
    names: list[str] = []
    privates: list[_Private] = []
    taken: set[str] = set()
    by_key: dict[str, _Private] = {}
    for surf, mat in zip(model.spec.surfaces, model.media[1:], strict=True):
        if surf.is_air:
            names.append("")
            continue
        if isinstance(mat, CatalogGlass) and not private_catalog:
            try:
                names.append(codev_glass_name(mat.glass))
                continue
            except SpecError:
                pass  # no CODE V catalog name: write it as a private glass
        key = json.dumps(_material_json(surf.material), sort_keys=True)
        if key not in by_key:
            by_key[key] = _Private(private_name(_private_label(surf.material), taken), surf.material, mat)
            privates.append(by_key[key])
        names.append(by_key[key].name)
    return names, privates


def _private_label(material: Any) -> str:
    if isinstance(material, str):
        return material.rpartition(":")[2]
    return getattr(material, "name", None) or getattr(material, "glass", None) or "MODEL"


def _material_json(material: Any) -> Any:
    if isinstance(material, str):
        return material
    kind = ("model" if isinstance(material, ModelGlassSpec) else "tabulated"
            if isinstance(material, TabulatedGlassSpec) else "agf")
    return material.model_dump(mode="json", exclude_none=True) | {"type": kind}


def _private_wavelengths(spec: LensSpec, privates: list[_Private]) -> list[float]:
    """Lens wavelengths plus F, d, C, g lines (inside every private glass's range) up to four."""
    chosen = list(spec.spectrum.wavelengths_nm)
    for extra in _EXTRA_NM:
        if len(chosen) >= MIN_PRIVATE_WAVELENGTHS:
            break
        inside = all(p.material.valid_range_um[0] <= extra * 1e-3 <= p.material.valid_range_um[1]
                     for p in privates)
        if inside and all(abs(extra - w) > 1.0 for w in chosen):
            chosen.append(extra)
    if len(chosen) < MIN_PRIVATE_WAVELENGTHS:
        lo = max(p.material.valid_range_um[0] for p in privates) * 1e3
        hi = min(p.material.valid_range_um[1] for p in privates) * 1e3
        for k in range(1, 8):
            if len(chosen) >= MIN_PRIVATE_WAVELENGTHS:
                break
            w = round(lo + (hi - lo) * k / 8, 4)
            if all(abs(w - c) > 1.0 for c in chosen):
                chosen.append(w)
    return sorted(chosen, reverse=True)


def _private_catalog(spec: LensSpec, privates: list[_Private]) -> list[str]:
    wl_nm = _private_wavelengths(spec, privates)
    wl_um = torch.tensor([w * 1e-3 for w in wl_nm], dtype=torch.float64)
    lines = ["PRV", "PWL " + " ".join(fmt_exact(w) for w in wl_nm)]
    for p in privates:
        idx = p.material.index(wl_um).tolist()
        lines.append(f"'{p.name}' " + " ".join(fmt_exact(n) for n in idx))
    lines.append("END")
    return lines


def _surface(surf: Any, material: str, *, path: str) -> list[str]:
    base = surf.base if isinstance(surf, DiffractiveSurface) else surf
    radius = getattr(base, "radius", math.inf)
    head = f"S {fmt_exact(0.0 if math.isinf(radius) else radius)} {fmt_exact(surf.thickness)}"
    out = [head + (f" {material}" if material else "")]
    if surf.stop:
        out.append("  STO")
    if surf.label:
        out.append(f"  SLB \"{_quote(surf.label)}\"")
    if surf.semi_diameter is not None:
        out.append(f"  CIR {fmt_exact(surf.semi_diameter)}")
    if base.type == "conic":
        out += ["  CON", f"  K {fmt_exact(base.conic)}"]
    elif base.type == "asphere":
        out += ["  ASP", f"  K {fmt_exact(base.conic)}"]
        for power, value in base.coefficients.items():
            if power not in ASPHERE_LETTERS:
                raise SpecError(f"CODE V's ASP surface stops at r^20 (A…J); r^{power} cannot be exported",
                                path=f"{path}.base.coefficients" if isinstance(surf, DiffractiveSurface)
                                else f"{path}.coefficients", got=power)
            out.append(f"  {ASPHERE_LETTERS[power]} {fmt_exact(value)}")
    if isinstance(surf, DiffractiveSurface):
        out += ["  DIF DOE", f"  HOR {surf.order}", f"  HWL {fmt_exact(surf.design_wavelength_nm)}", "  HCT R"]
        for power, value in surf.phase.items():
            hco = phase_to_hco(value, power, surf.design_wavelength_nm)
            out.append(f"  HCO C{power // 2} {fmt_derived(hco)}")
    return out
