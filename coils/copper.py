"""The copper of a winding: resistivity and the resistance of a coil's conductor.

A coil of ``N`` turns of mean radius ``a`` has ``N 2 pi a`` metres of wire per coil (the mean
turn of a uniformly wound rectangular section has the mean radius); its resistance is
``rho l / A_wire`` with ``A_wire`` the conductor's cross-section:

* round wire of bare diameter ``d``: ``A_wire = pi d^2 / 4``;
* a winding section ``w x h`` filled to the fraction ``f`` by copper: ``A_wire = f w h / N``
  (``f = pi / 4`` for square-packed round wire, insulation neglected).

Resistivity is that of annealed copper at 20 degC (IEC 60028, the International Annealed
Copper Standard), the value :func:`coils.design.winding_power` uses too.
"""

from __future__ import annotations

import math

from ._validate import positive

__all__ = [
    "COPPER_RESISTIVITY",
    "COPPER_TEMPERATURE_COEFFICIENT",
    "SQUARE_PACKING",
    "turn_length",
    "round_wire_area",
    "winding_resistance",
]

#: Resistivity of annealed copper at 20 degC, ohm m (IEC 60028).
COPPER_RESISTIVITY = 1.7241e-8
#: Temperature coefficient of copper's resistivity near 20 degC, 1/K.
COPPER_TEMPERATURE_COEFFICIENT = 0.00393
#: Copper fill of a winding section of square-packed round wire (insulation neglected), pi/4.
SQUARE_PACKING = math.pi / 4


def turn_length(radius: float) -> float:
    """Length (m) of one turn of mean radius ``radius`` (m): ``2 pi radius``."""
    return 2.0 * math.pi * radius


def round_wire_area(diameter: float) -> float:
    """Conductor cross-section (m^2) of round wire of bare ``diameter`` (m): ``pi d^2 / 4``."""
    d = positive(diameter, "wire_diameter")
    return math.pi * d * d / 4.0


def winding_resistance(
    radius: float,
    turns: float,
    coils: int,
    *,
    wire_diameter: float | None = None,
    section: tuple[float, float] | None = None,
    fill: float = SQUARE_PACKING,
    resistivity: float = COPPER_RESISTIVITY,
) -> float:
    """Resistance (ohm) of ``coils`` identical coils in series, each of ``turns`` turns.

    Parameters
    ----------
    radius : float
        Mean radius of the turns, m.
    turns : float
        Turns per coil.
    coils : int
        Coils in series (1 for a coil, 2 for a Helmholtz or Maxwell pair).
    wire_diameter : float, optional
        Bare diameter of round wire, m.  If ``section`` is given too, the turns must fit in it
        at the fill ``fill``.
    section : (float, float), optional
        Winding cross-section (width, height) per coil, m; used when ``wire_diameter`` is not
        given: the copper fills ``fill`` of it.
    fill : float
        Copper fraction of the section, in (0, 1]; default pi/4 (square-packed round wire).
    resistivity : float
        Ohm m; default annealed copper at 20 degC.

    Returns
    -------
    float
        ``resistivity * coils * turns * 2 pi radius / A_wire``, ohm.

    Raises
    ------
    ValueError
        If neither ``wire_diameter`` nor ``section`` is given, if the wire does not fit the
        section, or on a bad parameter (named).

    Examples
    --------
    >>> round(winding_resistance(0.1, 200, 2, wire_diameter=1.5e-3), 4)   # ohm
    2.4521
    """
    fill = positive(fill, "fill")
    if fill > 1:
        raise ValueError(f"fill is a fraction of the winding section and must be <= 1; got {fill}")
    length = coils * turns * turn_length(radius)
    if wire_diameter is not None:
        area = round_wire_area(wire_diameter)
        if section is not None:
            capacity = fill * section[0] * section[1] / area
            if turns > capacity:
                raise ValueError(
                    f"{turns:g} turns of {1e3 * math.sqrt(4 * area / math.pi):g} mm wire do "
                    f"not fit a {1e3 * section[0]:g} x {1e3 * section[1]:g} mm winding (room "
                    f"for {capacity:.0f} at fill {fill:.3g})"
                )
    elif section is not None:
        area = fill * section[0] * section[1] / turns
    else:
        raise ValueError("the resistance needs a wire_diameter or a winding section")
    return positive(resistivity, "resistivity") * length / area
