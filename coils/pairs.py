"""Real coils: a single multi-turn coil, Helmholtz and Maxwell pairs (tier 3, validated API)."""

from __future__ import annotations

import math

import numpy as np
from scipy.constants import mu_0

from ._validate import as_axis, as_vector, finite_scalar, positive
from .coaxial import CoaxialCoils
from .winding import gauss_filaments, turn_filaments

__all__ = ["Coil", "CoilPair", "HelmholtzPair", "MaxwellPair", "HELMHOLTZ_FACTOR", "MAXWELL_FACTOR"]

#: Helmholtz centre field B = HELMHOLTZ_FACTOR * mu0 N I / R, (4/5)^(3/2).
HELMHOLTZ_FACTOR = (4.0 / 5.0) ** 1.5
#: Maxwell centre gradient dB/dz = MAXWELL_FACTOR * mu0 N I / R^2, 48 sqrt(3) / 7^(5/2).
MAXWELL_FACTOR = 48.0 * math.sqrt(3.0) / 7.0**2.5


def _winding_filaments(z0, radius, turns, current, winding, filaments, turn_layout):
    """Filament rows for one coil at axial offset z0 (current sign included in ``current``)."""
    if winding is None:
        if turn_layout is not None:
            raise ValueError("turn_layout needs a winding=(width, height) cross-section")
        return np.array([[z0, radius, turns * current]]), None
    if len(winding) != 2:
        raise ValueError(f"winding must be (width, height) in metres; got {winding!r}")
    width = positive(winding[0], "winding width")
    height = positive(winding[1], "winding height")
    if height >= 2 * radius:
        raise ValueError(f"winding height {height} m must be below twice the radius {radius} m")
    if turn_layout is not None:
        na, nr = turn_layout
        if na * nr != turns:
            raise ValueError(
                f"turn_layout {turn_layout} places {na * nr} turns; the coil has {turns}"
            )
        fil = turn_filaments(z0, radius, current, width, height, na, nr)
    else:
        na, nr = filaments
        fil = gauss_filaments(z0, radius, turns * current, width, height, na, nr)
    return fil, (z0, radius, width, height)


def _coil_parameters(radius, turns, current) -> tuple[float, float, float]:
    """Validated (radius m > 0, turns > 0, current A finite)."""
    return positive(radius, "radius"), positive(turns, "turns"), finite_scalar(current, "current")


class Coil(CoaxialCoils):
    """A single multi-turn circular coil.

    Parameters
    ----------
    radius : float
        Mean radius R, m.
    turns : float
        Number of turns N.
    current : float
        Current I per turn, A (counter-clockwise about ``axis``; may be negative).
    axis : {"x", "y", "z"} or array-like, shape (3,)
        Coil axis.
    center : array-like, shape (3,)
        Centre of the coil, m.
    winding : (width, height), optional
        Winding cross-section in m (width along the axis, height radial).  None: one filament.
    filaments : (int, int)
        Gauss-Legendre points (axial, radial) modelling a finite winding.
    turn_layout : (int, int), optional
        Model a finite winding turn by turn instead: turns per layer, layers (product = turns).
    """

    def __init__(
        self,
        radius,
        turns,
        current,
        axis="z",
        center=(0.0, 0.0, 0.0),
        winding=None,
        filaments=(3, 3),
        turn_layout=None,
    ):
        self.radius, self.turns, self.current = _coil_parameters(radius, turns, current)
        fil, box = _winding_filaments(
            0.0, self.radius, self.turns, self.current, winding, filaments, turn_layout
        )
        super().__init__(fil, axis, center, [box] if box else [])
        self.winding = winding

    def __repr__(self):
        return (
            f"Coil(radius={self.radius}, turns={self.turns}, current={self.current}, "
            f"axis={self.axis.tolist()}, center={self.center.tolist()})"
        )


class CoilPair(CoaxialCoils):
    """Two identical coaxial coils at ``center +- spacing/2 * axis``.

    ``sign = +1``: currents in the same sense (uniform field, Helmholtz);
    ``sign = -1``: opposed currents (gradient field, Maxwell / anti-Helmholtz); the coil on the
    +axis side carries +current, so the axial gradient is positive for positive current.
    """

    sign: float = 1.0
    default_spacing_factor: float = 1.0

    def __init__(
        self,
        radius,
        turns,
        current,
        axis="y",
        center=(0.0, 0.0, 0.0),
        spacing=None,
        winding=None,
        filaments=(3, 3),
        turn_layout=None,
    ):
        self.radius, self.turns, self.current = _coil_parameters(radius, turns, current)
        if spacing is None:
            spacing = self.default_spacing_factor * self.radius
        self.spacing = positive(spacing, "spacing")
        axis_vec = as_axis(axis)
        center = as_vector(center, "center")
        rows, boxes = [], []
        for side, cur in ((-1.0, self.sign * self.current), (1.0, self.current)):
            fil, box = _winding_filaments(
                side * self.spacing / 2,
                self.radius,
                self.turns,
                cur,
                winding,
                filaments,
                turn_layout,
            )
            rows.append(fil)
            if box:
                boxes.append(box)
        if winding is not None and self.spacing <= positive(winding[0], "winding width"):
            raise ValueError(
                f"spacing {self.spacing} m must exceed the winding width {winding[0]} m"
            )
        super().__init__(np.vstack(rows), axis_vec, center, boxes)
        self.winding = winding

    @property
    def ampere_turns(self) -> float:
        """N I per coil, A."""
        return self.turns * self.current

    def __repr__(self):
        return (
            f"{type(self).__name__}(radius={self.radius}, turns={self.turns}, "
            f"current={self.current}, axis={self.axis.tolist()}, "
            f"center={self.center.tolist()}, spacing={self.spacing})"
        )


class HelmholtzPair(CoilPair):
    """Helmholtz pair: two coils, same current, spacing R by default (uniform field).

    Parameters are those of :class:`CoilPair`: ``radius`` (m), ``turns``, ``current`` (A),
    ``axis``, ``center`` (m), ``spacing`` (m, default R), ``winding`` ((width, height) m),
    ``filaments`` (Gauss points of a finite winding), ``turn_layout``.

    Examples
    --------
    >>> from coils import HelmholtzPair
    >>> pair = HelmholtzPair(radius=0.1, turns=100, current=2.0, axis="y")
    >>> float(pair.B([[0.0, 0.0, 0.0]])[0, 1])   # T, = (4/5)^1.5 mu0 N I / R
    0.00179835...
    >>> pair.ideal().uniform
    True
    """

    sign = 1.0
    default_spacing_factor = 1.0

    @property
    def center_field(self) -> float:
        """Closed-form centre field (4/5)^{3/2} mu0 N I / R of the filament pair at spacing R, T.

        Exact only for the default spacing and no winding; a finite winding differs slightly.
        """
        return HELMHOLTZ_FACTOR * mu_0 * self.turns * self.current / self.radius


class MaxwellPair(CoilPair):
    """Maxwell (anti-Helmholtz) gradient pair: opposed currents, spacing sqrt(3) R by default.

    The centre field is zero and the gradient is ``g diag(-1/2, 1, -1/2)`` in the pair frame,
    with ``g = 48 sqrt(3)/7^(5/2) mu0 N I / R^2`` along the axis.

    Examples
    --------
    >>> from coils import MaxwellPair
    >>> pair = MaxwellPair(radius=0.1, turns=100, current=2.0, axis="y")
    >>> float(pair.gradient([[0.0, 0.0, 0.0]])[0, 1, 1])   # T/m
    0.0161174...
    """

    sign = -1.0
    default_spacing_factor = math.sqrt(3.0)

    @property
    def center_gradient(self) -> float:
        """Closed-form axial centre gradient 48 sqrt(3)/7^{5/2} mu0 N I / R^2, T/m
        (default spacing, filament model)."""
        return MAXWELL_FACTOR * mu_0 * self.turns * self.current / self.radius**2
