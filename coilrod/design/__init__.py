"""Design studies on top of the models: how far real coils move the robot from the ideal field."""

from .studies import coil_shift, make_pair, plot_shift, shift_vs_placement, shift_vs_radius

__all__ = ["coil_shift", "make_pair", "plot_shift", "shift_vs_placement", "shift_vs_radius"]
