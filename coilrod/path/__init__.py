"""The one path-following engine every model drives.

A model implements :class:`PathProblem` (``linearize`` -> residual and tangent, ``solve``,
``d_residual_d_scale``, ``error``, ``stability``; optionally batched over stacks of states) and
the engine does the rest: :func:`newton` (line search, chord iterations, batched),
:func:`follow_load` (load stepping with cuts, stability checked at every step and changes
located, jump detection, chunks of a smooth path corrected together, snap-through around folds)
and :class:`ArcLength` (pseudo-arclength through limit points).  Events are plain dicts
(:mod:`coilrod.path.events`).
"""

from .arclength import ArcLength
from .corrector import NewtonOptions, NewtonResult, newton
from .events import StabilityWarning, warn_events
from .protocol import Linearization, PathProblem
from .stepping import PathOptions, PathPoint, PathRun, follow_load

__all__ = [
    "PathProblem",
    "Linearization",
    "NewtonOptions",
    "NewtonResult",
    "newton",
    "PathOptions",
    "PathPoint",
    "PathRun",
    "follow_load",
    "ArcLength",
    "StabilityWarning",
    "warn_events",
]
