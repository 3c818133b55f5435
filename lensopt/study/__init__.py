"""Studies over whole designs: sweeps of a spec over a grid of values with multi-start optimization
(``lensopt sweep``). Above ``optim`` and ``spec`` (it edits specs and runs the optimizer); no UI."""

from lensopt.study.keys import Vary, get_key, parse_vary, set_key
from lensopt.study.sweep import Settings, SweepEvent, SweepResult, expand_grid, perturbed_spec, run_sweep

__all__ = ["Vary", "get_key", "parse_vary", "set_key", "Settings", "SweepEvent", "SweepResult", "expand_grid",
           "perturbed_spec", "run_sweep"]
