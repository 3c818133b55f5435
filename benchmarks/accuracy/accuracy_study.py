"""Issue 13 measurements: ``lensopt accuracy`` on the Cooke triplet and the C-mount lens, the 1 %-ESR
recommendation checked on a third lens, and the wall time of the ray-heavy commands per trace backend;
issue 29: part ``defaults``, the reporting default gauss:16 against the old rings:24 and each lens's
optimizer sampling on every shipped lens (benchmarks/accuracy/results_accuracy_defaults.json).

    .venv/bin/python benchmarks/accuracy/accuracy_study.py [--part accuracy,third,commands] [--repeats 3]

Part ``accuracy`` writes its lens in benchmarks/accuracy/results_accuracy_knobs.json and accuracy_<lens>.png (the
plot ``lensopt accuracy -o`` draws) and prints markdown tables. Part ``third`` takes each lens's
recommended setting for a 1 % ESR target and measures its ESR error on specs/double_gauss.toml against
that lens's own converged reference. Part ``commands`` runs ``lensopt trace --sampling rings:32`` and
``rings:64``, ``lensopt plot psf``, ``lensopt simulate`` and ``lensopt evaluate --count 20`` on the shipped
lenses as separate processes (what a user waits for, imports and compilation included), interleaved, per
``--backends`` (default eager, auto, compiled; ``auto@cold``: auto with an empty compile cache), e.g. the
issue-13 session-21 run, after ``lensopt warmup`` into the cache dir:

    .venv/bin/python benchmarks/accuracy/accuracy_study.py --part commands --repeats 3 --backends eager,auto@cold,auto \
        --cache-dir /tmp/lensopt_cache --commands-json results_backend_commands_aot.json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch

from lensopt import accel
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.plot.accuracy import accuracy_figure
from lensopt.plot.style import save_figure
from lensopt.qa.accuracy import DEFAULT_KNOBS, Point, _cast, run_accuracy, spot_reference, weighted_spot
from lensopt.spec import build, load_spec

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "benchmarks" / "accuracy"
LENSES = {"cooke": ROOT / "specs" / "cooke_triplet.toml", "cmount": ROOT / "lenses" / "cmount_4p.json"}
THIRD = ROOT / "specs" / "double_gauss.toml"
KNOBS_JSON = BENCH / "results_accuracy_knobs.json"  # {lens key: what ``lensopt accuracy --json`` prints, + runs}


def _records() -> dict:
    return json.loads(KNOBS_JSON.read_text()) if KNOBS_JSON.exists() else {}


def _record(key: str, data: dict) -> None:
    KNOBS_JSON.write_text(json.dumps({**_records(), key: data}, indent=1))


def part_accuracy(repeats: int, keys: list[str], knobs: tuple[str, ...], merge: bool = False) -> dict:
    out = {}
    for key in keys:
        path = LENSES[key]
        model = build(load_spec(path))
        t0 = time.perf_counter()
        res = run_accuracy(model, knobs=knobs, repeats=repeats)
        wall, load = time.perf_counter() - t0, os.getloadavg()
        runs = []
        if merge and key in _records():  # keep the recorded points of the knobs not measured now (one table per lens)
            prev = _records()[key]
            kept = [Point(p["knob"], p["setting"], p["errors"], p["time_s"], p.get("note", ""))
                    for p in prev["points"] if p["knob"] not in knobs]
            res.points = kept + res.points
            res.reference = {**prev["reference"], **res.reference}
            res.compile_s = res.compile_s if "compiled" in knobs else prev.get("compile_s")
            res.settings = {**res.settings, "knobs": sorted({p.knob for p in res.points})}
            first = {"knobs": prev["settings"].get("knobs"), "repeats": prev["settings"].get("repeats"),
                     "wall_s": prev.get("wall_s"), "load": prev.get("load")}
            runs = prev.get("runs", [first])
        data = res.as_json(0.01, 0.05)
        data["wall_s"] = wall
        data["load"] = load
        data["runs"] = runs + [{"knobs": list(knobs), "repeats": repeats, "wall_s": wall, "load": load}]
        _record(key, data)
        save_figure(accuracy_figure(data, title=model.spec.name), BENCH / f"accuracy_{key}.png", dpi=120)
        out[key] = data
        print(f"\n### {model.spec.name} ({path.relative_to(ROOT)}), {data['wall_s']:.0f} s, load {data['load']}\n")
        ref = data["reference"]["spot"]
        print(f"spot reference: ESR {ref['esr_um']:.9f} µm, {ref['nodes']}, last doubling {ref['agreement']:.1e}; "
              f"compile {data['compile_s']}")
        print("\n| knob | setting | ESR err | RMS err | aim err | PSF NRMSE | image RMSE | time s |")
        print("| --- | --- | --- | --- | --- | --- | --- | --- |")
        for p in data["points"]:
            e = p["errors"]
            cells = " | ".join(f"{e[m]:.2e}" if m in e else "" for m in ("esr", "rms", "aim", "psf", "sim"))
            print(f"| {p['knob']} | {p['setting']} | {cells} | {p['time_s']:.4f} |")
        for m, r in data["recommendation"].items():
            c = r["cheapest"]
            print(f"- {m} ≤ 1 %: " + (f"{c['setting']} ({c['errors'][m]:.2e}, {c['time_s']:.4f} s)" if c
                                      else r.get("why_not", "")))
    return out


def esr_error(model, setting: str) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    """ESR relative error of ``setting`` ('grid:24', 'rings:16 float32', 'rings:8 compiled') and the
    reference's convergence."""
    words = setting.split()
    ps = PupilSampling.parse(words[0])
    lens = _cast(model.lens, torch.float32) if "float32" in words else model.lens
    ref = spot_reference(model)
    engine = accel.engine("compiled" if "compiled" in words else "eager")
    with torch.no_grad():
        pts = ps.points(dtype=lens.dtype)
        b = trace_bundle(lens, model.system, pts, half_pupil=ps.half, engine=engine)
        fw = torch.tensor(model.system.field_weights, dtype=lens.dtype) if model.system.field_weights else None
        esr, _ = weighted_spot(b, torch.ones(pts.shape[0], dtype=lens.dtype),
                               model.system.wavelength_weights.to(lens.dtype), fw)
    return abs(1e3 * float(esr) - ref["esr_um"]) / ref["esr_um"], ref["agreement"]


def part_third(results: dict) -> None:
    """Each lens's 1 % ESR recommendation (from ``results`` or the recorded JSON) on the third lens."""
    if not results:
        results = {k: v for k, v in _records().items() if k in LENSES}
    third = build(load_spec(THIRD))
    print(f"\n### 1 % ESR recommendation checked on {THIRD.relative_to(ROOT)}\n")
    print("| recommended on | setting | its error there | error on the third lens | meets 1 %? |")
    print("| --- | --- | --- | --- | --- |")
    for key, data in results.items():
        c = data["recommendation"]["esr"]["cheapest"]
        err, agree = esr_error(third, c["setting"])
        print(f"| {key} | {c['setting']} | {c['errors']['esr']:.2e} | {err:.2e} (reference converged to {agree:.0e}) "
              f"| {'yes' if err <= 0.01 else 'no'} |")
    for s in ("rings:16", "rings:64", "grid:16", "grid:24", "grid:48"):
        print(f"- {s} on the third lens: ESR error {esr_error(third, s)[0]:.2e}")


def part_commands(repeats: int, lenses: list[str], only: list[str] | None, backends: list[str],
                  cache: str | None, json_name: str) -> None:
    """Each command as its own process per backend, interleaved. A backend ``auto@cold`` is ``auto`` with
    an empty ``TORCHINDUCTOR_CACHE_DIR`` (no AOT package, no Inductor cache); the others use ``cache``
    (default: the environment's)."""
    import tempfile

    py = [sys.executable, "-c", "from lensopt.cli.app import app; app()"]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "2")}
    if cache:
        env["TORCHINDUCTOR_CACHE_DIR"] = cache
    cold = tempfile.mkdtemp(prefix="lensopt_cold_cache_")
    tmp = ROOT / "out" / "accuracy_study"
    tmp.mkdir(parents=True, exist_ok=True)
    img = ROOT / "lensopt" / "imaging" / "data" / "coffee.png"
    rows = []
    for lens in (ROOT / name if "/" in name else ROOT / "lenses" / f"{name}.json" for name in lenses):
        cmds = {"trace rings:32": ["trace", str(lens), "--sampling", "rings:32", "--json"],
                "trace rings:64": ["trace", str(lens), "--sampling", "rings:64", "--json"],
                "plot psf": ["plot", "psf", str(lens), "-o", str(tmp / "psf.png")],
                "simulate": ["simulate", str(lens), str(img), "--region", "corner", "-o", str(tmp / "sim.png")],
                "evaluate": ["evaluate", str(lens), "--count", "20", "--json"]}
        for name, args in cmds.items():
            if only is not None and name not in only:
                continue
            times: dict[str, list[float]] = {}
            for _ in range(repeats):  # interleaved: every backend sees the same load
                for backend in backends:
                    run_env = {**env, "TORCHINDUCTOR_CACHE_DIR": cold} if backend.endswith("@cold") else env
                    t0 = time.perf_counter()
                    r = subprocess.run([*py, *args, "--backend", backend.split("@")[0]], env=run_env,
                                       capture_output=True, text=True)
                    dt = time.perf_counter() - t0
                    if r.returncode != 0:
                        raise SystemExit(f"{name} {lens.name} {backend}: {r.stderr[-500:]}")
                    times.setdefault(backend, []).append(dt)
            rows.append((lens.name, name, times))
            med = {b: float(np.median(v)) for b, v in times.items()}
            cells = " | ".join(f"{med[b]:.2f}" + ("" if b == backends[0] else f" ({med[b] / med[backends[0]]:.2f}×)")
                               for b in backends)
            print(f"| {lens.name} | {name} | {cells} | {os.getloadavg()[0]:.1f} |", flush=True)
    (BENCH / json_name).write_text(json.dumps(
        {"rows": [{"lens": a, "command": b, "times_s": c} for a, b, c in rows], "backends": backends,
         "repeats": repeats, "load": os.getloadavg()}, indent=1))


def part_illumination(grid: int) -> None:
    """The flux-counting illumination reference (millions of rays in 2 M-ray tiles) per backend, in process."""
    from lensopt.analysis.irradiance import relative_illumination_flux

    model = build(load_spec(ROOT / "specs" / "wide_angle_laikin.toml"))
    print(f"\n### relative_illumination_flux, specs/wide_angle_laikin.toml, grid {grid}, spec fields\n")
    print("| backend | s | RI per field |")
    print("| --- | --- | --- |")
    base = None
    for name in ("eager", "auto", "compiled", "auto"):
        t0 = time.perf_counter()
        r = relative_illumination_flux(model.lens, model.system, model.system.rel_field, grid=grid,
                                       engine=accel.engine(name))
        dt = time.perf_counter() - t0
        ri = r.relative_illumination if hasattr(r, "relative_illumination") else r
        vals = [float(v) for v in torch.as_tensor(ri).flatten()]
        base = base or vals
        diff = max(abs(a - b) for a, b in zip(vals, base, strict=True))
        print(f"| {name} | {dt:.1f} | {', '.join(f'{v:.6f}' for v in vals)} (max diff to eager {diff:.1e}) |",
              flush=True)


DEFAULTS = ("gauss:16", "rings:24")  # the reporting default since issue 29, and the trace default before it


def part_defaults(repeats: int) -> dict:
    """Issue 29: the reporting default ``gauss:16`` against the old ``rings:24`` and the lens's own optimizer
    sampling, on every shipped lens: ESR and worst-field RMS error against the converged quadrature reference
    (``qa.accuracy.spot_reference``), and the time of the spot computation (points, eager trace, weighted
    spot statistics) as wall and CPU medians of ``repeats`` runs, 1 thread. The ESR of each setting is
    cross-checked against what ``lensopt trace`` reports (``analysis.report.trace_report``)."""
    from lensopt.analysis.report import trace_report
    from lensopt.engine import Engine

    engine = Engine()  # eager: no compilation inside a timing
    rows = []
    for path in sorted(p for p in (ROOT / "lenses").glob("*.json") if p.name != "check_baseline.json"):
        spec = load_spec(path)
        model = build(spec)
        lens, system = model.lens, model.system
        fw = torch.tensor(system.field_weights, dtype=lens.dtype) if system.field_weights else None
        ref = spot_reference(model, engine=engine)
        opt = spec.optimize.sampling if spec.optimize is not None else None
        settings = [*DEFAULTS, *([opt] if opt and opt not in DEFAULTS else [])]
        row = {"lens": path.name, "name": spec.name, "wavelengths": int(lens.wavelength_um.numel()),
               "fields": len(system.rel_field), "aim": system.aim, "reference": ref, "optimizer_sampling": opt,
               "settings": {}}
        for text in settings:
            ps = PupilSampling.parse(text, weighted=True)

            def run(ps: PupilSampling = ps, lens=lens, system=system, fw=fw):  # type: ignore[no-untyped-def]
                with torch.no_grad():
                    pts = ps.points(dtype=lens.dtype, engine=engine)
                    wts = ps.weights(dtype=lens.dtype)
                    b = trace_bundle(lens, system, pts, half_pupil=ps.half, engine=engine)
                    return weighted_spot(b, torch.ones(pts.shape[0], dtype=lens.dtype) if wts is None else wts,
                                         system.wavelength_weights, fw)

            run()  # warm
            walls, cpus = [], []
            for _ in range(repeats):
                w0, c0 = time.perf_counter(), time.process_time()
                esr, rms = run()
                walls.append(time.perf_counter() - w0)
                cpus.append(time.process_time() - c0)
            shown = trace_report(model, ps, engine=engine)["effective_spot_radius_um"]
            e_esr = abs(1e3 * float(esr) - ref["esr_um"]) / ref["esr_um"]
            e_rms = float(np.max(np.abs(1e3 * rms.numpy() - np.array(ref["rms_um"])) / np.array(ref["rms_um"])))
            row["settings"][text] = {"rays_per_field_wavelength": int(ps.count), "esr_um": 1e3 * float(esr),
                                     "esr_um_trace_report": shown, "esr_error": e_esr, "rms_error_worst_field": e_rms,
                                     "wall_ms": 1e3 * float(np.median(walls)), "cpu_ms": 1e3 * float(np.median(cpus))}
        rows.append(row)
        g, r = row["settings"]["gauss:16"], row["settings"]["rings:24"]
        o = row["settings"].get(opt) if opt not in DEFAULTS else None
        print(f"| {path.name} | {100 * g['esr_error']:.2g} | {g['wall_ms']:.1f} ({g['cpu_ms']:.1f}) | "
              f"{100 * r['esr_error']:.2g} | {r['wall_ms']:.1f} ({r['cpu_ms']:.1f}) | "
              f"{g['wall_ms'] / r['wall_ms']:.2f} | "
              + (f"{opt}: {100 * o['esr_error']:.2g}, {o['wall_ms']:.1f} ({o['cpu_ms']:.1f})" if o else "—") + " |",
              flush=True)
    data = {"command": "OMP_NUM_THREADS=1 .venv/bin/python benchmarks/accuracy/accuracy_study.py --part defaults",
            "repeats": repeats, "threads": torch.get_num_threads(), "load": os.getloadavg(), "lenses": rows}
    (BENCH / "results_accuracy_defaults.json").write_text(json.dumps(data, indent=1))
    return data


KEEP = {"rings": ("rings:4", "rings:16", "rings:64"), "rings_fixed": ("rings:16:nojitter", "rings:64:nojitter"),
        "grid": ("grid:8", "grid:16", "grid:24", "grid:32", "grid:48", "grid:96"),
        "float32": ("rings:16 float32", "rings:64 float32"), "compiled": ("rings:16 compiled", "rings:64 compiled")}


def summarize() -> None:
    """Condensed markdown of the recorded results_accuracy_knobs.json (every point is in the JSON)."""
    data = {k: v for k, v in _records().items() if k in LENSES}
    print("| knob | setting | " + " | ".join(f"{k} error | {k} s" for k in data) + " |")
    print("| --- | --- | " + " | ".join("--- | ---" for _ in data) + " |")
    first = next(iter(data.values()))
    for p in first["points"]:
        if p["knob"] in KEEP and p["setting"] not in KEEP[p["knob"]]:
            continue
        cells = []
        for d in data.values():
            q = next((q for q in d["points"] if q["knob"] == p["knob"] and q["setting"] == p["setting"]), None)
            if q is None:
                cells.append(" | ")
                continue
            e = q["errors"]
            psnr = f" ({q['note']})" if q["note"].startswith("PSNR") else ""
            err = (f"ESR {e['esr']:.2e}, RMS {e['rms']:.2e}" if "esr" in e else
                   " ".join(f"{v:.2e}" for v in e.values()) + psnr)
            cells.append(f"{err} | {q['time_s']:.3f}")
        print(f"| {p['knob']} | {p['setting']} | " + " | ".join(cells) + " |")
    for k, d in data.items():
        print(f"\n{k}: " + "; ".join(
            f"{m} ≤ 1 %: " + (f"{r['cheapest']['setting']}" if r["cheapest"] else "none (" + r["why_not"] + ")")
            for m, r in d["recommendation"].items()))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--part", default="accuracy,third,commands", help="also: defaults, illumination, summary")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--lenses", default="cooke_triplet_opt,cmount_4p", help="shipped lenses for --part commands")
    ap.add_argument("--accuracy-lenses", default="cooke,cmount", help="lenses of --part accuracy")
    ap.add_argument("--knobs", default=",".join(DEFAULT_KNOBS), help="knobs of --part accuracy")
    ap.add_argument("--backends", default="eager,auto,compiled",
                    help="--part commands: backends to time (auto@cold: auto with an empty Inductor cache)")
    ap.add_argument("--cache-dir", default=None, help="--part commands: TORCHINDUCTOR_CACHE_DIR of the runs")
    ap.add_argument("--commands-json", default="results_backend_commands.json",
                    help="--part commands: file name under benchmarks/")
    ap.add_argument("--merge", action="store_true",
                    help="--part accuracy: keep the recorded points of the other knobs in results_accuracy_knobs.json")
    ap.add_argument("--commands", default=None,
                    help="e.g. 'trace rings:32,trace rings:64,plot psf,simulate,evaluate' (default: all)")
    a = ap.parse_args()
    parts = a.part.split(",")
    if "summary" in parts:
        summarize()
        return
    torch.set_num_threads(int(os.environ.get("OMP_NUM_THREADS", "2")))
    print(f"load before: {os.getloadavg()}")
    if "defaults" in parts:
        print("\n| lens | gauss:16 ESR error % | ms wall (CPU) | rings:24 ESR error % | ms wall (CPU) | time ratio | "
              "optimizer sampling: error %, ms |")
        print("| --- | --- | --- | --- | --- | --- | --- |")
        part_defaults(a.repeats)
    results = (part_accuracy(a.repeats, a.accuracy_lenses.split(","), tuple(a.knobs.split(",")), a.merge)
               if "accuracy" in parts else {})
    if "third" in parts:
        part_third(results)
    if "commands" in parts:
        backends = a.backends.split(",")
        print("\n| lens | command | " + " | ".join(f"{b} s" for b in backends) + " | load |")
        print("| --- | --- | " + " | ".join("---" for _ in backends) + " | --- |")
        part_commands(a.repeats, a.lenses.split(","), a.commands.split(",") if a.commands else None, backends,
                      a.cache_dir, a.commands_json)
    if "illumination" in parts:
        part_illumination(401)
    print(f"load after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
