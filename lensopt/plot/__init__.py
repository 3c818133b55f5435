"""Figures (matplotlib, Agg): each function takes analysis results and returns a ``Figure``; nothing here
traces rays. ``save_figure`` writes a figure atomically, in the format its file name says.

    style.py      colours, scale bars, ``save_figure``
    layout.py     2D meridional layout
    fans.py       ray fans
    spots.py      spot diagrams
    field.py      distortion and relative illumination against field
    psf.py        RGB PSFs across the field
    mtf.py        MTF against frequency
    regions.py    sensor tiles and a sampled batch
    tolerance.py  tolerancing: CDF, histogram, sensitivity
    sweep.py      design sweeps
    accuracy.py   accuracy against time
    opd.py        OPD fans (tangential, sagittal) per field
    wavefront.py  wavefront maps with RMS, P-V and Strehl per field
    field_curves.py  astigmatic field curves, distortion, lateral colour
    focal_shift.py   chromatic focal shift against wavelength
    encircled.py  encircled / ensquared energy per field
    mtf_field.py  MTF against field at chosen frequencies
    through_focus.py  MTF through focus
"""

from lensopt.plot.fans import plot_fans
from lensopt.plot.layout import plot_layout
from lensopt.plot.spots import plot_spots
from lensopt.plot.style import save_figure, wavelength_color

__all__ = ["plot_fans", "plot_layout", "plot_spots", "save_figure", "wavelength_color"]
