"""Tolerancing (S6.2): perturbed lenses with a leading trial dimension, compensators, sensitivity and
Monte Carlo (``lensopt tolerance``).

    model.py      tolerances, random draws, perturbed lenses
    setup.py      a tolerance Job from a traced lens and settings
    evaluate.py   vmapped metrics of perturbed lenses, focus compensator
    psnr.py       PSNR before/after restoration as a metric
    run.py        sensitivity, Monte Carlo, yields, RSS
"""
