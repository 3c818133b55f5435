"""Where LM's CPU time goes on the lm_vs_adam C-mount problem (glasses held, N = 16) until it reaches a
merit (default: the best Adam's 180 s merit of issue 14's runs): Jacobians, trial evaluations, solves,
accepted and rejected steps; process CPU time, so the load of other processes does not enter.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/lm_step_split.py 3.2262e-3
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lm_vs_adam import problem  # noqa: E402

from lensopt.engine import retain_freed_memory  # noqa: E402
from lensopt.optim import lm as lmmod  # noqa: E402
from lensopt.optim.driver import make_optimizer  # noqa: E402


def main() -> None:
    torch.set_num_threads(1)
    retain_freed_memory()
    target = float(sys.argv[1]) if len(sys.argv) > 1 else 3.2262e-3
    p = problem("cmount")
    opt = make_optimizer(p, p.theta0, "lm", "eager")
    spent = {"Jacobian": 0.0, "trial evaluations": 0.0, "damped solve": 0.0}

    def timed(name, fn):  # noqa: ANN001, ANN202
        def wrapper(*a):  # noqa: ANN002, ANN202
            c = time.process_time()
            try:
                return fn(*a)
            finally:
                spent[name] += time.process_time() - c
        return wrapper

    opt._jacobian = timed("Jacobian", opt._jacobian)
    opt._evaluate = timed("trial evaluations", opt._evaluate)
    lmmod.damped_step = timed("damped solve", lmmod.damped_step)
    one = torch.ones(p.size, dtype=p.dtype)
    c0, w0 = time.process_time(), time.perf_counter()
    merit, k = opt.merit(one), 0
    while merit > target and k < 3000:
        info = opt.step(one)
        k += 1
        if info.accepted:
            merit = min(merit, info.merit)
    cpu = time.process_time() - c0
    print(f"steps {k} (accepted {opt.accepted}, rejected {opt.rejected}), merit {merit:.4e}, CPU {cpu:.1f} s, "
          f"wall {time.perf_counter() - w0:.1f} s, load {os.getloadavg()}")
    for name, s in spent.items():
        print(f"  {name}: {s:.1f} s ({100 * s / cpu:.0f} %)")


if __name__ == "__main__":
    main()
