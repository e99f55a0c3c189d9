"""The field protocol shared by every source, and the algebra of fields (sums and scaling).

Every field maps points ``(n, 3)`` in metres to

* ``B(points)``: flux density, shape ``(n, 3)``, tesla;
* ``gradient(points)``: ``G[k, i, j] = dB_i/dx_j``, shape ``(n, 3, 3)``, tesla per metre;
* ``hessian(points)``: ``H[k, i, j, l] = d2B_i/(dx_j dx_l)``, shape ``(n, 3, 3, 3)``, T/m^2;
* ``B_gradient_hessian(points)``: the three at once (one compiled pass per coaxial coil group);
* ``evaluator()``: a function ``(points, hessian) -> (B, G, H)`` for a solver's repeated
  evaluations at points it made itself (no validation; coaxial coils call their compiled pass
  directly).

and says what it does not need to compute, so solvers can skip work:

* ``uniform``: the gradient is identically zero (no force path, no gradient evaluation);
* ``linear``: the gradient is constant (the hessian is identically zero).

Every source of :mod:`coils` is immutable (:mod:`coils._immutable`): its attributes cannot be
assigned and its arrays are read-only, so they always describe the field it computes; change
one with ``with_current`` / ``with_currents`` or ``replace(**changes)``, which return copies.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable

import numpy as np

from ._immutable import Immutable
from ._validate import as_points, finite_scalar

__all__ = ["Field", "FieldSum", "ScaledField"]

#: Points evaluated per chunk by sources whose kernels allocate per-point temporaries.
CHUNK = 65536


class Field(Immutable, ABC):
    """Base class of all magnetic field sources (a protocol with shared conveniences).

    Subclasses implement ``_B(points)`` and ``_gradient(points)`` on validated ``(n, 3)`` arrays;
    they may override ``_B_and_gradient`` and ``_B_gradient_hessian`` when the quantities share
    work, ``_hessian`` when a closed form exists, and ``_add_to`` to accumulate into a sum's
    arrays without temporaries.  Public methods validate once and dispatch.

    The sources of :mod:`coils` are immutable (``_immutable = True``, see
    :mod:`coils._immutable`): assigning an attribute raises ``AttributeError``, their arrays
    are read-only, and :meth:`~coils._immutable.Immutable.replace` returns a changed copy.  A
    user's subclass is sealed only if it sets ``_immutable = True``.
    """

    #: True if the gradient is identically zero everywhere.
    uniform: bool = False
    #: True if the gradient is constant in space (hessian identically zero).
    linear: bool = False

    # -- public API ---------------------------------------------------------------------------
    def B(self, points) -> np.ndarray:
        """Flux density at ``points``.

        Parameters
        ----------
        points : array-like, shape (n, 3) or (3,)
            Positions in metres.

        Returns
        -------
        ndarray, shape (n, 3)
            B in tesla.
        """
        return self._B(as_points(points))

    def gradient(self, points) -> np.ndarray:
        """Gradient ``G[k, i, j] = dB_i/dx_j`` at ``points`` (m), shape (n, 3, 3), T/m."""
        pts = as_points(points)
        if self.uniform:
            return np.zeros((pts.shape[0], 3, 3))
        return self._gradient(pts)

    def B_and_gradient(self, points) -> tuple[np.ndarray, np.ndarray]:
        """``(B, G)`` at ``points`` in one pass: shapes (n, 3) in T and (n, 3, 3) in T/m."""
        pts = as_points(points)
        if self.uniform:
            return self._B(pts), np.zeros((pts.shape[0], 3, 3))
        return self._B_and_gradient(pts)

    def hessian(self, points) -> np.ndarray:
        """Second derivatives ``H[k, i, j, l] = d2B_i/(dx_j dx_l)``, shape (n, 3, 3, 3), T/m^2.

        Zero for linear fields.  Coils (:class:`coils.coaxial.CoaxialCoils`: single coils,
        Helmholtz and Maxwell pairs, also inside sums and scalings) give it in exact closed
        form, symmetric in all three indices and traceless to rounding; a gridded field gives
        the second derivatives of its interpolant.  Other sources use a central difference of
        their exact gradient (step ``1e-4`` of the source's length scale), accurate to about
        ``1e-8`` relative; it is used only in Newton tangents, where it costs no accuracy of the
        converged state.
        """
        pts = as_points(points)
        if self.linear or self.uniform:
            return np.zeros((pts.shape[0], 3, 3, 3))
        return self._hessian(pts)

    def B_gradient_hessian(self, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """B, gradient and hessian at ``points`` in one pass.

        Parameters
        ----------
        points : array-like, shape (n, 3) or (3,)
            Positions in metres.

        Returns
        -------
        B : ndarray, shape (n, 3)
            Flux density, T.
        G : ndarray, shape (n, 3, 3)
            ``G[k, i, j] = dB_i/dx_j``, T/m.
        H : ndarray, shape (n, 3, 3, 3)
            ``H[k, i, j, l] = d2B_i/(dx_j dx_l)``, T/m^2.

        Notes
        -----
        The same values as :meth:`B`, :meth:`gradient` and :meth:`hessian` (and the same
        errors); coils compute the three in one compiled pass over the points, which is what a
        Newton solver needs per iteration.
        """
        pts = as_points(points)
        n = pts.shape[0]
        if self.uniform:
            return self._B(pts), np.zeros((n, 3, 3)), np.zeros((n, 3, 3, 3))
        if self.linear:
            B, G = self._B_and_gradient(pts)
            return B, G, np.zeros((n, 3, 3, 3))
        return self._B_gradient_hessian(pts)

    def evaluator(self):
        """A function ``fields(points, hessian)`` for a solver's repeated evaluations.

        ``fields(points, hessian)`` returns ``(B, G, H)`` at ``points``, shapes (n, 3) T,
        (n, 3, 3) T/m and, if ``hessian``, (n, 3, 3, 3) T/m^2 (else None): the values and
        errors of :meth:`B_and_gradient` and :meth:`B_gradient_hessian`.  The points must be
        a finite C-contiguous float64 array (n, 3) in m made by the caller, which is not
        validated again (it may be made read-only); sources that can skip their per-call
        dispatch (coaxial coils: their compiled pass is called directly) override this.
        """

        def fields(points, hessian):
            if hessian:
                return self.B_gradient_hessian(points)
            B, G = self.B_and_gradient(points)
            return B, G, None

        return fields

    @property
    def length_scale(self) -> float:
        """A length (m) over which the field varies; used for finite-difference steps."""
        return 1.0

    def __add__(self, other: Field) -> Field:
        if not isinstance(other, Field):
            return NotImplemented
        return FieldSum([self, other])

    def __radd__(self, other):
        if isinstance(other, int | float) and not isinstance(other, bool) and other == 0:
            # sum([...]) starts from 0
            return self
        return NotImplemented

    def __mul__(self, factor: float) -> Field:
        return ScaledField(self, factor)

    __rmul__ = __mul__

    # -- defaults for subclasses ---------------------------------------------------------------
    @abstractmethod
    def _B(self, pts: np.ndarray) -> np.ndarray:
        """B (n, 3) in T at validated points (n, 3) in m; every source implements it."""

    def _gradient(self, pts: np.ndarray) -> np.ndarray:
        return self._B_and_gradient(pts)[1]

    def _B_and_gradient(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self._B(pts), self._gradient(pts)

    def _B_gradient_hessian(self, pts: np.ndarray):
        B, G = self._B_and_gradient(pts)
        return B, G, self._hessian(pts)

    def _add_to(self, pts: np.ndarray, B, G, H, factor: float) -> None:
        """Add ``factor`` times B, G, H of this field to the arrays given (None: not wanted).

        The arrays are C-contiguous, shapes (n, 3), (n, 3, 3), (n, 3, 3, 3); callers pass
        ``G = None`` for uniform fields and ``H = None`` for linear ones.
        """
        if H is not None:
            H += factor * self._hessian(pts)
        if G is not None:
            if B is not None:
                b, g = self._B_and_gradient(pts)
                B += factor * b
            else:
                g = self._gradient(pts)
            G += factor * g
        elif B is not None:
            B += factor * self._B(pts)

    def _hessian(self, pts: np.ndarray) -> np.ndarray:
        h = 1e-4 * self.length_scale
        n = pts.shape[0]
        out = np.empty((n, 3, 3, 3))
        for axis in range(3):
            step = np.zeros(3)
            step[axis] = h
            gp = self._gradient(pts + step)
            gm = self._gradient(pts - step)
            out[:, :, :, axis] = (gp - gm) / (2 * h)
        # symmetrise in the two derivative indices (exact for a smooth field)
        return 0.5 * (out + out.transpose(0, 1, 3, 2))


def as_field(value, name: str = "field") -> Field:
    """Return ``value`` if it is a :class:`Field` ("field must be a coils Field; got
    function")."""
    if not isinstance(value, Field):
        raise ValueError(f"{name} must be a coils Field; got {type(value).__name__}")
    return value


class AccumulatedField(Field):
    """A field whose every evaluation is one :meth:`_add_to` into zeroed arrays (sums of
    sources: superpositions, dipole sums); subclasses define ``_add_to`` only."""

    def _sum(self, pts, want_B: bool, want_G: bool, want_H: bool):
        n = pts.shape[0]
        B = np.zeros((n, 3)) if want_B else None
        G = np.zeros((n, 3, 3)) if want_G else None
        H = np.zeros((n, 3, 3, 3)) if want_H else None
        self._add_to(pts, B, G, H, 1.0)
        return B, G, H

    def _B(self, pts):
        return self._sum(pts, True, False, False)[0]

    def _gradient(self, pts):
        return self._sum(pts, False, True, False)[1]

    def _B_and_gradient(self, pts):
        return self._sum(pts, True, True, False)[:2]

    def _hessian(self, pts):
        return self._sum(pts, False, False, True)[2]

    def _B_gradient_hessian(self, pts):
        return self._sum(pts, True, True, True)


class OnePassField(Field):
    """A field whose B, gradient and hessian come from one pass, :meth:`_fields` (finite
    magnets: the hessian reuses the pass's intermediate terms); subclasses define ``_fields``
    and may override ``_B`` with a cheaper pass."""

    @abstractmethod
    def _fields(self, pts: np.ndarray, want_H: bool):
        """B (n, 3) T, gradient (n, 3, 3) T/m and, if ``want_H``, the hessian (n, 3, 3, 3)
        T/m^2 (else None) at validated points (n, 3) in m."""

    def _B(self, pts):
        return self._fields(pts, False)[0]

    def _gradient(self, pts):
        return self._fields(pts, False)[1]

    def _B_and_gradient(self, pts):
        return self._fields(pts, False)[:2]

    def _hessian(self, pts):
        return self._fields(pts, True)[2]

    def _B_gradient_hessian(self, pts):
        return self._fields(pts, True)


class FieldSum(AccumulatedField):
    """Superposition of fields: B and its derivatives add.

    Parameters
    ----------
    parts : sequence of Field
        The fields to superpose (nested sums are flattened); stored as the tuple ``parts``.
    """

    _immutable = True

    def __init__(self, parts):
        if isinstance(parts, Field | str) or not isinstance(parts, Iterable):
            raise ValueError(f"parts must be a sequence of coils Fields; got {parts!r}")
        flat: list[Field] = []
        for part in parts:
            as_field(part, "every part")
            flat.extend(part.parts if type(part) is FieldSum else [part])
        if not flat:
            raise ValueError("a field sum needs at least one part")
        self.parts = tuple(flat)
        self.uniform = all(p.uniform for p in flat)
        self.linear = all(p.linear or p.uniform for p in flat)

    @property
    def length_scale(self) -> float:
        return min(p.length_scale for p in self.parts)

    def _add_to(self, pts, B, G, H, factor):
        for p in self.parts:
            p._add_to(
                pts,
                B,
                None if p.uniform else G,
                None if (p.uniform or p.linear) else H,
                factor,
            )

    def __repr__(self):
        return f"{type(self).__name__}({list(self.parts)!r})"


class ScaledField(Field):
    """A field multiplied by a constant factor (e.g. a current scaling in a load sweep).

    Parameters
    ----------
    field : Field
        The field scaled.
    factor : float
        The factor (finite).
    """

    _immutable = True

    def __init__(self, field: Field, factor: float):
        self.field = as_field(field)
        self.factor = finite_scalar(factor, "factor")
        self.uniform = field.uniform
        self.linear = field.linear

    @property
    def length_scale(self) -> float:
        return self.field.length_scale

    def _scaled(self, pts, want_B: bool, want_G: bool, want_H: bool):
        n = pts.shape[0]
        B = np.zeros((n, 3)) if want_B else None
        G = np.zeros((n, 3, 3)) if want_G else None
        H = np.zeros((n, 3, 3, 3)) if want_H else None
        self.field._add_to(pts, B, G, H, self.factor)
        return B, G, H

    def _B(self, pts):
        return self._scaled(pts, True, False, False)[0]

    def _gradient(self, pts):
        return self._scaled(pts, False, True, False)[1]

    def _B_and_gradient(self, pts):
        return self._scaled(pts, True, True, False)[:2]

    def _hessian(self, pts):
        return self._scaled(pts, False, False, True)[2]

    def _B_gradient_hessian(self, pts):
        return self._scaled(pts, True, True, True)

    def _add_to(self, pts, B, G, H, factor):
        self.field._add_to(pts, B, G, H, factor * self.factor)

    def __repr__(self):
        return f"{self.factor!r} * {self.field!r}"
