"""The robot description: geometry, material and magnetization of a hard-magnetic rod."""

from __future__ import annotations

from dataclasses import dataclass

from coils._validate import positive

from .magnetization import Magnetization
from .sections import Circle, Rectangle

__all__ = ["Rod"]


@dataclass(frozen=True)
class Rod:
    """A straight hard-magnetic rod, clamped at s = 0, tangent +x in the reference state.

    Parameters
    ----------
    length : float
        L in metres.
    youngs_modulus : float
        E in Pa.
    section : Circle or Rectangle
        Cross-section (area A in m^2, second moment I in m^4).
    magnetization : Magnetization
        |M|(s) in A/m and theta_m(s) in rad.

    Examples
    --------
    >>> from coilrod import Rod, Circle, Magnetization
    >>> rod = Rod(0.04, 1e6, Circle(2e-3), Magnetization(128e3, 0.0))
    >>> f"{rod.bending_stiffness:.4e}"   # E I = E pi D^4 / 64 in N m^2
    '7.8540e-07'
    """

    length: float
    youngs_modulus: float
    section: Circle | Rectangle
    magnetization: Magnetization

    def __post_init__(self):
        object.__setattr__(self, "length", positive(self.length, "length"))
        object.__setattr__(self, "youngs_modulus", positive(self.youngs_modulus, "youngs_modulus"))
        if not isinstance(self.section, Circle | Rectangle):
            raise ValueError(
                f"section must be coilrod.Circle or coilrod.Rectangle; got {self.section!r}"
            )
        if not isinstance(self.magnetization, Magnetization):
            raise ValueError(
                f"magnetization must be a coilrod.Magnetization; got {self.magnetization!r}"
            )
        self.magnetization.check_length(self.length)

    @property
    def area(self) -> float:
        """Cross-section area A, m^2."""
        return self.section.area

    @property
    def bending_stiffness(self) -> float:
        """E I in N m^2."""
        return self.youngs_modulus * self.section.second_moment

    def magnetoelastic_number(self, B: float) -> float:
        """lambda = |M|max |B| A L^2 / (E I) for a field magnitude ``B`` (T); dimensionless."""
        M = self.magnetization.max_magnitude(self.length)
        return M * B * self.area * self.length**2 / self.bending_stiffness

    def field_for_lambda(self, lam: float) -> float:
        """|B| in T that gives the magneto-elastic number ``lam`` (inverse of the above)."""
        M = self.magnetization.max_magnitude(self.length)
        if M == 0:
            raise ValueError("the rod has zero magnetization: no field reaches lambda > 0")
        return lam * self.bending_stiffness / (M * self.area * self.length**2)
