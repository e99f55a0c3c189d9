"""Cross-sections of the robot: area (m^2), second moments about the body axes z (in-plane
bending) and y (out-of-plane bending), and the Saint-Venant torsion constant (m^4).

Body axes of the reference (straight) rod: x along the tangent, y the in-plane normal, z the
binormal.  Bending in the x-y plane turns the section about z (``second_moment``); bending out
of that plane turns it about y (``second_moment_y``); twisting about x is resisted by G J
(``torsion_constant``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from coils._validate import positive

__all__ = ["Circle", "Rectangle", "rectangle_torsion_constant"]

#: Riemann zeta(5) (Apery-like constant; DLMF 25.6), the sum of 1/n^5 over n >= 1.
_ZETA5 = 1.0369277551433699263313655
#: Odd n of the series of ``1 - tanh`` kept in :func:`rectangle_torsion_constant` (1 to 53):
#: the first one left out, n = 55, is below 2 exp(-55 pi) / 55^5 < 1e-80 (a/b >= 1).
_ODD_TERMS = np.arange(1, 55, 2, dtype=float)


def rectangle_torsion_constant(a: float, b: float) -> float:
    """Saint-Venant torsion constant J of a solid a x b rectangle, m^4 (a, b in m).

    Parameters
    ----------
    a, b : float
        Side lengths, m (either order; positive).

    Returns
    -------
    float
        J in m^4, exact to round-off.

    Notes
    -----
    Timoshenko & Goodier, *Theory of Elasticity* (3rd ed., 1970), section 109, eq. (168): with
    ``a`` the longer and ``b`` the shorter side,

        J = a b^3 / 3 [1 - 192 b / (pi^5 a) sum_{n = 1, 3, 5, ...} tanh(n pi a / (2 b)) / n^5].

    The sum is taken without truncation error: sum_{n odd} 1/n^5 = (1 - 2^-5) zeta(5) in
    closed form, and what remains, sum_{n odd} (1 - tanh(n pi a / (2 b))) / n^5 with
    1 - tanh(x) = 2 / (exp(2x) + 1), decays like exp(-n pi a / b): the 27 odd terms kept
    (n = 1 to 53, one vectorised sum) reach far below the double-precision round-off.
    Square: J = 0.1406 a^4; thin strip (a >> b): J -> a b^3 / 3 (1 - 0.630 b / a).

    Examples
    --------
    >>> round(rectangle_torsion_constant(1.0, 1.0), 4)   # Timoshenko's k1 for a/b = 1
    0.1406
    """
    a, b = positive(a, "a"), positive(b, "b")
    a, b = max(a, b), min(a, b)
    x = _ODD_TERMS * math.pi * a / b  # 2 n pi a / (2 b)
    one_minus_tanh = 2.0 / (np.exp(np.minimum(x, 700.0)) + 1.0)
    tail = float(np.sum(one_minus_tanh / _ODD_TERMS**5))
    series = (31.0 / 32.0) * _ZETA5 - tail
    return a * b**3 / 3.0 * (1.0 - 192.0 * b / (math.pi**5 * a) * series)


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
        """I_z = pi D^4 / 64, m^4 (bending about z: in the x-y plane)."""
        return math.pi * self.diameter**4 / 64

    @property
    def second_moment_y(self) -> float:
        """I_y = pi D^4 / 64, m^4 (bending about y: out of the x-y plane)."""
        return math.pi * self.diameter**4 / 64

    @property
    def torsion_constant(self) -> float:
        """Saint-Venant J = pi D^4 / 32, m^4 (the polar moment: a circle does not warp)."""
        return math.pi * self.diameter**4 / 32

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
        Extent along y (in the bending plane), metres.  I_z = width * thickness^3 / 12,
        I_y = thickness * width^3 / 12.
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
        """I_z = width * thickness^3 / 12, m^4 (bending about z: in the x-y plane)."""
        return self.width * self.thickness**3 / 12

    @property
    def second_moment_y(self) -> float:
        """I_y = thickness * width^3 / 12, m^4 (bending about y: out of the x-y plane)."""
        return self.thickness * self.width**3 / 12

    @property
    def torsion_constant(self) -> float:
        """Saint-Venant J, m^4 (exact series; see :func:`rectangle_torsion_constant`)."""
        return rectangle_torsion_constant(self.width, self.thickness)

    @property
    def height(self) -> float:
        """Extent in the bending plane (along y), m."""
        return self.thickness
