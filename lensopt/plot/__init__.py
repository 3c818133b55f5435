"""Matplotlib figures: they take analysis results and never trace by themselves."""
