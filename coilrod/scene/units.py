"""Quantities with units in scene files: ``"40 mm"``, ``"5 mT"``, ``"640 kA/m"``, ``"1 MPa"``.

A scene states every dimensional number with its unit; :func:`parse_quantity` converts it to SI
and says exactly what is wrong otherwise ("missing unit", "unknown unit", wrong dimension).
"""

from __future__ import annotations

import math
import re

__all__ = [
    "UnitError",
    "parse_quantity",
    "read_quantity",
    "dimension_of",
    "DIMENSIONS",
    "SI_UNITS",
    "short_int",
]


class UnitError(ValueError):
    """A quantity string without a unit, with an unknown unit, or of the wrong dimension."""


#: Units accepted for each dimension, with their SI factor.
DIMENSIONS: dict[str, dict[str, float]] = {
    "length": {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "um": 1e-6, "µm": 1e-6, "km": 1e3},
    "flux density": {"T": 1.0, "mT": 1e-3, "uT": 1e-6, "µT": 1e-6, "G": 1e-4, "mG": 1e-7},
    "gradient": {"T/m": 1.0, "mT/m": 1e-3, "mT/mm": 1.0, "T/mm": 1e3, "G/cm": 1e-2},
    "magnetization": {"A/m": 1.0, "kA/m": 1e3, "MA/m": 1e6},
    "pressure": {"Pa": 1.0, "kPa": 1e3, "MPa": 1e6, "GPa": 1e9},
    "current": {"A": 1.0, "mA": 1e-3, "kA": 1e3},
    "angle": {"rad": 1.0, "deg": math.pi / 180, "°": math.pi / 180},
}
#: The SI unit of each dimension (factor 1 in :data:`DIMENSIONS`).
SI_UNITS = {dim: next(u for u, f in units.items() if f == 1.0) for dim, units in DIMENSIONS.items()}

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_RE = re.compile(rf"^\s*(?P<num>{_NUMBER})\s*(?P<unit>\S*)\s*$")


def parse_quantity(value, dimension: str, key: str = "value") -> float:
    """Convert ``"40 mm"`` (a string with a unit) to SI for ``dimension``.

    Parameters
    ----------
    value : str
        Number and unit, e.g. ``"5 mT"``, ``"0.5 T/m"``, ``"90 deg"``.  A bare number is an
        error ("missing unit"), except ``0`` for angles.
    dimension : str
        One of :data:`DIMENSIONS`.
    key : str
        The scene key, for the error message.

    Returns
    -------
    float
        The value in SI units (m, T, T/m, A/m, Pa, A, rad).

    Examples
    --------
    >>> parse_quantity("40 mm", "length")
    0.04
    >>> parse_quantity("90 deg", "angle")
    1.5707963267948966
    """
    units = DIMENSIONS[dimension]
    if isinstance(value, bool):
        raise UnitError(f"{key}: expected a {dimension} with a unit, e.g. '{_example(dimension)}'")
    if isinstance(value, int | float):
        if dimension == "angle" and value == 0:
            return 0.0
        if isinstance(value, float) and not math.isfinite(value):  # nan, inf, 1e400
            raise UnitError(
                f"{key}: missing unit in {value!r}, and the number must be finite; write a "
                f"finite number with a unit, e.g. '{_example(dimension)}'"
            )
        if isinstance(value, int) and abs(value) >= 10**15:
            raise UnitError(
                f"{key}: missing unit in {short_int(value)}; write it as a string with a "
                f"unit, e.g. '{_example(dimension)}'"
            )
        raise UnitError(
            f"{key}: missing unit in {value!r}; write it as a string with a unit, "
            f"e.g. '{value} {next(iter(units))}' ({dimension}: {', '.join(units)})"
        )
    if not isinstance(value, str):
        raise UnitError(
            f"{key}: expected a {dimension} such as '{_example(dimension)}'; got {value!r}"
        )
    match = _RE.match(value)
    if not match:
        raise UnitError(
            f"{key}: cannot read {value!r} as a number with a unit, e.g. '{_example(dimension)}'"
        )
    number, unit = float(match["num"]), match["unit"]
    if not unit:
        raise UnitError(f"{key}: missing unit in {value!r} ({dimension}: {', '.join(units)})")
    if unit not in units:
        other = [d for d, u in DIMENSIONS.items() if unit in u]
        hint = f"; {unit!r} is a {other[0]}" if other else ""
        raise UnitError(
            f"{key}: unknown unit {unit!r} for a {dimension} (use one of {', '.join(units)}){hint}"
        )
    result = number * units[unit]
    if not math.isfinite(result):
        raise UnitError(f"{key}: {value!r} is not finite")
    return result


def dimension_of(unit: str) -> str | None:
    """The dimension whose units include ``unit`` (None if none does).

    Examples
    --------
    >>> dimension_of("kA/m"), dimension_of("mm"), dimension_of("furlong")
    ('magnetization', 'length', None)
    """
    return next((dim for dim, units in DIMENSIONS.items() if unit in units), None)


def read_quantity(value: str, key: str = "value") -> tuple[float, str | None]:
    """Read ``"60 mm"`` (any known unit) or ``"0.2"`` (a plain number) without knowing the
    dimension beforehand.

    Parameters
    ----------
    value : str
        A number, optionally followed by a unit of one of :data:`DIMENSIONS`.
    key : str
        What the value is for, for the error message.

    Returns
    -------
    (float, str or None)
        The value in SI units and its dimension (None for a plain number).

    Raises
    ------
    UnitError
        If ``value`` is not a number with an optional unit, or the unit is unknown.

    Examples
    --------
    >>> read_quantity("60 mm")
    (0.06, 'length')
    >>> read_quantity("0.25")
    (0.25, None)
    """
    match = _RE.match(value) if isinstance(value, str) else None
    if not match:
        raise UnitError(
            f"{key}: cannot read {value!r} as a number with an optional unit, e.g. '40 mm'"
        )
    number, unit = float(match["num"]), match["unit"]
    if not math.isfinite(number):
        raise UnitError(f"{key}: {value!r} is not finite")
    if not unit:
        return number, None
    dim = dimension_of(unit)
    if dim is None:
        known = ", ".join(u for units in DIMENSIONS.values() for u in units)
        raise UnitError(f"{key}: unknown unit {unit!r} in {value!r} (known units: {known})")
    result = number * DIMENSIONS[dim][unit]
    if not math.isfinite(result):
        raise UnitError(f"{key}: {value!r} is not finite")
    return result, dim


#: A typical value of each dimension, quoted in error messages.
EXAMPLES = {
    "length": "40 mm",
    "flux density": "5 mT",
    "gradient": "0.5 T/m",
    "magnetization": "640 kA/m",
    "pressure": "1 MPa",
    "current": "2 A",
    "angle": "90 deg",
}


def short_int(value: int) -> str:
    """A long integer for a message, e.g. "an integer of about 400 digits" (no str(), which
    Python refuses beyond 4300 digits)."""
    return f"an integer of about {math.ceil(value.bit_length() * math.log10(2))} digits"


def _example(dimension: str) -> str:
    return EXAMPLES[dimension]
