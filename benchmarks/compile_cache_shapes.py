"""Does Inductor's on-disk cache spare the compilation of the trace in a new process with a new ray count?

Each invocation is a fresh process that traces specs/achromat_f10.toml with ``rings:N`` on the compiled
backend and prints how long the first call took (compilation included). Run it for N = 8, then 12, with
a private cache directory, static shapes and then dynamic shapes (issue 13, benchmarks/RESULTS.md):

    for a in "8 static" "12 static" "8 dyn" "12 dyn"; do
        TORCHINDUCTOR_CACHE_DIR=/tmp/cc .venv/bin/python benchmarks/compile_cache_shapes.py $a; done
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import torch

from lensopt import accel
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build, load_spec


def main() -> None:
    n, mode = int(sys.argv[1]), sys.argv[2]
    if mode == "dyn":
        import torch._dynamo as dynamo

        dynamo.config.automatic_dynamic_shapes = True
        dynamo.config.assume_static_by_default = False
    m = build(load_spec(Path(__file__).resolve().parents[1] / "specs" / "achromat_f10.toml"))
    pts = PupilSampling.parse(f"rings:{n}").points(dtype=torch.float64)
    t = time.perf_counter()
    with torch.no_grad():
        trace_bundle(m.lens, m.system, pts, half_pupil=True, engine=accel.engine("compiled"))
    print(n, mode, "first call", round(time.perf_counter() - t, 1), "s")


if __name__ == "__main__":
    main()
