"""Figures: the only part of jaxvs that imports matplotlib."""

from ._bode import bode_plot as bode_plot
