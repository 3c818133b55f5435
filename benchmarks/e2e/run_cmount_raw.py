"""The C-mount study's image-driven row (seed S6.2, Table S15 "raw image quality"): LM on GTRA from the
spot-optimized lenses/cmount_4p.json (specs/cmount_4p_raw.toml). Logs every step, writes the lens and a
JSON record (steps, wall time, held-out PSNR before/after, ESR, constraints, load). SIGINT (Ctrl-C)
stops early and keeps the lens reached so far.

    PYTHONPATH=$PWD OMP_NUM_THREADS=2 python benchmarks/e2e/run_cmount_raw.py [--steps N] \
        [--out lenses/cmount_4p_raw.json]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from lensopt.analysis.report import trace_report
from lensopt.design import build_problem, optimize
from lensopt.optics.sampling import PupilSampling
from lensopt.optim.report import constraint_report
from lensopt.spec import build, load_spec, save_json

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--spec", default=str(ROOT / "specs" / "cmount_4p_raw.toml"))
    ap.add_argument("--steps", type=int, default=None)
    ap.add_argument("--optimizer", default=None)
    ap.add_argument("--out", default=str(ROOT / "lenses" / "cmount_4p_raw.json"))
    ap.add_argument("--record", default=str(ROOT / "benchmarks" / "e2e" / "results_cmount_raw.json"))
    args = ap.parse_args()
    spec = load_spec(args.spec)
    load0 = os.getloadavg()
    t0 = time.perf_counter()

    def log(p) -> None:  # noqa: ANN001
        print(f"step {p.step}/{p.steps} merit {p.merit:.5e} image loss {p.image_loss:.5e} PSNR {p.psnr_db:.3f} dB "
              f"ESR {p.esr_um:.3f} um lambda {p.damping:.2e} acc {p.accepted} rej {p.rejected} "
              f"{p.elapsed_s:.0f} s {p.event}", flush=True)

    result = optimize(spec, optimizer=args.optimizer, steps=args.steps, seed=0, callback=log)
    wall = time.perf_counter() - t0
    save_json(result.spec, Path(args.out))
    sampling = PupilSampling.parse("rings:24", seed=0)
    final = build_problem(result.spec, seed=0)
    cons = constraint_report(final, final.theta0, sampling)
    record = {
        "spec": os.path.relpath(args.spec, ROOT), "output": os.path.relpath(args.out, ROOT),
        "optimizer": args.optimizer or spec.optimize.optimizer,
        "steps": result.steps, "stop_reason": result.stop_reason, "interrupted": result.interrupted,
        "wall_s": wall, "load_before": load0, "load_after": os.getloadavg(),
        "held_out_psnr_db": {"start": result.start_psnr_db, "final": result.final_psnr_db},
        "esr_um_rings24": {"start": trace_report(build(spec), sampling)["effective_spot_radius_um"],
                           "final": trace_report(build(result.spec), sampling)["effective_spot_radius_um"]},
        "constraints_satisfied": cons["satisfied"], "constraints": cons,
        "history": [list(h) for h in result.history], "image_history": [list(h) for h in result.image_history],
    }
    tmp = Path(args.record).with_suffix(".tmp")
    tmp.write_text(json.dumps(record, indent=1))
    os.replace(tmp, args.record)
    print(json.dumps({k: v for k, v in record.items() if k not in ("history", "image_history", "constraints")}))


if __name__ == "__main__":
    main()
