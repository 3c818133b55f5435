"""Does the optimizer's result depend on torch's intra-op thread count? Optimizes SPEC for N steps with 1
and then 2 threads in one process and compares the written lenses (``dump_json``) byte for byte.

    PYTHONPATH=. python benchmarks/thread_determinism.py specs/cmount_4p.toml --steps 4 [--optimizer adam]
"""

from __future__ import annotations

import argparse
import time

import torch

from lensopt.design import optimize
from lensopt.spec import dump_json, load_spec


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("spec")
    ap.add_argument("--steps", type=int, default=6)
    ap.add_argument("--optimizer", default=None)
    args = ap.parse_args()
    out = []
    for n in (1, 2):
        torch.set_num_threads(n)
        t0 = time.perf_counter()
        out.append(dump_json(optimize(load_spec(args.spec), optimizer=args.optimizer, steps=args.steps).spec))
        print(f"{n} thread(s): {time.perf_counter() - t0:.1f} s")
    print("identical" if out[0] == out[1] else "DIFFERENT")


if __name__ == "__main__":
    main()
