"""Why the compiled trace keeps its masks as float flags (issue 14): the same per-ray logic compiled by
Inductor (CPU, float64), written with boolean mask algebra (``&``, ``|``, ``~``) and written with
nested ``torch.where`` selects on comparisons. Both give the same numbers (checked); the boolean
version pays mask-format conversions lane by lane in Inductor's C++ code.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/mask_algebra.py [--rays 1e6] [--repeats 9]
"""

from __future__ import annotations

import argparse
import os
import time

import torch


def arithmetic(x, y, z, a):  # noqa: ANN001, ANN201 - the baseline: the arithmetic alone
    for _ in range(6):
        t = torch.sqrt(x * x + y * y + 1.0) / (z + 2.0)
        x, y, z = x + t * a, y - t * a, z * 0.5 + t
    return x + y + z


def boolean(x, y, z, a):  # noqa: ANN001, ANN201
    status = torch.zeros_like(x)
    for s in range(6):
        t = torch.sqrt(x * x + y * y + 1.0) / (z + 2.0)
        m1, m2, m3 = t > 0.3, x < 0.7, y > 0.1
        m = (m1 & m2) | (m3 & ~m1)
        status = torch.where((status == 0) & m, float(s + 1), status)
        x, y, z = torch.where(status == 0, x + t * a, x), torch.where(status == 0, y - t * a, y), z * 0.5 + t
    return x + y + z + status


def selects(x, y, z, a):  # noqa: ANN001, ANN201
    status = torch.zeros_like(x)
    for s in range(6):
        t = torch.sqrt(x * x + y * y + 1.0) / (z + 2.0)
        m = torch.where(t > 0.3, torch.where(x < 0.7, 1.0, 0.0), torch.where(y > 0.1, 1.0, 0.0))
        status = torch.where(status == 0, torch.where(m > 0, float(s + 1), 0.0), status)
        x, y, z = torch.where(status == 0, x + t * a, x), torch.where(status == 0, y - t * a, y), z * 0.5 + t
    return x + y + z + status


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=float, default=1e6)
    ap.add_argument("--repeats", type=int, default=9)
    args = ap.parse_args()
    g = torch.Generator().manual_seed(0)
    x, y, z, a = (torch.rand(int(args.rays), generator=g, dtype=torch.float64) for _ in range(4))
    fns = {f.__name__: torch.compile(f, fullgraph=True) for f in (arithmetic, boolean, selects)}
    for fn in fns.values():
        fn(x, y, z, a)  # compile
    assert torch.equal(fns["boolean"](x, y, z, a), fns["selects"](x, y, z, a))
    load = os.getloadavg()[0]
    times: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(args.repeats):  # interleaved
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn(x, y, z, a)
            times[k].append(time.perf_counter() - t0)
    print(f"{int(args.rays):.0e} rays, {torch.get_num_threads()} thread(s), "
          f"load {load:.1f} → {os.getloadavg()[0]:.1f}; "
          "medians of interleaved repeats; boolean and selects give equal results\n")
    print("| formulation | median ms |\n| --- | ---: |")
    for k, v in times.items():
        print(f"| {k} | {1e3 * sorted(v)[len(v) // 2]:.1f} |")


if __name__ == "__main__":
    main()
