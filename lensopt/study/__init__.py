"""Studies over whole designs (``lensopt sweep``, ``lensopt design``). Above ``optim`` and ``spec`` (it edits
specs and runs the optimizer); no UI.

    keys.py    dotted keys into a spec, ``--vary``
    sweep.py   a spec over a grid of values with multi-start optimization
    procedure.py  the seed's design procedure: rounds of perturbed starts (multi-start or basin hopping)
                  until the best agree; the distinct minima
"""

from lensopt.study.keys import Vary, get_key, parse_vary, set_key
from lensopt.study.sweep import Settings, SweepEvent, SweepResult, expand_grid, perturbed_spec, run_sweep

__all__ = ["Vary", "get_key", "parse_vary", "set_key", "Settings", "SweepEvent", "SweepResult", "expand_grid",
           "perturbed_spec", "run_sweep"]
