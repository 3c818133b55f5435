"""(Superseded by ``lensopt optimize LENS.json --full-weight``, session 23; kept for the session-22
commands in benchmarks/README.md.) Write a copy of a lens whose constraint groups have no weight schedule (full weight
from the first step), to continue an optimized lens without the restart of the schedules (issue 15, session 22).

``lensopt optimize LENS.json`` on a written lens restarts the spec's schedules (constraints at 1–10 % of their
weight for the first half): the lens then drifts out of its constraints and, on the studies, LM can stall
there (damping above 1e12) before the weights come back. With the glasses bound there is nothing left for a
schedule to protect, so this removes them.

    PYTHONPATH=. python benchmarks/studies/full_weight_spec.py lenses/microscope_8p_wd12.json out/mol_full.json
    lensopt optimize out/mol_full.json -o out/mol_more.json --steps 1500 --seed 0
"""

from __future__ import annotations

import sys
from pathlib import Path

from lensopt.spec import dump_json, load_spec


def main(src: str, dst: str) -> None:
    spec = load_spec(src)
    cons = spec.optimize.constraints
    for name in type(cons).model_fields:
        group = getattr(cons, name)
        if group is not None and name != "glass_catalog" and getattr(group, "schedule", None) is not None:
            group.schedule = None
    Path(dst).write_text(dump_json(spec))


if __name__ == "__main__":
    main(*sys.argv[1:3])
