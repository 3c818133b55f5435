"""LM on GTRA against Adam on the scalar image loss (reverse mode through trace, rendering and loss),
same problem (specs/cmount_4p_raw.toml: the spot-optimized C-mount lens, objective "raw"), same batches
(seeded by step), same optimizer time budget. Records the batch image loss per step and the held-out
PSNR at checkpoints against optimizer time (evaluation time excluded), and plots both. The clock is the
process CPU time (``time.process_time``, one thread): on this shared, loaded machine wall time depends
on the other sessions, CPU time does not.

    PYTHONPATH=$PWD OMP_NUM_THREADS=1 python benchmarks/raw_lm_vs_adam.py --budget 240
    # → benchmarks/results_raw_lm_vs_adam.json, benchmarks/raw_lm_vs_adam.png
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import torch

from lensopt.optim import Problem
from lensopt.optim.run import _next_batch, make_optimizer
from lensopt.spec import load_spec

ROOT = Path(__file__).resolve().parents[1]


def run(method: str, budget: float, every: float, count: int, lr: float) -> dict:
    spec = load_spec(ROOT / "specs" / "cmount_4p_raw.toml")
    spec.optimize = spec.optimize.model_copy(update={"adam": spec.optimize.adam.model_copy(update={"lr": lr})})
    p = Problem(spec, seed=0, method=method)
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
    return {"method": method, "steps": k, "accepted": state.accepted, "rejected": state.rejected,
            "step_log": steps, "evals": evals}


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for r in res["runs"]:
        label = "LM on GTRA" if r["method"] == "lm" else f"Adam on L (lr {res['adam_lr']:g})"
        ax[0].plot([s[0] for s in r["step_log"]], [s[2] for s in r["step_log"]], ".-", label=label)
        ax[1].plot([e[0] for e in r["evals"]], [e[2] for e in r["evals"]], "o-", label=label)
    ax[0].set(xlabel="optimizer CPU time (s, 1 thread)", ylabel="image loss L of the step's batch (MSE)",
              title="loss (batches change every step)")
    ax[1].set(xlabel="optimizer CPU time (s, 1 thread)", ylabel="held-out raw PSNR (dB)", title="held-out PSNR")
    for a in ax:
        a.legend()
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--budget", type=float, default=240.0)
    ap.add_argument("--every", type=float, default=60.0)
    ap.add_argument("--count", type=int, default=16, help="held-out patches per checkpoint")
    ap.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate (scaled variables)")
    args = ap.parse_args()
    load0 = os.getloadavg()
    runs = [run(m, args.budget, args.every, args.count, args.lr) for m in ("lm", "adam")]
    res = {"budget_s": args.budget, "adam_lr": args.lr, "threads": torch.get_num_threads(), "load_before": load0,
           "load_after": os.getloadavg(), "clock": "process CPU time, 1 thread",
           "note": "loaded shared 2-core machine", "runs": runs}
    out = ROOT / "benchmarks" / "results_raw_lm_vs_adam.json"
    out.write_text(json.dumps(res, indent=1))
    plot(res, ROOT / "benchmarks" / "raw_lm_vs_adam.png")
    for r in runs:
        e0, e1 = r["evals"][0], r["evals"][-1]
        print(f"{r['method']}: {r['steps']} steps ({r['accepted']} accepted) in {e1[0]:.0f} s; held-out PSNR "
              f"{e0[2]:.3f} -> {e1[2]:.3f} dB; ESR {e0[3]:.3f} -> {e1[3]:.3f} um")


if __name__ == "__main__":
    main()
