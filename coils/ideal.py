"""Ideal fields of the published models: uniform (Config A) and constant-gradient (Config B)."""

from __future__ import annotations

import numpy as np

from ._immutable import sealed
from ._validate import as_array, as_count, as_vector, finite_scalar, nonnegative
from .field import Field, as_field

__all__ = ["UniformField", "LinearField", "maxwell_gradient", "linearize"]


class LinearField(Field):
    """A field with constant gradient: ``B(x) = B0 + G (x - origin)`` (Config (B)).

    Parameters
    ----------
    B0 : array-like, shape (3,)
        Flux density at ``origin``, tesla.
    gradient : array-like, shape (3, 3)
        ``G[i, j] = dB_i/dx_j`` in T/m.  A physical (current-free) field has G symmetric and
        traceless; that is not enforced, so idealised models can be explored, but
        :attr:`is_physical` tells.
    origin : array-like, shape (3,)
        Reference point, metres.

    Attributes
    ----------
    B0, origin : ndarray, shape (3,)
        Read-only copies of the parameters (T, m).
    G : ndarray, shape (3, 3)
        The gradient, T/m (read-only).

    Notes
    -----
    Immutable (:mod:`coils._immutable`): change it with ``replace(B0=..., gradient=...,
    origin=...)``.

    Examples
    --------
    >>> import numpy as np
    >>> from coils import LinearField
    >>> f = LinearField(B0=(0, 0, 0), gradient=np.diag([-0.5, 1.0, -0.5]))
    >>> f.B([[0.0, 0.2, 0.0]])
    array([[0. , 0.2, 0. ]])
    """

    linear = True
    _immutable = True

    def __init__(self, B0=(0.0, 0.0, 0.0), gradient=None, origin=(0.0, 0.0, 0.0)):
        self.B0 = sealed(as_vector(B0, "B0"))
        G = np.zeros((3, 3)) if gradient is None else as_array(gradient, "gradient", (3, 3))
        self.G = sealed(G)
        # G^T C-contiguous: ``x @ G.T`` with the transposed view takes numpy's generic loop,
        # about five times slower than with a contiguous operand (650 points: 57 against 12 us)
        self._GT = sealed(np.ascontiguousarray(G.T))
        self.origin = sealed(as_vector(origin, "origin"))
        self.uniform = not np.any(G)

    @property
    def is_physical(self) -> bool:
        """True if the gradient is symmetric and traceless (curl-free, divergence-free)."""
        scale = max(np.abs(self.G).max(), 1e-300)
        return bool(
            np.allclose(self.G, self.G.T, atol=1e-12 * scale)
            and abs(np.trace(self.G)) <= 1e-12 * scale
        )

    def _B(self, pts):
        return self.B0 + (pts - self.origin) @ self._GT

    def _gradient(self, pts):
        return np.broadcast_to(self.G, (pts.shape[0], 3, 3)).copy()

    def __repr__(self):
        return (
            f"LinearField(B0={self.B0.tolist()}, gradient={self.G.tolist()}, "
            f"origin={self.origin.tolist()})"
        )


class UniformField(LinearField):
    """A spatially uniform flux density (the ideal Helmholtz pair, Config (A)).

    A :class:`LinearField` with zero gradient; ``uniform`` is True, so solvers skip the force.

    Parameters
    ----------
    B : array-like, shape (3,)
        Flux density in tesla (the attribute ``B0``, read-only; change it with
        ``replace(B=...)``).

    Examples
    --------
    >>> from coils import UniformField
    >>> UniformField(B=(0, 5e-3, 0)).B([[0.01, 0.0, 0.0]])
    array([[0.   , 0.005, 0.   ]])
    """

    uniform = True
    linear = True

    def __init__(self, B=(0.0, 0.0, 0.0)):
        super().__init__(B0=as_vector(B, "B"))

    def _B(self, pts):
        return np.broadcast_to(self.B0, pts.shape).copy()

    def __repr__(self):
        return f"UniformField(B={self.B0.tolist()})"


def maxwell_gradient(g: float, axis: int = 1) -> np.ndarray:
    """The ideal Maxwell-pair gradient ``g * diag(-1/2, 1, -1/2)`` with ``axis`` the pair axis.

    Parameters
    ----------
    g : float
        Axial gradient dB_axis/dx_axis in T/m.
    axis : int
        Index (0, 1, 2) of the pair axis; the seed's Config (B) uses 1 (y).

    Returns
    -------
    ndarray, shape (3, 3)
        T/m.
    """
    g = finite_scalar(g, "g")
    axis = as_count(axis, "axis", 0, 2)
    d = np.full(3, -0.5 * g)
    d[axis] = g
    return np.diag(d)


def linearize(field: Field, center, zero_tol: float = 1e-12) -> LinearField:
    """The :class:`LinearField` of ``field``'s B and gradient at ``center`` (m).

    This is the ideal field that the published models assume.  Entries of B and of the gradient
    below ``zero_tol`` times their natural scale (the largest entry, or ``|B0| / length_scale``
    for the gradient) are round-off of a symmetric arrangement and are set to exactly zero, so a
    Helmholtz pair linearizes to a uniform field and a Maxwell pair to a pure gradient.

    Parameters
    ----------
    field : Field
        The field to linearise.
    center : array-like, shape (3,)
        Working point, m.
    zero_tol : float
        Relative size (>= 0) below which entries are set to zero.

    Returns
    -------
    LinearField
        ``B0`` (3,) in T at ``center``, gradient (3, 3) in T/m, origin ``center``.
    """
    field = as_field(field)
    zero_tol = nonnegative(zero_tol, "zero_tol")
    c = as_vector(center, "center")
    B0, G0 = field.B_and_gradient(c[None, :])
    B0, G0 = B0[0], G0[0]
    scale_g = max(np.abs(G0).max(), np.linalg.norm(B0) / field.length_scale)
    scale_b = max(np.abs(B0).max(), np.abs(G0).max() * field.length_scale)
    G0 = np.where(np.abs(G0) < zero_tol * scale_g, 0.0, G0)
    B0 = np.where(np.abs(B0) < zero_tol * scale_b, 0.0, B0)
    return LinearField(B0=B0, gradient=G0, origin=c)
