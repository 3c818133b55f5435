"""Cost of one Levenberg–Marquardt step on the shipped study specs, against a baseline commit measured in
the same run (issue 25: ops per residual evaluation, one residual evaluation, one Jacobian, one
accepted step; one thread, process CPU time and wall time, medians).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/optimize/lm_step_cost.py --baseline 5eb699a \\
        --json benchmarks/optimize/results_lm_step_cost.json

With ``--baseline REF`` the script checks REF out into a temporary git worktree and runs every
measurement once in a child process on REF's package and once on this checkout's, alternating spec by
spec, so that both see the same machine load; the table gives both and their ratio. Without it, it
measures this checkout only. ``--child`` is the child process's entry (prints one JSON line).

- *ops*: aten operations dispatched by one residual evaluation (no gradients).
- *residual*: ``Problem.evaluate`` at a θ not evaluated before (θ0 scaled by 1 + k·1e-12).
- *Jacobian*: ``Problem.jacobian`` at a θ just evaluated (as LM computes it after a trial).
- *accepted step*: LM from θ0 (the spec's settings, weights at the start of the schedule) for
  ``--steps`` steps; CPU time of the run divided by the accepted steps (median of ``--repeats`` runs).
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
SPECS = ("specs/telephoto_5p_tr080.toml", "specs/telephoto_5p1_middle_tr075.toml", "specs/cmount_4p.toml",
         "specs/microscope_8p_wd12.toml")


def _cpu() -> float:
    return time.process_time()


def measure(spec: str, repeats: int, steps: int) -> dict:
    import torch
    from torch.utils._python_dispatch import TorchDispatchMode

    import lensopt
    from lensopt.design import build_problem
    try:
        from lensopt.optim.driver import make_optimizer
    except ImportError:  # a baseline from before optim/run.py became optim/driver.py
        from lensopt.optim.run import make_optimizer
    from lensopt.spec import load_spec

    torch.set_num_threads(1)
    problem = build_problem(load_spec(ROOT / spec))
    theta0 = problem.theta0

    class Count(TorchDispatchMode):
        def __init__(self) -> None:
            super().__init__()
            self.n = 0

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):  # noqa: ANN001, ANN202
            self.n += 1
            return func(*args, **(kwargs or {}))

    with torch.no_grad(), Count() as count:
        problem.residuals(theta0 * (1 + 1e-11))

    def timed(fn) -> tuple[float, float]:  # noqa: ANN001
        c, w = _cpu(), time.perf_counter()
        fn()
        return _cpu() - c, time.perf_counter() - w

    problem.evaluate(theta0)  # warm-up (functorch builds its rules on first use)
    problem.jacobian(theta0)
    evals, jacs = [], []
    for k in range(repeats):
        theta = theta0 * (1 + (k + 1) * 1e-12)
        evals.append(timed(lambda t=theta: problem.evaluate(t)))
        jacs.append(timed(lambda t=theta: problem.jacobian(t)))
    scale = problem.row_scale(0.0)
    runs = []
    for _ in range(repeats):  # one LM run is a single sample of a noisy clock: the median of ``repeats`` runs
        opt = make_optimizer(problem, theta0, "lm")
        c, w = _cpu(), time.perf_counter()
        for _ in range(steps):
            opt.step(scale)
        runs.append((_cpu() - c, time.perf_counter() - w))
    step_cpu, step_wall = statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)
    acc = max(opt.accepted, 1)
    return {
        "spec": spec, "package": str(Path(lensopt.__file__).parent), "N": problem.num_variables, "M": problem.size,
        "ops": count.n,
        "residual_cpu_s": statistics.median(e[0] for e in evals),
        "residual_wall_s": statistics.median(e[1] for e in evals),
        "jacobian_cpu_s": statistics.median(j[0] for j in jacs),
        "jacobian_wall_s": statistics.median(j[1] for j in jacs),
        "steps": steps, "accepted": opt.accepted,
        "step_cpu_s": step_cpu / acc, "step_wall_s": step_wall / acc,
    }


def _child(package_root: Path, spec: str, repeats: int, steps: int) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONPATH=str(package_root))
    out = subprocess.run([sys.executable, __file__, "--child", spec, "--repeats", str(repeats), "--steps", str(steps)],
                         env=env, capture_output=True, text=True, check=True, cwd=package_root)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("specs", nargs="*", default=list(SPECS))
    ap.add_argument("--baseline", help="git ref measured beside this checkout (a temporary worktree)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--child", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(measure(a.child, a.repeats, a.steps)))
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = None
        if a.baseline:
            base = Path(tmp) / "baseline"
            subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(base), a.baseline],
                           check=True)
        try:
            for spec in a.specs:
                row = {"spec": spec, "new": _child(ROOT, spec, a.repeats, a.steps)}
                if base is not None:
                    row["baseline"] = _child(base, spec, a.repeats, a.steps)
                rows.append(row)
                print(json.dumps(row), flush=True)
        finally:
            if base is not None:
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base)], check=False)
    keys = [("ops", "ops / residual", "{:.0f}"), ("residual_cpu_s", "residual (CPU s)", "{:.3f}"),
            ("jacobian_cpu_s", "Jacobian (CPU s)", "{:.3f}"), ("step_cpu_s", "accepted step (CPU s)", "{:.3f}"),
            ("step_wall_s", "accepted step (wall s)", "{:.3f}")]
    print("\n| spec | quantity | baseline | now | ratio |\n|---|---|---|---|---|")
    for row in rows:
        for k, label, fmt in keys:
            new, old = row["new"][k], row.get("baseline", {}).get(k)
            ratio = f"{old / new:.1f}×" if old else ""
            before = fmt.format(old) if old else ""
            print(f"| {Path(row['spec']).stem} | {label} | {before} | {fmt.format(new)} | {ratio} |")
    if a.json:
        meta = {"date": time.strftime("%Y-%m-%d"), "baseline": a.baseline, "load": os.getloadavg(),
                "command": " ".join(sys.argv)}
        a.json.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
