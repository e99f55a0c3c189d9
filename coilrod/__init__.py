"""coilrod: magnetic soft continuum robots in real coil fields (rod and FEM models)."""

from . import presets
from .errors import ConvergenceError
from .fem import solve_fem  # scikit-fem itself is imported lazily, inside the call
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
    "solve_fem",
]
