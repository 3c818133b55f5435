"""Tolerancing (S6.2): perturbed lenses with a leading trial dimension, compensators, sensitivity and
Monte Carlo (``lensopt tolerance``). A spec becomes a ``Job`` in ``lensopt.design.tolerance``.

    model.py        tolerances, random draws, perturbed lenses
    evaluate.py     vmapped metrics of perturbed lenses, focus and LM compensators
    psnr.py         PSNR before/after restoration as a metric
    job.py          the study (``Job``), the scalar metric, trials in chunks (serial or Dask)
    setup.py        a ``Job`` from a traced lens and settings
    sensitivity.py  each tolerance at ±limit, inverse sensitivity, RSS prediction
    monte_carlo.py  random trials, yield table, worst trials
"""
