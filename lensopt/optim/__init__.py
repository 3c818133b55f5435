"""Lens optimization (S2): parameterization θ, solves, residuals, Levenberg–Marquardt and Adam, glass
catalogs, and the driver that runs a ``Problem``. Plain tensors and dataclasses only: a spec becomes a
problem in ``lensopt.design``; the restoration network is trained in ``lensopt.restore``.

    variables.py          θ ↔ lens tensors (S2.1)
    solves.py             solves applied inside the residual function
    rays.py               the optimization rays
    residuals.py          pure residual terms (S2.2)
    terms.py              the residual terms: one static ordered tuple (TERMS) and what they see
    problem.py            Problem: residuals(θ), Jacobian, checks
    jacobian.py           the LM Jacobian in three forward-mode stages (jacfwd, differential trace, vmap-jvp)
    settings.py           plain frozen settings
    schedule.py           weight schedules
    lm.py                 Levenberg–Marquardt (S2.3.2)
    adam.py               Adam (S2.3.1)
    driver.py             the driver: phases, glass binding, progress, Ctrl-C
    report.py             constraint margins of a lens
    gtra.py               generalized transverse ray aberrations (S66–S68)
    image_objective.py    ``objective = "raw"``: image batches and the image loss
"""

from lensopt.optim.driver import OptimizeError, OptimizeResult, Progress, run_problem
from lensopt.optim.problem import Evaluation, Problem, ProblemSetup

__all__ = ["Evaluation", "OptimizeError", "OptimizeResult", "Problem", "ProblemSetup", "Progress", "run_problem"]
