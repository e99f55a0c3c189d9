"""Far field of a coaxial group of loops: its exterior multipole series (tier 1, compiled).

Filaments ``i`` of radius ``a_i`` in the planes ``z = z_i`` carry ampere-turns ``I_i``, all about
the common axis z; ``d >= max_i sqrt(a_i^2 + z_i^2)`` bounds their distance from the origin.

Series
------
On the axis, for ``z > d``, each loop's ``Bz = (mu0 I a^2 / 2) ((z - z_i)^2 + a^2)^(-3/2)``
expands by the generating function of the Gegenbauer polynomials ``C_n = C_n^(3/2) = P'_(n+1)``
(``d_i = sqrt(a_i^2 + z_i^2)``, ``x_i = z_i / d_i``)::

    Bz(z) = sum_n b_n z^-(n+3),     b_n = sum_i (mu0 I_i a_i^2 / 2) C_n(x_i) d_i^n,

and the exterior solution of Laplace's equation with these values on the axis is the scalar
potential ``Phi = sum_l M_l r^-(l+1) P_l(cos theta)`` with ``b_n = mu0 (n + 2) M_(n+1)``
(``B = -mu0 grad Phi``; ``4 pi M_1 = sum_i I_i pi a_i^2`` is the dipole moment).  With
``zeta = z / r``, ``eps = d / r`` and the normalised moments ``beta_n = b_n / d^n``, the
identities ``d/dz [r^-(l+1) P_l] = -(l+1) r^-(l+2) P_(l+1)`` and
``(1/rho) d/drho [r^-k g(zeta)] = -r^-(k+2) (k g + zeta g')`` (with
``P'_(l+1) = zeta P'_l + (l+1) P_l`` and its derivative) give the invariants of
:mod:`coils.loop` in closed form::

    Bz = r^-3 sum_n beta_n eps^n P_(n+2)           Q  = r^-4 sum_n beta_n eps^n P'_(n+2) / (n+2)
    b1 = -r^-5 sum_n beta_n eps^n P'_(n+3)         q1 = -r^-6 sum_n beta_n eps^n P''_(n+3) / (n+2)
    c1 = r^-6 sum_n beta_n eps^n (n+3) P'_(n+4)    d1 = r^-7 sum_n beta_n eps^n P''_(n+4)

The Legendre polynomials and their first two derivatives come from the stable three-term
recurrences (``|zeta| <= 1``), so no term cancels except at genuine zeros, on and off the axis.
The leading term (``n = 0``) is the dipole field; a Maxwell pair has ``beta_0 = 0`` exactly (the
moments are summed with ``math.fsum``), so its far field keeps full relative precision too,
which no sum of the filaments' own fields can do (their dipoles cancel).

Switch radius and truncation
----------------------------
The series is used where ``r > SWITCH * d`` (``SWITCH = 4``, so ``eps < 1/4``); nearer,
:mod:`coils.loop` sums the filaments.  With ``mu = sum_i mu0 |I_i| a_i^2 / 2``,
``|C_n| <= (n+1)(n+2)/2`` and ``|P^(j)_k| <= P^(j)_k(1)``, every term ``n`` of every sum above is
bounded by ``mu W(n) eps^n`` with ``W(n) = (n+1)(n+2)...(n+6)/16``.  The sums stop after term
``N - 1``, the first ``N`` at which the tail bound ``2 mu W(N) eps^N`` (valid while
``eps (N+7)/(N+1) <= 1/2``) is below ``2^-60 |beta_n0| eps^n0``, where ``n0`` is the first
non-zero moment: the truncation error of every invariant is below ``2^-60`` of the leading
multipole's term (one loop: 46 terms at the switch radius, 13 at ``r = 100 d``, 4 at
``r = 10^6 d``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ._immutable import kernel_input

__all__ = ["SWITCH", "Moments", "group_moments", "multipole_point", "multipole_invariants"]

#: The multipole series is used beyond SWITCH times the group radius d.
SWITCH = 4.0
#: Relative truncation error (against the leading multipole term).
TOL = 2.0**-60
#: Moments computed (more than the truncation rule ever needs at eps < 1/4 for kappa > 1e-12).
N_MAX = 120


class Moments(NamedTuple):
    """Normalised axial moments of a coaxial group (see the module docstring).

    Attributes
    ----------
    beta : ndarray, shape (N_MAX + 1,)
        ``beta_n = b_n / d^n``, T m^3.
    d : float
        Group radius, m (the series converges for ``r > d``).
    n0 : int
        Index of the first non-zero moment.
    kappa : float
        ``TOL |beta_n0| / mu``: the truncation threshold on ``2 W(N) eps^(N - n0)``.
    """

    beta: np.ndarray
    d: float
    n0: int
    kappa: float


def group_moments(filaments, mu0: float, d: float | None = None, n_max: int = N_MAX) -> Moments:
    """Axial moments of coaxial filaments about their common origin.

    Parameters
    ----------
    filaments : array-like, shape (f, 3)
        Rows ``(z_offset, radius, current)`` in m, m, A (as in :class:`coils.CoaxialCoils`).
    mu0 : float
        Vacuum permeability, T m / A.
    d : float, optional
        Group radius, m; at least ``max sqrt(radius^2 + z_offset^2)`` (the default).
    n_max : int
        Highest moment computed.

    Returns
    -------
    Moments
    """
    fil = np.asarray(filaments, dtype=float)
    z0, a, cur = fil[:, 0], fil[:, 1], fil[:, 2]
    di = np.hypot(a, z0)
    if d is None:
        d = float(di.max())
    x = z0 / di
    strength = 0.5 * mu0 * cur * a * a
    C = np.empty((n_max + 1, len(fil)))  # Gegenbauer C_n^(3/2)(x_i)
    C[0] = 1.0
    if n_max >= 1:
        C[1] = 3.0 * x
    for n in range(2, n_max + 1):
        C[n] = ((2 * n + 1) * x * C[n - 1] - (n + 1) * C[n - 2]) / n
    ratio = di / d
    beta = np.array([math.fsum(strength * C[n] * ratio**n) for n in range(n_max + 1)], dtype=float)
    mu = math.fsum(np.abs(strength))
    nonzero = np.flatnonzero(beta)
    if mu == 0.0 or nonzero.size == 0:
        return Moments(beta, float(d), 0, math.inf)
    n0 = int(nonzero[0])
    return Moments(beta, float(d), n0, TOL * abs(beta[n0]) / mu)


@njit(cache=True, error_model="numpy", fastmath={"contract"})
def multipole_point(beta, n0, kappa, eps, zeta):
    """The six angular sums of the module docstring at one point (compiled, no checks).

    Parameters
    ----------
    beta : ndarray, shape (N,)
        Normalised moments, T m^3.
    n0 : int
        First non-zero moment.
    kappa : float
        Truncation threshold (:class:`Moments`).
    eps : float
        ``d / r`` (< 1/4 where used).
    zeta : float
        ``z / r``.

    Returns
    -------
    SBz, SQ, Sb1, Sq1, Sc1, Sd1 : float
        The sums; the invariants are ``Bz = SBz/r^3``, ``Q = SQ/r^4``, ``b1 = Sb1/r^5``,
        ``q1 = Sq1/r^6``, ``c1 = Sc1/r^6``, ``d1 = Sd1/r^7``.
    """
    SBz = 0.0
    SQ = 0.0
    Sb1 = 0.0
    Sq1 = 0.0
    Sc1 = 0.0
    Sd1 = 0.0
    if not kappa < math.inf:
        return SBz, SQ, Sb1, Sq1, Sc1, Sd1
    # P_k, P'_k, P''_k: run the recurrences from k = 0 to k = 4, keeping P_2, P'_2
    p_prev, p = 1.0, zeta  # P_0, P_1
    d1_prev, d1 = 0.0, 1.0
    d2_prev, d2 = 0.0, 0.0
    P2 = D1_2 = 0.0
    for k in range(1, 4):
        c = 2.0 * k + 1.0
        p_next = (c * zeta * p - k * p_prev) / (k + 1.0)
        d1_next = d1_prev + c * p
        d2_next = d2_prev + c * d1
        if k == 1:
            P2, D1_2 = p_next, d1_next
        p_prev, p = p, p_next
        d1_prev, d1 = d1, d1_next
        d2_prev, d2 = d2, d2_next
    # at term n: P2, D1_2 hold index n + 2, *_prev index n + 3, p, d1, d2 index n + 4
    epsn = 1.0  # eps^n
    rel = 1.0  # eps^(n + 1 - n0) once n >= n0
    W = 45.0  # W(n) = (n+1)...(n+6)/16 at n = 0
    for n in range(beta.shape[0]):
        bn = beta[n] * epsn
        inv = 1.0 / (n + 2.0)
        SBz += bn * P2
        SQ += bn * D1_2 * inv
        Sb1 -= bn * d1_prev
        Sq1 -= bn * d2_prev * inv
        Sc1 += bn * (n + 3.0) * d1
        Sd1 += bn * d2
        # stop when the tail bound of the terms m >= N = n + 1 is small enough
        W *= (n + 7.0) / (n + 1.0)
        if n >= n0:
            rel *= eps
            if eps * (n + 8.0) <= 0.5 * (n + 2.0) and 2.0 * W * rel <= kappa:
                break
        epsn *= eps
        k = n + 4.0  # advance the recurrences to index n + 5
        c = 2.0 * k + 1.0
        p_next = (c * zeta * p - k * p_prev) / (k + 1.0)
        d1_next = d1_prev + c * p
        d2_next = d2_prev + c * d1
        P2, D1_2 = p_prev, d1_prev
        p_prev, p = p, p_next
        d1_prev, d1 = d1, d1_next
        d2_prev, d2 = d2, d2_next
    return SBz, SQ, Sb1, Sq1, Sc1, Sd1


@njit(cache=True, error_model="numpy")
def _invariants(rho, z, beta, d, n0, kappa, out):
    for k in range(rho.shape[0]):
        r = math.hypot(rho[k], z[k])
        SBz, SQ, Sb1, Sq1, Sc1, Sd1 = multipole_point(beta, n0, kappa, d / r, z[k] / r)
        r2 = r * r
        out[k, 0] = SQ / (r2 * r2)
        out[k, 1] = SBz / (r2 * r)
        out[k, 2] = Sb1 / (r2 * r2 * r)
        out[k, 3] = Sq1 / (r2 * r2 * r2)
        out[k, 4] = Sc1 / (r2 * r2 * r2)
        out[k, 5] = Sd1 / (r2 * r2 * r2 * r)


def multipole_invariants(rho, z, moments: Moments) -> np.ndarray:
    """The invariants of the multipole series at many points (for tests and inspection).

    Parameters
    ----------
    rho, z : array-like, shape (n,)
        Cylindrical coordinates about the group's axis and origin, m (``r`` well above ``d``;
        no scaling against overflow here).
    moments : Moments
        From :func:`group_moments`.

    Returns
    -------
    ndarray, shape (n, 6)
        Columns ``Q, Bz, b1, q1, c1, d1`` as in :func:`coils.loop.loop_invariants`.
    """
    # read-only inputs: one compiled version whatever the arrays' flags (z may be broadcast)
    rho = kernel_input(rho)
    z = kernel_input(np.broadcast_to(z, rho.shape))
    out = np.empty((rho.shape[0], 6))
    beta = kernel_input(moments.beta)  # read-only, as the coil pass passes it
    _invariants(rho, z, beta, moments.d, moments.n0, moments.kappa, out)
    return out
