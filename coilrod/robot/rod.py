"""The robot description: geometry, material and magnetization of a hard-magnetic rod."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

from coils._validate import finite_scalar, positive

from ..errors import UnitsWarning
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
        Cross-section (area A in m^2, second moments I_z, I_y and torsion constant J in m^4).
    magnetization : Magnetization
        |M|(s) in A/m, theta_m(s) and the elevation psi_m(s) in rad.
    poisson_ratio : float, optional
        nu, dimensionless, in (-1, 0.5]; sets the shear modulus G = E / (2 (1 + nu)) of the
        torsional stiffness G J.  Default 0.5: an incompressible elastomer (G = E / 3).

    Warns
    -----
    coilrod.UnitsWarning
        Where no robot of this kind can be -- a length over 1 m, a section larger than L/3, a
        modulus outside 1 kPa - 10 GPa, a magnetization over 2 MA/m -- naming the value and
        the unit expected (millimetres typed for metres are the usual cause).  Scale-free
        studies with unit values may ignore it.

    Examples
    --------
    >>> from coilrod import Rod, Circle, Magnetization
    >>> rod = Rod(0.04, 1e6, Circle(2e-3), Magnetization(128e3, 0.0))
    >>> f"{rod.bending_stiffness:.4e}"   # E I = E pi D^4 / 64 in N m^2
    '7.8540e-07'
    >>> [f"{k:.4e}" for k in rod.stiffnesses]   # (G J, E I_y, E I_z), G = E / 3
    ['5.2360e-07', '7.8540e-07', '7.8540e-07']
    """

    length: float
    youngs_modulus: float
    section: Circle | Rectangle
    magnetization: Magnetization
    poisson_ratio: float = 0.5

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
        nu = finite_scalar(self.poisson_ratio, "poisson_ratio")
        if not -1.0 < nu <= 0.5:
            raise ValueError(f"poisson_ratio must lie in (-1, 0.5]; got {nu!r}")
        object.__setattr__(self, "poisson_ratio", nu)
        for message in self._unit_doubts():
            warnings.warn(message, UnitsWarning, stacklevel=3)

    def _unit_doubts(self) -> list[str]:
        """What looks like a unit slip (see the class docstring's Warns)."""
        L, E = self.length, self.youngs_modulus
        doubts = []
        if L > 1.0:
            doubts.append(
                f"length = {L:g} m: a magnetic continuum robot is shorter than 1 m -- lengths "
                "are in metres (40 mm = 0.04)"
            )
        size = max(self.section.height, getattr(self.section, "width", self.section.height))
        if size > L / 3:
            what = "diameter" if isinstance(self.section, Circle) else "section side"
            doubts.append(
                f"{what} = {size:g} m is over L/3 = {L / 3:g} m: not a slender rod -- section "
                "sizes are in metres (2 mm = 2e-3)"
            )
        if not 1e3 <= E <= 1e10:
            doubts.append(
                f"youngs_modulus = {E:g} Pa lies outside 1 kPa - 10 GPa -- the modulus is in Pa "
                "(1 MPa = 1e6)"
            )
        try:
            M = self.magnetization.max_magnitude(L)
        except ValueError:  # a profile that is not finite: the solvers name it where used
            M = 0.0
        if M > 2e6:
            doubts.append(
                f"magnetization up to {M:g} A/m is over 2 MA/m (beyond NdFeB's remanence) -- "
                "|M| is in A/m (128 kA/m = 128e3)"
            )
        return doubts

    def __repr__(self) -> str:
        return (
            f"Rod(length={self.length:g} m, youngs_modulus={self.youngs_modulus:g} Pa, "
            f"section={self.section!r}, magnetization={self.magnetization!r}, "
            f"poisson_ratio={self.poisson_ratio:g})"
        )

    @property
    def area(self) -> float:
        """Cross-section area A, m^2."""
        return self.section.area

    @property
    def bending_stiffness(self) -> float:
        """E I_z in N m^2 (bending in the x-y plane)."""
        return self.youngs_modulus * self.section.second_moment

    @property
    def shear_modulus(self) -> float:
        """G = E / (2 (1 + nu)) in Pa."""
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def torsional_stiffness(self) -> float:
        """G J in N m^2 (Saint-Venant torsion; J of :attr:`section`)."""
        return self.shear_modulus * self.section.torsion_constant

    @property
    def stiffnesses(self) -> tuple[float, float, float]:
        """(G J, E I_y, E I_z) in N m^2: the diagonal of the body-frame stiffness in the
        frame (tangent, normal, binormal) -- twist, bending out of the x-y plane (about the
        normal y), bending in it (about the binormal z)."""
        E = self.youngs_modulus
        return (
            self.torsional_stiffness,
            E * self.section.second_moment_y,
            E * self.section.second_moment,
        )

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
