"""coilrod: magnetic soft continuum robots in real coil fields (rod and FEM models).

The folders name the architecture: ``robot`` (what the robot is) -> ``rod`` and ``fem`` (the
models) driven by ``path`` (the one path-following engine) -> results; ``design`` and ``scene``
(TOML scenes, planner, runner, figures, CLI) sit on top.
"""

from . import _moved  # noqa: F401  (old 0.1 module paths stay importable)
from .contact import Insertion, MeshVessel, Vessel, VesselNetwork, Wall, insert
from .control import ControlResult, solve_currents
from .design.calibrate import Calibration, IdentifiabilityError, calibrate
from .design.optimize import MagnetizationDesign, optimize_magnetization
from .design.sensitivity import Sensitivities, SingularStateError, sensitivities
from .design.sweep import SweepResult, sweep  # dask is imported only for a cluster
from .design.workspace import Workspace, workspace
from .errors import ConvergenceError, UnitsWarning
from .fem import solve_fem  # scikit-fem itself is imported lazily, inside the call
from .path.events import StabilityWarning
from .robot import Circle, Magnetization, Rectangle, Rod, presets
from .rod import RodPath, RodResult, elastica, solve_rod, trace_rod  # noqa: F401 (elastica: a module)

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
    "UnitsWarning",
    "sensitivities",
    "Sensitivities",
    "SingularStateError",
    "workspace",
    "Workspace",
    "optimize_magnetization",
    "MagnetizationDesign",
    "solve_currents",
    "ControlResult",
    "sweep",
    "SweepResult",
    "calibrate",
    "Calibration",
    "IdentifiabilityError",
    "Wall",
    "Vessel",
    "MeshVessel",
    "VesselNetwork",
    "insert",
    "Insertion",
]


def __dir__() -> list[str]:
    """The public API only (``__all__``): ``dir(coilrod)`` shows what users call; the
    submodules stay importable (``coilrod.elastica``, ``coilrod.rod``, ...)."""
    return sorted(__all__)
