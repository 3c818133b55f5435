"""What the designer's analyses cost in time (``lensopt accuracy``, the rows after the spot/PSF/image ones).

Each knob sweeps the sampling of one analysis, the others at their defaults, on the lens's fields, and
scores every setting against the same analysis at a converged setting (the reference, also timed):

================  ===================================  ===============================================
knob              settings (reference)                 error (metric)
================  ===================================  ===============================================
wavefront         pupil grid N = 8 … 64 (160)           RMS wavefront error, relative, worst field × λ (wfe)
zernike           pupil grid N = 8 … 64 (160)           37 Fringe coefficients, max |Δc| / max |c| (zernike)
strehl            pupil samples 16 … 48 (96)            PSF Strehl ratio, absolute (strehl)
seidel            — (closed form)                       none: paraxial, no sampling; time only (seidel)
field_curves      differential rays δ = 1e-2 … 1e-4     T and S focus, max |Δ| / max |focus| (field)
                  (1e-5)
focal_shift       5 … 41 wavelengths (401)             the interpolated curve, max |Δ| / range (focal)
encircled         rings:8 … 64 (rings:128)              radius of 80 % encircled energy, relative (ee)
encircled_diffr.  pupil N = 32 … 64 (96, pitch /24)     diffraction EE on axis, absolute (ee)
mtf_field         rings:8 … 64 (rings:128)              heuristic MTF at 3 frequencies × 11 fields (mtf)
through_focus     rings:8 … 32 (rings:96)               the same at 5 focus positions (mtf)
================  ===================================  ===============================================
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch

from lensopt.engine import Engine
from lensopt.qa.measure import Point, timed
from lensopt.spec.build import Model

__all__ = ["ANALYSIS_KNOBS", "ANALYSIS_METRICS", "ANALYSIS_ERRORS", "analysis_points"]

ANALYSIS_KNOBS = {"wavefront": "wfe", "zernike": "zernike", "strehl": "strehl", "seidel": "seidel",
                  "field_curves": "field", "focal_shift": "focal", "encircled": "ee",
                  "encircled_diffraction": "ee", "mtf_field": "mtf", "through_focus": "mtf"}
ANALYSIS_METRICS = {"wfe": "RMS wavefront error, relative", "zernike": "Zernike coefficients, max |Δc|/max |c|",
                    "strehl": "Strehl ratio, absolute", "seidel": "Seidel sums (closed form)",
                    "field": "field curvature, relative", "focal": "focal shift curve, relative",
                    "ee": "encircled energy (r80 relative / EE absolute)", "mtf": "MTF, absolute"}

ANALYSIS_ERRORS = {
    "wavefront": "RMS wavefront error, relative, worst field × λ",
    "zernike": "37 Fringe coefficients, max |Δc|/max |c|",
    "strehl": "PSF Strehl ratio, absolute",
    "seidel": "none: closed form, no sampling",
    "field_curves": "T and S focus, max |Δ|/max |focus|",
    "focal_shift": "focal shift curve, max |Δ|/range",
    "encircled": "radius of 80 % encircled energy, relative",
    "encircled_diffraction": "diffraction EE on axis, absolute",
    "mtf_field": "MTF, 3 frequencies × 11 fields, absolute",
    "through_focus": "MTF, 5 focus positions × fields, absolute",
}
"""What each knob's error measures (the table of the module doc; the column ``lensopt accuracy`` prints)."""


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(float(np.max(np.abs(b))), 1e-300))


Knob = tuple[list[tuple[str, Any]], Callable[..., np.ndarray], Any, Callable[..., float]]
"""(label and value of each setting, the function of a setting, the reference setting, error)."""


def _note(metric: str, err: float) -> str:
    return f"{ANALYSIS_METRICS[metric]}: {err:.2e}"


def knob_table(model: Model, *, engine: Engine | None = None) -> dict[str, Knob]:
    """knob → (label and value of each setting, the function of a setting, the reference setting, error of
    a setting's result against the reference's) for ``model``; every trace on ``engine``."""
    from lensopt.analysis.encircled import diffraction_energy, geometric_energy
    from lensopt.analysis.field_curves import chromatic_focal_shift, field_curves
    from lensopt.analysis.mtf_field import mtf_vs_field, through_focus_mtf
    from lensopt.analysis.seidel import seidel_sums
    from lensopt.analysis.strehl import strehl
    from lensopt.analysis.wavefront import map_grid, wavefront, wavefront_stats
    from lensopt.analysis.zernike import fit_zernike
    from lensopt.optics.paraxial import first_order

    lens, system = model.lens, model.system
    rel = torch.tensor(system.rel_field, dtype=lens.dtype)
    fo = first_order(lens, system)
    cutoff = 1.0 / (float(lens.wavelength_um.min()) * 1e-3 * abs(float(fo.working_fnumber)))
    nus = [cutoff / 10, cutoff / 4, cutoff / 2]

    def grid_wavefront(n: int):
        pts, inside = map_grid(n, dtype=lens.dtype)
        return wavefront(lens, system, pts[inside], rel_field=rel, fo=fo, engine=engine)

    def wfe(n: int) -> np.ndarray:
        return wavefront_stats(grid_wavefront(n)).rms.numpy()

    def zern(n: int) -> np.ndarray:
        wf = grid_wavefront(n)
        return fit_zernike(wf.pupil, wf.opd, wf.valid, ordering="fringe", terms=37).coefficients.numpy()

    def r80(sampling: str) -> np.ndarray:
        e = geometric_energy(lens, system, rel_field=rel, sampling=sampling, engine=engine)
        r = e.radius_mm.numpy()
        return np.array([np.interp(0.8, c, r) for c in e.encircled.numpy()])

    axis = torch.zeros(1, dtype=lens.dtype)

    def ee_diffraction(n: int, fine: bool = False) -> np.ndarray:
        airy = 1.22 * float(lens.wavelength_um[system.reference]) * 1e-3 * abs(float(fo.working_fnumber))
        radii = torch.linspace(0.0, 6.0 * airy, 25, dtype=lens.dtype)
        return diffraction_energy(lens, system, rel_field=axis, radii=radii, pupil_samples=n,
                                  pitch_mm=airy / (24 if fine else 12), engine=engine).encircled.numpy()

    focus = torch.linspace(-4.0, 4.0, 5, dtype=lens.dtype) * 2.0 * float(lens.wavelength_um[system.reference]) \
        * 1e-3 * float(fo.working_fnumber) ** 2

    def tf(sampling: str) -> np.ndarray:
        r = through_focus_mtf(lens, system, nus, focus_mm=focus, rel_field=rel, sampling=sampling, engine=engine)
        return np.stack([r.sagittal.numpy(), r.tangential.numpy()])

    def mtf(sampling: str) -> np.ndarray:
        r = mtf_vs_field(lens, system, nus, fields=11, sampling=sampling, engine=engine)
        return np.stack([r.sagittal.numpy(), r.tangential.numpy()])

    def field(delta: float) -> np.ndarray:
        c = field_curves(lens, system, rel, delta=delta, engine=engine)
        return np.stack([c.tangential_mm.numpy(), c.sagittal_mm.numpy()])

    def focal(samples: int) -> np.ndarray:
        s = chromatic_focal_shift(lens, system, media=model.media, samples=samples)
        dense = torch.linspace(float(s.wavelength_um.min()), float(s.wavelength_um.max()), 401)
        return np.interp(dense.numpy(), s.wavelength_um.numpy(), s.shift_mm.numpy())

    return {
        "wavefront": ([(f"pupil grid {n}", n) for n in (8, 16, 32, 64)], wfe, 160, _rel),
        "zernike": ([(f"pupil grid {n}, Fringe 37", n) for n in (8, 16, 32, 64)], zern, 160, _rel),
        "strehl": ([(f"pupil samples {n}", n) for n in (16, 32, 48)],
                   lambda n: strehl(lens, system, rel_field=rel, pupil_samples=n, engine=engine).psf.numpy(), 96,
                   lambda a, b: float(np.max(np.abs(a - b)))),
        "seidel": ([("paraxial sums", None)], lambda _: seidel_sums(lens, system).total.numpy(), None,
                   lambda a, b: 0.0),
        "field_curves": ([(f"δ = {d:g}", d) for d in (1e-2, 1e-3, 1e-4)], field, 1e-5, _rel),
        "focal_shift": ([(f"{k} wavelengths", k) for k in (5, 11, 41)], focal, 401, _rel),
        "encircled": ([(f"rings:{n}", f"rings:{n}") for n in (8, 16, 32, 64)], r80, "rings:128",
                      lambda a, b: float(np.max(np.abs(a / b - 1.0)))),
        "encircled_diffraction": ([(f"pupil {n}, pitch Airy/12, axis", n) for n in (32, 48, 64)], ee_diffraction,
                                  96, lambda a, b: float(np.max(np.abs(a - b)))),
        "mtf_field": ([(f"rings:{n}, 11 fields × 3 frequencies", f"rings:{n}") for n in (8, 16, 32, 64)], mtf,
                      "rings:128", lambda a, b: float(np.max(np.abs(a - b)))),
        "through_focus": ([(f"rings:{n}, 5 focus × {len(system.rel_field)} fields", f"rings:{n}")
                           for n in (8, 16, 32)], tf, "rings:96", lambda a, b: float(np.max(np.abs(a - b)))),
    }


def analysis_points(model: Model, knobs: Sequence[str], repeats: int,
                    progress: Callable[[str], None], *,
                    engine: Engine | None = None) -> tuple[list[Point], dict[str, Any]]:
    """Points of the analysis knobs in ``knobs`` and the reference timings (see the module doc); every
    trace on ``engine`` (its memory budget; the accuracy command's engine traces eagerly)."""
    table = knob_table(model, engine=engine)
    points: list[Point] = []
    info: dict[str, Any] = {}
    for knob in knobs:
        settings, fn, ref_setting, error = table[knob]
        metric = ANALYSIS_KNOBS[knob]
        progress(f"{knob}: reference")
        t0 = time.perf_counter()
        with torch.no_grad():
            ref = fn(ref_setting) if knob != "encircled_diffraction" else fn(ref_setting, True)
        info[knob] = {"reference": str(ref_setting), "time_s": time.perf_counter() - t0}
        for label, setting in settings:
            progress(f"{knob}: {label}")

            def run(setting: Any = setting, fn: Callable[..., np.ndarray] = fn) -> np.ndarray:
                with torch.no_grad():
                    return fn(setting)

            out, t = timed(run, repeats)
            err = error(out, ref)
            note = "closed form, no sampling" if knob == "seidel" else _note(metric, err)
            points.append(Point(knob, label, {metric: err}, t, note=note))
    return points, info
