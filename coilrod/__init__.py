"""coilrod: magnetic soft continuum robots in real coil fields (rod and FEM models)."""

from . import elastica, presets
from .continuation import RodPath, trace_rod
from .errors import ConvergenceError
from .fem import solve_fem  # scikit-fem itself is imported lazily, inside the call
from .magnetization import Magnetization
from .rod import Rod
from .rod_result import RodResult, StabilityWarning
from .rod_solver import solve_rod
from .sections import Circle, Rectangle

__all__ = [
    "Rod",
    "Circle",
    "Rectangle",
    "Magnetization",
    "ConvergenceError",
    "presets",
    "solve_fem",
    "solve_rod",
    "trace_rod",
    "RodResult",
    "RodPath",
    "StabilityWarning",
    "elastica",
]
