"""What accuracy costs in time, measured on one lens (``lensopt accuracy``).

Every knob that trades accuracy for time is swept alone, the others at their defaults, and each
setting is scored by the error of what the user asked for against a converged reference, and by its
wall time (median of ``repeats`` runs, compilation excluded and reported apart; every knob but ``compiled``
traces eagerly, on an engine without the compiled traces, so that no compilation lands inside a knob's
timing):

============  ==========================================  =============================================
knob          settings                                    error (against)
============  ==========================================  =============================================
rings         ``rings:N`` (jittered), N = 4 … 64          ESR and worst-field RMS spot radius, relative
rings_fixed   ``rings:N:nojitter``                        (the quadrature reference below)
grid          ``grid:N``, N = 8 … 96
gauss         ``gauss:N`` (the quadrature below as a
              sampling, with its weights), N = 4 … 24
float32       ``rings:N`` traced in float32
compiled      ``rings:N`` on the compiled trace
aim_steps     full aiming with 1 … 4 Newton steps         ESR relative to full aiming with 12 steps (on
                                                          the reference nodes: the aiming error alone)
psf_rings     PSF ``rings:N``, triangular KDE, heuristic  PSF NRMSE (RMSE / peak range) against the FFT
psf_kernel    count / triangular / cosine at ``rings:32``  diffraction PSF (exit-pupil OPD → Fourier
psf_bins      estimation bins pitch/1, /2, /3             transform), averaged over fields × wavelengths
diffraction   none / incoherent / heuristic
sim_grid      PSF grid 1×1 … 8×6 (simulation)             image RMSE (and PSNR) against a 12×9 grid,
sim_overlap   patch overlap 0 … 0.5                       36 fields, rings:48
wavefront …   the designer's analyses: wavefront, zernike, strehl, seidel, field_curves, focal_shift,
              encircled, encircled_diffraction, mtf_field, through_focus (``qa.accuracy_analyses``)
============  ==========================================  =============================================

**The spot reference** is a product quadrature over the half pupil: Gauss–Legendre in the radius
(weight r dr) × the midpoint rule in the pupil angle on (0, π) — with the mirror symmetry x → −x
that is the periodic trapezoid rule on the full circle, exponentially convergent for a smooth
integrand. Each ray carries its quadrature weight in the same ESR/RMS definitions as
``analysis.spot.spot_stats``. The node counts are doubled until two successive ESRs agree to
``REF_TOL`` (1e-9 relative); the achieved agreement is returned with the result. (Vignetting or
clipping make the integrand non-smooth: the loop then stops at its cap and says so.)
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from torch import Tensor

from lensopt.accel import on_backend
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.optics.bundle import Bundle, trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.qa.accuracy_analyses import analysis_points
from lensopt.qa.measure import Point, timed
from lensopt.spec.build import Model

__all__ = ["KNOBS", "DEFAULT_KNOBS", "Point", "AccuracyResult", "run_accuracy", "spot_reference",
           "weighted_spot", "pareto", "recommend", "parse_target", "parse_knobs"]

REF_TOL = 1e-9
SPOT_N = (4, 6, 8, 12, 16, 24, 32, 48, 64)
KNOBS = {
    "rings": "esr", "rings_fixed": "esr", "grid": "esr", "gauss": "esr", "float32": "esr", "compiled": "esr",
    "aim_steps": "aim",
    "psf_rings": "psf", "psf_kernel": "psf", "psf_bins": "psf", "diffraction": "psf",
    "sim_grid": "sim", "sim_overlap": "sim",
    "wavefront": "wfe", "zernike": "zernike", "strehl": "strehl", "seidel": "seidel", "field_curves": "field",
    "focal_shift": "focal", "encircled": "ee", "encircled_diffraction": "ee", "mtf_field": "mtf",
    "through_focus": "mtf",
}
"""Knob → the error it is scored by: ``esr`` (also RMS per field), ``aim`` (ESR error of the aiming alone),
``psf`` (NRMSE), ``sim`` (image RMSE); the analyses' metrics are in ``qa.accuracy_analyses``."""
ANALYSES = ("wavefront", "zernike", "strehl", "seidel", "field_curves", "focal_shift", "encircled",
            "encircled_diffraction", "mtf_field", "through_focus")
DEFAULT_KNOBS = ("rings", "rings_fixed", "grid", "gauss", "float32", "compiled", "aim_steps", "psf_rings", "psf_kernel",
                 "psf_bins", "diffraction", "sim_grid", "sim_overlap", *ANALYSES)
METRICS = {"esr": "ESR relative error", "rms": "worst-field RMS relative error",
           "aim": "ESR relative error of full aiming", "psf": "PSF NRMSE",
           "sim": "simulated-image RMSE", "wfe": "RMS wavefront error, relative",
           "zernike": "Zernike coefficients, max |Δc|/max |c|", "strehl": "Strehl ratio, absolute",
           "seidel": "Seidel sums (closed form)", "field": "field curvature, relative",
           "focal": "focal shift curve, relative", "ee": "encircled energy (r80 relative / EE absolute)",
           "mtf": "MTF, absolute"}


@dataclass
class AccuracyResult:
    lens: str
    points: list[Point]
    reference: dict[str, Any]
    compile_s: float | None = None
    settings: dict[str, Any] = field(default_factory=dict)

    def as_json(self, target: float, budget: float | None) -> dict[str, Any]:
        return {"lens": self.lens, "reference": self.reference, "compile_s": self.compile_s,
                "settings": self.settings, "target": target, "budget_s": budget,
                "points": [{"knob": p.knob, "setting": p.setting, "errors": p.errors, "time_s": p.time_s,
                            "note": p.note} for p in self.points],
                "pareto": {m: [_pt(p) for p in pareto(self.points, m)] for m in METRICS
                           if any(m in p.errors for p in self.points)},
                "recommendation": {m: recommend(self.points, m, target, budget) for m in METRICS
                                   if any(m in p.errors for p in self.points)}}


def _pt(p: Point) -> dict[str, Any]:
    return {"knob": p.knob, "setting": p.setting, "errors": p.errors, "time_s": p.time_s}


def parse_target(text: str | float) -> float:
    """``1%`` → 0.01; ``0.01`` → 0.01; must be > 0."""
    s = str(text).strip()
    try:
        v = float(s[:-1]) / 100.0 if s.endswith("%") else float(s)
    except ValueError:
        raise LensoptError("expected a number or a percentage like 1%", path="--target", got=text) from None
    if not (v > 0 and math.isfinite(v)):
        raise LensoptError("must be > 0", path="--target", got=text)
    return v


def parse_knobs(text: str | None) -> tuple[str, ...]:
    if text is None or text.strip() in ("", "all"):
        return DEFAULT_KNOBS
    names = tuple(k.strip() for k in text.split(",") if k.strip())
    bad = [k for k in names if k not in KNOBS]
    if bad or not names:
        raise LensoptError(f"unknown knob; one of {', '.join(KNOBS)}", path="--knobs", got=",".join(bad) or text)
    return names


# ------------------------------------------------------------------------------------------ spots


def weighted_spot(bundle: Bundle, weights: Tensor, wavelength_weights: Tensor,
                  field_weights: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """(ESR, RMS per field (F,)) of ``bundle`` with per-ray pupil weights ``weights`` (P,): the definitions
    of ``spot_stats`` (polychromatic centroid per field, x̄ = 0 on a half pupil, RMS over valid rays)
    with every ray standing for its own pupil area (equal weights give ``spot_stats`` exactly)."""
    res = bundle.result
    xy = res.pos[..., :2]
    valid = res.valid
    ww = wavelength_weights.to(xy.dtype)[None, :, None] * weights.to(xy.dtype) * valid.to(xy.dtype)
    total = ww.sum((1, 2)).clamp_min(torch.finfo(xy.dtype).tiny)
    c = (torch.where(valid.unsqueeze(-1), xy, 0.0) * ww.unsqueeze(-1)).sum((1, 2)) / total.unsqueeze(-1)
    if bundle.half_pupil:
        c = torch.stack([torch.zeros_like(c[..., 0]), c[..., 1]], -1)
    d2 = torch.where(valid, ((xy - c[:, None, None, :]) ** 2).sum(-1), 0.0)
    rms = ((ww * d2).sum((1, 2)) / total).sqrt()
    fw = torch.ones_like(rms) if field_weights is None else field_weights.to(rms.dtype)
    return ((fw * rms**2).sum() / fw.sum()).sqrt(), rms


def _quadrature(n_r: int, n_a: int) -> tuple[Tensor, Tensor]:
    """(P, 2) half-pupil nodes (px ≥ 0) and (P,) weights of Gauss–Legendre(r dr) × midpoint(ψ on (0, π))."""
    x, w = np.polynomial.legendre.leggauss(n_r)
    r = (x + 1) / 2
    wr = w / 2 * r  # ∫₀¹ f r dr
    psi = math.pi * (np.arange(n_a) + 0.5) / n_a
    rr, pp = np.meshgrid(r, psi, indexing="ij")
    pts = np.stack([rr * np.sin(pp), rr * np.cos(pp)], -1).reshape(-1, 2)
    wts = np.repeat(wr, n_a) * (math.pi / n_a)
    return torch.from_numpy(pts), torch.from_numpy(wts)


def _field_weights(model: Model) -> Tensor | None:
    sw = model.system.field_weights
    return torch.tensor(sw, dtype=torch.float64) if sw else None


def spot_reference(model: Model, *, aim: str | None = None, aim_steps: int | None = None, start: int = 16,
                   cap: int = 256, engine: Engine | None = None) -> dict[str, Any]:
    """ESR and RMS per field by the doubling quadrature (see the module doc); {esr_um, rms_um, nodes,
    agreement (relative change of the ESR at the last doubling), converged}."""
    lens, system = model.lens, model.system
    fw = _field_weights(model)
    prev = None
    n = start
    with torch.no_grad():
        while True:
            pts, wts = _quadrature(n, 2 * n)
            b = trace_bundle(lens, system, pts.to(lens.dtype), half_pupil=True, aim=aim, aim_steps=aim_steps,
                             engine=engine)
            esr, rms = weighted_spot(b, wts, system.wavelength_weights, fw)
            if prev is not None:
                agree = abs(float(esr) - prev[0]) / abs(float(esr))
                if agree <= REF_TOL or 2 * n > cap:
                    return {"esr_um": 1e3 * float(esr), "rms_um": [1e3 * float(v) for v in rms],
                            "nodes": f"Gauss-Legendre {n} radii x midpoint {2 * n} angles (half pupil)",
                            "agreement": agree, "converged": agree <= REF_TOL,
                            "failed_rays": int((~b.result.valid).sum())}
            prev = (float(esr), rms)
            n *= 2


def _spot_points(model: Model, knob: str, ref: dict[str, Any], repeats: int, *,
                 engine: Engine | None = None) -> list[Point]:
    lens, system = model.lens, model.system
    fw = _field_weights(model)
    ref_esr, ref_rms = ref["esr_um"] * 1e-3, np.array(ref["rms_um"]) * 1e-3
    out = []
    samplings = {"rings": [f"rings:{n}" for n in SPOT_N], "rings_fixed": [f"rings:{n}:nojitter" for n in SPOT_N],
                 "grid": [f"grid:{n}" for n in (8, 12, 16, 24, 32, 48, 64, 96)],
                 "gauss": [f"gauss:{n}" for n in (4, 6, 8, 10, 12, 16, 24)],
                 "float32": [f"rings:{n}" for n in SPOT_N], "compiled": [f"rings:{n}" for n in SPOT_N]}[knob]
    work = lens
    if knob == "float32":
        work = _cast(lens, torch.float32)
    backend = "compiled" if knob == "compiled" else "eager"
    eng = on_backend(engine, "compiled") if backend == "compiled" else engine
    for text in samplings:
        ps = PupilSampling.parse(text, weighted=True)

        def run(ps: PupilSampling = ps) -> tuple[Tensor, Tensor]:
            with torch.no_grad():
                pts = ps.points(dtype=work.dtype, engine=eng)
                wts = ps.weights(dtype=work.dtype)
                b = trace_bundle(work, system, pts, half_pupil=ps.half, engine=eng)
                return weighted_spot(b, torch.ones(pts.shape[0], dtype=work.dtype) if wts is None else wts,
                                     system.wavelength_weights.to(work.dtype), fw)

        if backend == "compiled":
            run()  # compile outside the timing
        (esr, rms), t = timed(run, repeats)
        e_esr = abs(float(esr) - ref_esr) / ref_esr
        e_rms = float(np.max(np.abs(rms.double().numpy() - ref_rms) / ref_rms))
        out.append(Point(knob, text + (" float32" if knob == "float32" else "") +
                         (" compiled" if knob == "compiled" else ""), {"esr": e_esr, "rms": e_rms}, t))
    return out


def _cast(lens: Any, dtype: torch.dtype) -> Any:
    import dataclasses

    return dataclasses.replace(lens, **{f.name: getattr(lens, f.name).to(dtype) for f in dataclasses.fields(lens)
                                        if isinstance(getattr(lens, f.name), Tensor)
                                        and getattr(lens, f.name).is_floating_point()})


def _aim_points(model: Model, repeats: int, *, engine: Engine | None = None) -> tuple[list[Point], dict[str, Any]]:
    """Full aiming with 1–4 Newton steps, traced on the reference quadrature (so that only the aiming
    error shows), against full aiming with 12 steps on the same nodes."""
    ref = spot_reference(model, aim="full", aim_steps=12, engine=engine)
    n = int(ref["nodes"].split()[1])
    pts, wts = _quadrature(n, 2 * n)
    pts = pts.to(model.lens.dtype)
    fw = _field_weights(model)
    out = []
    for steps in (1, 2, 3, 4):
        def run(steps: int = steps) -> Tensor:
            with torch.no_grad():
                b = trace_bundle(model.lens, model.system, pts, half_pupil=True, aim="full", aim_steps=steps,
                                 engine=engine)
                return weighted_spot(b, wts, model.system.wavelength_weights, fw)[0]
        esr, t = timed(run, repeats)
        out.append(Point("aim_steps", f"aim full, {steps} step(s)",
                         {"aim": abs(1e3 * float(esr) - ref["esr_um"]) / ref["esr_um"]}, t,
                         note=f"on the reference nodes; vs 12 steps ({ref['esr_um']:.4f} µm)"))
    return out, ref


# -------------------------------------------------------------------------------------------- PSFs


def _psf_points(model: Model, knobs: Sequence[str], repeats: int, pitch_um: float,
                progress: Callable[[str], None], *, engine: Engine | None = None) -> tuple[list[Point], dict[str, Any]]:
    from lensopt.analysis.psf_reference import diffraction_psf, pupil_samples_for
    from lensopt.analysis.psf_stack import PsfSettings, compute_psfs
    from lensopt.optics.paraxial import first_order

    lens, system = model.lens, model.system
    rel = torch.tensor(system.rel_field, dtype=torch.float64)
    pitch = pitch_um * 1e-3
    base = PsfSettings(sampling="rings:32", pitch_mm=pitch, diffraction="heuristic")
    # Every PSF here is traced eagerly (the ``compiled`` knob measures the backend): under ``auto`` the
    # rays of the FFT reference would otherwise trigger an in-process compilation inside some knob's timing.
    with torch.no_grad():
        size = compute_psfs(lens, system, rel, base, engine=engine).psf.shape[-1]
        size = max(size | 1, 31)
        center = compute_psfs(lens, system, rel, PsfSettings(sampling="rings:64", pitch_mm=pitch, size=size),
                              engine=engine).center
        progress("FFT reference PSF")
        t0 = time.perf_counter()
        # One field at a time: the OPD trace of every pupil sample × wavelength of all fields at once can
        # exceed the memory budget (12 wavelengths × 5 fields of the C-mount lens: 9 M recorded rays).
        def fft(n: int | None) -> Tensor:
            return torch.cat([diffraction_psf(lens, system, rel[f:f + 1], center[f:f + 1], pitch_mm=pitch, size=size,
                                              subsamples=3, pupil_samples=n,
                                              engine=engine) for f in range(rel.shape[0])])

        ref = fft(None)
        t_ref = time.perf_counter() - t0
        n = pupil_samples_for((size // 2 + 0.5) * pitch, float(lens.wavelength_um.min()),
                              float(first_order(lens, system).working_fnumber))
        ref_half = fft(n // 2)
    span = ref.amax((-1, -2)) - ref.amin((-1, -2))

    def nrmse(est: Tensor) -> float:
        return float((((est - ref) ** 2).mean((-1, -2)).sqrt() / span).mean())

    info = {"size": size, "pitch_um": pitch_um, "time_s": t_ref,
            "self_check_nrmse": nrmse(ref_half)}
    variants: dict[str, list[tuple[str, dict[str, Any]]]] = {
        "psf_rings": [(f"rings:{n}", {"sampling": f"rings:{n}"}) for n in (4, 8, 16, 24, 32, 48, 64)],
        "psf_kernel": [(f"{k} kernel, rings:32", {"kernel": k}) for k in ("count", "triangular", "cosine")],
        "psf_bins": [(f"estimate on bins pitch/{o}, rings:32", {"oversample": o}) for o in (1, 3, 5)],
        "diffraction": [(f"diffraction {d}, rings:32", {"diffraction": d}) for d in ("none", "incoherent",
                                                                                       "heuristic")],
    }
    out = []
    for knob in knobs:
        for label, kw in variants[knob]:
            progress(f"{knob}: {label}")
            s = PsfSettings(**{**base.__dict__, "size": size, **kw})

            def run(s: PsfSettings = s) -> Tensor:
                with torch.no_grad():
                    return compute_psfs(lens, system, rel, s, engine=engine).psf

            psf, t = timed(run, repeats)
            out.append(Point(knob, label, {"psf": nrmse(psf)}, t))
    return out, info


# -------------------------------------------------------------------------------------- simulation


def _sim_points(model: Model, knobs: Sequence[str], repeats: int,
                progress: Callable[[str], None], *, engine: Engine | None = None) -> tuple[list[Point], dict[str, Any]]:
    from importlib.resources import files

    from lensopt.imaging.io import read_image
    from lensopt.imaging.plan import PlanOptions, parse_effects
    from lensopt.imaging.simulate import plan_scene, run_plan

    img, _ = read_image(files("lensopt.imaging") / "data" / "coffee.png", engine=engine)
    h, w, c = img.shape
    info = {"width": w, "height": h, "channels": c}

    def simulate(**kw: Any) -> np.ndarray:
        opts = PlanOptions(**{"sampling": "rings:16", **kw})
        plan, pilot, reg, sensor = plan_scene(model, info, region="corner",
                                              effects=parse_effects("+convolution,-noise"), options=opts, engine=engine)
        with torch.inference_mode():
            return run_plan(model, plan, pilot, reg, sensor, img, opts, engine=engine).image

    progress("reference simulation (12x9 grid, 36 fields, rings:48)")
    t0 = time.perf_counter()
    try:
        ref = simulate(grid=(12, 9), fields=36, sampling="rings:48")
    except LensoptError as err:  # e.g. no [sensor] (RGB weights are derived from the spectrum, S4.1.2)
        return [], {"skipped": f"the lens cannot simulate the RGB test scene: {err}"}
    ref_info = {"grid": "12x9", "fields": 36, "sampling": "rings:48", "time_s": time.perf_counter() - t0,
                "image": f"coffee.png {w}x{h} on the sensor corner"}
    variants = {"sim_grid": [(f"grid {g[0]}x{g[1]}", {"grid": g}) for g in ((1, 1), (2, 2), (3, 3), (5, 4), (8, 6))],
                "sim_overlap": [(f"overlap {o:g}, grid 3x3", {"grid": (3, 3), "overlap": o})
                                for o in (0.0, 0.125, 0.25, 0.5)]}
    out = []
    for knob in knobs:
        for label, kw in variants[knob]:
            progress(f"{knob}: {label}")
            im, t = timed(lambda kw=kw: simulate(**kw), repeats)
            rmse = float(np.sqrt(np.mean((im.astype(np.float64) - ref) ** 2)))
            psnr = 20 * math.log10(1 / max(rmse, 1e-12))
            out.append(Point(knob, label, {"sim": rmse}, t, note=f"PSNR {psnr:.2f} dB"))
    return out, ref_info


# ---------------------------------------------------------------------------------------- driver


def run_accuracy(model: Model, *, knobs: Sequence[str] = DEFAULT_KNOBS, repeats: int = 3, pitch_um: float | None = None,
                 progress: Callable[[float, str], None] | None = None, engine: Engine | None = None) -> AccuracyResult:
    """Measure every knob in ``knobs`` on ``model`` (see the module doc); ``progress(fraction, what)``;
    ``engine``: its memory budget bounds every trace; the ``compiled`` knob traces on its compiled traces,
    every other knob eagerly."""
    knobs = parse_knobs(",".join(knobs))
    full = engine or Engine()
    engine = Engine(max_memory=full.max_memory, on_compile=full.on_compile)  # eager
    report = progress or (lambda f, s: None)
    groups = [k for k in knobs if KNOBS[k] == "esr"]
    analyses = [k for k in knobs if k in ANALYSES]
    steps = len(groups) + ("aim_steps" in knobs) + any(KNOBS[k] == "psf" for k in knobs) * 2 \
        + any(KNOBS[k] == "sim" for k in knobs) * 2 + bool(analyses) * 2 + 1
    done = 0

    def tick(what: str) -> None:
        nonlocal done
        report(min(done / steps, 1.0), what)
        done += 1

    tick("spot reference (quadrature, doubling to 1e-9)")
    ref = spot_reference(model, engine=engine)
    reference: dict[str, Any] = {"spot": ref}
    points: list[Point] = []
    compile_s = None
    for k in groups:
        tick(f"{k}")
        if k == "compiled":
            from lensopt.accel.compiled import clear_compiled_cache

            clear_compiled_cache()
            t0 = time.perf_counter()
            with torch.no_grad():
                pts = PupilSampling.parse("rings:4").points(dtype=model.lens.dtype, engine=engine)
                trace_bundle(model.lens, model.system, pts, half_pupil=True, engine=on_backend(engine, "compiled"))
            compile_s = time.perf_counter() - t0
        points += _spot_points(model, k, ref, repeats, engine=engine)
    if "aim_steps" in knobs:
        tick("aim_steps")
        pts, aim_ref = _aim_points(model, repeats, engine=engine)
        points += pts
        reference["aim"] = aim_ref
    psf_knobs = [k for k in knobs if KNOBS[k] == "psf"]
    if psf_knobs:
        tick("PSFs")
        spec = model.spec
        pitch = pitch_um or (spec.sensor.pixel_pitch_um if spec.sensor is not None else 1.0)
        pts, reference["psf"] = _psf_points(model, psf_knobs, repeats, pitch, lambda s: report(done / steps, s),
                                            engine=engine)
        points += pts
        tick("PSFs done")
    sim_knobs = [k for k in knobs if KNOBS[k] == "sim"]
    if sim_knobs:
        tick("simulation")
        pts, reference["sim"] = _sim_points(model, sim_knobs, max(1, repeats // 2), lambda s: report(done / steps, s),
                                            engine=engine)
        points += pts
        tick("simulation done")
    if analyses:
        tick("analyses")
        pts, reference["analyses"] = analysis_points(model, analyses, repeats, lambda s: report(done / steps, s),
                                                     engine=engine)
        points += pts
        tick("analyses done")
    report(1.0, "done")
    return AccuracyResult(model.spec.name, points, reference, compile_s, {"knobs": list(knobs), "repeats": repeats})


def pareto(points: Sequence[Point], metric: str) -> list[Point]:
    """Points not beaten by another on both time and ``metric`` error, fastest first."""
    pts = sorted((p for p in points if metric in p.errors), key=lambda p: (p.time_s, p.errors[metric]))
    front, best = [], math.inf
    for p in pts:
        if p.errors[metric] < best:
            front.append(p)
            best = p.errors[metric]
    return front


def recommend(points: Sequence[Point], metric: str, target: float, budget: float | None) -> dict[str, Any]:
    """The cheapest setting whose ``metric`` error ≤ ``target`` and, with a budget, the smallest error within it."""
    ok = [p for p in points if metric in p.errors and p.errors[metric] <= target]
    out: dict[str, Any] = {"target": target,
                           "cheapest": _pt(min(ok, key=lambda p: p.time_s)) if ok else None}
    if not ok:
        best = min((p for p in points if metric in p.errors), key=lambda p: p.errors[metric], default=None)
        out["why_not"] = (f"no measured setting reaches {target:g}; the best is {best.setting} "
                          f"({best.errors[metric]:.3g})" if best else "not measured")
    if budget is not None:
        within = [p for p in points if metric in p.errors and p.time_s <= budget]
        out["budget_buys"] = _pt(min(within, key=lambda p: p.errors[metric])) if within else None
    return out
