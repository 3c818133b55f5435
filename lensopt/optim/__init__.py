"""Optimization (S2): parameterization θ, solves, residuals, Levenberg–Marquardt and Adam, glass
catalogs, and the driver that runs a ``Problem``. Plain tensors and dataclasses only: a spec becomes a
problem in ``lensopt.design``."""

from lensopt.optim.problem import Evaluation, Problem, ProblemSetup
from lensopt.optim.run import OptimizeError, OptimizeResult, Progress, run_problem

__all__ = ["Evaluation", "OptimizeError", "OptimizeResult", "Problem", "ProblemSetup", "Progress", "run_problem"]
