"""Design from a spec: the optimization problem of a lens spec, the optimized values written back into a
spec, and the spec-level drivers of ``lensopt optimize``. This layer reads the spec and hands plain
tensors and dataclasses to ``lensopt.optim``, which never imports the spec.

    setup.py       spec → ProblemSetup → Problem (``build_problem``); ``[optimize]`` as plain settings
    writeback.py   θ → spec; glass binding (``bind_glasses``)
    run.py         ``optimize(spec)``: build, run (``optim.run``), bind, write back
    joint_run.py   ``objective = "restored"``: the joint lens + network run (checkpoints, resume, DDP, TensorBoard)
"""

from lensopt.design.run import optimize
from lensopt.design.setup import SpecProblem, build_problem
from lensopt.design.writeback import bind_glasses, to_spec

__all__ = ["SpecProblem", "bind_glasses", "build_problem", "optimize", "to_spec"]
