"""Figures (matplotlib, Agg): each function takes analysis results and returns a ``Figure``; nothing
here traces rays. ``save_figure`` writes a figure atomically, in the format its file name says."""

from lensopt.plot.fans import plot_fans
from lensopt.plot.layout import plot_layout
from lensopt.plot.spots import plot_spots
from lensopt.plot.style import save_figure, wavelength_color

__all__ = ["plot_fans", "plot_layout", "plot_spots", "save_figure", "wavelength_color"]
