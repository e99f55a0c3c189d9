"""Cross-sections of the robot: area (m^2) and second moment about the bending axis z (m^4)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from coils._validate import positive

__all__ = ["Circle", "Rectangle"]


@dataclass(frozen=True)
class Circle:
    """Solid circular section.

    Parameters
    ----------
    diameter : float
        Diameter D in metres.

    Examples
    --------
    >>> Circle(diameter=2e-3).area
    3.141592653589793e-06
    """

    diameter: float

    def __post_init__(self):
        object.__setattr__(self, "diameter", positive(self.diameter, "diameter"))

    @property
    def area(self) -> float:
        """A = pi D^2 / 4, m^2."""
        return math.pi * self.diameter**2 / 4

    @property
    def second_moment(self) -> float:
        """I = pi D^4 / 64, m^4 (bending about z)."""
        return math.pi * self.diameter**4 / 64

    @property
    def height(self) -> float:
        """Extent in the bending plane (along y), m."""
        return self.diameter


@dataclass(frozen=True)
class Rectangle:
    """Solid rectangular section; ``thickness`` lies in the bending plane (along y).

    Parameters
    ----------
    width : float
        Extent along z (out of the bending plane), metres.
    thickness : float
        Extent along y (in the bending plane), metres.  I = width * thickness^3 / 12.
    """

    width: float
    thickness: float

    def __post_init__(self):
        object.__setattr__(self, "width", positive(self.width, "width"))
        object.__setattr__(self, "thickness", positive(self.thickness, "thickness"))

    @property
    def area(self) -> float:
        """A = width * thickness, m^2."""
        return self.width * self.thickness

    @property
    def second_moment(self) -> float:
        """I = width * thickness^3 / 12, m^4 (bending about z)."""
        return self.width * self.thickness**3 / 12

    @property
    def height(self) -> float:
        """Extent in the bending plane (along y), m."""
        return self.thickness
