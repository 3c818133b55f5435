"""System data of an imported Zemax file: aperture, fields, vignetting, spectrum (see ``zemax.read``).

Zemax conventions taken (OpticStudio manual, "System Explorer"):

- Aperture: ``ENPD d`` entrance pupil diameter; ``FNUM f 0`` image-space F/# (= EFL/EPD, lensopt's
  ``fnumber``); ``FNUM f 1`` paraxial working F/# 1/(2 n' |u'|); ``OBNA x 0`` object-space NA, the
  paraxial marginal slope tan(asin NA) (as rayoptics and CODE V readers do), ``OBNA x 1`` object cone
  angle in degrees; ``FLOA`` float by stop size: the EPD whose paraxial marginal ray fills the stop's
  semi-diameter (``DIAM`` of the STOP surface).
- Fields ``FTYP t …``: t = 0 angle (degrees), 1 object height, 2 paraxial image height; 3 (real image
  height), 4 (theodolite angle) and object-space telecentricity are refused. A field at (x, y) is
  taken at its radial distance (lensopt is rotationally symmetric) with a warning. An object height
  h becomes the angle atan(h / (d + z_EP)) of the chief ray to the paraxial entrance pupil, which is
  what lensopt's angle field launches for a finite object.
- Vignetting ``VDYN``/``VCYN``/``VCXN`` (decenter and compression, pupil y' = VDY + (1 − VCY) y):
  superior = VCY − VDY, inferior = VCY + VDY, lateral = VCX; ``VDXN`` and ``VANN`` are ignored with a
  warning.
- Wavelengths ``WAVM slot λ weight`` (µm) or ``WAVL``/``WWGT``; ``PWAV`` the primary (reference) one;
  ``FTYP``'s fourth number is the count in use. Duplicates are merged with a warning.
- ``RAIM`` with a non-zero aiming type → lensopt's ``aim = "chief"``; off → ``"none"``.
"""

from __future__ import annotations

import math
from typing import Any

from lensopt.errors import SpecError
from lensopt.optics.paraxial import first_order
from lensopt.spec.build import build
from lensopt.spec.io import parse_spec

__all__ = ["system_from_zemax"]

_AGREE = 1e-12


def _values(zf: Any, key: str, count: int | None) -> list[float] | None:
    items = zf.system.get(key)
    if not items:
        return None
    _line, tokens = items[-1]
    out = []
    for t in tokens[1:]:
        try:
            out.append(float(t))
        except ValueError:
            raise SpecError(f"line {_line}: {key}: expected numbers, got {t!r}", path=zf.source) from None
    return out[:count] if count is not None else out


def _ftyp(zf: Any) -> tuple[int, int, int | None, int | None]:
    item = zf.last("FTYP")
    if item is None:
        return 0, 0, None, None
    tokens = item[1]

    def at(i: int) -> int | None:
        try:
            return int(float(tokens[i]))
        except (IndexError, ValueError):
            return None

    return at(1) or 0, at(2) or 0, at(3), at(4)


def system_from_zemax(zf: Any, surfaces: list[dict[str, Any]], object_distance: float | None,
                      extras: dict[str, Any], warnings: list[str]) -> Any:
    """Assemble and validate the lens spec from the parsed file and the surfaces (mm)."""
    src = zf.source
    kind, telecentric, n_fields, n_waves = _ftyp(zf)
    if telecentric:
        raise SpecError("object-space telecentric systems (FTYP) are not supported", path=src)
    spectrum = _spectrum(zf, n_waves, warnings)
    ref_nm = spectrum["reference_nm"]
    for surf in surfaces:
        if surf.get("type") == "diffractive" and "design_wavelength_nm" not in surf:
            surf["design_wavelength_nm"] = ref_nm
    name_item = zf.last("NAME")
    name = " ".join(name_item[1][1:]).strip() if name_item else ""
    aim_item = zf.last("RAIM")
    aim = "none"
    if aim_item is not None and len(aim_item[1]) > 2 and aim_item[1][2] not in ("0", "0.0"):
        aim = "chief"
    if extras.get("aim") in ("none", "chief", "full"):
        aim = extras["aim"]
    obj: Any = "infinity" if object_distance is None else {"distance": object_distance}
    defocus = extras.get("defocus")
    if isinstance(defocus, int | float) and math.isfinite(defocus) and defocus != 0:
        surfaces[-1]["thickness"] -= defocus  # export_zemax added lensopt's image defocus to the last gap
    else:
        defocus = 0.0
    data: dict[str, Any] = {
        "name": name or "lens",
        "system": {"aperture": {"epd": 1.0}, "field": {"hfov_deg": 1.0, "relative": [0.0]}, "object": obj,
                   "aim": aim},
        "spectrum": spectrum,
        "surfaces": surfaces,
        "image": {"defocus": float(defocus)},
    }
    if getattr(zf, "elements", None):
        data["elements"] = zf.elements
    for key in ("aim_steps", "front_aperture", "sensor"):
        if key in extras:
            (data if key == "sensor" else data["system"])[key] = extras[key]
    if isinstance(extras.get("rgb_weights"), list):
        spectrum["rgb_weights"] = extras["rgb_weights"]
    provisional = parse_spec(data)
    model = build(provisional)
    fo = first_order(model.lens, model.system)
    n_image = float(model.lens.index[-1, model.system.reference])
    data["system"]["aperture"] = _aperture(zf, object_distance, fo, n_image, extras, warnings)
    data["system"]["field"], vig = _fields(zf, kind, n_fields, object_distance, fo, extras, warnings)
    if kind == 3:
        data["system"]["field"] = _real_image_height_field(data, data["system"]["field"], fo, warnings)
    if vig is not None:
        data["system"]["vignetting"] = vig
    return parse_spec(data)


def _spectrum(zf: Any, n_waves: int | None, warnings: list[str]) -> dict[str, Any]:
    src = zf.source
    slots: dict[int, tuple[float, float]] = {}
    for line, tokens in zf.system.get("WAVM", []):
        try:
            slots[int(tokens[1])] = (float(tokens[2]), float(tokens[3]) if len(tokens) > 3 else 1.0)
            if not all(math.isfinite(v) for v in slots[int(tokens[1])]):
                raise ValueError
        except (IndexError, ValueError):
            raise SpecError(f"line {line}: WAVM needs a slot number and a wavelength in µm", path=src) from None
    if not slots:
        wavl = _values(zf, "WAVL", None) or []
        weights = _values(zf, "WWGT", None) or []
        slots = {i + 1: (w, weights[i] if i < len(weights) else 1.0) for i, w in enumerate(wavl)}
    if not slots:
        raise SpecError("the file gives no wavelengths (WAVM or WAVL)", path=src)
    order = sorted(slots)
    if n_waves is not None and n_waves > 0:
        if len([k for k in order if k <= n_waves]) < n_waves:
            warnings.append(f"FTYP declares {n_waves} wavelengths but the file gives {len(order)} (truncated?)")
        order = [k for k in order if k <= n_waves]
    pw_item = zf.last("PWAV")
    try:
        primary = int(float(pw_item[1][1])) if pw_item and len(pw_item[1]) > 1 else order[0]
    except (ValueError, OverflowError):
        raise SpecError(f"line {pw_item[0]}: PWAV needs a wavelength number", path=src) from None
    if primary not in order:
        raise SpecError(f"primary wavelength PWAV {primary} is not one of the wavelengths in use", path=src)
    wl_nm: list[float] = []
    weights_out: list[float] = []
    ref_nm = _nm(slots[primary][0])
    for k in order:
        w_nm = _nm(slots[k][0])
        if not w_nm > 0:
            raise SpecError(f"wavelength {k} must be positive (got {slots[k][0]} µm)", path=src)
        if w_nm in wl_nm:
            warnings.append(f"wavelength {k} ({w_nm:g} nm) repeats an earlier one: merged (weights added)")
            weights_out[wl_nm.index(w_nm)] += slots[k][1]
            continue
        wl_nm.append(w_nm)
        weights_out.append(slots[k][1])
    exact = zf_extras_wavelengths(zf)
    if exact is not None and len(exact) == len(wl_nm) and all(
            abs(a - b) <= _AGREE * b for a, b in zip(exact, wl_nm, strict=True)):
        ref_nm = exact[wl_nm.index(ref_nm)]
        wl_nm = exact
    out: dict[str, Any] = {"wavelengths_nm": wl_nm, "reference_nm": ref_nm}
    if any(w != 1.0 for w in weights_out):
        out["weights"] = weights_out
    return out


def zf_extras_wavelengths(zf: Any) -> list[float] | None:
    """lensopt's exact wavelengths (nm) from the file's NOTE lines, if given."""
    value = getattr(zf, "extras", {}).get("wavelengths_nm")
    if isinstance(value, list) and all(isinstance(v, int | float) for v in value):
        return [float(v) for v in value]
    return None


def _fields(zf: Any, kind: int, n_fields: int | None, object_distance: float | None, fo: Any,
            extras: dict[str, Any], warnings: list[str]) -> tuple[dict[str, Any], dict[str, list[float]] | None]:
    src = zf.source
    if kind == 4:
        raise SpecError("field type FTYP 4 (theodolite angle) is not supported; use angle, object height or "
                        "(paraxial or real) image height", path=src)
    if kind not in (0, 1, 2, 3):
        raise SpecError(f"unknown field type FTYP {kind}", path=src)
    ys = _values(zf, "YFLN", n_fields) or _values(zf, "YFLD", n_fields) or [0.0]
    xs = _values(zf, "XFLN", n_fields) or _values(zf, "XFLD", n_fields) or [0.0] * len(ys)
    n = len(ys) if n_fields is None else min(n_fields, len(ys))
    if n_fields is not None and len(ys) < n_fields:
        warnings.append(f"FTYP declares {n_fields} fields but YFLN gives {len(ys)} (truncated?)")
    ys, xs = ys[:n], (xs + [0.0] * n)[:n]
    if n_fields is None:  # old files without FTYP list 12 slots: drop the unused (zero) ones at the end
        while len(ys) > 1 and ys[-1] == 0 and xs[-1] == 0:
            ys, xs = ys[:-1], xs[:-1]
        n = len(ys)
    scale = zf.scale
    if any(x != 0 for x in xs):
        warnings.append("x fields taken at their radial distance (lensopt is rotationally symmetric)")
    if kind == 0 and not any(xs):
        values = [abs(y) for y in ys]
    elif kind == 0:
        values = [math.degrees(math.atan(math.hypot(math.tan(math.radians(x)), math.tan(math.radians(y)))))
                  for x, y in zip(xs, ys, strict=True)]
    else:
        values = [math.hypot(x, y) * scale for x, y in zip(xs, ys, strict=True)]
    if any(y < 0 for y in ys):
        warnings.append("negative y fields taken as their mirror images (rotational symmetry)")
    if kind == 1:
        if object_distance is None:
            raise SpecError("object-height fields (FTYP 1) need a finite object distance", path=src)
        reach = object_distance + float(fo.entrance_pupil_z)
        values = [math.degrees(math.atan(v / reach)) for v in values]
    top = max(values)
    relative = [v / top for v in values] if top > 0 else [0.0] * len(values)
    ext = extras.get("field")
    if isinstance(ext, dict) and kind != 1:
        try:
            e_top, e_rel = float(ext["max"]), [float(u) for u in ext["relative"]]
            if len(e_rel) == len(values) and e_top > 0 and all(
                    abs(u * e_top - v) <= _AGREE * e_top for u, v in zip(e_rel, values, strict=True)):
                top, relative = e_top, e_rel
        except (KeyError, TypeError, ValueError):
            pass
    if top == 0:
        top = 1.0
    out: dict[str, Any] = {"image_height" if kind in (2, 3) else "hfov_deg": top, "relative": relative}
    weights = _values(zf, "FWGN", n)
    if weights is not None and len(weights) == n and any(w != 1.0 for w in weights):
        out["weights"] = weights
    return out, _vignetting(zf, n, warnings)


def _real_image_height_field(data: dict[str, Any], fld: dict[str, Any], fo: Any,
                             warnings: list[str]) -> dict[str, Any]:
    """Zemax's real image heights (FTYP 3) as object angles: for each height h, the angle whose real chief
    ray (aimed as the lens's ``aim`` says) lands at h on the image surface. Secant iterations on all fields
    at once (one trace per iteration), to 1e-12 relative."""
    import copy

    import torch

    from lensopt.optics.bundle import trace_bundle

    top = fld["image_height"]
    targets = [u * top for u in fld["relative"]]
    live = [i for i, h in enumerate(targets) if h > 0]

    def heights(angles: list[float]) -> list[float]:
        d = copy.deepcopy(data)
        a_max = max(angles)
        d["system"]["field"] = {"hfov_deg": a_max, "relative": [a / a_max for a in angles]}
        d["system"].pop("vignetting", None)
        model = build(parse_spec(d))
        bundle = trace_bundle(model.lens, model.system, torch.zeros(1, 2, dtype=torch.float64))
        ref = model.system.reference
        if not bool(bundle.result.valid[:, ref, 0].all()):
            raise SpecError("a real chief ray does not reach the image while solving the real image height "
                            "fields (FTYP 3)", path="FTYP")
        return bundle.result.pos[:, ref, 0, 1].abs().tolist()

    angles = [0.0] * len(targets)
    if live:
        t0 = [math.degrees(math.atan(targets[i] / abs(float(fo.efl)))) for i in live]
        t1 = [t * 1.001 for t in t0]
        y0 = [heights(_fill(angles, live, t0))[i] - targets[i] for i in live]
        y1 = [heights(_fill(angles, live, t1))[i] - targets[i] for i in live]
        for _ in range(30):
            if all(abs(e) <= 1e-12 * targets[i] for e, i in zip(y1, live, strict=True)):
                break
            step = [(e1 * (b - a) / (e1 - e0)) if e1 != e0 else 0.0
                    for a, b, e0, e1 in zip(t0, t1, y0, y1, strict=True)]
            t0, y0 = t1, y1
            t1 = [b - s for b, s in zip(t1, step, strict=True)]
            if not all(0 < t < 90 for t in t1):
                raise SpecError("could not solve the real image height fields (FTYP 3) for object angles",
                                path="FTYP")
            got = heights(_fill(angles, live, t1))
            y1 = [got[i] - targets[i] for i in live]
        if any(abs(e) > 1e-9 * max(1.0, targets[i]) for e, i in zip(y1, live, strict=True)):
            raise SpecError("could not solve the real image height fields (FTYP 3) for object angles", path="FTYP")
        angles = _fill(angles, live, t1)
    a_top = max(angles)
    warnings.append("real image height fields (FTYP 3) converted to object angles (" + ", ".join(
        f"{a:.6f}°" for a in angles) + "): the real chief rays land on the given heights")
    out = {"hfov_deg": a_top if a_top > 0 else 1.0, "relative": [a / a_top if a_top > 0 else 0.0 for a in angles]}
    if "weights" in fld:
        out["weights"] = fld["weights"]
    return out


def _fill(base: list[float], idx: list[int], values: list[float]) -> list[float]:
    out = list(base)
    for i, v in zip(idx, values, strict=True):
        out[i] = v
    return out


def _vignetting(zf: Any, n: int, warnings: list[str]) -> dict[str, list[float]] | None:
    vals = {k: (_values(zf, k, n) or []) + [0.0] * n for k in ("VDXN", "VDYN", "VCXN", "VCYN", "VANN")}
    vals = {k: v[:n] for k, v in vals.items()}
    if any(vals["VDXN"]):
        warnings.append("ignored the x vignetting decenters VDXN (lensopt's lateral factor is symmetric)")
    if any(vals["VANN"]):
        warnings.append("ignored the vignetting angles VANN")
    if not any(vals["VDYN"]) and not any(vals["VCYN"]) and not any(vals["VCXN"]):
        return None
    sup = [c - d for c, d in zip(vals["VCYN"], vals["VDYN"], strict=True)]
    inf = [c + d for c, d in zip(vals["VCYN"], vals["VDYN"], strict=True)]
    out = {"superior": sup, "inferior": inf, "lateral": vals["VCXN"]}
    exact = getattr(zf, "extras", {}).get("vignetting")
    if isinstance(exact, dict):
        try:
            if all(len(exact[k]) == n and all(abs(float(a) - b) <= 1e-12 for a, b in zip(exact[k], out[k], strict=True))
                   for k in out):
                return {k: [float(a) for a in exact[k]] for k in out}
        except (KeyError, TypeError, ValueError):
            pass
    return out


def _aperture(zf: Any, object_distance: float | None, fo: Any, n_image: float, extras: dict[str, Any],
              warnings: list[str]) -> dict[str, float]:
    src = zf.source
    scale = zf.scale
    # fo is the paraxial data for EPD = 1: every paraxial height and slope is linear in the EPD.
    if zf.last("FLOA") is not None:
        stop = next((s for s in zf.surfaces[1:-1] if s.stop), zf.surfaces[1])
        if not stop.diam:
            raise SpecError("FLOA (float by stop size) needs the stop's semi-diameter (DIAM), which the file "
                            "does not give", path=src)
        epd = stop.diam * scale / float(fo.stop_semi_diameter)
        return _fnumber_from_extras(epd, fo, extras)
    keys = [k for k in ("ENPD", "FNUM", "OBNA") if zf.last(k) is not None]
    if not keys:
        raise SpecError("the file gives no system aperture (ENPD, FNUM, OBNA or FLOA)", path=src)
    if len(keys) > 1:
        warnings.append(f"several aperture operands ({', '.join(keys)}): {keys[0]} used")
    key = keys[0]
    line, tokens = zf.last(key)
    try:
        value = float(tokens[1])
        flag = int(float(tokens[2])) if len(tokens) > 2 else 0
    except (IndexError, ValueError):
        raise SpecError(f"line {line}: {key} needs a number", path=src) from None
    if not value > 0:
        raise SpecError(f"line {line}: {key} must be positive (got {value:g})", path=src)
    if key == "ENPD":
        return _fnumber_from_extras(value * scale, fo, extras)
    if key == "FNUM" and flag == 0:
        return {"fnumber": value}
    if key == "FNUM":
        slope = 1.0 / (2.0 * value * n_image)
        return {"epd": slope * 2.0 * float(fo.working_fnumber) * n_image}
    if object_distance is None:
        raise SpecError(f"line {line}: OBNA needs a finite object distance", path=src)
    if flag == 0:
        if value >= 1:
            raise SpecError(f"line {line}: the object NA must be below 1 (object space is air)", path=src)
        slope = math.tan(math.asin(value))
    else:
        slope = math.tan(math.radians(value))
    return {"epd": 2.0 * slope * (object_distance + float(fo.entrance_pupil_z))}


def _fnumber_from_extras(epd: float, fo: Any, extras: dict[str, Any]) -> dict[str, float]:
    ext = extras.get("aperture")
    fnumber = ext.get("fnumber") if isinstance(ext, dict) else None
    if isinstance(fnumber, int | float) and fnumber > 0:
        implied = abs(float(fo.efl)) / fnumber
        if abs(implied - epd) <= _AGREE * 10 * epd:
            return {"fnumber": float(fnumber)}
    return {"epd": epd}


def _nm(um: float) -> float:
    """µm → nm, to 12 significant digits (0.58756180000000002 µm is 587.5618 nm, not 587.5618000000001)."""
    return float(f"{um * 1e3:.12g}")
