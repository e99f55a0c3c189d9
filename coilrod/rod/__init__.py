"""Kirchhoff rod models: meshes, the planar discrete rod, the closed-form elastica, solvers."""

from ..robot.rod import Rod  # noqa: F401  (the 0.1 path coilrod.rod.Rod)
from . import elastica
from .result import RodResult
from .solve import solve_rod
from .trace import RodPath, trace_rod

__all__ = ["solve_rod", "trace_rod", "RodResult", "RodPath", "elastica"]
