"""Superposition of coils and ideal fields, and the current channels that drive it.

A :class:`CoilSystem` is a sum of parts.  Its **current channels** are the parts with one
driven current each:

* a :class:`~coils.Coil`: its current per turn;
* a :class:`~coils.CoilPair` (Helmholtz, Maxwell): both coils in series, one current with the
  pair's sign convention (the +axis coil carries ``I``, the other ``sign * I``);
* the channels of a nested :class:`CoilSystem`, in its order.

Every other part -- :class:`~coils.UniformField`, :class:`~coils.LinearField`, a scaled coil
``2 * pair``, a :class:`~coils.GriddedField`, a bare :class:`~coils.CoaxialCoils` -- is
**fixed**: its field is added unchanged whatever the currents.  Biot-Savart is linear in the
currents, so at any point

    B(x; I) = B_fixed(x) + sum_j I_j b_j(x),     G(x; I) = G_fixed(x) + sum_j I_j g_j(x),

with ``b_j`` (T/A) and ``g_j`` (T/(A m)) the field and gradient of channel ``j`` per ampere
(:meth:`CoilSystem.unit_fields`).  Each channel has a current limit (``max_current``) and a
copper resistance (the coil's ``resistance``), hence the power ``sum_j R_j I_j^2``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ._immutable import _show as _short
from ._immutable import sealed
from ._validate import _show, as_array, as_bool, as_limits, as_points, as_vector
from .field import Field, FieldSum
from .pairs import Coil, CoilPair

__all__ = ["CoilSystem"]

_LETTERS = "xyz"


def _is_channel(part: Field) -> bool:
    return isinstance(part, Coil | CoilPair)


def _axis_label(axis: np.ndarray) -> str:
    """The label of a unit axis: '+x' or '-y' for a coordinate axis, else the rounded vector."""
    for i in range(3):
        if abs(axis[i]) == 1.0:
            return ("+" if axis[i] > 0 else "-") + _LETTERS[i]
    return "(" + ", ".join(f"{v:.3g}" for v in axis) + ")"


def _default_name(channel) -> str:
    return f"{type(channel).__name__} axis {_axis_label(channel.axis)}"


class CoilSystem(FieldSum):
    """A superposition of field sources whose coils are driven by current channels.

    Parameters
    ----------
    parts : sequence of Field
        Coils, pairs, ideal fields or other systems.  Every :class:`~coils.Coil` and
        :class:`~coils.CoilPair` is a current channel (m of them, in order; a nested system
        contributes its channels); every other part is fixed (see :mod:`coils.system`).
    center : array-like, shape (3,), optional
        Working point for :meth:`ideal` and :meth:`currents_for` (m); default: the mean of the
        parts' centres.
    max_current : float or array-like, shape (m,), optional
        Limit of ``|I_j|`` per channel, A (> 0; ``inf``: no limit; a scalar applies to every
        channel).  Default: no limit, except that channels of a nested system keep its limits
        (limits only tighten: the smaller one applies).
    names : sequence of str, shape (m,), optional
        Channel names used in messages; default the nested systems' names or
        ``"HelmholtzPair axis +y"`` and the like.

    Raises
    ------
    ValueError
        On a bad parameter (named), or if a channel's present current exceeds its limit.

    Notes
    -----
    Immutable, like every source (:mod:`coils._immutable`): :meth:`with_currents`,
    :meth:`with_limits` and ``replace(parts=..., center=..., max_current=..., names=...)``
    return changed copies; ``center`` is a read-only array and ``parts`` a tuple.

    Examples
    --------
    >>> from coils import CoilSystem, HelmholtzPair, MaxwellPair, UniformField
    >>> system = CoilSystem([HelmholtzPair(0.1, 100, 1.0), MaxwellPair(0.1, 100, 1.0)])
    >>> len(system.parts)
    2
    >>> system.currents, system.names
    (array([1., 1.]), ('HelmholtzPair axis +y', 'MaxwellPair axis +y'))
    >>> earth = UniformField((0.0, 0.0, -45e-6))      # a fixed part: no current
    >>> CoilSystem([HelmholtzPair(0.1, 100, 1.0, axis="x"), earth], max_current=5.0).max_current
    array([5.])
    """

    _caches = ("_units",)

    def __init__(self, parts, center=None, *, max_current=None, names=None):
        super().__init__(parts)
        if center is None:
            centres = [p.center for p in self.parts if hasattr(p, "center")]
            center = np.mean(centres, axis=0) if centres else np.zeros(3)
        self.center = sealed(as_vector(center, "center"))
        channels, fixed, limits, default_names = [], [], [], []
        for part in self.parts:
            if _is_channel(part):
                channels.append(part)
                limits.append(np.inf)
                default_names.append(_default_name(part))
            elif isinstance(part, CoilSystem):
                channels.extend(part._channels)
                fixed.extend(part._fixed)
                limits.extend(part._max_current)
                default_names.extend(part._names)
            else:
                fixed.append(part)
        m = len(channels)
        self._channels = tuple(channels)
        self._fixed = tuple(fixed)
        limit = np.array(limits, dtype=float)
        if max_current is not None:
            limit = np.minimum(limit, as_limits(max_current, "max_current", m))
        limit.setflags(write=False)
        self._max_current = limit
        self._names = tuple(default_names) if names is None else self._as_names(names, m)
        self._units = None  # the channels at 1 A, built on first use (a cache)
        for j, ch in enumerate(self._channels):
            if abs(ch.current) > limit[j]:
                raise ValueError(
                    f"channel {j} ({self._names[j]}) carries {ch.current:g} A, above its "
                    f"max_current {limit[j]:g} A"
                )

    def _how_to_change(self, name: str, value) -> str:
        hint = {"currents": "with_currents", "max_current": "with_limits"}.get(name)
        if hint is not None:
            return f"use .{hint}({_short(value)}) for a changed copy"
        return super()._how_to_change(name, value)

    @staticmethod
    def _as_names(names, m: int) -> tuple[str, ...]:
        if (
            isinstance(names, str)
            or not isinstance(names, Sequence)
            or len(names) != m
            or not all(isinstance(n, str) for n in names)
        ):
            raise ValueError(f"names must be a sequence of {m} strings; got {_show(names)}")
        return tuple(names)

    # -- the channels ---------------------------------------------------------------------------
    @property
    def channels(self) -> tuple:
        """The current channels (Coil and CoilPair objects), in order; length m."""
        return self._channels

    @property
    def fixed_parts(self) -> tuple:
        """The parts without a current (ideal fields, scaled coils, ...): their field is added
        unchanged whatever the currents."""
        return self._fixed

    @property
    def names(self) -> tuple[str, ...]:
        """Channel names, length m."""
        return self._names

    @property
    def currents(self) -> np.ndarray:
        """Present channel currents, shape (m,), A (a copy; per turn, both coils of a pair)."""
        return np.array([ch.current for ch in self._channels], dtype=float)

    @property
    def max_current(self) -> np.ndarray:
        """Current limit of each channel, shape (m,), A (``inf``: none); a copy."""
        return self._max_current.copy()

    @property
    def resistance(self) -> np.ndarray:
        """Copper resistance of each channel (both coils of a pair in series), shape (m,), ohm.

        Raises
        ------
        ValueError
            Naming the channels whose coils have no resistance (give the coils
            ``wire_diameter``, ``resistance`` or a ``winding``).
        """
        missing = [j for j, ch in enumerate(self._channels) if ch.resistance is None]
        if missing:
            which = ", ".join(f"{j} ({self._names[j]})" for j in missing)
            raise ValueError(
                f"channels {which} have no resistance: build their coils with wire_diameter=, "
                f"resistance= or winding="
            )
        return np.array([ch.resistance for ch in self._channels], dtype=float)

    def _as_currents(self, currents, name: str = "currents") -> np.ndarray:
        return as_vector(currents, name, len(self._channels))

    def _check_limits(self, currents: np.ndarray, name: str = "currents") -> None:
        over = np.nonzero(np.abs(currents) > self._max_current)[0]
        if over.size:
            j = int(over[0])
            raise ValueError(
                f"{name}[{j}] = {currents[j]:g} A exceeds max_current[{j}] = "
                f"{self._max_current[j]:g} A (channel {j}: {self._names[j]})"
            )

    def with_currents(self, currents) -> CoilSystem:
        """The same system with the channels driven by ``currents``.

        Parameters
        ----------
        currents : array-like, shape (m,)
            Channel currents, A (finite; ``|I_j| <= max_current[j]``).

        Returns
        -------
        CoilSystem
            A new system (this one is unchanged) with the same parts, centre, limits and
            names; its coils equal coils built with these currents.

        Raises
        ------
        ValueError
            If ``currents`` has the wrong shape or a non-finite entry, or if a current exceeds
            its channel's limit (naming the channel).  Limits are hardware ratings and are
            always enforced; to explore beyond them use ``with_limits``.

        Examples
        --------
        >>> from coils import CoilSystem, HelmholtzPair
        >>> system = CoilSystem([HelmholtzPair(0.1, 100, 1.0)], max_current=10.0)
        >>> system.with_currents([4.0]).currents
        array([4.])
        >>> system.with_currents([12.0])
        Traceback (most recent call last):
        ...
        ValueError: currents[0] = 12 A exceeds max_current[0] = 10 A (channel 0: ...)
        """
        current = self._as_currents(currents)
        self._check_limits(current)
        return self._rebuilt(current)

    def with_limits(self, max_current) -> CoilSystem:
        """The same system with other current limits (channels of nested systems included).

        Parameters
        ----------
        max_current : float or array-like, shape (m,)
            New limits, A (> 0; ``inf``: none); the present currents must respect them.

        Returns
        -------
        CoilSystem
            A new system; this one is unchanged.

        Examples
        --------
        >>> from coils import CoilSystem, HelmholtzPair
        >>> system = CoilSystem([HelmholtzPair(0.1, 100, 1.0)], max_current=10.0)
        >>> system.with_limits(50.0).with_currents([40.0]).currents
        array([40.])
        """
        return self._relimited(as_limits(max_current, "max_current", len(self._channels)))

    def _relimited(self, limit: np.ndarray) -> CoilSystem:
        parts, k = [], 0
        for part in self.parts:
            if isinstance(part, CoilSystem):
                m = len(part._channels)
                parts.append(part._relimited(limit[k : k + m]))
                k += m
            else:
                k += _is_channel(part)
                parts.append(part)
        return type(self)(parts, center=self.center, max_current=limit, names=self._names)

    def _rebuilt(self, current: np.ndarray) -> CoilSystem:
        parts, k = [], 0
        for part in self.parts:
            if _is_channel(part):
                parts.append(part.with_current(current[k]))
                k += 1
            elif isinstance(part, CoilSystem):
                m = len(part._channels)
                parts.append(part._rebuilt(current[k : k + m]))
                k += m
            else:
                parts.append(part)
        return type(self)(
            parts, center=self.center, max_current=self._max_current, names=self._names
        )

    def _unit_channels(self):
        if self._units is None:
            self._set_cache("_units", tuple(ch.with_current(1.0) for ch in self._channels))
        return self._units

    # -- linearity in the currents --------------------------------------------------------------
    def unit_fields(self, points, *, hessian: bool = False):
        """Field and gradient per ampere of every channel at ``points``.

        Parameters
        ----------
        points : array-like, shape (n, 3) or (3,)
            Positions, m.
        hessian : bool
            Also return the second derivatives per ampere.

        Returns
        -------
        B : ndarray, shape (n, 3, m)
            ``B[k, i, j]``: B_i at point k per ampere in channel j, T/A.
        G : ndarray, shape (n, 3, 3, m)
            ``G[k, i, l, j] = dB_i/dx_l`` per ampere in channel j, T/(A m).
        H : ndarray, shape (n, 3, 3, 3, m)
            Only with ``hessian``: ``d2B_i/(dx_l dx_p)`` per ampere, T/(A m^2).

        Notes
        -----
        One compiled pass over the points per channel, the whole filament set covered once
        (what one evaluation of the system costs).  The fixed parts are not included: the
        system's field is ``B_fixed + B @ currents`` (and likewise for the gradient).

        Examples
        --------
        >>> import numpy as np
        >>> from coils import CoilSystem, HelmholtzPair
        >>> system = CoilSystem([HelmholtzPair(0.1, 100, 2.0, axis=a) for a in "xyz"])
        >>> Bu, Gu = system.unit_fields([[0.0, 0.0, 0.0]])
        >>> Bu.shape, Gu.shape
        ((1, 3, 3), (1, 3, 3, 3))
        >>> np.allclose(Bu[0] @ system.currents, system.B([0.0, 0.0, 0.0])[0], rtol=1e-14)
        True
        """
        pts = as_points(points)
        hessian = as_bool(hessian, "hessian")
        n, m = pts.shape[0], len(self._channels)
        B = np.zeros((m, n, 3))
        G = np.zeros((m, n, 3, 3))
        H = np.zeros((m, n, 3, 3, 3)) if hessian else None
        for j, unit in enumerate(self._unit_channels()):
            unit._add_to(pts, B[j], G[j], H[j] if hessian else None, 1.0)
        out = (
            np.ascontiguousarray(np.moveaxis(B, 0, -1)),
            np.ascontiguousarray(np.moveaxis(G, 0, -1)),
        )
        if hessian:
            out += (np.ascontiguousarray(np.moveaxis(H, 0, -1)),)
        return out

    def fixed_field(self, points) -> tuple[np.ndarray, np.ndarray]:
        """B (n, 3) in T and gradient (n, 3, 3) in T/m of the fixed parts at ``points`` (m)."""
        pts = as_points(points)
        n = pts.shape[0]
        B, G = np.zeros((n, 3)), np.zeros((n, 3, 3))
        for part in self._fixed:
            part._add_to(pts, B, None if part.uniform else G, None, 1.0)
        return B, G

    def power(self, currents=None):
        """Copper power ``sum_j R_j I_j^2`` of a current vector, W.

        Parameters
        ----------
        currents : array-like, shape (m,) or (p, m), optional
            Channel currents, A; default the present ones.

        Returns
        -------
        float or ndarray, shape (p,)
            W, with ``R_j`` the channel resistances (:attr:`resistance`, at 20 degC).

        Raises
        ------
        ValueError
            If a channel has no resistance, or on bad currents (named).

        Examples
        --------
        >>> from coils import CoilSystem, HelmholtzPair
        >>> pair = HelmholtzPair(0.1, 200, 1.0, wire_diameter=1.5e-3)
        >>> system = CoilSystem([pair])
        >>> round(system.power([3.0]), 3)      # W = 9 A^2 x 2.452 ohm
        22.068
        """
        R = self.resistance
        if currents is None:
            return float(np.sum(R * self.currents**2))
        m = len(self._channels)
        arr = as_array(currents, "currents")
        if arr.ndim == 1 and arr.shape == (m,):
            return float(np.sum(R * arr**2))
        if arr.ndim == 2 and arr.shape[1] == m:
            return np.sum(R * arr**2, axis=1)
        raise ValueError(f"currents must have shape ({m},) or (p, {m}); got {arr.shape}")

    # -- currents for a target ------------------------------------------------------------------
    def currents_for(self, B=None, gradient=None, *, at=None, weights=None) -> np.ndarray:
        """The minimum-power channel currents that make a field and/or gradient at a point.

        Parameters
        ----------
        B : array-like, shape (3,), optional
            Target flux density at ``at``, T.
        gradient : array-like, shape (3, 3), optional
            Target gradient ``G[i, j] = dB_i/dx_j`` at ``at``, T/m (symmetric and traceless,
            as any current-free field's).  At least one of ``B`` and ``gradient`` is needed; a
            target left out is free.
        at : array-like, shape (3,), optional
            The point, m; default :attr:`center`.
        weights : array-like, shape (m,), optional
            Positive weights ``w_j`` of the minimised ``sum_j w_j I_j^2``; default the channel
            resistances (the copper power) if every channel has one, else equal weights
            (the smallest ``sum I_j^2``).

        Returns
        -------
        ndarray, shape (m,)
            Currents, A, within :attr:`max_current`: ``with_currents(I)`` makes the target
            (the fixed parts' field included) to about 1e-9 relative.

        Raises
        ------
        ValueError
            If the channels cannot make the target at that point (the message gives what they
            miss by), if no currents within the limits make it (the message gives the largest
            fraction of it that they allow), or on a bad argument (named).

        Notes
        -----
        The target is linear in the currents, ``A I = b`` with ``A`` from :meth:`unit_fields`
        and ``b`` the target minus the fixed parts' field.  Among its solutions the one of
        least ``sum w I^2`` is the weighted minimum-norm solution; if it exceeds a limit, the
        least-power solution within the limits is found exactly (a least-distance program,
        :mod:`coils.currents`).  With more channels than target components the currents are
        not unique and this picks the cheapest.

        Examples
        --------
        >>> import numpy as np
        >>> from coils import CoilSystem, HelmholtzPair
        >>> system = CoilSystem([HelmholtzPair(r, 200, 0.0, axis=a, wire_diameter=2e-3)
        ...                      for r, a in [(0.10, "x"), (0.14, "y"), (0.18, "z")]])
        >>> I = system.currents_for(B=(0.0, 5e-3, 0.0))
        >>> np.round(I, 4) + 0.0                # A: only the y pair is driven
        array([0.    , 3.8925, 0.    ])
        >>> np.round(1e3 * system.with_currents(I).B(system.center)[0], 9) + 0.0   # mT
        array([0., 5., 0.])
        """
        from .currents import currents_for_target

        m = len(self._channels)
        if m == 0 and (B is not None or gradient is not None):
            raise ValueError("the system has no current channels (only fixed parts)")
        point = self.center if at is None else as_vector(at, "at")
        R = [ch.resistance for ch in self._channels]
        default = np.ones(m) if any(r is None for r in R) else np.array(R, dtype=float)
        words = {
            "who": "the coil system",
            "channels": "channels",
            "channel": "channel",
            "limits": "",
            "fixed": "the fixed parts' field",
            "currents": "minimum-power",
        }
        return currents_for_target(self, point, B, gradient, weights, default, self._names, words)

    # -- as before ------------------------------------------------------------------------------
    def ideal(self, zero_tol: float = 1e-12):
        """The LinearField of B and gradient at ``center`` (see :func:`coils.ideal.linearize`)."""
        from .ideal import linearize

        return linearize(self, self.center, zero_tol)

    def to_magpylib(self):
        """All coil filaments as one ``magpylib.Collection`` (ideal parts are skipped)."""
        import magpylib as magpy

        children = [p.to_magpylib() for p in self.parts if hasattr(p, "to_magpylib")]
        return magpy.Collection(*children)
