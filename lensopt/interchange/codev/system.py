"""System data of an imported CODE V file: aperture, fields, vignetting, spectrum (see ``codev.read``)."""

from __future__ import annotations

import math
from typing import Any

from lensopt.errors import SpecError
from lensopt.interchange.codev.syntax import Command
from lensopt.optics.paraxial import first_order
from lensopt.spec.build import build
from lensopt.spec.io import parse_spec
from lensopt.spec.models import LensSpec

__all__ = ["system_from_codev"]

_FIELD_KINDS = {"YAN": "angle", "YOB": "object", "YIM": "image"}
#: Relative agreement required before the exact field values of lensopt's comments replace the file's.
_EXTRAS_FIELD_TOLERANCE = 1e-12


def system_from_codev(name: str, system: dict[str, tuple[Command, list[float]]], scale: float,
                      object_distance: float | None, surfaces: list[dict[str, Any]], defocus: float,
                      extras: dict[str, Any], warnings: list[str], *, source: str) -> LensSpec:
    """Assemble and validate the lens spec from the parsed system commands and surfaces."""

    def err(key: str, message: str) -> SpecError:
        cmd = system[key][0] if key in system else None
        where = f"line {cmd.line} ({key}): " if cmd is not None else f"{key}: "
        return SpecError(where + message, path=source)

    spectrum = _spectrum(system, err)
    obj: Any = "infinity" if object_distance is None else {"distance": object_distance}
    aim = extras.get("aim") if extras.get("aim") in ("none", "chief", "full") else "chief"
    data: dict[str, Any] = {
        "name": name,
        "system": {"aperture": {"epd": 1.0}, "field": {"hfov_deg": 1.0, "relative": [0.0]}, "object": obj,
                   "aim": aim},
        "spectrum": spectrum,
        "surfaces": surfaces,
        "image": {"defocus": defocus},
    }
    if isinstance(extras.get("aim_steps"), int):
        data["system"]["aim_steps"] = extras["aim_steps"]
    if isinstance(extras.get("front_aperture"), dict):
        data["system"]["front_aperture"] = extras["front_aperture"]
    if isinstance(extras.get("sensor"), dict):
        data["sensor"] = extras["sensor"]
    if isinstance(extras.get("rgb_weights"), list):
        data["spectrum"]["rgb_weights"] = extras["rgb_weights"]
    provisional = parse_spec(data)  # validates surfaces and spectrum, names bad fields
    kind, values = _field_values(system, err, warnings)
    if kind != "angle":
        values = [v * scale for v in values]  # object and image heights are lengths (DIM)
    needs_paraxial = kind == "object" or any(k in system for k in ("NA", "NAO")) or (
        "FNO" in system and object_distance is not None) or isinstance(extras.get("aperture"), dict)
    fo, n_image = _paraxial(provisional) if needs_paraxial else (None, 1.0)
    data["system"]["field"] = _field(kind, values, system, extras, fo, object_distance, err)
    data["system"]["aperture"] = _aperture(system, scale, object_distance, fo, n_image, extras, err)
    vig = _vignetting(system, len(values), err)
    if vig is not None:
        data["system"]["vignetting"] = vig
    return parse_spec(data)


def _paraxial(spec: LensSpec) -> tuple[Any, float]:
    """First-order data of the lens with EPD = 1, and the image-space index (reference wavelength)."""
    model = build(spec)
    return first_order(model.lens, model.system), float(model.lens.index[-1, model.system.reference])


def _spectrum(system: dict[str, tuple[Command, list[float]]], err: Any) -> dict[str, Any]:
    if "WL" not in system or not system["WL"][1]:
        raise err("WL", "the file gives no wavelengths (WL)")
    wl = system["WL"][1]
    out: dict[str, Any] = {"wavelengths_nm": wl}
    if "WTW" in system:
        out["weights"] = system["WTW"][1]
    if "REF" in system:
        ref = system["REF"][1]
        if not ref or ref[0] != int(ref[0]) or not 1 <= ref[0] <= len(wl):
            raise err("REF", f"reference wavelength must be a number 1…{len(wl)}")
        out["reference_nm"] = wl[int(ref[0]) - 1]
    return out


def _field_values(system: dict[str, tuple[Command, list[float]]], err: Any,
                  warnings: list[str]) -> tuple[str, list[float]]:
    for key in ("XRI", "YRI"):
        if key in system:
            raise err(key, "real-image-height fields are not supported; use YIM (paraxial) or YAN")
    kinds = [k for k in _FIELD_KINDS if k in system]
    if len(kinds) > 1:
        raise err(kinds[1], f"several field types given ({', '.join(kinds)})")
    key = kinds[0] if kinds else "YAN"
    values = system[key][1] if kinds else [0.0]
    x_key = "X" + key[1:]
    if x_key in system and any(v != 0 for v in system[x_key][1]):
        raise err(x_key, "x fields are not supported: lensopt's fields lie in the y–z plane")
    if not values:
        raise err(key, "no field values")
    if any(v < 0 for v in values):
        warnings.append(f"negative {key} fields taken as their mirror images (rotational symmetry)")
    return _FIELD_KINDS[key], [abs(v) for v in values]


def _field(kind: str, values: list[float], system: dict[str, tuple[Command, list[float]]],
           extras: dict[str, Any], fo: Any, object_distance: float | None, err: Any) -> dict[str, Any]:
    key = {"angle": "YAN", "object": "YOB", "image": "YIM"}[kind]
    out: dict[str, Any] = {}
    if kind == "object":
        if object_distance is None or fo is None:
            raise err("YOB", "object-height fields need a finite object distance (SO)")
        # CODE V: the chief ray of an object point at height h aims at the paraxial entrance pupil;
        # lensopt's angle field launches exactly that ray, with tan θ = h / (d + z_EP).
        reach = object_distance + float(fo.entrance_pupil_z)
        values = [math.degrees(math.atan(v / reach)) for v in values]
        kind = "angle"
    top = max(values)
    relative = [v / top for v in values] if top > 0 else [0.0 for _ in values]
    ext = extras.get("field")
    if key != "YOB" and isinstance(ext, dict) and _field_extras_agree(ext, values):
        top, relative = float(ext["max"]), [float(u) for u in ext["relative"]]
    elif top == 0:
        top = 1.0  # on-axis only: any positive maximum; relative fields are all 0
    out["hfov_deg" if kind == "angle" else "image_height"] = top
    out["relative"] = relative
    if "WTF" in system:
        weights = system["WTF"][1]
        if len(weights) != len(values):
            raise err("WTF", f"needs one weight per field ({len(values)})")
        out["weights"] = weights
    return out


def _field_extras_agree(ext: dict[str, Any], values: list[float]) -> bool:
    try:
        top = float(ext["max"])
        rel = [float(u) for u in ext["relative"]]
    except (KeyError, TypeError, ValueError):
        return False
    if len(rel) != len(values) or not top > 0:
        return False
    return all(abs(u * top - v) <= _EXTRAS_FIELD_TOLERANCE * top for u, v in zip(rel, values, strict=True))


def _aperture(system: dict[str, tuple[Command, list[float]]], scale: float, object_distance: float | None,
              fo: Any, n_image: float, extras: dict[str, Any], err: Any) -> dict[str, float]:
    keys = [k for k in ("EPD", "FNO", "NA", "NAO") if k in system]
    if not keys:
        raise err("EPD", "the file gives no aperture (EPD, FNO, NA or NAO)")
    if len(keys) > 1:
        raise err(keys[1], f"several apertures given ({', '.join(keys)})")
    key = keys[0]
    values = system[key][1]
    if not values or not values[0] > 0:
        raise err(key, "must be one positive number")
    v = values[0]
    if key == "EPD":
        return _fnumber_from_extras(v * scale, extras, fo)
    if key == "FNO" and object_distance is None:
        return {"fnumber": v}  # infinite object: CODE V's FNO is EFL/EPD, lensopt's fnumber
    if key == "NAO":
        if object_distance is None:
            raise err(key, "NAO needs a finite object distance (SO)")
        if v >= 1:
            raise err(key, "NAO must be below 1 (object space is air)")
        slope = math.tan(math.asin(v))
        return {"epd": 2.0 * slope * (object_distance + float(fo.entrance_pupil_z))}
    # Image-space aperture: the paraxial marginal slope u' is linear in the EPD; fo was computed
    # with EPD = 1, so EPD = u'_wanted / u'_1 with u'_1 = 1 / (2 working f-number).
    slope_1 = 1.0 / (2.0 * float(fo.working_fnumber))
    if key == "FNO":
        slope = 1.0 / (2.0 * v)
    else:
        if v >= n_image:
            raise err(key, "NA must be below the image-space index")
        slope = math.tan(math.asin(v / n_image))
    return {"epd": slope / slope_1}


def _fnumber_from_extras(epd: float, extras: dict[str, Any], fo: Any) -> dict[str, float]:
    """lensopt's f-number (from the comments) where the file's EPD is the one it implies."""
    ext = extras.get("aperture")
    fnumber = ext.get("fnumber") if isinstance(ext, dict) else None
    if isinstance(fnumber, int | float) and fnumber > 0 and fo is not None:
        implied = abs(float(fo.efl)) / fnumber
        if abs(implied - epd) <= _EXTRAS_FIELD_TOLERANCE * epd:
            return {"fnumber": float(fnumber)}
    return {"epd": epd}


def _vignetting(system: dict[str, tuple[Command, list[float]]], n: int, err: Any) -> dict[str, list[float]] | None:
    keys = ("VUY", "VLY", "VUX", "VLX")
    if not any(k in system for k in keys):
        return None
    got = {}
    for k in keys:
        vals = system[k][1] if k in system else [0.0] * n
        if len(vals) != n:
            raise err(k, f"needs one factor per field ({n})")
        got[k] = vals
    if any(abs(a - b) > 0 for a, b in zip(got["VUX"], got["VLX"], strict=True)) and "VLX" in system \
            and "VUX" in system:
        raise err("VLX", "VUX and VLX differ; lensopt's lateral vignetting factor is symmetric")
    lateral = got["VUX"] if "VUX" in system else got["VLX"]
    return {"inferior": got["VLY"], "superior": got["VUY"], "lateral": lateral}
