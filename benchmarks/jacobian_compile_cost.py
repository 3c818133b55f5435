"""What compiling the LM Jacobian costs (issue 14): capture (make_fx of jacfwd) and then Inductor, either
directly on the captured aten graph (``direct``, what ``CompiledJacobian`` does) or through
``torch.compile`` of the GraphModule (``dynamo``: Dynamo re-traces the generated Python first), with the
wall and CPU time of the compile, a cProfile of it, the agreement with eager jacfwd and the cost of one
compiled Jacobian against one eager residual evaluation measured right after.

    OMP_NUM_THREADS=1 TORCHINDUCTOR_CACHE_DIR=/tmp/ic_direct .venv/bin/python benchmarks/jacobian_compile_cost.py \\
        cooke_triplet_opt.toml direct

Use a fresh ``TORCHINDUCTOR_CACHE_DIR`` per mode for a cold compile (the same one again: a second process).
"""

from __future__ import annotations

import cProfile
import os
import pstats
import statistics
import sys
import time
from pathlib import Path

import torch

from lensopt.accel.jacobian import capture_jacobian
from lensopt.design import build_problem
from lensopt.spec import load_spec

SPECS = Path(__file__).resolve().parents[1] / "specs"


def main() -> None:
    torch.set_num_threads(1)
    spec, mode = sys.argv[1], sys.argv[2]
    p = build_problem(load_spec(SPECS / spec))
    th = p.theta0
    t0 = time.perf_counter()
    gm = capture_jacobian(p.residuals, th)
    print("capture", time.perf_counter() - t0, "nodes", len(gm.graph.nodes), "load", os.getloadavg(), flush=True)
    pr = cProfile.Profile()
    t0, c0 = time.perf_counter(), time.process_time()
    pr.enable()
    if mode == "dynamo":
        fn = torch.compile(gm, fullgraph=True, dynamic=False)
    else:
        from torch._inductor import compile as inductor_compile

        fn = inductor_compile(gm, [th])
    out = fn(th)
    pr.disable()
    print(mode, "compile wall", time.perf_counter() - t0, "cpu", time.process_time() - c0, "load", os.getloadavg(),
          flush=True)
    J0, _ = p.jacobian(th)
    print("diff", float((out[0] - J0).abs().max() / J0.abs().max()))
    ts, tr = [], []
    for _ in range(7):
        t = time.perf_counter()
        fn(th)
        ts.append(time.perf_counter() - t)
    for _ in range(7):
        t = time.perf_counter()
        p.residuals(th)
        tr.append(time.perf_counter() - t)
    a, b = statistics.median(ts), statistics.median(tr)
    print("per call", a, "res", b, "evals", a / b)
    pstats.Stats(pr).sort_stats("cumulative").print_stats(45)


if __name__ == "__main__":
    main()
