"""Optimization (S2): parameterization θ, solves, residuals, Levenberg–Marquardt and Adam, glass
catalogs, and the driver that runs a ``Problem``. Plain tensors and dataclasses only: a spec becomes a
problem in ``lensopt.design``.

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
    compiled_jacobian.py  the LM Jacobian compiled (AOT/Inductor)
    run.py                the driver: phases, glass binding, progress
    report.py             constraint margins of a lens
    gtra.py               generalized transverse ray aberrations (S66–S68)
    image_objective.py    ``objective = "raw"``: image batches and the image loss
    irm.py                training the restoration network on a fixed lens (S4.3.2)
    irm_run.py            a whole train-irm run; loading a network; restoring images (``restoration_hook``)
    joint.py              one joint lens + network step; ``Dist`` for DDP
"""

from lensopt.optim.problem import Evaluation, Problem, ProblemSetup
from lensopt.optim.run import OptimizeError, OptimizeResult, Progress, run_problem

__all__ = ["Evaluation", "OptimizeError", "OptimizeResult", "Problem", "ProblemSetup", "Progress", "run_problem"]
