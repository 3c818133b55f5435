"""Issue 13: the trace's share of the ray-heavy commands, per backend (in-process, each command its own process).

Each run is a fresh process that wraps ``accel.dispatch.trace_with`` with a timer, runs one CLI command
(``--backend`` given) and reports the rays traced, the seconds spent in ``trace_with`` (the part the
backend changes; imports, aiming, PSF binning, convolution and plotting are the same on every backend)
and which backend each call took. Backends interleaved, medians of ``--repeats``:

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/trace/command_trace_time.py --cache-dir DIR [--repeats 3]
        [--lenses specs/cooke_triplet.toml,cmount_4p] [--json benchmarks/trace/results_command_trace_time.json]

Run ``lensopt warmup LENS`` with ``TORCHINDUCTOR_CACHE_DIR=DIR`` first, or ``auto`` has no package to use.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
IMG = ROOT / "lensopt" / "imaging" / "data" / "coffee.png"
OUT = ROOT / "out" / "command_trace_time"


def child(args: list[str]) -> None:
    from lensopt.accel import dispatch as backend

    calls: list[tuple[int, str, float]] = []
    real, choose = backend.trace_with, backend.choose_backend
    chosen: list[str] = []

    def spy_choose(*a, **kw):  # type: ignore[no-untyped-def]
        chosen.append(choose(*a, **kw))
        return chosen[-1]

    def timed(lens, rays, **kw):  # type: ignore[no-untyped-def]
        import torch

        n = torch.broadcast_shapes(rays.pos.shape[:-1], rays.dir.shape[:-1], rays.wavelength.shape).numel()
        t = time.perf_counter()
        out = real(lens, rays, **kw)
        calls.append((n, chosen[-1] if chosen else "?", time.perf_counter() - t))
        return out

    backend.choose_backend = spy_choose
    backend.trace_with = timed  # what lensopt.accel.engine puts in the CLI's engines
    from lensopt.cli.app import app

    try:
        app(args, standalone_mode=False)
    except SystemExit:
        pass
    by: dict[str, int] = {}
    for n, b, _ in calls:
        by[b] = by.get(b, 0) + n
    print(json.dumps({"rays": sum(c[0] for c in calls), "trace_s": sum(c[2] for c in calls), "calls": len(calls),
                      "rays_by_backend": by}))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--child", nargs=argparse.REMAINDER)
    ap.add_argument("--lenses", default="specs/cooke_triplet.toml,cmount_4p")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cache-dir", default=None)
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    if a.child is not None:
        child(a.child)
        return
    OUT.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    if a.cache_dir:
        env["TORCHINDUCTOR_CACHE_DIR"] = a.cache_dir
    rows = []
    print("| lens | command | rays | trace s, eager | trace s, auto | ratio | auto's rays on |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for name in a.lenses.split(","):
        lens = str(ROOT / name if "/" in name else ROOT / "lenses" / f"{name}.json")
        cmds = {"trace rings:32": ["trace", lens, "--sampling", "rings:32", "--json"],
                "trace rings:64": ["trace", lens, "--sampling", "rings:64", "--json"],
                "plot psf": ["plot", "psf", lens, "-o", str(OUT / "psf.png")],
                "simulate": ["simulate", lens, str(IMG), "--region", "corner", "-o", str(OUT / "sim.png")],
                "evaluate": ["evaluate", lens, "--count", "20", "--json"]}
        for cname, args in cmds.items():
            res: dict[str, list[dict]] = {"eager": [], "auto": []}
            for _ in range(a.repeats):
                for b in res:
                    r = subprocess.run([sys.executable, __file__, "--child", *args, "--backend", b], env=env,
                                       capture_output=True, text=True)
                    if r.returncode != 0:
                        raise SystemExit(r.stderr[-1000:])
                    res[b].append(json.loads(r.stdout.strip().splitlines()[-1]))
            med = {b: statistics.median(x["trace_s"] for x in v) for b, v in res.items()}
            rows.append({"lens": Path(lens).name, "command": cname, "runs": res})
            e, au = med["eager"], med["auto"]
            print(f"| {Path(lens).name} | {cname} | {res['eager'][0]['rays']:,} | {e:.3f} | {au:.3f} "
                  f"| {e / au:.1f}× | {res['auto'][0]['rays_by_backend']} |", flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps({"rows": rows, "load": os.getloadavg()}, indent=1))


if __name__ == "__main__":
    main()
