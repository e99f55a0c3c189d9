"""The field protocol shared by every source, and the algebra of fields (sums and scaling).

Every field maps points ``(n, 3)`` in metres to

* ``B(points)``: flux density, shape ``(n, 3)``, tesla;
* ``gradient(points)``: ``G[k, i, j] = dB_i/dx_j``, shape ``(n, 3, 3)``, tesla per metre;
* ``hessian(points)``: ``H[k, i, j, l] = d2B_i/(dx_j dx_l)``, shape ``(n, 3, 3, 3)``, T/m^2.

and says what it does not need to compute, so solvers can skip work:

* ``uniform``: the gradient is identically zero (no force path, no gradient evaluation);
* ``linear``: the gradient is constant (the hessian is identically zero).
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from ._validate import as_points, finite_scalar

__all__ = ["Field", "FieldSum", "ScaledField"]

#: Points evaluated per chunk by sources whose kernels allocate per-point temporaries.
CHUNK = 65536


class Field(ABC):
    """Base class of all magnetic field sources (a protocol with shared conveniences).

    Subclasses implement ``_B(points)`` and ``_gradient(points)`` on validated ``(n, 3)`` arrays;
    they may override ``_B_and_gradient`` when the two share work and ``_hessian`` when a closed
    form exists.  Public methods validate once and dispatch.
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

    @property
    def length_scale(self) -> float:
        """A length (m) over which the field varies; used for finite-difference steps."""
        return 1.0

    def __add__(self, other: Field) -> Field:
        if not isinstance(other, Field):
            return NotImplemented
        return FieldSum([self, other])

    def __radd__(self, other):
        if isinstance(other, int | float) and other == 0:  # sum([...]) support
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


class FieldSum(Field):
    """Superposition of fields: B and its derivatives add.

    Parameters
    ----------
    parts : sequence of Field
        The fields to superpose (nested sums are flattened).
    """

    def __init__(self, parts):
        flat: list[Field] = []
        for part in parts:
            if not isinstance(part, Field):
                raise ValueError(f"every part must be a coils Field; got {type(part).__name__}")
            flat.extend(part.parts if type(part) is FieldSum else [part])
        if not flat:
            raise ValueError("a field sum needs at least one part")
        self.parts = flat
        self.uniform = all(p.uniform for p in flat)
        self.linear = all(p.linear or p.uniform for p in flat)

    @property
    def length_scale(self) -> float:
        return min(p.length_scale for p in self.parts)

    def _B(self, pts):
        return sum(p._B(pts) for p in self.parts)

    def _gradient(self, pts):
        return sum(p._gradient(pts) for p in self.parts if not p.uniform) + np.zeros(
            (pts.shape[0], 3, 3)
        )

    def _B_and_gradient(self, pts):
        B = np.zeros((pts.shape[0], 3))
        G = np.zeros((pts.shape[0], 3, 3))
        for p in self.parts:
            if p.uniform:
                B += p._B(pts)
            else:
                b, g = p._B_and_gradient(pts)
                B += b
                G += g
        return B, G

    def _hessian(self, pts):
        H = np.zeros((pts.shape[0], 3, 3, 3))
        for p in self.parts:
            if not (p.uniform or p.linear):
                H += p._hessian(pts)
        return H

    def __repr__(self):
        return f"{type(self).__name__}({self.parts!r})"


class ScaledField(Field):
    """A field multiplied by a constant factor (e.g. a current scaling in a load sweep)."""

    def __init__(self, field: Field, factor: float):
        if not isinstance(field, Field):
            raise ValueError(f"field must be a coils Field; got {type(field).__name__}")
        self.field = field
        self.factor = finite_scalar(factor, "factor")
        self.uniform = field.uniform
        self.linear = field.linear

    @property
    def length_scale(self) -> float:
        return self.field.length_scale

    def _B(self, pts):
        return self.factor * self.field._B(pts)

    def _gradient(self, pts):
        return self.factor * self.field._gradient(pts)

    def _B_and_gradient(self, pts):
        b, g = self.field._B_and_gradient(pts)
        return self.factor * b, self.factor * g

    def _hessian(self, pts):
        return self.factor * self.field._hessian(pts)

    def __repr__(self):
        return f"{self.factor!r} * {self.field!r}"
