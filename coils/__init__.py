"""coils: magnetic fields of ideal sources and real coil pairs (Biot-Savart, exact gradients).

Knows fields and nothing of robots.  Every source follows the :class:`~coils.field.Field`
protocol: ``B(points)`` -> (n, 3) T, ``gradient(points)`` -> (n, 3, 3) T/m with
``[k, i, j] = dB_i/dx_j``, points (n, 3) in metres.
"""

from .field import Field, FieldSum, ScaledField
from .ideal import LinearField, UniformField, maxwell_gradient

__all__ = [
    "Field",
    "FieldSum",
    "ScaledField",
    "UniformField",
    "LinearField",
    "maxwell_gradient",
]
