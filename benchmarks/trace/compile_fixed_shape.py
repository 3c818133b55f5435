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


def study(lens_path: str, n: int, repeats: int, chunks: list[int], json_out: Path | None,
          cache: str | None = None) -> dict:
    """Issue 29: why the AOT package ran at a third of in-process ``torch.compile``. One process, one thread,
    a private empty Inductor cache; ``n`` rays of ``trace_speed.make_rays`` (every field × wavelength,
    uniform pupil). Variants, timed interleaved (median wall and CPU of ``repeats`` calls on all ``n`` rays):

    - ``compiled``: ``torch.compile`` of ``trace_kernel`` in process, chunks of ``dispatch.COMPILED_CHUNK``;
    - ``aot trace@C``: a package exported from the reference ``trace`` (what ``accel.aot`` built before
      issue 29), chunks of C rays;
    - ``aot kernel@C``: a package exported from ``trace_kernel``, the graph ``torch.compile`` compiles
      (the per-wavelength n/n' table passed in, near-root quadrics, component-major outputs), chunks of C;
    - ``aot kernel@C (runner only)``: the package's ``run`` on pre-made chunks, without the dispatch's
      padding, copies and concatenation;
    - ``compiled, one call``: ``compiled_trace`` on all ``n`` rays at once, made component-major before the
      clock (how benchmarks/trace/trace_speed.py measures the compiled trace); ``eager``: ``trace``.

    ``cache``: an Inductor cache folder of an earlier run whose packages are reused (their build cost is
    the earlier run's, kept in the JSON).
    """
    cache = cache or tempfile.mkdtemp(prefix="lensopt_inductor_study_")
    os.environ["TORCHINDUCTOR_CACHE_DIR"] = cache
    import torch

    from lensopt.accel import aot, dispatch
    from lensopt.accel.compiled import compiled_trace, component_major_rays, near_only_surfaces
    from lensopt.optics.lens import Lens
    from lensopt.optics.trace import KernelOptions, Rays, index_ratio, trace, trace_kernel

    sys.path.insert(0, str(ROOT / "benchmarks" / "trace"))
    from trace_speed import make_rays

    torch.set_num_threads(1)
    model, rays = make_rays(Path(lens_path), n)
    lens = model.lens
    n = rays.pos.shape[0]
    names = aot._LENS_TENSORS
    opts = KernelOptions(near_only=near_only_surfaces(lens))

    class Ref(torch.nn.Module):  # the graph accel.aot exported before issue 29
        def forward(self, *ts):  # type: ignore[no-untyped-def]
            f = dict(zip(names, ts[:8], strict=True))
            r = trace(Lens(shapes=lens.shapes, stop=lens.stop, **f), Rays(*ts[8:11]))
            return r.pos, r.dir, r.status, r.backtrack

    class Kernel(torch.nn.Module):  # the graph accel.compiled compiles
        def forward(self, *ts):  # type: ignore[no-untyped-def]
            f = dict(zip(names, ts[:8], strict=True))
            r = trace_kernel(Lens(shapes=lens.shapes, stop=lens.stop, **f), Rays(*ts[8:11]), opts, ratio=ts[11])
            return r.pos, r.dir, r.status, r.backtrack

    lens_args = [getattr(lens, k).detach().contiguous() for k in names]
    ratio = index_ratio(lens).contiguous()

    def inputs(c: int, j: int = 0, kernel: bool = True) -> list:  # chunk j, component-major rays
        sl = slice(j * c, (j + 1) * c)
        pos = rays.pos[sl].t().contiguous().t()
        dir = rays.dir[sl].t().contiguous().t()
        return [*lens_args, pos, dir, rays.wavelength[sl].contiguous()] + ([ratio] if kernel else [])

    def build(module: torch.nn.Module, c: int, kernel: bool) -> tuple:
        import torch._inductor

        path = Path(cache) / f"{type(module).__name__}_{c}.pt2"
        if path.exists():
            return aot.load_package(path), None
        w0, c0 = time.perf_counter(), time.process_time()
        with torch.no_grad():
            prog = torch.export.export(module, tuple(inputs(c, 0, kernel)), strict=False)
            torch._inductor.aoti_compile_and_package(prog, package_path=str(path),
                                                     inductor_configs={"max_fusion_size": aot._MAX_FUSION_SIZE})
        cost = {"build_wall_s": time.perf_counter() - w0, "build_cpu_s": time.process_time() - c0}
        return aot.load_package(path), cost

    def chunked(runner, c: int, kernel: bool):  # type: ignore[no-untyped-def]
        def fn(lens_, r, **kw):  # type: ignore[no-untyped-def]
            from lensopt.optics.trace import RayTrace
            a = [*lens_args, r.pos, r.dir, r.wavelength.contiguous()] + ([ratio] if kernel else [])
            pos, dir, status, back = runner.run(a)
            return RayTrace(pos=pos, dir=dir, status=status, backtrack=back, hits=(), failed_at=None)
        return lambda: dispatch._compiled_in_chunks(fn, lens, rays, size=c)

    variants: dict = {}
    info: dict = {"lens": Path(lens_path).name, "rays": n, "threads": torch.get_num_threads(),
                  "compiled_chunk": dispatch.COMPILED_CHUNK, "torch": torch.__version__}
    with torch.no_grad():
        ref = trace(lens, rays)
        w0, c0 = time.perf_counter(), time.process_time()
        variants["compiled"] = lambda: dispatch._compiled_in_chunks(compiled_trace, lens, rays,
                                                                    size=dispatch.COMPILED_CHUNK)
        variants["compiled"]()
        info["compiled_first_call"] = {"wall_s": time.perf_counter() - w0, "cpu_s": time.process_time() - c0}
        cm = component_major_rays(rays)
        variants["compiled, one call"] = lambda: compiled_trace(lens, cm, fallback=False)
        w0, c0 = time.perf_counter(), time.process_time()
        variants["compiled, one call"]()
        info["compiled_one_call_first_call"] = {"wall_s": time.perf_counter() - w0, "cpu_s": time.process_time() - c0}
        variants["eager"] = lambda: trace(lens, rays)
        for c in chunks:
            for module, kernel in ((Ref(), False), (Kernel(), True)):
                runner, cost = build(module, c, kernel)
                name = f"aot {'kernel' if kernel else 'trace'}@{c}"
                if cost is not None:
                    info[name + " build"] = cost
                variants[name] = chunked(runner, c, kernel)
                if kernel:
                    pre = [inputs(c, j, True) for j in range(n // c)]
                    variants[name + " (runner only)"] = lambda runner=runner, pre=pre: [runner.run(a) for a in pre]
                print(f"built {name}: {cost}", flush=True)
        checks = {}
        for name, fn in variants.items():
            if "runner only" in name:
                continue
            out = fn()
            checks[name] = {"max_diff_mm": float((out.pos - ref.pos)[ref.valid].abs().max()),
                            "same_status": bool(torch.equal(out.status, ref.status))}
        times: dict = {k: {"wall": [], "cpu": []} for k in variants}
        for _ in range(repeats):
            for name, fn in variants.items():
                w0, c0 = time.perf_counter(), time.process_time()
                fn()
                times[name]["wall"].append(time.perf_counter() - w0)
                times[name]["cpu"].append(time.process_time() - c0)
    base = statistics.median(times["compiled"]["wall"])
    rows = {k: {"wall_ms": 1e3 * statistics.median(v["wall"]), "cpu_ms": 1e3 * statistics.median(v["cpu"]),
                "wall_vs_compiled": statistics.median(v["wall"]) / base, **checks.get(k, {})} for k, v in times.items()}
    res = {**info, "repeats": repeats, "load": os.getloadavg(), "variants": rows}
    for k, v in rows.items():
        print(f"| {k} | {v['wall_ms']:.1f} | {v['cpu_ms']:.1f} | {v['wall_vs_compiled']:.2f} |", flush=True)
    if json_out is not None:
        data = json.loads(json_out.read_text()) if json_out.exists() else {}
        old = data.get("aot_vs_compiled", {})
        res = {**{k: v for k, v in old.items() if k.endswith(" build")}, **res}  # builds of reused packages
        data["aot_vs_compiled"] = res
        json_out.write_text(json.dumps(data, indent=1))
    return res


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--child", default=None)
    ap.add_argument("--lenses", default="cooke_triplet_opt,cmount_4p")
    ap.add_argument("--warm", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", default=None)
    ap.add_argument("--kind", default="aot", choices=("aot", "compiled"),
                    help="aot: the AOT package (accel.aot); compiled: torch.compile in the process")
    ap.add_argument("--study", action="store_true", help="issue 29: AOT package variants against torch.compile "
                    "in one process (--lenses: one lens; --rays, --chunks)")
    ap.add_argument("--rays", type=int, default=1 << 20)
    ap.add_argument("--chunks", default="16384,65536")
    ap.add_argument("--study-cache", default=None, help="--study: reuse the packages of this Inductor cache folder")
    a = ap.parse_args()
    if a.study:
        name = a.lenses.split(",")[0]
        study(str(ROOT / name if "/" in name else ROOT / "lenses" / f"{name}.json"), a.rays, a.repeats,
              [int(c) for c in a.chunks.split(",")], Path(a.json) if a.json else None, a.study_cache)
    elif a.child:
        print(json.dumps(child(a.child, a.repeats, a.kind)))
    else:
        parent(a.lenses.split(","), a.warm, a.repeats, a.kind, Path(a.json) if a.json else None)


if __name__ == "__main__":
    main()
