"""Control in real coil systems: the currents (or a permanent magnet's pose) that put the tip on
a target."""

from .currents import ControlResult, ControlWarning, solve_currents
from .magnet_pose import MagnetPoseResult, solve_magnet_pose

__all__ = [
    "solve_currents",
    "ControlResult",
    "ControlWarning",
    "solve_magnet_pose",
    "MagnetPoseResult",
]
