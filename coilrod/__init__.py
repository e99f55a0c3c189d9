"""coilrod: magnetic soft continuum robots in real coil fields (rod and FEM models)."""

from . import presets
from .errors import ConvergenceError
from .magnetization import Magnetization
from .rod import Rod
from .sections import Circle, Rectangle

__all__ = [
    "Rod",
    "Circle",
    "Rectangle",
    "Magnetization",
    "ConvergenceError",
    "presets",
]
