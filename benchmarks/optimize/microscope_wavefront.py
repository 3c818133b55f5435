"""Spot-optimized against wavefront-optimized microscope objective (issue 28): for each lens, every Table
S12 requirement on the dense ray sample (``analysis.requirements.check_requirements``, as
``benchmarks/studies/studies_report.py`` and ``tests/test_lenses.py`` check the shipped lens), the Strehl
ratio per field (from the diffraction PSF and Maréchal's estimate, per wavelength and polychromatic), the RMS
wavefront error per field, the MTF against field, and the ESR on the seed's measure; with the CPU time of the
run that made it (``<lens>.run.json`` beside it, written by ``run`` mode).

    OMP_NUM_THREADS=1 PYTHONPATH=. .venv/bin/python benchmarks/optimize/microscope_wavefront.py \\
        lenses/microscope_8p_wd12.json out/mw_spot_spec.json out/mw_wavefront_spec.json ... \\
        --json benchmarks/optimize/results_microscope_wavefront.json

Definitions (all from ``lensopt.analysis``; pupil: a 64 × 64 equal-area grid):
- per wavelength: ``analysis.strehl.strehl`` (PSF peak searched about each wavelength's chief ray, so lateral
  colour costs nothing there; Maréchal exp(−(2πσ)²) of the piston- and tilt-removed RMS σ).
- polychromatic Strehl (PSF): the peak of Σ_λ ŵ_λ I_λ(x) / I_λ,perfect(0) — each wavelength's Debye PSF
  (``psf_reference.debye_intensity``) on one image-plane grid about the reference wavelength's chief ray (all
  wavelengths' reference spheres centred there, so lateral colour counts), ŵ the spec's spectral weights;
  the peak searched as ``strehl.peak_strehl`` searches (nested 21 × 21 grids) over ± (lateral colour span +
  3 Airy radii). Polychromatic Maréchal: Σ ŵ_λ exp(−(2πσ_λ)²) (no lateral colour). RMS (poly): √Σ ŵ_λ σ_λ².
- MTF: ``analysis.mtf_field.mtf_vs_field`` (polychromatic, tangential and sagittal), method ``--mtf-method``.

``run`` mode: one optimization run, timed by its own CPU time:

timed by this process's CPU time (``time.process_time``, one intra-op thread).

    OMP_NUM_THREADS=1 PYTHONPATH=. .venv/bin/python benchmarks/optimize/microscope_wavefront.py \\
        run --merit wavefront --start spec --steps 290 -o out/mw_wavefront_spec.json

``--merit spot``: the spot spec (``specs/microscope_8p_wd12.toml``); ``wavefront``: its wavefront twin
(``specs/microscope_8p_wd12_wavefront.toml``: the same lens, constraints and variables, the merit its
``[optimize.wavefront]`` and a small TRA). ``--start spec``: from the spec's crude start, with its schedules
and the glass binding at mid-run; ``--start shipped``: continuing from ``lenses/microscope_8p_wd12.json``
(glasses already bound) at full constraint weight (``--full-weight``), the shipped lens's own [optimize]
for ``spot``, and that [optimize] with the twin's ``tra`` and ``wavefront`` for ``wavefront``; there no
schedule depends on the step count, so ``--cpu-budget S`` (with a large ``--steps``) ends both merits' runs
after the same CPU seconds (the step that crosses S completes). Writes the
lens (``-o``) and beside it ``<out>.run.json``: steps, stop reason, CPU seconds, wall seconds.
The step counts of the recorded runs were chosen so that each run takes about the same CPU time
(benchmarks/README.md, optimize).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import torch

from lensopt.analysis.mtf_field import mtf_vs_field
from lensopt.analysis.psf_reference import debye_intensity
from lensopt.analysis.requirements import check_requirements, failed, table_s12
from lensopt.analysis.spot import seed_esr
from lensopt.analysis.strehl import strehl
from lensopt.analysis.wavefront import map_grid, trace_to_sphere
from lensopt.design import optimize
from lensopt.files import write_text_atomic
from lensopt.optics.paraxial import first_order
from lensopt.spec import build, dump_json, load_spec

FIELDS = [0.0, 0.25, 0.5, 0.75, 1.0]
ROOT = Path(__file__).resolve().parents[2]
SPOT = ROOT / "specs" / "microscope_8p_wd12.toml"
WAVEFRONT = ROOT / "specs" / "microscope_8p_wd12_wavefront.toml"
SHIPPED = ROOT / "lenses" / "microscope_8p_wd12.json"


def start_spec(merit: str, start: str):  # noqa: ANN201 - a LensSpec
    if start == "spec":
        return load_spec(SPOT if merit == "spot" else WAVEFRONT)
    spec = load_spec(SHIPPED)
    if merit == "wavefront":
        twin = load_spec(WAVEFRONT).optimize
        spec.optimize = spec.optimize.model_copy(update={"tra": twin.tra, "wavefront": twin.wavefront})
    return spec




def requirements(spec) -> dict:  # noqa: ANN001
    model = build(spec)
    glass = [s for s in spec.surfaces if not s.is_air]
    names = [s.material if isinstance(s.material, str) else s.material.name for s in glass]
    checks = check_requirements(model.lens, model.system, table_s12(), glass_gaps=[not s.is_air for s in spec.surfaces],
                                materials=names)
    return {"met": failed(checks) == [], "failed": failed(checks),
            "checks": {c.name: {"value": c.value if isinstance(c.value, str) else float(c.value), "limit": c.limit,
                                "ok": c.ok} for c in checks}}


@torch.no_grad()
def poly_strehl(lens, system, rel: torch.Tensor, n: int, levels: int = 4, points: int = 21) -> list[float]:  # noqa: ANN001
    """Polychromatic PSF Strehl per field (module docstring)."""
    fo = first_order(lens, system)
    pupil, inside = map_grid(n, dtype=lens.dtype)
    ref = system.reference
    st0 = trace_to_sphere(lens, system, pupil, rel_field=rel, fo=fo)
    center = st0.center[:, ref, :2]  # (F, 2): the reference wavelength's chief ray on the image surface
    st = trace_to_sphere(lens, system, pupil, rel_field=rel, fo=fo, center=center)
    ok = st.valid & inside & st.chief_valid.unsqueeze(-1)
    path = torch.where(ok, st.opl - st.chief_opl.unsqueeze(-1), torch.zeros_like(st.opl))
    n_img = lens.index[-1]
    ww = system.wavelength_weights / system.wavelength_weights.sum()
    wn = abs(float(fo.working_fnumber))
    out = []
    for f in range(len(rel)):
        spread = float((st0.center[f, :, :2] - center[f]).abs().max())
        airy = 1.22 * float(lens.wavelength_um.max()) * 1e-3 * wn
        span, cx, cy, best = spread + 3.0 * airy, 0.0, 0.0, 0.0
        for _ in range(levels):
            g = torch.linspace(-span, span, points, dtype=torch.float64)
            total = torch.zeros(points, points, dtype=torch.float64)
            for j in range(lens.wavelength_um.shape[0]):
                lam = float(lens.wavelength_um[j])
                amp = ok[f, j].to(torch.float64)
                perfect = float(amp.sum()) ** 2
                if perfect <= 0:
                    continue
                ax, ay = st.towards[f, j, :, 0] * n_img[j], st.towards[f, j, :, 1] * n_img[j]
                inten = debye_intensity(path[f, j], ax, ay,
                                        amp, 2.0 * math.pi / (lam * 1e-3), g + cx, g + cy)
                total += float(ww[j]) * inten / perfect
            i = int(torch.argmax(total))
            best = float(total.reshape(-1)[i])
            cy, cx = cy + float(g[i // points]), cx + float(g[i % points])
            span = span * 2.0 / (points - 1) * 1.5
        out.append(best)
    return out


def analyse(path: Path, freqs: list[float], mtf_method: str, pupil: int) -> dict:
    spec = load_spec(path)
    model = build(spec)
    lens, system = model.lens, model.system
    rel = torch.tensor(FIELDS, dtype=lens.dtype)
    t0 = time.process_time()
    st = strehl(lens, system, rel_field=rel, pupil_samples=pupil)
    ww = system.wavelength_weights / system.wavelength_weights.sum()
    ref = system.reference
    mtf = mtf_vs_field(lens, system, freqs, fields=rel, method=mtf_method)
    run = path.with_suffix(".run.json")
    out = {
        "lens": str(path),
        "run": json.loads(run.read_text()) if run.exists() else None,
        "requirements": requirements(spec),
        "seed_esr_um": 1e3 * float(seed_esr(lens, system)),
        "fields": FIELDS,
        "wavelengths_nm": [1e3 * float(x) for x in lens.wavelength_um],
        "strehl_psf_poly": poly_strehl(lens, system, rel, pupil),
        "strehl_psf_mean": (st.psf * ww).sum(1).tolist(),
        "strehl_marechal_mean": (st.marechal * ww).sum(1).tolist(),
        "strehl_psf_ref": st.psf[:, ref].tolist(),
        "strehl_marechal_ref": st.marechal[:, ref].tolist(),
        "rms_waves_poly": (st.rms_waves ** 2 * ww).sum(1).sqrt().tolist(),
        "rms_waves_ref": st.rms_waves[:, ref].tolist(),
        "rms_waves": st.rms_waves.tolist(),
        "strehl_psf": st.psf.tolist(),
        "mtf": {"method": mtf_method, "frequency": freqs, "cutoff": mtf.cutoff,
                "tangential": mtf.tangential.tolist(), "sagittal": mtf.sagittal.tolist()},
        "analysis_cpu_s": 0.0,
    }
    out["analysis_cpu_s"] = round(time.process_time() - t0, 1)
    return out


def tables(results: dict) -> str:
    """The README's two markdown tables from a results JSON: one row per lens, then one per lens and field."""
    rows = ["| lens | merit, start | steps | CPU s | Table S12 | ESR µm (seed) | RMS poly (waves), fields 0 … 1 "
            "| Strehl poly PSF, fields 0 … 1 |", "| --- | --- | ---: | ---: | --- | ---: | --- | --- |"]
    for name, r in results["lenses"].items():
        run = r["run"] or {}
        how = f"{run['merit']}, {run['start']}" if run else "shipped spot lens"
        req = "met" if r["requirements"]["met"] else "fails: " + ", ".join(r["requirements"]["failed"])
        rows.append(f"| `{name}` | {how} | {run.get('steps', '')} | {run.get('cpu_s', '')} | {req} | "
                    f"{r['seed_esr_um']:.3f} | " + " / ".join(f"{x:.3f}" for x in r["rms_waves_poly"]) + " | "
                    + " / ".join(f"{x:.3f}" for x in r["strehl_psf_poly"]) + " |")
    nu = results["frequencies"]
    head = " | ".join(f"MTF {v:g} T / S" for v in nu)
    rows += ["", "| lens | field | Strehl poly PSF | mean of λ PSF / Maréchal | 550 nm PSF / Maréchal | RMS 550 | "
             f"{head} |",
             "| --- | ---: | ---: | --- | --- | ---: |" + " --- |" * len(nu)]
    for name, r in results["lenses"].items():
        for i, f in enumerate(r["fields"]):
            t, sa = r["mtf"]["tangential"][i], r["mtf"]["sagittal"][i]
            mtf = " | ".join(f"{t[k]:.3f} / {sa[k]:.3f}" for k in range(len(nu)))
            rows.append(f"| `{name}` | {f:g} | {r['strehl_psf_poly'][i]:.3f} | {r['strehl_psf_mean'][i]:.3f} / "
                        f"{r['strehl_marechal_mean'][i]:.3f} | {r['strehl_psf_ref'][i]:.3f} / "
                        f"{r['strehl_marechal_ref'][i]:.3f} "
                        f"| {r['rms_waves_ref'][i]:.3f} | {mtf} |")
    return "\n".join(rows)


def run_main(argv: list[str]) -> None:
    """``run``: one timed optimization run (module docstring)."""
    ap = argparse.ArgumentParser(description="one timed run")
    ap.add_argument("--merit", choices=["spot", "wavefront"], required=True)
    ap.add_argument("--start", choices=["spec", "shipped"], required=True)
    ap.add_argument("--steps", type=int, required=True)
    ap.add_argument("--cpu-budget", type=float, default=None,
                    help="stop once the run has used this many CPU seconds (the lens so far is kept)")
    ap.add_argument("-o", "--output", type=Path, required=True)
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    spec = start_spec(a.merit, a.start)
    c0, w0 = time.process_time(), time.perf_counter()

    def stop_at_budget(_progress) -> None:  # noqa: ANN001 - a Progress
        if a.cpu_budget is not None and time.process_time() - c0 >= a.cpu_budget:
            raise KeyboardInterrupt  # run_problem keeps the lens so far, as on Ctrl-C

    res = optimize(spec, steps=a.steps, seed=0, full_weight=a.start == "shipped", callback=stop_at_budget)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    a.output.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(a.output, dump_json(res.spec))
    rec = {"merit": a.merit, "start": a.start, "steps_asked": a.steps, "cpu_budget_s": a.cpu_budget, "steps": res.steps,
           "stop_reason": res.stop_reason, "cpu_s": round(cpu, 2), "wall_s": round(wall, 2),
           "threads": torch.get_num_threads(), "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
           "bound": [str(b) for b in res.bound], "warning": res.warning}
    write_text_atomic(a.output.with_suffix(".run.json"), json.dumps(rec, indent=1) + "\n")
    print(json.dumps(rec))


def main() -> None:
    if sys.argv[1:2] == ["run"]:
        run_main(sys.argv[2:])
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("lenses", nargs="*", type=Path)
    ap.add_argument("--tables", type=Path, help="print the README tables of this results JSON and stop")
    ap.add_argument("--frequencies", default="200,400,800", help="MTF frequencies, cycles/mm")
    ap.add_argument("--mtf-method", default="reference")
    ap.add_argument("--pupil", type=int, default=64)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    if a.tables:
        print(tables(json.loads(a.tables.read_text())))
        return
    torch.set_num_threads(1)
    freqs = [float(x) for x in a.frequencies.split(",")]
    rows = {}
    for p in a.lenses:
        r = analyse(p, freqs, a.mtf_method, a.pupil)
        rows[p.stem] = r
        cpu = r["run"]["cpu_s"] if r["run"] else float("nan")
        print(f"{p.stem}: req {'met' if r['requirements']['met'] else r['requirements']['failed']}, "
              f"ESR {r['seed_esr_um']:.3f} um, run CPU {cpu} s, analysis {r['analysis_cpu_s']} s", flush=True)
        for i, f in enumerate(FIELDS):
            print(f"  field {f:.2f}: Strehl poly PSF {r['strehl_psf_poly'][i]:.3f}"
                  f"  mean PSF {r['strehl_psf_mean'][i]:.3f}"
                  f"  Marechal {r['strehl_marechal_mean'][i]:.3f}  550: {r['strehl_psf_ref'][i]:.3f}/"
                  f"{r['strehl_marechal_ref'][i]:.3f}  RMS poly {r['rms_waves_poly'][i]:.3f}"
                  f" 550 {r['rms_waves_ref'][i]:.3f}"
                  f"  MTF T " + " ".join(f"{x:.3f}" for x in r["mtf"]["tangential"][i])
                  + " S " + " ".join(f"{x:.3f}" for x in r["mtf"]["sagittal"][i]), flush=True)
    if a.json:
        write_text_atomic(a.json, json.dumps({"frequencies": freqs, "lenses": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
