"""Closed-form field and exact gradient of a circular current loop (tier 1: pure kernels).

A filament of radius ``a`` in the plane ``z = 0``, centred on the origin, carries current ``I``
counter-clockwise about +z.  With ``alpha^2 = a^2 + rho^2 + z^2 - 2 a rho``,
``beta^2 = a^2 + rho^2 + z^2 + 2 a rho``, ``m = k^2 = 1 - alpha^2/beta^2`` and
``C = mu0 I / pi`` (Simpson, Lane, Immer, Youngquist, NASA 2001):

    B_rho = C z / (2 alpha^2 beta rho) [(a^2 + rho^2 + z^2) E(m) - alpha^2 K(m)]
    B_z   = C     / (2 alpha^2 beta)     [(a^2 - rho^2 - z^2) E(m) + alpha^2 K(m)]

The gradient needs only ``dB_z/dz``, ``dB_z/drho`` and ``B_rho/rho``: ``curl B = 0`` gives
``dB_rho/dz = dB_z/drho`` and ``div B = 0`` gives ``dB_rho/drho = -B_rho/rho - dB_z/dz``.
``dB_z/d(.)`` is differentiated in closed form with ``dK/dm = g(m) / (2 (1 - m))`` and
``dE/dm = -D(m) / 2``, where ``D = (K - E)/m`` and ``g = (E - (1 - m) K)/m``.

Near the axis (m -> 0) the brackets cancel catastrophically; ``D``, ``g`` and
``F = ((1 - m/2) E - (1 - m) K)/m^2`` are then taken from their hypergeometric power series,
so the kernel keeps full relative precision on and near the axis.  Near the wire (m -> 1) ``K``
is evaluated from ``1 - m`` directly (``scipy.special.ellipkm1``).

These functions perform no input checks (tier 1); :mod:`coils.coaxial` handles frames, winding
checks and validation.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ellipe, ellipkm1

__all__ = ["loop_field_cyl", "loop_B_and_gradient_local"]

#: Below this modulus m the series forms of D, g and F are used (error < 1e-16 with 24 terms).
_M_SERIES = 0.1
_N_TERMS = 24


def _series_coefficients(n_terms: int = _N_TERMS):
    """Power-series coefficients (highest power first, for np.polyval) of D, g and F in m."""
    n = np.arange(n_terms + 3)
    a = np.ones(n.size)
    for i in range(1, n.size):  # a_n = ((2n)! / (4^n n!^2))^2
        a[i] = a[i - 1] * ((2 * i - 1) / (2 * i)) ** 2
    k = math.pi / 2 * a  # K(m) = sum k_n m^n
    e = math.pi / 2 * a / (1 - 2 * n)  # E(m) = sum e_n m^n
    d = (k - e)[1 : n_terms + 1]  # D = (K - E)/m
    g = -d + k[:n_terms]  # g = K - D
    f1 = e[2:] - e[1:-1] / 2 - k[2:] + k[1:-1]  # coefficients of m^2.. of (1-m/2)E-(1-m)K
    f = f1[:n_terms]
    return d[::-1].copy(), g[::-1].copy(), f[::-1].copy()


_D_SERIES, _G_SERIES, _F_SERIES = _series_coefficients()


def _elliptic_parts(m: np.ndarray, m1: np.ndarray):
    """K, E and the cancellation-free combinations D, g, F at modulus m (m1 = 1 - m)."""
    K = ellipkm1(m1)
    E = ellipe(m)
    small = m < _M_SERIES
    big = ~small
    D = np.empty_like(m)
    g = np.empty_like(m)
    F = np.empty_like(m)
    if np.any(small):
        ms = m[small]
        D[small] = np.polyval(_D_SERIES, ms)
        g[small] = np.polyval(_G_SERIES, ms)
        F[small] = np.polyval(_F_SERIES, ms)
    if np.any(big):
        mb, Kb, Eb, m1b = m[big], K[big], E[big], m1[big]
        D[big] = (Kb - Eb) / mb
        g[big] = (Eb - m1b * Kb) / mb
        F[big] = ((1 - 0.5 * mb) * Eb - m1b * Kb) / (mb * mb)
    return K, E, D, g, F


def loop_field_cyl(rho: np.ndarray, z: np.ndarray, a: float, current: float = 1.0):
    """Field of one loop in cylindrical components, with the gradient invariants.

    Parameters
    ----------
    rho, z : ndarray, shape (n,)
        Cylindrical coordinates of the points in the loop frame, metres (rho >= 0).
    a : float
        Loop radius, metres.
    current : float
        Current in amperes (counter-clockwise about +z).

    Returns
    -------
    Q : ndarray, shape (n,)
        ``B_rho / rho`` in T/m (finite on the axis).
    Bz : ndarray, shape (n,)
        Axial flux density, T.
    dBz_dz, dBz_drho : ndarray, shape (n,)
        Derivatives of ``B_z``, T/m.
    alpha2 : ndarray, shape (n,)
        Squared distance to the wire, m^2.

    Notes
    -----
    Points on the wire (rho = a, z = 0) give inf; callers exclude them.
    """
    C = 4e-7 * current  # mu0 I / pi with mu0 = 4e-7 pi (CODATA scaling applied by caller)
    rho2 = rho * rho
    r2 = rho2 + z * z
    s = a * a + r2
    two_a_rho = 2.0 * a * rho
    alpha2 = (rho - a) ** 2 + z * z  # = s - 2 a rho, without cancellation near the wire
    beta2 = s + two_a_rho
    beta = np.sqrt(beta2)
    m1 = alpha2 / beta2
    m = two_a_rho * 2.0 / beta2
    K, E, D, g, F = _elliptic_parts(m, m1)

    inv_a2b = 1.0 / (alpha2 * beta)
    a2_minus_r2 = (a - rho) * (a + rho) - z * z  # without cancellation near the wire
    Pz = a2_minus_r2 * E + alpha2 * K
    Bz = 0.5 * C * Pz * inv_a2b
    # B_rho / rho = C z beta F m^2 / (2 alpha^2 rho^2), with m^2 / rho^2 = 16 a^2 / beta^4
    Q = 8.0 * C * z * a * a * F * inv_a2b / beta2

    # derivatives of m: dm = -(d(alpha^2) beta^2 - alpha^2 d(beta^2)) / beta^4
    dm_dz = -8.0 * a * rho * z / (beta2 * beta2)
    dm_drho = -2.0 * ((rho - a) * beta2 - (rho + a) * alpha2) / (beta2 * beta2)
    # dPz = -d(r^2) E - (a^2 - r^2) D/2 dm + d(alpha^2) K + beta^2 g dm / 2
    common = -0.5 * a2_minus_r2 * D + 0.5 * beta2 * g
    dPz_dz = -2.0 * z * E + common * dm_dz + 2.0 * z * K
    dPz_drho = -2.0 * rho * E + common * dm_drho + 2.0 * (rho - a) * K
    # Bz = C/2 Pz alpha^-2 beta^-1
    dBz_dz = 0.5 * C * inv_a2b * (dPz_dz - Pz * (2.0 * z / alpha2 + z / beta2))
    dBz_drho = 0.5 * C * inv_a2b * (dPz_drho - Pz * (2.0 * (rho - a) / alpha2 + (rho + a) / beta2))
    return Q, Bz, dBz_dz, dBz_drho, alpha2


def loop_B_and_gradient_local(
    p: np.ndarray,
    filaments: np.ndarray,
    with_gradient: bool = True,
    nearest: np.ndarray | None = None,
):
    """B and gradient of coaxial filaments, in their common local frame (axis = local z).

    Parameters
    ----------
    p : ndarray, shape (n, 3)
        Points in the local frame, metres.
    filaments : ndarray, shape (f, 3)
        Rows ``(z_offset, radius, current)``: loop plane at local ``z = z_offset`` (m),
        radius (m) and ampere-turns carried (A).
    with_gradient : bool
        If False, only B is computed (the gradient array is None).
    nearest : ndarray, shape (n,), optional
        If given, filled with ``min over filaments of (distance to the wire / radius)^2``, so the
        caller can detect points on a winding without recomputing distances.

    Returns
    -------
    B : ndarray, shape (n, 3)
        T, scaled for mu0 = 4e-7 pi (the caller rescales to CODATA mu0).
    G : ndarray, shape (n, 3, 3) or None
        ``G[k, i, j] = dB_i/dx_j`` in T/m, same scaling.
    """
    x, y = p[:, 0], p[:, 1]
    rho = np.hypot(x, y)
    Q = np.zeros_like(rho)
    Bz = np.zeros_like(rho)
    Gzz = np.zeros_like(rho)
    Gzr = np.zeros_like(rho)
    if nearest is not None:
        nearest.fill(np.inf)
    for z0, a, cur in filaments:
        q, bz, gzz, gzr, alpha2 = loop_field_cyl(rho, p[:, 2] - z0, a, cur)
        if nearest is not None:
            np.minimum(nearest, alpha2 / (a * a), out=nearest)
        Q += q
        Bz += bz
        if with_gradient:
            Gzz += gzz
            Gzr += gzr
    B = np.empty_like(p)
    B[:, 0] = Q * x
    B[:, 1] = Q * y
    B[:, 2] = Bz
    if not with_gradient:
        return B, None
    # unit radial vector (any direction on the axis: the terms it multiplies vanish there)
    with np.errstate(invalid="ignore", divide="ignore"):
        ex = np.where(rho > 0, x / rho, 1.0)
        ey = np.where(rho > 0, y / rho, 0.0)
    # dB_rho/drho = -Q - dBz/dz;  dB_i/dx_j (i,j in x,y) = Brr e_i e_j + Q (delta_ij - e_i e_j)
    Brr_minus_Q = -2.0 * Q - Gzz
    G = np.empty((p.shape[0], 3, 3))
    G[:, 0, 0] = Q + Brr_minus_Q * ex * ex
    G[:, 1, 1] = Q + Brr_minus_Q * ey * ey
    G[:, 0, 1] = G[:, 1, 0] = Brr_minus_Q * ex * ey
    G[:, 0, 2] = G[:, 2, 0] = Gzr * ex
    G[:, 1, 2] = G[:, 2, 1] = Gzr * ey
    G[:, 2, 2] = Gzz
    return B, G
