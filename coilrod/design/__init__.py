"""Design studies on top of the models: how far real coils move the robot from the ideal field.

Sweeps of a scene over a grid of parameter values (serial, local processes, Dask) are
:func:`coilrod.sweep` (:mod:`coilrod.design.sweep`, not imported here).
"""

from .studies import coil_shift, make_pair, plot_shift, shift_vs_placement, shift_vs_radius

__all__ = ["coil_shift", "make_pair", "plot_shift", "shift_vs_placement", "shift_vs_radius"]
