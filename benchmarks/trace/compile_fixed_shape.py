"""Issue 13: what the compiled trace costs and buys per process when it is always fed one shape.

The compiled kernels get fixed chunks (``backend.COMPILED_CHUNK`` rays for ``torch.compile``,
``aot.AOT_CHUNK`` for an AOT package; the last chunk padded), so a lens structure compiles once per
machine. ``--kind compiled``: ``torch.compile`` in the process (later processes find Inductor's on-disk
caches); ``--kind aot`` (default): the structure's AOT package (``accel.aot``), built by the cold process.
Each measurement is a fresh process (``--child``) that:

1. imports lensopt and builds the lens and a ray batch (the ``rings:64`` bundle of every field and
   wavelength, the batch ``lensopt trace --sampling rings:64`` traces);
2. times its first compiled call on one chunk: the compilation with a cold cache; with a warm one,
   whatever a new process pays (Dynamo's tracing and the cache look-ups, or loading the package);
3. times steady calls (median of ``--repeats``) of the compiled and the eager trace on n rays, n from
   100 to the whole batch, interleaved.

The parent runs, per lens, with a private, empty ``TORCHINDUCTOR_CACHE_DIR``: one cold process, then
``--warm`` warm ones (benchmarks/README.md, trace):

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/trace/compile_fixed_shape.py --kind aot \
        --lenses cooke_triplet_opt,cmount_4p --warm 2 --repeats 5 \
        --json benchmarks/trace/results_compile_fixed_shape_aot.json
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SIZES = (100, 1_000, 4_000, 16_384, 65_536, 262_144)


def child(lens_path: str, repeats: int, kind: str) -> dict:
    t0 = time.perf_counter()
    import torch

    from lensopt import accel
    from lensopt.accel import aot
    from lensopt.accel import dispatch as backend
    from lensopt.engine import Engine
    from lensopt.optics import bundle
    from lensopt.optics.sampling import PupilSampling
    from lensopt.optics.trace import Rays, trace
    from lensopt.spec import build, load_spec

    torch.set_num_threads(int(os.environ.get("OMP_NUM_THREADS", "1")))
    t_import = time.perf_counter() - t0
    model = build(load_spec(lens_path))
    captured: list[Rays] = []
    def capture(lens, rays, **kw):  # type: ignore[no-untyped-def]
        captured.append(rays)
        return trace(lens, rays, upto=kw["upto"], record=kw["record"])

    with torch.no_grad():
        bundle.trace_bundle(model.lens, model.system, PupilSampling.parse("rings:64").points(dtype=torch.float64),
                            half_pupil=True, engine=Engine(backend="eager", tracer=capture))
    rays = captured[-1]
    pos, dir = torch.broadcast_tensors(rays.pos, rays.dir)
    pos, dir = pos.reshape(-1, 3), dir.reshape(-1, 3)
    wl = torch.broadcast_to(rays.wavelength, rays.pos.shape[:-1]).reshape(-1)
    total = pos.shape[0]
    chunk = aot.AOT_CHUNK if kind == "aot" else backend.COMPILED_CHUNK
    out: dict = {"import_s": t_import, "batch_rays": total, "chunk": chunk, "kind": kind}

    def sub(n: int) -> Rays:
        idx = torch.arange(n) % total
        return Rays(pos[idx], dir[idx], wl[idx])

    lens = model.lens
    with torch.no_grad():
        r = sub(chunk)
        t = time.perf_counter()
        if kind == "aot" and not aot.has_package(lens):
            out["build_s"] = aot.build_package(lens)
        backend.trace_with(lens, r, engine=accel.engine("compiled"))
        out["first_call_s"] = time.perf_counter() - t
        if kind == "aot":
            assert aot.has_package(lens) and backend.choose_backend(lens, chunk, backend="compiled") == "aot"
        t = time.perf_counter()
        backend.trace_with(lens, r, engine=accel.engine("compiled"))
        out["second_call_s"] = time.perf_counter() - t
        check = sub(min(total, 100_000))
        a, b = trace(lens, check), backend.trace_with(lens, check, engine=accel.engine("compiled"))
        ok = a.valid
        out["max_diff_mm"] = float((a.pos - b.pos)[ok].abs().max())
        out["same_status"] = bool(torch.equal(a.status, b.status))
        steady: dict[str, dict[str, float]] = {}
        for n in (*SIZES, total):
            r = sub(n)
            times: dict[str, list[float]] = {"eager": [], "compiled": []}
            for _ in range(repeats):
                for name in ("eager", "compiled"):
                    t = time.perf_counter()
                    backend.trace_with(lens, r, engine=accel.engine(name))
                    times[name].append(time.perf_counter() - t)
            steady[str(n)] = {k: statistics.median(v) for k, v in times.items()}
        out["steady_s"] = steady
    out["load"] = os.getloadavg()
    return out


def parent(lenses: list[str], warm: int, repeats: int, kind: str, json_out: Path | None) -> None:
    results = {}
    for name in lenses:
        path = ROOT / name if "/" in name else ROOT / "lenses" / f"{name}.json"
        runs = []
        with tempfile.TemporaryDirectory(prefix="lensopt_inductor_") as cache:
            env = {**os.environ, "TORCHINDUCTOR_CACHE_DIR": cache, "PYTHONPATH": str(ROOT)}
            for i in range(1 + warm):
                t = time.perf_counter()
                r = subprocess.run([sys.executable, __file__, "--child", str(path), "--repeats", str(repeats),
                                    "--kind", kind],
                                   env=env, capture_output=True, text=True)
                if r.returncode != 0:
                    raise SystemExit(r.stderr[-2000:])
                d = json.loads(r.stdout.strip().splitlines()[-1])
                d["process_s"] = time.perf_counter() - t
                d["cache"] = "cold" if i == 0 else "warm"
                runs.append(d)
                print(f"{path.name} {kind} {d['cache']}: first compiled call {d['first_call_s']:.2f} s, second "
                      f"{d['second_call_s'] * 1e3:.1f} ms, process {d['process_s']:.1f} s, max diff "
                      f"{d['max_diff_mm']:.1e} mm, same status {d['same_status']}, load {d['load'][0]:.1f}", flush=True)
        results[path.name] = runs
        last = runs[-1]
        print(f"\n{path.name}: batch {last['batch_rays']} rays (rings:64, all fields and wavelengths)")
        print(f"| rays | eager ms | compiled ms (chunks of {last['chunk']}) | ratio |")
        print("| --- | --- | --- | --- |")
        for n, v in last["steady_s"].items():
            e, c = v["eager"], v["compiled"]
            print(f"| {int(n):,} | {e * 1e3:.2f} | {c * 1e3:.2f} | {e / c:.2f} |")
    if json_out is not None:
        json_out.write_text(json.dumps(results, indent=1))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--child", default=None)
    ap.add_argument("--lenses", default="cooke_triplet_opt,cmount_4p")
    ap.add_argument("--warm", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", default=None)
    ap.add_argument("--kind", default="aot", choices=("aot", "compiled"),
                    help="aot: the AOT package (accel.aot); compiled: torch.compile in the process")
    a = ap.parse_args()
    if a.child:
        print(json.dumps(child(a.child, a.repeats, a.kind)))
    else:
        parent(a.lenses.split(","), a.warm, a.repeats, a.kind, Path(a.json) if a.json else None)


if __name__ == "__main__":
    main()
