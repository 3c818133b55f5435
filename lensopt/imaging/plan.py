"""The scene plan: decide what a simulation has to compute before computing it.

From the image (size, channels), the region it covers on the sensor and a cheap pilot trace, the plan
chooses: the fields that the region covers (a centre crop traces no corner field), the channels the
image has (grayscale: one channel, spectrum summed), the wavelengths those channels weigh, whether
diffraction matters (Airy radius against the pixel and the geometric blur), whether to convolve at
all (not when the whole PSF stays within a pixel), the PSF grid density (from how fast the blur
changes across the region and how much a cell's PSF would need to rotate), and the optional effects
(distortion, relative illumination, noise) with the reason for each decision.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from lensopt.errors import LensoptError
from lensopt.imaging.pilot import Pilot
from lensopt.imaging.rgb import RULE as RGB_RULE
from lensopt.imaging.rgb import rgb_weights_from_spectrum
from lensopt.imaging.scene import Region, Sensor

__all__ = ["Effects", "PlanOptions", "ScenePlan", "parse_effects", "make_plan", "channel_weights", "lens_colour",
           "EFFECT_NAMES"]

EFFECT_NAMES = ("convolution", "diffraction", "distortion", "relative_illumination", "noise")
_ALIASES = {"ri": "relative_illumination", "vignetting": "relative_illumination", "blur": "convolution",
            "psf": "convolution"}


@dataclass(frozen=True)
class Effects:
    """Forced effect switches from ``--effects``: None = let the plan decide."""

    forced: dict[str, bool] = field(default_factory=dict)
    noise_sigma: float | None = None


def parse_effects(text: str | None, *, option: str = "--effects") -> Effects:
    """``name``/``+name`` forces on, ``-name`` off, ``name=on|off``, ``noise=σ`` (fraction of max)."""
    forced: dict[str, bool] = {}
    sigma = None
    for raw in (text or "").split(","):
        item = raw.strip().lower()
        if not item:
            continue
        value: bool | None = True
        if item.startswith(("+", "-")):
            value, item = item[0] == "+", item[1:]
        elif "=" in item:
            item, v = item.split("=", 1)
            if v in ("on", "true", "yes"):
                value = True
            elif v in ("off", "false", "no"):
                value = False
            elif item == "noise":
                try:
                    sigma = float(v)
                except ValueError:
                    raise LensoptError("noise=σ needs a number", path=option, got=raw) from None
                if not 0 <= sigma < 1:
                    raise LensoptError("noise σ is a fraction of the maximum, in [0, 1)", path=option, got=raw)
                value = sigma > 0
            else:
                raise LensoptError("expected name=on|off", path=option, got=raw)
        name = _ALIASES.get(item, item)
        if name not in EFFECT_NAMES:
            raise LensoptError(f"unknown effect; known: {', '.join(EFFECT_NAMES)}", path=option, got=raw)
        forced[name] = bool(value)
    if forced.get("noise") and sigma is None:
        sigma = 0.005  # seed S3.3.1: 0.5 % of the maximum
    return Effects(forced, sigma)


@dataclass(frozen=True)
class PlanOptions:
    """Knobs of the plan (CLI options map onto these)."""

    sampling: str = "rings:32"
    kernel: str = "triangular"
    support: int = 2
    oversample: int = 1
    grid: tuple[int, int] | None = None  # forced (W_g, H_g)
    fields: int | None = None  # forced number of traced fields
    overlap: float = 0.25
    seed: int = 0
    passthrough_px: float = 0.3  # RMS blur below this (image pixels): no convolution
    change_tol: float = 0.1  # relative blur change allowed between neighbouring PSF cells
    change_tol_px: float = 0.25  # ... or this many pixels, whichever is larger
    max_grid: int = 16
    max_fields: int = 32


@dataclass
class ScenePlan:
    """Everything the simulation will do, as plain data (``as_json``)."""

    lens: str
    image: dict[str, Any]
    sensor: dict[str, Any]
    region: dict[str, Any]
    pixel_um: float
    channels: list[str]
    channel_weights: list[list[float]]  # (n_w used) × C
    wavelengths_nm: list[float]
    wavelength_index: list[int]
    fields_relative: list[float]
    fields_deg: list[float]
    field_radius_mm: list[float]
    radius_range_mm: tuple[float, float]
    psf_grid: tuple[int, int] | None
    overlap: float
    psf: dict[str, Any]
    diffraction: dict[str, Any]
    effects: dict[str, dict[str, Any]]
    blur_px: dict[str, float]
    notes: list[str]

    def as_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["psf_grid"] = list(self.psf_grid) if self.psf_grid else None
        d["radius_range_mm"] = list(self.radius_range_mm)
        return d


def channel_weights(spectrum: Any, channels: int, wavelengths_nm: list[float]) -> tuple[np.ndarray, list[str], str]:
    """W_w (n_w × C) for an image with ``channels`` channels and where it came from."""
    if channels == 1:
        w = np.asarray(spectrum.weights_or_uniform, dtype=np.float64)
        return (w / w.sum())[:, None], ["Y"], "spectrum weights summed into one channel"
    if spectrum.rgb_weights is not None:
        return np.asarray(spectrum.rgb_weights, dtype=np.float64), ["R", "G", "B"], "spectrum.rgb_weights"
    if len(wavelengths_nm) == 3:
        order = np.argsort(wavelengths_nm)[::-1]  # longest → R, middle → G, shortest → B
        w = np.zeros((3, 3))
        for col, row in enumerate(order):
            w[row, col] = 1.0
        return w, ["R", "G", "B"], "no spectrum.rgb_weights: the 3 wavelengths taken as R, G, B (longest first)"
    w = rgb_weights_from_spectrum(wavelengths_nm, spectrum.weights_or_uniform, path="spectrum")
    return w, ["R", "G", "B"], f"no spectrum.rgb_weights: {RGB_RULE}"


def lens_colour(spectrum: Any) -> tuple[np.ndarray, list[str], str]:
    """The colour model of a lens, one for every command: W_w (n_w × 3), the channel names (R, G, B) and
    where the weights came from — ``spectrum.rgb_weights``, else 3 wavelengths taken as R, G, B, else the
    seed's split of the spectrum (S4.1.2, ``imaging.rgb``). Training, rendering, simulation of colour
    images, evaluation, restoration and tolerancing all image in these channels."""
    return channel_weights(spectrum, 3, list(spectrum.wavelengths_nm))


def make_plan(
    *,
    lens_name: str,
    spectrum: Any,
    sensor: Sensor,
    region: Region,
    image: dict[str, Any],
    pilot: Pilot,
    effects: Effects,
    options: PlanOptions,
    notes: list[str] | None = None,
) -> ScenePlan:
    """Decide what to simulate (see the module doc); pure decisions on the pilot's numbers."""
    notes = list(notes or [])
    wl_all = list(spectrum.wavelengths_nm)
    ww, names, source = channel_weights(spectrum, image["channels"], wl_all)
    used = [i for i in range(len(wl_all)) if ww[i].sum() > 0]
    notes.append(f"channel weights: {source}")
    px_x, px_y = region.pixel_mm(sensor)
    px = 0.5 * (px_x + px_y)
    r_lo, r_hi = region.radius_range_mm(sensor)
    h_max = float(np.max(np.abs(pilot.height)))
    if r_hi > h_max * (1 + 1e-6):
        notes.append(f"the region reaches {r_hi:.3f} mm from the axis, beyond the lens's full field "
                     f"({h_max:.3f} mm): the full-field PSF is used there")
    u_lo, u_hi = float(pilot.u_of_radius(r_lo)), float(pilot.u_of_radius(r_hi))
    inside = (pilot.u >= u_lo) & (pilot.u <= u_hi)
    u_chk = np.unique(np.concatenate([[u_lo, u_hi], pilot.u[inside]]))
    lam_max_mm = max(wl_all[i] for i in used) * 1e-6
    wn = pilot.working_fnumber
    r1 = 1.22 * lam_max_mm * abs(wn)
    geo = pilot.at("rms", u_chk)
    forced = effects.forced
    diff_on, diff_reason = _diffraction_decision(forced, r1, px, geo)
    airy_rms = 0.6 * lam_max_mm * abs(wn) if diff_on else 0.0
    blur = np.sqrt(geo**2 + airy_rms**2) / px  # RMS blur, image pixels
    blur_max = float(blur.max())
    conv_on, conv_reason = _convolution_decision(forced, blur_max, options.passthrough_px)

    grid, fields_u = None, np.array([])
    if conv_on:
        grid, fields_u, why = _grid_and_fields(pilot, region, sensor, u_lo, u_hi, r_lo, r_hi, px, airy_rms, options)
        notes.append(why)
    r_fields = pilot.at("height", fields_u) if fields_u.size else np.array([])

    # Optional effects beyond the seed: off unless asked.
    disp = np.abs(pilot.at("height", u_chk) - pilot.at("paraxial", u_chk)) / px
    ri = pilot.at("ri", u_chk)
    eff: dict[str, dict[str, Any]] = {
        "convolution": {"on": conv_on, "reason": conv_reason},
        "diffraction": {"on": diff_on and conv_on, "reason": diff_reason if conv_on else "no convolution"},
        "distortion": _optional(forced, "distortion",
                                f"real vs paraxial image height differ by up to {disp.max():.2f} px in the region"),
        "relative_illumination": _optional(forced, "relative_illumination",
                                           f"relative illumination (all rays) down to {ri.min():.3f} in the "
                                           "region"),
        "noise": _optional(forced, "noise", "additive Gaussian noise, seeded"),
    }
    if eff["noise"]["on"]:
        eff["noise"]["sigma"] = effects.noise_sigma if effects.noise_sigma is not None else 0.005
        eff["noise"]["seed"] = options.seed
    pitch_psf = min(sensor.pitch_mm, px)
    return ScenePlan(
        lens=lens_name,
        image=image,
        sensor={"pixel_pitch_um": round(sensor.pitch_mm * 1e3, 9),  # 7.2, not 7.200000000000001
                "resolution": [sensor.width, sensor.height]},
        region=region.as_dict(),
        pixel_um=px * 1e3,
        channels=names,
        channel_weights=[[float(v) for v in ww[i]] for i in used],
        wavelengths_nm=[wl_all[i] for i in used],
        wavelength_index=used,
        fields_relative=[float(v) for v in fields_u],
        fields_deg=[float(v) for v in pilot.at("field_deg", fields_u)] if fields_u.size else [],
        field_radius_mm=[float(v) for v in r_fields],
        radius_range_mm=(r_lo, r_hi),
        psf_grid=grid,
        overlap=options.overlap,
        psf={"sampling": options.sampling, "kernel": options.kernel, "support_bins": options.support,
             "pitch_um": pitch_psf * 1e3, "oversample": options.oversample,
             "resize_to_pixel": abs(pitch_psf - px) > 1e-9 * px, "working_fnumber": wn,
             "airy_radius_um": r1 * 1e3},
        diffraction={"on": eff["diffraction"]["on"], "reason": eff["diffraction"]["reason"]},
        effects=eff,
        blur_px={"max_rms": blur_max, "min_rms": float(blur.min())},
        notes=notes,
    )


def _diffraction_decision(forced: dict[str, bool], r1: float, px: float, geo: np.ndarray) -> tuple[bool, str]:
    """Whether to apply diffraction, and why: the Airy radius ``r1`` (mm) against a pixel ``px`` (mm) and
    against the geometric RMS blur ``geo`` (mm) in the region (unless ``--effects`` forces it)."""
    if "diffraction" in forced:
        return forced["diffraction"], "forced by --effects"
    if r1 < 0.5 * px:
        return False, f"Airy radius {r1 * 1e3:.2f} µm < half a pixel ({px * 1e3:.2f} µm)"
    if float(geo.min()) > 4.0 * r1:
        return False, (f"geometric RMS blur ≥ {geo.min() * 1e3:.1f} µm everywhere in the region, "
                       f"> 4 × Airy radius {r1 * 1e3:.2f} µm")
    return True, (f"Airy radius {r1 * 1e3:.2f} µm = {r1 / px:.2f} px, geometric RMS blur "
                  f"down to {geo.min() * 1e3:.2f} µm")


def _convolution_decision(forced: dict[str, bool], blur_max: float, passthrough_px: float) -> tuple[bool, str]:
    """Whether to convolve at all, and why: the largest RMS blur (image pixels) against the pass-through
    limit (unless ``--effects`` forces it)."""
    if "convolution" in forced:
        return forced["convolution"], "forced by --effects"
    if blur_max < passthrough_px:
        return False, (f"pass-through: the PSF stays within a pixel (largest RMS blur "
                       f"{blur_max:.3f} px < {passthrough_px} px)")
    return True, f"RMS blur up to {blur_max:.2f} px"


def _optional(forced: dict[str, bool], name: str, what: str) -> dict[str, Any]:
    if name in forced:
        return {"on": forced[name], "reason": f"forced by --effects; {what}"}
    return {"on": False, "reason": f"not requested (--effects +{name}); {what}"}


def _grid_and_fields(
    pilot: Pilot, region: Region, sensor: Sensor, u_lo: float, u_hi: float, r_lo: float, r_hi: float, px: float,
    airy_rms: float, opt: PlanOptions,
) -> tuple[tuple[int, int], np.ndarray, str]:
    """PSF grid (W_g, H_g) and traced fields from how fast the blur changes across the region."""
    u = np.linspace(u_lo, u_hi, 65) if u_hi > u_lo else np.array([u_lo])
    r = pilot.at("height", u)
    blur = np.sqrt(pilot.at("rms", u) ** 2 + airy_rms**2) / px
    asym = np.abs(pilot.at("sigma_y", u) - pilot.at("sigma_x", u)) / px
    asym = np.where(asym > 0.05 * blur + 0.05, asym, 0.0)  # below: sampling noise of the pilot, not shape
    # Radial step (image pixels) over which the blur changes by the tolerance.
    if u.size > 1 and (r[-1] - r[0]) > 0:
        slope = np.abs(np.gradient(blur, r / px))
        tol = np.maximum(opt.change_tol * blur, opt.change_tol_px)
        step_change = float(np.min(tol / np.maximum(slope, 1e-12)))
    else:
        step_change = math.inf
    # A cell spans an azimuth of about size / r: keep the rotation error (asymmetry × angle) ≤ 0.5 px.
    with np.errstate(divide="ignore"):
        step_rot = float(np.min(np.where(asym > 0, 0.5 * (r / px) / np.maximum(asym, 1e-12), np.inf)))
    cell = min(step_change, step_rot)
    if opt.grid is not None:
        gw, gh = opt.grid
        why = f"PSF grid {gw}×{gh} forced"
    else:
        gw = int(min(max(1, math.ceil(region.image_w / cell)), opt.max_grid)) if math.isfinite(cell) else 1
        gh = int(min(max(1, math.ceil(region.image_h / cell)), opt.max_grid)) if math.isfinite(cell) else 1
        why = (f"PSF grid {gw}×{gh}: cells ≤ {cell:.0f} px (blur changes ≤ max({opt.change_tol:.0%}, "
               f"{opt.change_tol_px} px) per {step_change:.0f} px; rotation limit {step_rot:.0f} px)")
    span_px = (r_hi - r_lo) / px
    if opt.fields is not None:
        nf = opt.fields
    elif not math.isfinite(step_change) or span_px <= 0:
        nf = 1
    else:
        nf = int(min(max(1, math.ceil(span_px / step_change) + 1), opt.max_fields))
    if nf == 1:
        fields = np.array([float(pilot.u_of_radius(0.5 * (r_lo + r_hi)))])
    else:
        fields = np.asarray(pilot.u_of_radius(np.linspace(r_lo, r_hi, nf)), dtype=np.float64)
    return (gw, gh), np.unique(np.round(fields, 9)), why
