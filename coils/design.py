"""Coil design helpers: the current or turns for a target centre field or gradient, and the
copper resistance and power of a winding.

Targets are met through the linearity of Biot-Savart in the current, using the coil's exact
field at its centre -- so the helpers hold for finite windings and non-standard spacings, not
only for the textbook closed forms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ._validate import finite_scalar, positive
from .coaxial import CoaxialCoils
from .copper import COPPER_RESISTIVITY, COPPER_TEMPERATURE_COEFFICIENT
from .pairs import Coil, CoilPair

__all__ = [
    "current_for_field",
    "current_for_gradient",
    "turns_for_field",
    "turns_for_gradient",
    "wire_length",
    "WindingPower",
    "winding_power",
    "COPPER_RESISTIVITY",
    "COPPER_TEMPERATURE_COEFFICIENT",
]

#: Absolute zero, degC.
ABSOLUTE_ZERO = -273.15


def _as_coil(coil) -> Coil | CoilPair:
    """``coil`` if it is a Coil or a pair (it has turns, a radius and a current)."""
    if not isinstance(coil, Coil | CoilPair):
        raise ValueError(f"coil must be a Coil, HelmholtzPair or MaxwellPair; got {coil!r}")
    return coil


def _centre_values(coil: CoaxialCoils):
    coil = _as_coil(coil)
    B, G = coil.B_and_gradient(coil.center[None, :])
    n = coil.axis
    return float(B[0] @ n), float(n @ G[0] @ n)


def _scale_factor(coil: CoaxialCoils, target, quantity: str) -> float:
    """target / (the coil's present axial centre field or gradient): Biot-Savart is linear in
    the ampere-turns, so current or turns scale by this factor."""
    target = finite_scalar(target, quantity)
    b, g = _centre_values(coil)
    present = b if quantity == "B" else g
    if present == 0.0:
        what = "field" if quantity == "B" else "gradient"
        raise ValueError(f"{coil!r} produces no {what} at its centre; cannot scale to a target")
    return target / present


def current_for_field(coil: CoaxialCoils, B: float) -> float:
    """Current per turn (A) that gives the axial centre field ``B`` (T).

    Examples
    --------
    >>> from coils import HelmholtzPair
    >>> round(current_for_field(HelmholtzPair(0.1, 100, 1.0), 5e-3), 3)   # A
    5.561
    """
    return coil.current * _scale_factor(coil, B, "B")


def current_for_gradient(coil: CoaxialCoils, gradient: float) -> float:
    """Current per turn (A) that gives the axial centre gradient ``gradient`` (T/m)."""
    return coil.current * _scale_factor(coil, gradient, "gradient")


def turns_for_field(coil: CoaxialCoils, B: float) -> float:
    """Turns per coil (at the coil's current) that give the axial centre field ``B`` (T).

    Returned as a real number; round up to wind a real coil.
    """
    return coil.turns * _scale_factor(coil, B, "B")


def turns_for_gradient(coil: CoaxialCoils, gradient: float) -> float:
    """Turns per coil (at the coil's current) that give the axial centre gradient (T/m)."""
    return coil.turns * _scale_factor(coil, gradient, "gradient")


def wire_length(coil: CoaxialCoils) -> float:
    """Total conductor length (m): turns x 2 pi x mean radius, summed over the coils."""
    coil = _as_coil(coil)
    n_coils = 2 if hasattr(coil, "spacing") else 1
    return n_coils * coil.turns * 2 * math.pi * coil.radius


@dataclass(frozen=True)
class WindingPower:
    """Electrical budget of a coil or pair.

    Attributes
    ----------
    resistance : float
        Total resistance, ohm.
    power : float
        Dissipated power I^2 R, W.
    voltage : float
        Drive voltage I R, V.
    wire_length : float
        Conductor length, m.
    current_density : float
        Current per wire cross-section, A/m^2.
    """

    resistance: float
    power: float
    voltage: float
    wire_length: float
    current_density: float


def winding_power(
    coil: CoaxialCoils,
    wire_diameter: float,
    *,
    resistivity: float = COPPER_RESISTIVITY,
    temperature: float = 20.0,
    temperature_coefficient: float = COPPER_TEMPERATURE_COEFFICIENT,
    packing: float = math.pi / 4,
) -> WindingPower:
    """Resistance and power of the coil wound with round wire (copper by default).

    Parameters
    ----------
    coil : Coil, HelmholtzPair or MaxwellPair
        Its ``turns``, ``radius``, ``current`` and optional ``winding`` are used.
    wire_diameter : float
        Bare conductor diameter, m.
    resistivity : float
        At 20 degC, ohm m.
    temperature : float
        Winding temperature, degC (above -273.15); ``rho(T) = rho20 (1 + alpha (T - 20))``.
    temperature_coefficient : float
        alpha, 1/K.
    packing : float
        Fill factor of round wire in the winding section, in (0, 1] (pi/4 for square packing);
        if the coil has a ``winding`` cross-section, the turns must fit in it.

    Raises
    ------
    ValueError
        If the wire does not fit the winding cross-section, or on a bad parameter (named).
    """
    coil = _as_coil(coil)
    d = positive(wire_diameter, "wire_diameter")
    temperature = finite_scalar(temperature, "temperature")
    if temperature <= ABSOLUTE_ZERO:
        raise ValueError(
            f"temperature must be above absolute zero ({ABSOLUTE_ZERO} degC); got {temperature}"
        )
    packing = positive(packing, "packing")
    if packing > 1:
        raise ValueError(f"packing is a fill factor and must be in (0, 1]; got {packing}")
    rho = positive(resistivity, "resistivity") * (
        1 + finite_scalar(temperature_coefficient, "temperature_coefficient") * (temperature - 20.0)
    )
    if rho <= 0:
        raise ValueError("resistivity at that temperature is not positive")
    area = math.pi * d * d / 4
    winding = getattr(coil, "winding", None)
    if winding is not None:
        capacity = packing * winding[0] * winding[1] / area
        if coil.turns > capacity:
            raise ValueError(
                f"{coil.turns:g} turns of {1e3 * d:g} mm wire do not fit a "
                f"{1e3 * winding[0]:g} x {1e3 * winding[1]:g} mm winding (room for "
                f"{capacity:.0f} at packing {packing:.3g})"
            )
    length = wire_length(coil)
    resistance = rho * length / area
    current = abs(coil.current)
    return WindingPower(
        resistance=resistance,
        power=current**2 * resistance,
        voltage=current * resistance,
        wire_length=length,
        current_density=current / area,
    )
