"""Optimization (S2): parameterization θ, solves, residuals, Levenberg–Marquardt and Adam, glass
catalogs, and the driver behind ``lensopt optimize``."""

from lensopt.optim.problem import Evaluation, Problem
from lensopt.optim.run import OptimizeError, OptimizeResult, Progress, optimize

__all__ = ["Evaluation", "OptimizeError", "OptimizeResult", "Problem", "Progress", "optimize"]
