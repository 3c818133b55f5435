"""LM against Adam on the same problem and wall-time budget (issue 3; seed S2.3): merit ½‖ℓ‖² against
wall time, from the same residual function.

Problem: the C-mount study's crude start (specs/cmount_4p.toml) with the glasses held at the start
glass, so that both optimizers see one fixed merit function (no binding, no schedule); the Cooke
triplet problem (specs/cooke_triplet_opt.toml) with ``--problem cooke``. Adam runs with several
learning rates (the best is reported); LM with the Table S7 defaults.

    .venv/bin/python benchmarks/optimize/lm_vs_adam.py --budget 180 \\
        --json benchmarks/optimize/results_lm_vs_adam.json \\
        --plot benchmarks/optimize/lm_vs_adam.png

``--jacobian compiled`` gives LM the compiled forward-mode Jacobian (``accel.jacobian``, its AOT
package): its first call — loading the problem's package, or capturing and compiling it when this machine
has none yet — runs *inside* LM's clock and is reported beside the curves (where the package came from and
the seconds of that first call); ``--jacobian eager compiled``: one LM run with each. Run it twice: the
first run on a machine builds the package within LM's time, a second run loads it.

On a loaded machine: ``--clock cpu`` measures every run by its own process CPU time (one thread, so on
an idle machine the same as its wall time) and ``--parallel`` runs them at once, each in its own
process (the load the other sessions put on the machine then slows every run alike and does not enter
the clock); ``--lm-budget`` stops LM sooner (its time to the target merit is what is compared).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/optimize/lm_vs_adam.py --problem cmount --budget 180 --lm-budget 60 \
        --lrs 2e-3 4e-3 8e-3 --jacobian eager compiled --clock cpu --parallel The
"time to merit" table gives, for the merit the best Adam run reaches within the budget, how soon each
run first reaches it, and LM's lead over that Adam run (its time / LM's time).

The trace backend is pinned (``--backend``, default eager) for every run: under ``auto`` the residual
function switches to the compiled trace once 10 M rays of a structure have been traced in the
process, so a later run would pay a compile (minutes, and a backward graph for Adam) in the middle
of its clock, and runs would not see the same residual function.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import time
from pathlib import Path

import torch

from lensopt import accel
from lensopt.design import build_problem
from lensopt.engine import retain_freed_memory
from lensopt.optim import Problem
from lensopt.optim.driver import make_optimizer
from lensopt.spec import load_spec

SPECS = Path(__file__).resolve().parents[2] / "specs"


BACKEND = ["eager"]  # this script's --backend (set in main / _worker before the problems are built)


def problem(name: str) -> Problem:
    engine = accel.engine(BACKEND[0])
    if name == "cooke":
        return build_problem(load_spec(SPECS / "cooke_triplet_opt.toml"), engine=engine)
    spec = load_spec(SPECS / "cmount_4p.toml")
    for s in spec.surfaces:
        s.vary = [v for v in s.vary if v != "material"]
    return build_problem(spec, engine=engine)


def _cpu_s() -> float:
    """This process's CPU time and that of its finished children (the C++ compiler AOTInductor runs)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


CLOCKS = {"wall": time.perf_counter, "cpu": _cpu_s}


def run(p: Problem, method: str, budget_s: float, lr: float | None = None,
        jacobian: str = "eager", clock: str = "wall") -> tuple[list[tuple[float, float]], dict]:
    """(seconds, best merit so far) after every step until the budget is spent, and how the compiled
    Jacobian's first call went (where it came from, its seconds, within the clock; {} for eager).
    ``clock``: ``wall`` (perf_counter) or ``cpu`` (this process's CPU time and its children's: one
    thread, so on an idle machine the same as wall time, and robust to the load of other processes)."""
    now = CLOCKS[clock]
    if lr is not None:  # the settings are frozen dataclasses
        p.opt = dataclasses.replace(p.opt, adam=dataclasses.replace(p.opt.adam, lr=lr))
    opt = make_optimizer(p, p.theta0, method, jacobian if method == "lm" else "eager")
    first: dict = {}
    one = torch.ones(p.size, dtype=p.dtype)
    t0 = now()
    if method == "lm" and jacobian == "compiled":
        jac = opt._jacobian
        jac(p.theta0)  # load (or build) the package and check it: within the clock
        if not jac.compiled:
            raise RuntimeError(f"compiled Jacobian unavailable: {jac.failed}")
        first = {"source": jac.source, "first_call_s": now() - t0, "build_wall_s": jac.build_s}
    best = opt.merit(one)
    trace = [(0.0, best)]
    while now() - t0 < budget_s:
        info = opt.step(one)
        if info.accepted and math.isfinite(info.merit):
            best = min(best, info.merit)
        trace.append((now() - t0, best))
    return trace, first


def _worker(name: str, method: str, budget_s: float, lr: float | None, jacobian: str, clock: str,
            backend: str) -> tuple[str, list[tuple[float, float]], dict, tuple[float, float, float]]:
    """One optimizer run in a fresh process (``--parallel``)."""
    torch.set_num_threads(1)
    BACKEND[0] = backend
    retain_freed_memory()
    trace, info = run(problem(name), method, budget_s, lr, jacobian, clock)
    return method, trace, info, os.getloadavg()


def first_reach(trace: list[tuple[float, float]], merit: float) -> float:
    """Wall seconds at which the run's best merit first got to ``merit`` or below (inf: never)."""
    return next((t for t, m in trace if m <= merit), math.inf)


def thin(trace: list[tuple[float, float]], points: int = 400) -> list[list[float]]:
    """At most ~``points`` (wall s, merit) pairs: every k-th step and the last, rounded for the record."""
    k = max(1, len(trace) // points)
    kept = trace[::k] + ([trace[-1]] if (len(trace) - 1) % k else [])
    return [[round(t, 3), float(f"{m:.6e}")] for t, m in kept]


def at(trace: list[tuple[float, float]], t: float) -> float:
    """Best merit at ``t`` (the run's last, when its budget was shorter)."""
    return min(m for s, m in trace if s <= t)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problem", choices=["cmount", "cooke"], default="cmount")
    ap.add_argument("--budget", type=float, default=180.0, help="wall seconds per optimizer run")
    ap.add_argument("--lrs", type=float, nargs="+", default=[1e-4, 1e-3, 1e-2])
    ap.add_argument("--jacobian", choices=["eager", "compiled"], nargs="+", default=["eager"],
                    help="LM's Jacobian (several: one LM run each)")
    ap.add_argument("--backend", choices=["eager", "compiled", "auto"], default="eager",
                    help="trace backend of the residual function, for every run")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--plot", type=Path, default=None)
    ap.add_argument("--clock", choices=sorted(CLOCKS), default="wall",
                    help="wall: perf_counter; cpu: each run's process CPU time (load-robust)")
    ap.add_argument("--lm-budget", type=float, default=None,
                    help="LM's budget, if shorter (its time to the target merit is what is compared)")
    ap.add_argument("--parallel", action="store_true",
                    help="every run in its own process, all at once (with --clock cpu)")
    ap.add_argument("--prebuild", action="store_true",
                    help="build LM's Jacobian package first (when missing), outside every clock")
    args = ap.parse_args()
    load_before = os.getloadavg()
    torch.set_num_threads(1)
    retain_freed_memory()
    BACKEND[0] = args.backend
    p = problem(args.problem)
    if args.prebuild and "compiled" in args.jacobian:
        from lensopt.accel.jacobian import CompiledJacobian

        c0, jac = _cpu_s(), CompiledJacobian(problem(args.problem))
        jac(p.theta0)
        print(f"LM's Jacobian package: {jac.source or jac.failed}, {_cpu_s() - c0:.1f} s of CPU (before the runs)")
    lm_names = {j: "LM (Table S7)" + (", compiled Jacobian" if j == "compiled" else ", eager Jacobian"
                                       if len(args.jacobian) > 1 else "") for j in args.jacobian}
    jobs = ([(lm_names[j], "lm", None, j) for j in args.jacobian]
            + [(f"Adam lr={lr:g}", "adam", lr, "eager") for lr in args.lrs])
    budgets = {"lm": args.lm_budget or args.budget, "adam": args.budget}
    runs, first_call = {}, {}
    if args.parallel:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(len(jobs), mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = {name: pool.submit(_worker, args.problem, method, budgets[method], lr, jac, args.clock,
                                         args.backend) for name, method, lr, jac in jobs}
            for name, fut in futures.items():
                _, runs[name], first_call[name], _ = fut.result()
    else:
        for name, method, lr, jac in jobs:
            runs[name], first_call[name] = run(p if method == "lm" else problem(args.problem), method, budgets[method],
                                              lr, jac, args.clock)
    start = runs[jobs[0][0]][0][1]
    mode = ", runs in parallel" if args.parallel else ""
    checkpoints = [args.budget * f for f in (0.1, 0.25, 0.5, 1.0)]
    print(f"problem {args.problem}: N = {p.num_variables}, M = {p.size}, start merit {start:.4e}, "
          f"budget {args.budget:g} s ({args.clock} clock{mode}) per run"
          + (f" (LM {budgets['lm']:g} s)" if budgets["lm"] != args.budget else "")
          + f", load average {load_before} → {os.getloadavg()}\n")
    print("| optimizer | steps | " + " | ".join(f"merit at {c:g} s" for c in checkpoints) + " |")
    print("| --- | ---: | " + " | ".join("---:" for _ in checkpoints) + " |")
    for name, tr in runs.items():
        print(f"| {name} | {len(tr) - 1} | " + " | ".join(f"{at(tr, c):.4e}" for c in checkpoints) + " |")
    for name, c in first_call.items():
        if c:
            print(f"\n{name}: {c['source']}, first Jacobian call {c['first_call_s']:.1f} s (within its clock)")
    adams = {k: v for k, v in runs.items() if k.startswith("Adam")}
    best_adam = min(adams, key=lambda k: adams[k][-1][1])
    target = adams[best_adam][-1][1]
    t_adam = first_reach(adams[best_adam], target)
    print(f"\nTime to the merit the best Adam ({best_adam}) reaches in {args.budget:g} s, {target:.4e}:\n")
    print("| optimizer | first reaches it at (s) |\n| --- | ---: |")
    for name, tr in runs.items():
        print(f"| {name} | {first_reach(tr, target):.1f} |")
    leads = {}
    for name in lm_names.values():
        t_lm, c = first_reach(runs[name], target), first_call[name]
        leads[name] = {"reaches_s": t_lm, "lead": t_adam / t_lm, **c}
        print(f"\n{name}: lead over the best Adam {t_adam:.1f} s / {t_lm:.1f} s = **{t_adam / t_lm:.1f}×** sooner"
              + (f" (its Jacobian: {c['source']}, within the clock)" if c else ""))
    if args.json:
        from lensopt.files import write_text_atomic

        write_text_atomic(args.json, json.dumps({
            "problem": args.problem, "variables": p.num_variables, "residuals": p.size, "budget_s": args.budget,
            "loadavg_before": load_before, "loadavg_after": os.getloadavg(), "threads": torch.get_num_threads(),
            "jacobian": args.jacobian, "backend": args.backend,
            "clock": args.clock, "parallel": args.parallel, "lm_budget_s": budgets["lm"],
            "jacobian_first_call": first_call, "best_adam": best_adam,
            "target_merit": target, "best_adam_reaches_s": t_adam, "lm": leads,
            "runs": {k: thin(v) for k, v in runs.items()}}) + "\n")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from lensopt.files import atomic_path

        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        for name, tr in runs.items():
            ax.plot([t for t, _ in tr], [m for _, m in tr], label=name, lw=2 if name.startswith("LM") else 1)
        ax.set_yscale("log")
        ax.set_xlabel("wall time (s)" if args.clock == "wall" else "process CPU time (s)")
        ax.set_ylabel("best merit ½‖ℓ‖²")
        ax.set_title(f"LM vs Adam, {args.problem} (N = {p.num_variables})")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        fig.tight_layout()
        with atomic_path(args.plot) as tmp:
            fig.savefig(tmp, dpi=120)


if __name__ == "__main__":
    main()
