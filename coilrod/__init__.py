"""coilrod: magnetic soft continuum robots in real coil fields (rod and FEM models).

The folders name the architecture: ``robot`` (what the robot is) -> ``rod`` and ``fem`` (the
models) driven by ``path`` (the one path-following engine) -> results; ``design`` and ``scene``
(TOML scenes, planner, runner, figures, CLI) sit on top.
"""

from __future__ import annotations

import importlib

#: public name -> the submodule that defines it; each is imported on first use (PEP 562), so
#: ``coilrod --help`` or ``import coilrod.robot`` loads neither scipy's optimisers nor numba.
_LAZY = {
    "Insertion": ".contact",
    "MeshVessel": ".contact",
    "Vessel": ".contact",
    "VesselNetwork": ".contact",
    "Wall": ".contact",
    "insert": ".contact",
    "ControlResult": ".control",
    "MagnetPoseResult": ".control",
    "solve_magnet_pose": ".control",
    "solve_currents": ".control",
    "Calibration": ".design.calibrate",
    "IdentifiabilityError": ".design.calibrate",
    "calibrate": ".design.calibrate",
    "MagnetizationDesign": ".design.optimize",
    "optimize_magnetization": ".design.optimize",
    "Sensitivities": ".design.sensitivity",
    "SingularStateError": ".design.sensitivity",
    "sensitivities": ".design.sensitivity",
    "SweepResult": ".design.sweep",
    "sweep": ".design.sweep",
    "Workspace": ".design.workspace",
    "workspace": ".design.workspace",
    "ConvergenceError": ".errors",
    "UnitsWarning": ".errors",
    "solve_fem": ".fem",
    "StabilityWarning": ".path.events",
    "Circle": ".robot",
    "Magnetization": ".robot",
    "Rectangle": ".robot",
    "Rod": ".robot",
    "presets": ".robot",
    "RodPath": ".rod",
    "RodResult": ".rod",
    "elastica": ".rod",
    "solve_rod": ".rod",
    "trace_rod": ".rod",
}


def __getattr__(name: str):
    """Import a public name's submodule on first use and cache the name in this module."""
    if name not in _LAZY:
        raise AttributeError(f"module 'coilrod' has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    globals()[name] = value
    return value


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
    "solve_magnet_pose",
    "MagnetPoseResult",
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
