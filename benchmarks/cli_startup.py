"""Startup of ``lensopt --help``: wall time (alternating runs, median and min) and modules imported,
for this tree and a baseline tree (default: /work/main), plus ``python -c pass`` for scale.

    PYTHONPATH=. python benchmarks/cli_startup.py [--baseline DIR] [--repeats 12]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

HELP = ("import sys; sys.argv = ['lensopt', '--help']\nfrom lensopt.cli.app import app\n"
        "try:\n    app()\nexcept SystemExit:\n    pass")
COUNT = HELP + "\nprint(len(sys.modules), 'torch' in sys.modules, file=sys.stderr)"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baseline", default="/work/main")
    ap.add_argument("--repeats", type=int, default=12)
    args = ap.parse_args()
    trees = {"baseline": args.baseline, "this tree": str(Path(__file__).resolve().parents[1])}
    times: dict[str, list[float]] = {k: [] for k in trees}
    bare: list[float] = []
    # cwd=tree: "python -c" puts the working directory first on sys.path, before PYTHONPATH.
    for _ in range(args.repeats):
        for name, tree in trees.items():
            env = {**os.environ, "PYTHONPATH": tree}
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-c", HELP], env=env, cwd=tree, capture_output=True, check=True)
            times[name].append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "pass"], capture_output=True, check=True)
        bare.append(time.perf_counter() - t0)
    print(f"load average {os.getloadavg()[0]:.1f}")
    for name, tree in trees.items():
        env = {**os.environ, "PYTHONPATH": tree}
        err = subprocess.run([sys.executable, "-c", COUNT], env=env, cwd=tree, capture_output=True, text=True).stderr
        modules, torch = err.strip().splitlines()[-1].split()
        v = times[name]
        print(f"{name} ({tree}): median {statistics.median(v):.3f} s, min {min(v):.3f} s over {len(v)} runs; "
              f"{modules} modules, torch imported: {torch}")
    print(f"python -c pass: median {statistics.median(bare):.3f} s, min {min(bare):.3f} s")


if __name__ == "__main__":
    main()
