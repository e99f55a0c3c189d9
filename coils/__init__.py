"""coils: magnetic fields of ideal sources and real coil pairs (Biot-Savart, exact gradients).

Knows fields and nothing of robots.  Every source follows the :class:`~coils.field.Field`
protocol: ``B(points)`` -> (n, 3) T, ``gradient(points)`` -> (n, 3, 3) T/m with
``[k, i, j] = dB_i/dx_j``, points (n, 3) in metres.

A :class:`~coils.CoilSystem` is linear in the currents of its channels (coils and pairs):
``currents``, ``with_currents``, ``unit_fields``, ``power``, ``currents_for``;
:mod:`coils.presets` builds real arrangements (three-axis Helmholtz, Helmholtz + Maxwell, an
eight-coil hemisphere).

Sources are immutable: assigning an attribute raises ``AttributeError`` and their arrays are
read-only, so what a source says it is always matches the field it computes; change one with
``with_current(I)`` (a coil or a pair), ``with_currents(I)`` (a system) or
``replace(**changes)`` (any source), which return copies.
"""

from . import presets
from .coaxial import CoaxialCoils
from .field import Field, FieldSum, ScaledField
from .grid import GriddedField
from .ideal import LinearField, UniformField, linearize, maxwell_gradient
from .magnets import CuboidMagnet, CylinderMagnet, Dipole
from .mpem import MPEM
from .pairs import Coil, CoilPair, HelmholtzPair, MaxwellPair
from .region import UniformityReport, deviation, uniformity
from .system import CoilSystem

__all__ = [
    "Field",
    "FieldSum",
    "ScaledField",
    "UniformField",
    "LinearField",
    "linearize",
    "maxwell_gradient",
    "CoaxialCoils",
    "Coil",
    "CoilPair",
    "HelmholtzPair",
    "MaxwellPair",
    "CoilSystem",
    "uniformity",
    "deviation",
    "UniformityReport",
    "GriddedField",
    "MPEM",
    "Dipole",
    "CylinderMagnet",
    "CuboidMagnet",
    "presets",
]


def __dir__() -> list[str]:
    """The public API only (``__all__``): ``dir(coils)`` lists the sources and helpers, not
    the modules that implement them."""
    return sorted(__all__)
