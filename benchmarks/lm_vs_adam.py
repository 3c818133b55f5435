"""LM against Adam on the same problem and wall-time budget (issue 3; seed S2.3): merit ½‖ℓ‖² against
wall time, from the same residual function.

Problem: the C-mount study's crude start (specs/cmount_4p.toml) with the glasses held at the start
glass, so that both optimizers see one fixed merit function (no binding, no schedule); the Cooke
triplet problem (specs/cooke_triplet_opt.toml) with ``--problem cooke``. Adam runs with several
learning rates (the best is reported); LM with the Table S7 defaults.

    .venv/bin/python benchmarks/lm_vs_adam.py --budget 180 --json benchmarks/results_lm_vs_adam.json \\
        --plot benchmarks/lm_vs_adam.png

``--jacobian compiled`` gives LM the compiled forward-mode Jacobian (``optim.compiled_jacobian``); its
one-off capture + compile runs before the clock starts and is reported beside the curves. The
"time to merit" table gives, for the merit the best Adam run reaches within the budget, how soon each
run first reaches it, and LM's lead over that Adam run (its time / LM's time).

The trace backend is pinned (``--backend``, default eager) for every run: under ``auto`` the residual
function switches to the compiled trace once 10 M rays of a structure have been traced in the
process, so a later run would pay a compile (minutes, and a backward graph for Adam) in the middle
of its clock, and runs would not see the same residual function.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import torch

from lensopt.design import build_problem
from lensopt.optics.backend import set_backend
from lensopt.optim import Problem
from lensopt.optim.run import make_optimizer
from lensopt.spec import load_spec

SPECS = Path(__file__).resolve().parents[1] / "specs"


def problem(name: str) -> Problem:
    if name == "cooke":
        return build_problem(load_spec(SPECS / "cooke_triplet_opt.toml"))
    spec = load_spec(SPECS / "cmount_4p.toml")
    for s in spec.surfaces:
        s.vary = [v for v in s.vary if v != "material"]
    return build_problem(spec)


def run(p: Problem, method: str, budget_s: float, lr: float | None = None,
        jacobian: str = "eager") -> tuple[list[tuple[float, float]], float]:
    """(wall s, best merit so far) after every step until the budget is spent, and the seconds of
    the one-off Jacobian compile before the clock started (0 for eager)."""
    if lr is not None:
        p.opt.adam.lr = lr
    opt = make_optimizer(p, p.theta0, method, jacobian if method == "lm" else "eager")
    compile_s = 0.0
    if method == "lm" and jacobian == "compiled":
        t0 = time.perf_counter()
        opt._jacobian(p.theta0)  # capture + compile + check against eager, outside the clock
        compile_s = time.perf_counter() - t0
        if not opt._jacobian.compiled:
            raise RuntimeError(f"compiled Jacobian unavailable: {opt._jacobian.failed}")
    one = torch.ones(p.size, dtype=p.dtype)
    t0 = time.perf_counter()
    best = opt.merit(one)
    trace = [(0.0, best)]
    while time.perf_counter() - t0 < budget_s:
        info = opt.step(one)
        if info.accepted and math.isfinite(info.merit):
            best = min(best, info.merit)
        trace.append((time.perf_counter() - t0, best))
    return trace, compile_s


def first_reach(trace: list[tuple[float, float]], merit: float) -> float:
    """Wall seconds at which the run's best merit first got to ``merit`` or below (inf: never)."""
    return next((t for t, m in trace if m <= merit), math.inf)


def thin(trace: list[tuple[float, float]], points: int = 400) -> list[list[float]]:
    """At most ~``points`` (wall s, merit) pairs: every k-th step and the last, rounded for the record."""
    k = max(1, len(trace) // points)
    kept = trace[::k] + ([trace[-1]] if (len(trace) - 1) % k else [])
    return [[round(t, 3), float(f"{m:.6e}")] for t, m in kept]


def at(trace: list[tuple[float, float]], t: float) -> float:
    return min(m for s, m in trace if s <= t)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problem", choices=["cmount", "cooke"], default="cmount")
    ap.add_argument("--budget", type=float, default=180.0, help="wall seconds per optimizer run")
    ap.add_argument("--lrs", type=float, nargs="+", default=[1e-4, 1e-3, 1e-2])
    ap.add_argument("--jacobian", choices=["eager", "compiled"], default="eager", help="LM's Jacobian")
    ap.add_argument("--backend", choices=["eager", "compiled", "auto"], default="eager",
                    help="trace backend of the residual function, for every run")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--plot", type=Path, default=None)
    args = ap.parse_args()
    load_before = os.getloadavg()
    p = problem(args.problem)
    set_backend(args.backend)
    lm_name = "LM (Table S7)" + (", compiled Jacobian" if args.jacobian == "compiled" else "")
    runs = {}
    runs[lm_name], compile_s = run(p, "lm", args.budget, jacobian=args.jacobian)
    for lr in args.lrs:
        runs[f"Adam lr={lr:g}"], _ = run(problem(args.problem), "adam", args.budget, lr)
    start = runs[lm_name][0][1]
    checkpoints = [args.budget * f for f in (0.1, 0.25, 0.5, 1.0)]
    print(f"problem {args.problem}: N = {p.num_variables}, M = {p.size}, start merit {start:.4e}, "
          f"budget {args.budget:g} s per run, load average {load_before} → {os.getloadavg()}\n")
    print("| optimizer | steps | " + " | ".join(f"merit at {c:g} s" for c in checkpoints) + " |")
    print("| --- | ---: | " + " | ".join("---:" for _ in checkpoints) + " |")
    for name, tr in runs.items():
        print(f"| {name} | {len(tr) - 1} | " + " | ".join(f"{at(tr, c):.4e}" for c in checkpoints) + " |")
    if compile_s:
        print(f"\nOne-off capture + compile of LM's Jacobian (before the clock): {compile_s:.1f} s")
    adams = {k: v for k, v in runs.items() if k.startswith("Adam")}
    best_adam = min(adams, key=lambda k: adams[k][-1][1])
    target = adams[best_adam][-1][1]
    t_adam, t_lm = first_reach(adams[best_adam], target), first_reach(runs[lm_name], target)
    print(f"\nTime to the merit the best Adam ({best_adam}) reaches in {args.budget:g} s, {target:.4e}:\n")
    print("| optimizer | first reaches it at (s) |\n| --- | ---: |")
    for name, tr in runs.items():
        print(f"| {name} | {first_reach(tr, target):.1f} |")
    lead = t_adam / t_lm
    print(f"\nLM's lead over the best Adam: {t_adam:.1f} s / {t_lm:.1f} s = **{lead:.1f}×** sooner"
          + (f" ({t_adam:.1f} s / {t_lm + compile_s:.1f} s = {t_adam / (t_lm + compile_s):.2f}× counting the compile)"
             if compile_s else ""))
    if args.json:
        from lensopt.io.files import write_text_atomic

        write_text_atomic(args.json, json.dumps({
            "problem": args.problem, "variables": p.num_variables, "residuals": p.size, "budget_s": args.budget,
            "loadavg_before": load_before, "loadavg_after": os.getloadavg(), "threads": torch.get_num_threads(),
            "jacobian": args.jacobian, "backend": args.backend, "jacobian_compile_s": compile_s, "best_adam": best_adam,
            "target_merit": target, "best_adam_reaches_s": t_adam, "lm_reaches_s": t_lm,
            "runs": {k: thin(v) for k, v in runs.items()}}) + "\n")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from lensopt.io.files import atomic_path

        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        for name, tr in runs.items():
            ax.plot([t for t, _ in tr], [m for _, m in tr], label=name, lw=2 if name.startswith("LM") else 1)
        ax.set_yscale("log")
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel("best merit ½‖ℓ‖²")
        ax.set_title(f"LM vs Adam, {args.problem} (N = {p.num_variables})")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        fig.tight_layout()
        with atomic_path(args.plot) as tmp:
            fig.savefig(tmp, dpi=120)


if __name__ == "__main__":
    main()
