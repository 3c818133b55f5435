"""Design from a spec: the optimization problem of a lens spec (``setup``), the optimized values
written back into a spec (``writeback``), and the spec-level drivers of ``lensopt optimize``
(``run``; ``joint_run`` for ``objective = "restored"``). This layer reads the spec and hands plain
tensors and dataclasses to ``lensopt.optim``, which never imports the spec."""

from lensopt.design.run import optimize
from lensopt.design.setup import SpecProblem, build_problem
from lensopt.design.writeback import bind_glasses, to_spec

__all__ = ["SpecProblem", "bind_glasses", "build_problem", "optimize", "to_spec"]
