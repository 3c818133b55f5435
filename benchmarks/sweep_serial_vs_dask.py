"""``lensopt sweep`` serially and on a 2-worker Dask LocalCluster: the same table (every number but the
wall times), and the wall time of each. Writes benchmarks/results_sweep_cooke.json.

    PYTHONPATH=$PWD python benchmarks/sweep_serial_vs_dask.py [OUTDIR]

The sweep: specs/cooke_triplet_opt.toml, EFL solve target 48/50/52 mm, 3 starts per point (σ = 0.05),
the spec's 100 LM steps.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ARGS = ["specs/cooke_triplet_opt.toml", "--vary", "optimize.solves[0].value=48,50,52", "--starts", "3",
        "--perturb", "0.05", "--quiet", "--json"]


def run(scheduler: str, out: Path) -> tuple[dict, float]:
    cmd = [sys.executable, "-m", "lensopt", "sweep", *ARGS, "--scheduler", scheduler, "--workers", "2",
           "-o", str(out), "--restart"]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({p.returncode}): {p.stderr[-2000:]}")
    return json.loads(p.stdout), wall


def main() -> None:
    base = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("/tmp/lensopt_sweep_bench")
    serial, t_serial = run("serial", base / "serial")
    dask, t_dask = run("local", base / "dask")
    strip = [{k: v for k, v in r.items() if k != "wall_s"} for r in serial["points"]]
    same = strip == [{k: v for k, v in r.items() if k != "wall_s"} for r in dask["points"]]
    starts_s = json.loads((base / "serial" / "sweep.json").read_text())["starts"]
    starts_d = json.loads((base / "dask" / "sweep.json").read_text())["starts"]
    same_starts = ([{k: v for k, v in r.items() if k != "wall_s"} for r in starts_s]
                   == [{k: v for k, v in r.items() if k != "wall_s"} for r in starts_d])
    out = {"command": "lensopt sweep " + " ".join(ARGS) + " --scheduler serial|local --workers 2",
           "load_average_1min": os.getloadavg()[0], "wall_serial_s": t_serial, "wall_dask_2_workers_s": t_dask,
           "same_table": same, "same_every_start": same_starts, "points": serial["points"],
           "starts": [{k: r.get(k) for k in ("point", "start", "status", "esr_um", "merit", "steps", "stop_reason",
                                             "reason")} for r in starts_s]}
    (ROOT / "benchmarks" / "results_sweep_cooke.json").write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps({k: out[k] for k in ("wall_serial_s", "wall_dask_2_workers_s", "same_table",
                                          "same_every_start", "load_average_1min")}, indent=2))


if __name__ == "__main__":
    main()
