"""What the "cheap work first" changes save, on the Cooke and C-mount problems at their start points:
the eager forward-mode Jacobian with the failure-margin walk skipped when no ray fails (the default)
against the walk forced on, and the LM damped step with the inactive rows pruned (the default)
against the full system. Medians of interleaved repeats, one process.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/cheap_work.py --repeats 7
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import torch

from lensopt.design import build_problem
from lensopt.optim import residuals as res
from lensopt.optim.lm import damped_step
from lensopt.spec import load_spec

SPECS = Path(__file__).resolve().parents[1] / "specs"


def _full_step(J: torch.Tensor, r: torch.Tensor, D: torch.Tensor, lam: float) -> torch.Tensor:
    """The damped step on every row (no pruning): the same augmented system as lm.damped_step."""
    n = J.shape[1]
    A = torch.cat([J / D, lam**0.5 * torch.eye(n, dtype=J.dtype)])
    b = torch.cat([-r, torch.zeros(n, dtype=r.dtype)])
    return torch.linalg.lstsq(A, b.unsqueeze(-1), driver="gelsd").solution.squeeze(-1) / D


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    a = ap.parse_args()
    print(f"load average before: {os.getloadavg()}, torch threads {torch.get_num_threads()}\n")
    print("| problem | failed rays | Jacobian, walk forced s | Jacobian, walk skipped s | saving | "
          "solve, all rows s | solve, active rows s | rows active / all | max |Δstep| / max |step| |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name in ("cooke_triplet_opt.toml", "cmount_4p.toml"):
        p = build_problem(load_spec(SPECS / name))
        th = p.theta0
        tracing = res._tracing
        t = {"walk": [], "skip": [], "full": [], "pruned": []}
        J, r = p.jacobian(th)
        D = torch.linalg.vector_norm(J, dim=0).clamp_min(1e-6)
        for i in range(a.repeats + 1):
            for mode in ("walk", "skip"):
                res._tracing = (lambda: True) if mode == "walk" else tracing
                t0 = time.perf_counter()
                p.jacobian(th)
                if i:
                    t[mode].append(time.perf_counter() - t0)
            res._tracing = tracing
            for mode, fn in (("full", _full_step), ("pruned", damped_step)):
                t0 = time.perf_counter()
                fn(J, r, D, 1e-3)
                if i:
                    t[mode].append(time.perf_counter() - t0)
        m = {k: statistics.median(v) for k, v in t.items()}
        d_full, d_pruned = _full_step(J, r, D, 1e-3), damped_step(J, r, D, 1e-3)
        active = int(((r != 0) | (J != 0).any(1)).sum())
        print(f"| {name} | {p.failure_summary(th)[0]} | {m['walk']:.3f} | {m['skip']:.3f} | "
              f"{100 * (1 - m['skip'] / m['walk']):.0f} % | {m['full']:.4f} | {m['pruned']:.4f} | "
              f"{active} / {r.numel()} | {float((d_full - d_pruned).abs().max() / d_full.abs().max()):.1e} |")
    print(f"\nload average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
