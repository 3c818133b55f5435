"""LM on GTRA against Adam on the scalar image loss (reverse mode through trace, rendering and loss),
same problem (specs/cmount_4p_raw.toml: the spot-optimized C-mount lens, objective "raw"), same batches
(seeded by step), same optimizer time budget. Records the batch image loss per step and the held-out
PSNR at checkpoints against optimizer time (evaluation time excluded), and plots both. The clock is the
process CPU time (``time.process_time``, one thread): on this shared, loaded machine wall time depends
on the other sessions, CPU time does not.

    PYTHONPATH=$PWD OMP_NUM_THREADS=1 python benchmarks/e2e/raw_lm_vs_adam.py --budget 240
    # → benchmarks/e2e/results_raw_lm_vs_adam.json, benchmarks/e2e/raw_lm_vs_adam.png

Adam tuned over learning rates (each run in its own process, then merged; ``--name`` picks the files):

    for r in lm adam:3e-4 adam:1e-3 adam:3e-3; do
      PYTHONPATH=$PWD OMP_NUM_THREADS=1 python benchmarks/e2e/raw_lm_vs_adam.py --budget 150 --every 50 --count 8 \
        --runs $r --part /tmp/part_$r.json &
    done; wait
    PYTHONPATH=$PWD python benchmarks/e2e/raw_lm_vs_adam.py --name raw_lm_vs_adam_tuned --merge /tmp/part_*.json
    # → benchmarks/e2e/results_raw_lm_vs_adam_tuned.json, benchmarks/e2e/raw_lm_vs_adam_tuned.png

At the end of each run the constraints of its lens are measured (``constraint_report`` on rings:24 plus
the rim rays, as ``lensopt optimize``'s summary does).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import torch

from lensopt.design import build_problem
from lensopt.optics.sampling import PupilSampling
from lensopt.optim.driver import _next_batch, make_optimizer
from lensopt.optim.report import constraint_report
from lensopt.spec import load_spec

ROOT = Path(__file__).resolve().parents[2]


def run(method: str, budget: float, every: float, count: int, lr: float) -> dict:
    spec = load_spec(ROOT / "specs" / "cmount_4p_raw.toml")
    spec.optimize = spec.optimize.model_copy(update={"adam": spec.optimize.adam.model_copy(update={"lr": lr})})
    p = build_problem(spec, seed=0, method=method)
    state = make_optimizer(p, p.theta0, method)
    scale = p.row_scale(0.0)
    steps, evals = [], []
    clock, k, next_eval = 0.0, 0, 0.0
    while True:
        if clock >= next_eval or clock >= budget:
            with torch.no_grad():
                evals.append((clock, k, p.image.held_out_psnr(p.lens(state.theta)[0], count=count),
                              1e3 * p.spot_esr_mm(state.theta)))
            next_eval += every
            if clock >= budget:
                break
        a = time.process_time()
        loss = _next_batch(p, state, k, method)
        info = state.step(scale)
        clock += time.process_time() - a
        k += 1
        steps.append((clock, k, loss, info.accepted))
    rep = constraint_report(p, state.theta, PupilSampling.parse("rings:24", seed=0))
    cons = {"satisfied": rep["satisfied"], "failed_rays": rep["failed_rays"],
            "max_abs_distortion_percent": max(abs(v) for v in rep["distortion_percent"]),
            "max_angle_deg": rep["max_angle_deg"], "gaps_satisfied": all(g["satisfied"] for g in rep["gaps"])}
    return {"method": method, "lr": lr if method == "adam" else None, "steps": k, "accepted": state.accepted,
            "rejected": state.rejected, "step_log": steps, "evals": evals, "constraints": cons,
            "theta": state.theta.tolist()}


def label(r: dict) -> str:
    return "LM on GTRA" if r["method"] == "lm" else f"Adam on L (lr {r.get('lr') or 1e-3:g})"


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for r in res["runs"]:
        name = label(r)
        t, loss = [s[0] for s in r["step_log"]], [s[2] for s in r["step_log"]]
        k = 25  # running mean over 25 steps (each step's batch differs), the raw values faint behind it
        mean = [sum(loss[max(0, i - k + 1): i + 1]) / len(loss[max(0, i - k + 1): i + 1]) for i in range(len(loss))]
        (line,) = ax[0].plot(t, mean, "-", lw=1.8, label=f"{name}, mean of {k} steps")
        ax[0].plot(t, loss, ".", ms=2, alpha=0.25, color=line.get_color())
        ax[1].plot([e[0] for e in r["evals"]], [e[2] for e in r["evals"]], "o-", label=name)
    ax[0].set(xlabel="optimizer CPU time (s, 1 thread)", ylabel="image loss L of the step's batch (MSE)",
              title="loss (batches change every step)")
    ax[1].set(xlabel="optimizer CPU time (s, 1 thread)", ylabel="held-out raw PSNR (dB)", title="held-out PSNR")
    for a in ax:
        a.legend()
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def parse_runs(text: str) -> list[tuple[str, float]]:
    """``lm,adam:3e-4,adam`` → [(method, Adam lr)]; a bare ``adam`` takes ``--lr``."""
    out = []
    for item in text.split(","):
        method, _, lr = item.strip().partition(":")
        out.append((method, float(lr) if lr else float("nan")))
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--budget", type=float, default=240.0)
    ap.add_argument("--every", type=float, default=60.0)
    ap.add_argument("--count", type=int, default=16, help="held-out patches per checkpoint")
    ap.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate (scaled variables)")
    ap.add_argument("--runs", default="lm,adam", help="comma list of lm | adam | adam:LR")
    ap.add_argument("--part", type=Path, help="write only this process's runs to this JSON (merge later)")
    ap.add_argument("--merge", type=Path, nargs="+", help="combine --part files into the result and plot")
    ap.add_argument("--name", default="raw_lm_vs_adam", help="result stem: benchmarks/e2e/results_NAME.json, NAME.png")
    args = ap.parse_args()
    if args.merge:
        parts = [json.loads(f.read_text()) for f in args.merge]
        runs = [r for part in parts for r in part["runs"]]
        runs.sort(key=lambda r: (r["method"] != "lm", r.get("lr") or 0.0))
        res = {**{k: v for k, v in parts[0].items() if k != "runs"}, "parts": [
            {k: v for k, v in part.items() if k != "runs"} for part in parts], "runs": runs}
    else:
        load0 = os.getloadavg()
        runs = [run(m, args.budget, args.every, args.count, args.lr if lr != lr else lr)
                for m, lr in parse_runs(args.runs)]
        res = {"budget_s": args.budget, "adam_lr": args.lr, "threads": torch.get_num_threads(), "load_before": load0,
               "load_after": os.getloadavg(), "clock": "process CPU time, 1 thread",
               "note": "loaded shared 2-core machine", "runs": runs}
        if args.part:
            args.part.write_text(json.dumps(res, indent=1))
            return
    out = ROOT / "benchmarks" / "e2e" / f"results_{args.name}.json"
    out.write_text(json.dumps(res, indent=1))
    plot(res, ROOT / "benchmarks" / "e2e" / f"{args.name}.png")
    for r in runs:
        e0, e1 = r["evals"][0], r["evals"][-1]
        print(f"{label(r)}: {r['steps']} steps ({r['accepted']} accepted) in {e1[0]:.0f} s; held-out PSNR "
              f"{e0[2]:.3f} -> {e1[2]:.3f} dB; ESR {e0[3]:.3f} -> {e1[3]:.3f} um; constraints {r.get('constraints')}")


if __name__ == "__main__":
    main()
