"""One optimization run of the spot-against-wavefront comparison on the microscope objective (issue 28),
timed by this process's CPU time (``time.process_time``, one intra-op thread).

    OMP_NUM_THREADS=1 PYTHONPATH=. .venv/bin/python benchmarks/optimize/microscope_wavefront_run.py \\
        --merit wavefront --start spec --steps 290 -o out/mw_wavefront_spec.json

``--merit spot``: the spot spec (``specs/microscope_8p_wd12.toml``); ``wavefront``: its wavefront twin
(``specs/microscope_8p_wd12_wavefront.toml``: the same lens, constraints and variables, the merit its
``[optimize.wavefront]`` and a small TRA). ``--start spec``: from the spec's crude start, with its schedules
and the glass binding at mid-run; ``--start shipped``: continuing from ``lenses/microscope_8p_wd12.json``
(glasses already bound) at full constraint weight (``--full-weight``), the shipped lens's own [optimize]
for ``spot``, and that [optimize] with the twin's ``tra`` and ``wavefront`` for ``wavefront``; there no
schedule depends on the step count, so ``--cpu-budget S`` (with a large ``--steps``) ends both merits' runs
after the same CPU seconds (the step that crosses S completes). Writes the
lens (``-o``) and beside it ``<out>.run.json``: steps, stop reason, CPU seconds, wall seconds.
The step counts of the recorded runs were chosen so that each run takes about the same CPU time
(benchmarks/README.md, optimize).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import torch

from lensopt.design import optimize
from lensopt.files import write_text_atomic
from lensopt.spec import dump_json, load_spec

ROOT = Path(__file__).resolve().parents[2]
SPOT = ROOT / "specs" / "microscope_8p_wd12.toml"
WAVEFRONT = ROOT / "specs" / "microscope_8p_wd12_wavefront.toml"
SHIPPED = ROOT / "lenses" / "microscope_8p_wd12.json"


def start_spec(merit: str, start: str):  # noqa: ANN201 - a LensSpec
    if start == "spec":
        return load_spec(SPOT if merit == "spot" else WAVEFRONT)
    spec = load_spec(SHIPPED)
    if merit == "wavefront":
        twin = load_spec(WAVEFRONT).optimize
        spec.optimize = spec.optimize.model_copy(update={"tra": twin.tra, "wavefront": twin.wavefront})
    return spec


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--merit", choices=["spot", "wavefront"], required=True)
    ap.add_argument("--start", choices=["spec", "shipped"], required=True)
    ap.add_argument("--steps", type=int, required=True)
    ap.add_argument("--cpu-budget", type=float, default=None,
                    help="stop once the run has used this many CPU seconds (the lens so far is kept)")
    ap.add_argument("-o", "--output", type=Path, required=True)
    a = ap.parse_args()
    torch.set_num_threads(1)
    spec = start_spec(a.merit, a.start)
    c0, w0 = time.process_time(), time.perf_counter()

    def stop_at_budget(_progress) -> None:  # noqa: ANN001 - a Progress
        if a.cpu_budget is not None and time.process_time() - c0 >= a.cpu_budget:
            raise KeyboardInterrupt  # run_problem keeps the lens so far, as on Ctrl-C

    res = optimize(spec, steps=a.steps, seed=0, full_weight=a.start == "shipped", callback=stop_at_budget)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    a.output.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(a.output, dump_json(res.spec))
    rec = {"merit": a.merit, "start": a.start, "steps_asked": a.steps, "cpu_budget_s": a.cpu_budget, "steps": res.steps,
           "stop_reason": res.stop_reason, "cpu_s": round(cpu, 2), "wall_s": round(wall, 2),
           "threads": torch.get_num_threads(), "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
           "bound": [str(b) for b in res.bound], "warning": res.warning}
    write_text_atomic(a.output.with_suffix(".run.json"), json.dumps(rec, indent=1) + "\n")
    print(json.dumps(rec))


if __name__ == "__main__":
    main()
