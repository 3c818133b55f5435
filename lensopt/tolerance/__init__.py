"""Tolerancing (S6.2): perturbed lenses with a leading trial dimension, compensators, sensitivity and
Monte Carlo (``lensopt tolerance``)."""
