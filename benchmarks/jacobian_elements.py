"""Where an eager LM Jacobian's work goes (issue 14): one ``Problem.jacobian`` (eager jacfwd) under a
dispatch mode that counts, per lensopt source line, the operations and the tensor elements they write
(views left out). The eager Jacobian is bound by this memory traffic, not by per-operation overhead.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/jacobian_elements.py cmount_4p.toml
"""

from __future__ import annotations

import collections
import sys
import traceback
from pathlib import Path

import torch
from torch.utils._python_dispatch import TorchDispatchMode

from lensopt.design import build_problem
from lensopt.spec import load_spec

SPECS = Path(__file__).resolve().parents[1] / "specs"
VIEWS = {"alias", "select", "expand", "view", "slice", "unsqueeze", "squeeze", "permute", "t", "_unsafe_view",
         "as_strided", "unbind", "split", "detach"}
elements: collections.Counter = collections.Counter()
calls: collections.Counter = collections.Counter()


class Count(TorchDispatchMode):
    def __torch_dispatch__(self, func, types, args=(), kwargs=None):  # noqa: ANN001, ANN204
        out = func(*args, **(kwargs or {}))
        if isinstance(out, torch.Tensor) and func._opname not in VIEWS:
            frames = [f for f in traceback.extract_stack() if "lensopt/" in f.filename]
            key = f"{frames[-1].filename.split('lensopt/')[-1]}:{frames[-1].lineno}" if frames else "?"
            elements[key] += out.numel()
            calls[key] += 1
        return out


def main() -> None:
    torch.set_num_threads(1)
    p = build_problem(load_spec(SPECS / (sys.argv[1] if len(sys.argv) > 1 else "cmount_4p.toml")))
    p.jacobian(p.theta0)
    with Count():
        p.jacobian(p.theta0)
    total = sum(elements.values())
    print(f"{sum(calls.values())} operations, {total / 1e6:.1f} M elements written\n")
    by_file: collections.Counter = collections.Counter()
    for k, v in elements.items():
        by_file[k.split(":")[0]] += v
    for f, v in by_file.most_common():
        print(f"{100 * v / total:5.1f} %  {f}")
    print()
    for k, v in elements.most_common(30):
        print(f"{100 * v / total:5.1f} %  {calls[k]:5d} ops  {k}")


if __name__ == "__main__":
    main()
