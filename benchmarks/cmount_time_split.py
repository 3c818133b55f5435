"""Where the time of `lensopt optimize specs/cmount_4p.toml` goes (issue 14): the same library call as
the CLI (``design.optimize``, steps and schedule as in the spec, seed 0), with timers around the
Jacobian (``Problem.jacobian`` or the compiled one, its one-off capture + compile apart), the trial
residual evaluations (``Problem.evaluate``) and the damped least-squares solve (``lm.damped_step``).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/cmount_time_split.py [--jacobian compiled] [--steps N]

Prints a markdown table: wall time, steps, ESR (rings:24 of the optimization rays, the CLI's figure)
and the split. The rest ("other") is the optimizer loop, schedules, glass binding and the final report.
"""

from __future__ import annotations

import argparse
import os
import time
from collections import defaultdict
from pathlib import Path

from lensopt.accel import jacobian as compiled_jacobian
from lensopt.analysis.report import trace_report
from lensopt.design import optimize
from lensopt.optics.sampling import PupilSampling
from lensopt.optim import lm, problem
from lensopt.spec import build, load_spec

SPEC = Path(__file__).resolve().parents[1] / "specs" / "cmount_4p.toml"
spent: dict[str, float] = defaultdict(float)
calls: dict[str, int] = defaultdict(int)


def timed(name: str, fn):  # noqa: ANN001, ANN201 - a thin wrapper
    def wrapper(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            spent[name] += time.perf_counter() - t0
            calls[name] += 1
    return wrapper


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jacobian", choices=["eager", "compiled"], default="eager")
    ap.add_argument("--steps", type=int, default=None, help="default: the spec's steps")
    ap.add_argument("--spec", type=Path, default=SPEC)
    args = ap.parse_args()
    problem.Problem.jacobian = timed("Jacobian (eager jacfwd)", problem.Problem.jacobian)
    problem.Problem.evaluate = timed("residual evaluations (trial points, checks)", problem.Problem.evaluate)
    lm.damped_step = timed("damped least-squares solve", lm.damped_step)
    cj = compiled_jacobian.CompiledJacobian
    cj._build = timed("compiled Jacobian: capture + compile + check (one-off)", cj._build)
    cj.__call__ = timed("Jacobian (compiled, including its one-off build)", cj.__call__)
    load = os.getloadavg()
    t0 = time.perf_counter()
    res = optimize(load_spec(args.spec), steps=args.steps, seed=0, jacobian=args.jacobian)
    wall = time.perf_counter() - t0
    # The ESR the CLI reports (rings:24 over the spec's fields and wavelengths), start and final lens.
    sampling = PupilSampling.parse("rings:24", seed=0)
    esr = [trace_report(build(s), sampling)["effective_spot_radius_um"] for s in (load_spec(args.spec), res.spec)]
    print(f"`{args.spec.name}`, --jacobian {args.jacobian}: {res.steps} steps ({res.stop_reason}), "
          f"ESR (rings:24) {esr[0]:.3f} → {esr[1]:.3f} µm, wall {wall:.1f} s; "
          f"load {load[0]:.1f} → {os.getloadavg()[0]:.1f}; bound: {', '.join(b.name for b in res.bound) or '-'}\n")
    print("| part | calls | s | share of wall |\n| --- | ---: | ---: | ---: |")
    for name in sorted(spent, key=spent.get, reverse=True):
        print(f"| {name} | {calls[name]} | {spent[name]:.1f} | {100 * spent[name] / wall:.0f} % |")
    inner = spent.get("Jacobian (eager jacfwd)", 0.0) if args.jacobian == "compiled" else 0.0
    accounted = sum(v for k, v in spent.items() if not k.startswith("compiled Jacobian: capture")) - inner
    print(f"| other (loop, schedules, binding, report) | | {wall - accounted:.1f} | "
          f"{100 * (wall - accounted) / wall:.0f} % |")


if __name__ == "__main__":
    main()
