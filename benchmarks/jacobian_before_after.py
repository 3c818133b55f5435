"""The optimizer's eager Jacobian (``Problem.jacobian``, jacfwd through the eager trace) of this
checkout against another checkout's, in one process (issue 14): equal bit for bit, and its time.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/jacobian_before_after.py --before /path/to/old/checkout
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import torch
from trace_speed import import_before

SPECS = Path(__file__).resolve().parents[1] / "specs"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, required=True, help="root of the other checkout")
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    import_before(args.before)
    from lensopt_before.optim import Problem as OldProblem
    from lensopt_before.spec import load_spec as old_load_spec

    from lensopt.design import build_problem
    from lensopt.spec import load_spec

    print(f"load {os.getloadavg()[0]:.1f}, {torch.get_num_threads()} thread(s); medians of {args.repeats} "
          "interleaved repeats at the start point\n")
    print("| problem | J and ℓ equal bit for bit | Jacobian now s | before s | before / now |\n"
          "| --- | --- | ---: | ---: | ---: |")
    for name in ("cooke_triplet_opt", "cmount_4p"):
        new, old = build_problem(load_spec(SPECS / f"{name}.toml")), OldProblem(old_load_spec(SPECS / f"{name}.toml"))
        theta = new.theta0
        (jn, rn), (jo, ro) = new.jacobian(theta), old.jacobian(theta)
        same = torch.equal(jn, jo) and torch.equal(rn, ro)
        times: dict[str, list[float]] = {"now": [], "before": []}
        for _ in range(args.repeats):
            for key, p in (("now", new), ("before", old)):
                t0 = time.perf_counter()
                p.jacobian(theta)
                times[key].append(time.perf_counter() - t0)
        now, before = statistics.median(times["now"]), statistics.median(times["before"])
        print(f"| {name} (N = {new.num_variables}) | {same} | {now:.3f} | {before:.3f} | {before / now:.2f} |")


if __name__ == "__main__":
    main()
