"""Control in real coil systems: the currents that put the tip on a target."""

from .currents import ControlResult, ControlWarning, solve_currents

__all__ = ["solve_currents", "ControlResult", "ControlWarning"]
