"""Real coils: a single multi-turn coil, Helmholtz and Maxwell pairs (tier 3, validated API)."""

from __future__ import annotations

import math

import numpy as np
from scipy.constants import mu_0

from ._immutable import _show
from ._validate import as_array, as_axis, as_counts, as_vector, finite_scalar, positive
from .coaxial import CoaxialCoils
from .copper import winding_resistance
from .winding import gauss_filaments, turn_filaments, winding_section

__all__ = ["Coil", "CoilPair", "HelmholtzPair", "MaxwellPair", "HELMHOLTZ_FACTOR", "MAXWELL_FACTOR"]

#: Helmholtz centre field B = HELMHOLTZ_FACTOR * mu0 N I / R, (4/5)^(3/2).
HELMHOLTZ_FACTOR = (4.0 / 5.0) ** 1.5
#: Maxwell centre gradient dB/dz = MAXWELL_FACTOR * mu0 N I / R^2, 48 sqrt(3) / 7^(5/2).
MAXWELL_FACTOR = 48.0 * math.sqrt(3.0) / 7.0**2.5


#: Gauss-Legendre points (axial, radial) of a finite winding when ``filaments`` is not given.
DEFAULT_FILAMENTS = (3, 3)


def _coil_parameters(radius, turns, current) -> tuple[float, float, float]:
    """Validated (radius m > 0, turns > 0, current A finite).

    ``turns`` may be fractional: the filament and Gauss models use only the ampere-turns N I
    (:func:`_winding_model` demands a whole number for the turn-by-turn model).
    """
    return positive(radius, "radius"), positive(turns, "turns"), finite_scalar(current, "current")


def _winding_model(radius, turns, winding, filaments, turn_layout):
    """Validated winding description of a coil of ``radius`` (m) and ``turns``.

    Returns
    -------
    section : (float, float) or None
        Winding (width, height) in m, or None for a single filament.
    model : ("gauss", (int, int)) or ("turns", (int, int)) or None
        Gauss-Legendre points (axial, radial) of a uniform current density, or the turn-by-turn
        layout (turns per layer, layers); None for a single filament.
    """
    if winding is None:
        if turn_layout is not None:
            raise ValueError(
                f"turn_layout={turn_layout!r} needs a winding=(width, height) cross-section"
            )
        if filaments is not None:
            raise ValueError(
                f"filaments={filaments!r} model a finite winding cross-section; give "
                f"winding=(width, height) too"
            )
        return None, None
    width, height = winding_section(radius, *as_array(winding, "winding (width, height)", (2,)))
    if turn_layout is None:
        counts = DEFAULT_FILAMENTS if filaments is None else filaments
        return (width, height), ("gauss", as_counts(counts, "filaments", ("n_axial", "n_radial")))
    if filaments is not None:
        raise ValueError("give filaments (Gauss model) or turn_layout (turn by turn), not both")
    na, nr = as_counts(turn_layout, "turn_layout", ("turns_per_layer", "layers"))
    if not float(turns).is_integer():
        raise ValueError(
            f"turns must be a whole number for turn_layout (one filament per turn); got {turns}"
        )
    if na * nr != turns:
        raise ValueError(f"turn_layout {(na, nr)} places {na * nr} turns; the coil has {turns:g}")
    return (width, height), ("turns", (na, nr))


def _resistance(radius, turns, coils, section, resistance, wire_diameter):
    """Resistance (ohm) of the conductor of ``coils`` coils in series, or None if unknown.

    ``resistance`` (ohm) if given; else round copper wire of ``wire_diameter`` (m; the turns
    must fit the winding ``section`` if there is one); else the copper filling pi/4 of the
    ``section``; else None (a single filament says nothing of its wire).
    """
    if resistance is not None:
        if wire_diameter is not None:
            raise ValueError("give resistance or wire_diameter, not both")
        return positive(resistance, "resistance")
    if wire_diameter is None and section is None:
        return None
    return winding_resistance(radius, turns, coils, wire_diameter=wire_diameter, section=section)


def _winding_filaments(z0, radius, turns, current, section, model):
    """Filament rows ``(z, radius, current)`` of one coil at axial offset ``z0`` (m; the
    current's sign included in ``current``) and its winding box ``(z0, radius, width, height)``
    (None without a winding section)."""
    if section is None:
        return np.array([[z0, radius, turns * current]]), None
    width, height = section
    kind, (na, nr) = model
    if kind == "turns":
        fil = turn_filaments(z0, radius, current, width, height, na, nr)
    else:
        fil = gauss_filaments(z0, radius, turns * current, width, height, na, nr)
    return fil, (z0, radius, width, height)


def _with_current(coil, current):
    """A copy of ``coil`` (a Coil or a pair) at ``current`` A: same geometry, winding model and
    resistance; filaments rebuilt as the constructor builds them, so the copy equals a coil
    built with that current (without validating the unchanged parameters again)."""
    current = finite_scalar(current, "current")
    fil, _ = coil._build(current)
    params = None if coil._params is None else {**coil._params, "current": current}
    return coil._evolve(params, current=current, filaments=fil)


class _OneCurrent:
    """The "is immutable" hint of a coil or pair: a new current comes from ``with_current``."""

    def _how_to_change(self, name: str, value) -> str:
        if name == "current":
            v = _show(value)
            return f"use .with_current({v}) or .replace(current={v}) for a changed copy"
        return super()._how_to_change(name, value)


class Coil(_OneCurrent, CoaxialCoils):
    """A single multi-turn circular coil.

    Parameters
    ----------
    radius : float
        Mean radius R, m.
    turns : float
        Number of turns N (> 0; not a boolean).  The single-filament and Gauss models use only
        the ampere-turns N I, so a fractional N is accepted there (e.g. the result of
        :func:`coils.design.turns_for_field`, to be rounded when the coil is wound); the
        turn-by-turn model (``turn_layout``) needs a whole number.
    current : float
        Current I per turn, A (counter-clockwise about ``axis``; may be negative).
    axis : {"x", "y", "z"}, optionally signed ("-y"), or array-like, shape (3,)
        Coil axis (a non-zero vector, normalised).
    center : array-like, shape (3,)
        Centre of the coil, m.
    winding : (width, height), optional
        Winding cross-section in m (width along the axis, height radial, below 2 R).
        None: one filament of N I ampere-turns.
    filaments : (int, int), optional
        Gauss-Legendre points (axial, radial) modelling a finite winding of uniform current
        density; default (3, 3).  Needs ``winding``.
    turn_layout : (int, int), optional
        Model a finite winding turn by turn instead: turns per layer, layers (product = turns).
        Needs ``winding``; excludes ``filaments``.
    resistance : float, optional
        Resistance of the winding, ohm (> 0).  Excludes ``wire_diameter``.
    wire_diameter : float, optional
        Bare diameter of the round copper wire, m: the resistance is that of ``N 2 pi R`` of it
        at 20 degC (:mod:`coils.copper`); with ``winding`` the turns must fit in the section.

    Attributes
    ----------
    resistance : float or None
        Ohm: given, from ``wire_diameter``, else from ``winding`` filled to pi/4 by copper
        (square-packed round wire, insulation neglected); None for a single filament without
        a wire (then :meth:`coils.CoilSystem.power` cannot be computed).
    radius, turns, current, winding
        The parameters (validated; ``axis`` and ``center`` are read-only arrays).

    Raises
    ------
    ValueError
        On a bad parameter, naming it (see :mod:`coils._validate`).

    Notes
    -----
    Immutable: assigning an attribute raises ``AttributeError`` (the field would not follow);
    :meth:`with_current` and ``replace(**changes)`` (any constructor parameter, validated
    again) return changed copies.

    Examples
    --------
    >>> from coils import Coil
    >>> coil = Coil(0.05, 100, 1.0)
    >>> coil.current = 2.0
    Traceback (most recent call last):
    ...
    AttributeError: Coil is immutable (...): cannot set 'current'; use .with_current(2.0) or ...
    >>> coil.replace(turns=50).turns
    50.0
    """

    #: Coils in series in one current channel (one for a coil).
    n_coils: int = 1

    def __init__(
        self,
        radius,
        turns,
        current,
        axis="z",
        center=(0.0, 0.0, 0.0),
        winding=None,
        filaments=None,
        turn_layout=None,
        *,
        resistance=None,
        wire_diameter=None,
    ):
        self.radius, self.turns, self.current = _coil_parameters(radius, turns, current)
        section, model = _winding_model(self.radius, self.turns, winding, filaments, turn_layout)
        self._model = (section, model)
        fil, boxes = self._build(self.current)
        super().__init__(fil, axis, center, boxes)
        #: Winding cross-section (width, height) in m, or None.
        self.winding = section
        self.resistance = _resistance(
            self.radius, self.turns, self.n_coils, section, resistance, wire_diameter
        )

    def _build(self, current: float):
        """Filament rows (f, 3) and winding boxes of the coil at ``current`` (A)."""
        fil, box = _winding_filaments(0.0, self.radius, self.turns, current, *self._model)
        return fil, [box] if box else []

    def with_current(self, current) -> Coil:
        """The same coil carrying ``current`` (A per turn): a new object, this one unchanged.

        Its filaments are those a new coil built with ``current`` would have (same geometry,
        winding model and resistance).

        Examples
        --------
        >>> from coils import Coil
        >>> coil = Coil(0.05, 100, 1.0)
        >>> coil.with_current(-2.0).current, coil.current
        (-2.0, 1.0)
        """
        return _with_current(self, current)

    def __repr__(self):
        return (
            f"Coil(radius={self.radius}, turns={self.turns}, current={self.current}, "
            f"axis={self.axis.tolist()}, center={self.center.tolist()})"
        )


class CoilPair(_OneCurrent, CoaxialCoils):
    """Two identical coaxial coils at ``center +- spacing/2 * axis``.

    ``sign = +1``: currents in the same sense (uniform field, Helmholtz);
    ``sign = -1``: opposed currents (gradient field, Maxwell / anti-Helmholtz); the coil on the
    +axis side carries +current, so the axial gradient is positive for positive current.

    Parameters
    ----------
    radius, turns, current, axis, center, winding, filaments, turn_layout
        As for :class:`Coil` (m, -, A, -, m, (m, m), -, -), for each of the two coils; ``turns``
        and ``current`` are per coil, the default axis is "y".
    spacing : float, optional
        Distance between the coil planes, m (> the winding width); default the pair's own
        (R for Helmholtz, sqrt(3) R for Maxwell).
    resistance, wire_diameter : float, optional
        As for :class:`Coil`; the two coils are in series, so the wire is twice as long.

    Attributes
    ----------
    resistance : float or None
        Ohm, of both coils in series (see :class:`Coil`).
    radius, turns, current, spacing, winding
        The parameters (validated; ``axis`` and ``center`` are read-only arrays).

    Notes
    -----
    Immutable like :class:`Coil`: ``with_current(I)`` and ``replace(**changes)`` return changed
    copies (``pair.current = 3.35`` raises ``AttributeError`` saying so).
    """

    sign: float = 1.0
    default_spacing_factor: float = 1.0
    #: Coils in series in one current channel (both coils of the pair).
    n_coils: int = 2

    def __init__(
        self,
        radius,
        turns,
        current,
        axis="y",
        center=(0.0, 0.0, 0.0),
        spacing=None,
        winding=None,
        filaments=None,
        turn_layout=None,
        *,
        resistance=None,
        wire_diameter=None,
    ):
        self.radius, self.turns, self.current = _coil_parameters(radius, turns, current)
        if spacing is None:
            spacing = self.default_spacing_factor * self.radius
        self.spacing = positive(spacing, "spacing")
        axis_vec = as_axis(axis)
        center = as_vector(center, "center")
        section, model = _winding_model(self.radius, self.turns, winding, filaments, turn_layout)
        if section is not None and self.spacing <= section[0]:
            raise ValueError(
                f"spacing {self.spacing} m must exceed the winding width {section[0]} m"
            )
        self._model = (section, model)
        fil, boxes = self._build(self.current)
        super().__init__(fil, axis_vec, center, boxes)
        #: Winding cross-section (width, height) of each coil in m, or None.
        self.winding = section
        self.resistance = _resistance(
            self.radius, self.turns, self.n_coils, section, resistance, wire_diameter
        )

    def _build(self, current: float):
        """Filament rows (f, 3) and winding boxes of both coils at ``current`` (A per coil,
        the -axis coil carrying ``sign * current``)."""
        rows, boxes = [], []
        for side, cur in ((-1.0, self.sign * current), (1.0, current)):
            fil, box = _winding_filaments(
                side * self.spacing / 2, self.radius, self.turns, cur, *self._model
            )
            rows.append(fil)
            if box:
                boxes.append(box)
        return np.vstack(rows), boxes

    def with_current(self, current) -> CoilPair:
        """The same pair driven with ``current`` (A per turn, both coils in series with the
        pair's sign convention): a new object, this one unchanged.

        Examples
        --------
        >>> from coils import HelmholtzPair
        >>> pair = HelmholtzPair(0.1, 100, 1.0)
        >>> round(float(pair.with_current(3.0).B([0.0, 0.0, 0.0])[0, 1] / pair.center_field), 12)
        3.0
        """
        return _with_current(self, current)

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
