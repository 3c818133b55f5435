"""Design from a spec: every adapter from the spec (the data model) to an engine — the optimization
problem, the restoration configs, the tolerance job —, the optimized values written back into a spec,
and the spec-level drivers of ``lensopt optimize``. This layer reads the spec and hands plain tensors and
frozen dataclasses down to ``lensopt.optim``, ``lensopt.restore`` and ``lensopt.tolerance``, which never
import the spec.

    setup.py            spec → ProblemSetup → Problem (``build_problem``); ``[optimize]`` as plain settings
    writeback.py        θ → spec; glass binding (``bind_glasses``)
    optimize.py         ``optimize(spec)``: build, run (``optim.driver``), bind, write back
    restore.py          ``[restore]`` → the restoration network's configs
    tolerance.py        spec + ``[tolerance]`` → tolerance ``Job``; trials written back as specs
    tolerance_study.py  a whole tolerance study as plain data (sensitivity, Monte Carlo, worst trials, figures)
    joint.py            one joint lens + network step (S3.3.1): the restored-image objective, LM step, network step
    joint_run.py        ``objective = "restored"``: the joint lens + network run (checkpoints, resume, DDP, TensorBoard)
"""

from lensopt.design.optimize import optimize
from lensopt.design.setup import SpecProblem, build_problem
from lensopt.design.writeback import bind_glasses, to_spec

__all__ = ["SpecProblem", "bind_glasses", "build_problem", "optimize", "to_spec"]
