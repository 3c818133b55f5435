"""Glasses of an imported Zemax file (see ``zemax.read``): AGF catalogs given by the user, lensopt's
catalogs (the ``GCAT`` vendors first; a name in several catalogs resolved by the ``GLAS`` line's nd/vd),
Zemax model glasses (``___BLANK``), and one warning per AGF glass used outside its wavelength range."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from lensopt.errors import LensoptError, SpecError
from lensopt.materials.agf import AgfGlass, agf_glass
from lensopt.materials.catalog import find_glass, normalize_name

__all__ = ["material", "range_warnings", "VENDORS"]

#: GCAT names -> lensopt vendor keys.
VENDORS = {"SCHOTT": "schott", "OHARA": "ohara", "HIKARI": "hikari", "HOYA": "hoya", "CDGM": "cdgm",
           "SUMITA": "sumita"}


def material(zf: Any, s: Any, catalogs: Any, gcat: list[str], extra: dict[str, Any],
              warnings: list[str]) -> Any:
    src = zf.source
    if not s.glass:
        return "air"
    name = s.glass[0]
    where = f"line {s.glass_line}: surface {s.number}"
    upper = name.upper()
    if upper == "AIR":
        return "air"
    if upper == "MIRROR":
        raise SpecError(f"{where}: mirrors (GLAS MIRROR) are not supported: lensopt traces refractive systems only",
                        path=src)
    if upper in ("___BLANK", "MODEL"):  # OpticStudio writes ___BLANK, optiland's writer MODEL
        values = [t for t in s.glass[1:]]
        try:
            nd, vd = float(values[2]), float(values[3])
            dpgf = float(values[4]) if len(values) > 4 else 0.0
        except (IndexError, ValueError):
            raise SpecError(f"{where}: a model glass (___BLANK) needs nd and vd", path=src) from None
        model = {"nd": nd, "vd": vd, "dpgf": dpgf}
        ex = extra.get("material")
        if isinstance(ex, dict) and all(ex.get(k) == v for k, v in model.items()) and set(ex) <= {
                "nd", "vd", "dpgf", "name"}:
            return ex
        if isinstance(ex, str):
            try:
                from lensopt.materials import material_from_name

                mat = material_from_name(ex)
                if (mat.nd, mat.vd) == (nd, vd) and dpgf == 0.0:
                    return ex
            except LensoptError:
                pass
        note = f"model glass nd {nd:g}, vd {vd:g}, ΔPgF {dpgf:g}: lensopt's Hartmann dispersion"
        if not any(note in w for w in warnings):
            warnings.append(f"{note} (Zemax's model glass disperses slightly differently away from the d line)")
        return model
    ex = extra.get("material")
    if isinstance(ex, dict) and set(ex) == {"catalog", "glass"} and normalize_name(str(ex["glass"])) == \
            normalize_name(name):
        try:
            agf_glass(ex["catalog"], name)
            return ex
        except LensoptError:
            pass
    for c in catalogs:
        try:
            glass = agf_glass(c, name)
        except LensoptError:
            continue
        return {"catalog": str(Path(c).resolve()), "glass": glass.entry.name}
    vendors = [VENDORS[g] for g in gcat if g in VENDORS] + [
        VENDORS[k] for g in gcat for k in VENDORS if g.startswith(k) and g not in VENDORS]
    nd_file, vd_file = _file_nd_vd(s.glass)
    candidates = []
    for v in vendors:
        try:
            candidates.append(find_glass(f"{v}:{name}"))
        except LensoptError:
            continue
    if not candidates:
        try:
            candidates.append(find_glass(name))
        except LensoptError:
            cats = f" (GCAT {' '.join(gcat)})" if gcat else ""
            raise SpecError(f"{where}: unknown glass {name!r}{cats}: not in lensopt's catalogs; give its AGF "
                            "catalog with --catalog FILE.agf", path=src) from None
    found = candidates[0]
    if nd_file is not None and (nd_file, vd_file) == (1.5, 40.0):
        nd_file = None  # what older Zemax versions write for a catalog glass: a placeholder, not data
    if nd_file is not None and len(candidates) > 1 and min(abs(g.nd - nd_file) for g in candidates) <= 1e-3:
        # A name in several catalogs (F2: Schott and Hikari): the GLAS line's nd/vd pick the one meant.
        found = min(candidates, key=lambda g: abs(g.nd - nd_file) + abs(g.vd - (vd_file or g.vd)) / 100)
    ex = extra.get("material")
    if isinstance(ex, str):
        try:
            if find_glass(ex) == found:
                return ex
        except LensoptError:
            pass
    if nd_file is not None and abs(nd_file - found.nd) > 1e-3:
            warnings.append(f"surface {s.number}: glass {name} resolved to {found.label} with nd {found.nd:.5f}; the "
                            f"file says nd {nd_file:.5f}")
    return f"{found.vendor}:{found.name}"


def _file_nd_vd(glass: list[str]) -> tuple[float | None, float | None]:
    """nd and vd from a GLAS line (``GLAS name a b nd vd …``), None where absent or not a real index."""
    try:
        nd = float(glass[3])
        vd = float(glass[4]) if len(glass) > 4 else None
    except (IndexError, ValueError):
        return None, None
    return (nd, vd) if nd > 1.0 else (None, None)


def range_warnings(spec: Any, warnings: list[str]) -> None:
    """One warning per AGF glass used outside its catalog wavelength range."""
    from lensopt.spec.build import resolve_material

    wl_um = [w * 1e-3 for w in spec.spectrum.wavelengths_nm]
    seen: set[str] = set()
    for i, surf in enumerate(spec.surfaces):
        if isinstance(surf.material, str) or not hasattr(surf.material, "catalog"):
            continue
        mat = resolve_material(surf.material, path=f"surfaces[{i}].material")
        if not isinstance(mat, AgfGlass) or normalize_name(mat.label) in seen:
            continue
        seen.add(normalize_name(mat.label))
        outside = mat.outside_range(wl_um)
        if outside:
            lo, hi = mat.valid_range_um
            warnings.append(f"glass {mat.label}: wavelength(s) {', '.join(f'{w * 1e3:g}' for w in outside)} nm outside "
                            f"its catalog range {lo * 1e3:g}–{hi * 1e3:g} nm (the formula is extrapolated)")
