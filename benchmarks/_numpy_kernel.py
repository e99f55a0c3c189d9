"""The previous numpy kernel of coils (commit 9501399), kept only for benchmarks/bench_coils.py.

Everything below the marker is ``coils/loop.py`` of that commit, verbatim, followed by the
evaluation of a :class:`coils.CoaxialCoils` as ``coils/coaxial.py`` of that commit did it
(chunks, rotation, on-winding check).  Not part of the library: ``coils`` uses the compiled
kernel of coils/_compiled.py.
"""
# ruff: noqa

# ---- coils/loop.py at 9501399 ------------------------------------------------------------------

import math

import numpy as np
from scipy.special import ellipe, ellipkm1

__all__ = [
    "loop_field_cyl",
    "loop_B_and_gradient_local",
    "loop_hessian_cyl",
    "loop_hessian_local",
]

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


#: Below this t = 2 a rho / s (w = t^2 < 0.25) phi and its derivatives come from their series.
_T_SERIES = 0.5
_N_PHI = 40


def _phi_series_coefficients(n_terms: int = _N_PHI) -> np.ndarray:
    """Series coefficients of phi(w), phi'(w), phi''(w): column j holds the j-th derivative's
    coefficients of w^0 .. w^(n_terms - 1), shape (n_terms, 3)."""
    n = np.arange(n_terms + 1)
    e = np.ones(n.size)  # 2F1(-1/4, 1/4; 1; w)
    k = np.ones(n.size)  # 2F1(1/4, 3/4; 1; w)
    for i in range(1, n.size):
        e[i] = e[i - 1] * (i - 1.25) * (i - 0.75) / (i * i)
        k[i] = k[i - 1] * (i - 0.75) * (i - 0.25) / (i * i)
    phi = (np.cumsum(e) - k)[1:]  # e/(1-w) has the partial sums of e as coefficients
    j = np.arange(n_terms, dtype=float)
    out = np.zeros((n_terms, 3))
    out[:, 0] = phi
    out[:-1, 1] = phi[1:] * j[1:]
    out[:-2, 2] = phi[2:] * j[2:] * j[1:-1]
    return out


_PHI_SERIES = _phi_series_coefficients()


def _phi_and_derivatives(t: np.ndarray, v: np.ndarray, p: np.ndarray, m: np.ndarray):
    """phi(w), phi'(w), phi''(w) at w = t^2 (v = 1 - t, p = 1 + t, m = 2 t / p, all given).

    Away from the axis (``t >= _T_SERIES``), with ``K = K(m)``, ``E = E(m)`` (differentiated with
    ``dK/dm``, ``dE/dm`` of the module docstring and ``dm/dw = 1 / (t p^2)``)::

        phi   = 2 (E/v - K) / (pi t^2 p^(1/2))
        phi'  = ((2 - 5 t^2 / 2) K + 2 (2 t^2 - 1) E/v) / (pi v t^4 p^(3/2))
        phi'' = ((93 t^4 - 93 t^2 + 32) E/v - (45 t^4 - 69 t^2 + 32) K) / (8 pi v^2 t^6 p^(5/2))

    Near the axis the power series of phi (40 terms; truncation below 1e-19 at the switch).
    """
    f0 = np.empty_like(t)
    f1 = np.empty_like(t)
    f2 = np.empty_like(t)
    small = t < _T_SERIES
    big = ~small
    if np.any(small):
        w = t[small] ** 2
        powers = np.empty((_N_PHI, w.size))  # w^0 .. w^(N-1): all terms positive, no cancellation
        powers[0] = 1.0
        for j in range(1, _N_PHI):
            np.multiply(powers[j - 1], w, out=powers[j])
        f0[small], f1[small], f2[small] = _PHI_SERIES.T @ powers
    if np.any(big):
        tb, vb, pb = t[big], v[big], p[big]
        K = ellipkm1(vb / pb)  # 1 - m = (1 - t) / (1 + t)
        E = ellipe(m[big])
        t2 = tb * tb
        Ev = E / vb
        sp = np.sqrt(pb)
        f0[big] = (2.0 / math.pi) * (Ev - K) / (t2 * sp)
        f1[big] = ((2.0 - 2.5 * t2) * K + 2.0 * (2.0 * t2 - 1.0) * Ev) / (
            math.pi * vb * t2 * t2 * pb * sp
        )
        f2[big] = (
            (93.0 * t2 * (t2 - 1.0) + 32.0) * Ev - (45.0 * t2 * t2 - 69.0 * t2 + 32.0) * K
        ) / (8.0 * math.pi * vb * vb * t2 * t2 * t2 * pb * pb * sp)
    return f0, f1, f2


def loop_hessian_cyl(rho: np.ndarray, z: np.ndarray, a: float, current: float = 1.0):
    """The four derivatives of ``Q = B_rho / rho`` from which the hessian of one loop follows.

    Parameters
    ----------
    rho, z : ndarray, shape (n,)
        Cylindrical coordinates of the points in the loop frame, metres (rho >= 0).
    a : float or ndarray
        Loop radius, metres.
    current : float or ndarray
        Current in amperes (counter-clockwise about +z).  ``rho``, ``z``, ``a`` and
        ``current`` broadcast together (e.g. (n, 1), (n, f), (f,), (f,) for f loops); the
        outputs then have the broadcast shape instead of (n,).

    Returns
    -------
    b1 : ndarray, shape (n,)
        ``dQ/dz = (dB_z/drho)/rho``, T/m^2.
    c1 : ndarray, shape (n,)
        ``d2Q/dz2``, T/m^3.
    q1 : ndarray, shape (n,)
        ``(dQ/drho)/rho``, T/m^3.
    d1 : ndarray, shape (n,)
        ``d q1/dz``, T/m^4.
    alpha2 : ndarray, shape (n,)
        Squared distance to the wire, m^2.

    Notes
    -----
    All four are regular on the axis (functions of ``u = rho^2`` and ``z``); see the module
    docstring for the closed form.  Scaled for mu0 = 4e-7 pi, like :func:`loop_field_cyl`.
    """
    A = 4e-7 * math.pi * current * a * a  # C pi a^2 with C = mu0 I / pi
    u = rho * rho
    z2 = z * z
    s = a * a + u + z2
    two_a_rho = 2.0 * a * rho
    alpha2 = (rho - a) ** 2 + z2
    t = np.minimum(two_a_rho / s, 1.0)  # <= 1 exactly; rounding must not push m above 1
    v = alpha2 / s  # 1 - t without cancellation near the wire
    p = 1.0 + t
    m = 2.0 * t / p
    f0, f1, f2 = _phi_and_derivatives(t, v, p, m)

    inv_s = 1.0 / s
    a2 = a * a
    h = (a - rho) * (a + rho) + z2  # a^2 + z^2 - u, without cancellation near the wire
    # w = 4 a^2 u / s^2 and its derivatives in u and z
    w_u = 4.0 * a2 * h * inv_s**3
    w_z = -16.0 * a2 * u * z * inv_s**3
    w_uz = 8.0 * a2 * z * (4.0 * u - 2.0 * (a2 + z2)) * inv_s**4
    w_zz = -16.0 * a2 * u * (s - 6.0 * z2) * inv_s**4
    # S = s^(-5/2) and its derivatives
    S = inv_s * inv_s * np.sqrt(inv_s)
    S7 = S * inv_s
    S9 = S7 * inv_s
    S_u = -2.5 * S7
    S_z = -5.0 * z * S7
    S_zz = -5.0 * S7 + 35.0 * z2 * S9
    S_uz = 17.5 * z * S9
    # Q = A z P with P = S phi(w)
    P = S * f0
    P_u = S_u * f0 + S * f1 * w_u
    P_z = S_z * f0 + S * f1 * w_z
    P_zz = S_zz * f0 + 2.0 * S_z * f1 * w_z + S * (f2 * w_z * w_z + f1 * w_zz)
    P_uz = S_uz * f0 + S_u * f1 * w_z + S_z * f1 * w_u + S * (f2 * w_u * w_z + f1 * w_uz)
    b1 = A * (P + z * P_z)
    c1 = A * (2.0 * P_z + z * P_zz)
    q1 = 2.0 * A * z * P_u
    d1 = 2.0 * A * (P_u + z * P_uz)
    return b1, c1, q1, d1, alpha2


def loop_hessian_local(
    p: np.ndarray,
    filaments: np.ndarray,
    nearest: np.ndarray | None = None,
    unique_only: bool = False,
) -> np.ndarray:
    """Hessian of B of coaxial filaments, in their common local frame (axis = local z).

    Parameters
    ----------
    p : ndarray, shape (n, 3)
        Points in the local frame, metres.
    filaments : ndarray, shape (f, 3)
        Rows ``(z_offset, radius, current)`` as in :func:`loop_B_and_gradient_local`.
    nearest : ndarray, shape (n,), optional
        If given, filled with ``min over filaments of (distance to the wire / radius)^2``.
    unique_only : bool
        If True, return only the 10 distinct entries, shape (n, 10), in the order of the rows
        of ``SYMMETRIC_EXPANSION`` (``H.reshape(n, 27) = unique @ SYMMETRIC_EXPANSION``).

    Returns
    -------
    H : ndarray, shape (n, 3, 3, 3)
        ``H[k, i, j, l] = d2B_i/(dx_j dx_l)`` in T/m^2, scaled for mu0 = 4e-7 pi.

    Notes
    -----
    With ``B = (Q x, Q y, B_z)`` and greek indices over (x, y):
    ``H_abc = q1 (x_a d_bc + x_b d_ac + x_c d_ab) + q2 x_a x_b x_c`` with
    ``rho^2 q2 = -4 q1 - c1`` (Laplace), ``H_zab = b1 d_ab + d1 x_a x_b``, ``H_zza = c1 x_a``
    and ``H_zzz = -2 b1 - rho^2 d1`` (div B = 0); the other entries follow by symmetry.
    The filaments are evaluated together: temporaries hold ``n * f`` values (callers chunk).
    """
    x, y = p[:, 0], p[:, 1]
    u = x * x + y * y
    rho = np.sqrt(u)
    # all filaments at once: arrays (n, f), summed over the filaments
    z0, a, cur = filaments[:, 0], filaments[:, 1], filaments[:, 2]
    b1, c1, q1, d1, alpha2 = loop_hessian_cyl(rho[:, None], p[:, 2:3] - z0, a, cur)
    if nearest is not None:
        np.min(alpha2 / (a * a), axis=1, out=nearest)
    b1, c1, q1, d1 = (v.sum(axis=1) for v in (b1, c1, q1, d1))
    # q2 x_a x_b x_c = (rho^2 q2) x_a x_b x_c / rho^2, which is O(rho): zero on the axis
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(u > 0, (-4.0 * q1 - c1) / u, 0.0)
    rx, ry = r * x, r * y
    unique = np.stack(
        [
            3.0 * q1 * x + rx * x * x,  # xxx
            q1 * y + rx * x * y,  # xxy
            q1 * x + ry * x * y,  # xyy
            3.0 * q1 * y + ry * y * y,  # yyy
            b1 + d1 * x * x,  # xxz
            d1 * x * y,  # xyz
            b1 + d1 * y * y,  # yyz
            c1 * x,  # xzz
            c1 * y,  # yzz
            -2.0 * b1 - u * d1,  # zzz
        ],
        axis=1,
    )
    if not unique_only:
        return (unique @ SYMMETRIC_EXPANSION).reshape(-1, 3, 3, 3)
    return unique


def _symmetric_expansion() -> np.ndarray:
    """0/1 matrix (10, 27) mapping the 10 distinct entries of a fully symmetric 3x3x3 tensor
    (sorted index triples xxx, xxy, xyy, yyy, xxz, xyz, yyz, xzz, yzz, zzz) to all 27."""
    order = [(0, 0, 0), (0, 0, 1), (0, 1, 1), (1, 1, 1), (0, 0, 2)]
    order += [(0, 1, 2), (1, 1, 2), (0, 2, 2), (1, 2, 2), (2, 2, 2)]
    out = np.zeros((10, 27))
    for flat in range(27):
        idx = tuple(sorted((flat // 9, flat // 3 % 3, flat % 3)))
        out[order.index(idx), flat] = 1.0
    return out


#: (10, 27) map from the distinct entries of a symmetric 3x3x3 tensor to all of them.
SYMMETRIC_EXPANSION = _symmetric_expansion()


# ---- evaluation as in coils/coaxial.py at 9501399 ----------------------------------------------
from scipy.constants import mu_0

from coils._validate import as_points

_MU0_SCALE = mu_0 / (4e-7 * np.pi)
_CHUNK = 65536
_ON_WIRE_TOL = 1e-9


def _local_kernel(field, pts, kernel, *args):
    local = (pts - field.center) @ field.rotation
    nearest = np.empty(local.shape[0])
    with np.errstate(divide="ignore", invalid="ignore"):
        out = kernel(local, field.filaments, *args, nearest)
    bad = ~(nearest >= _ON_WIRE_TOL**2)
    if np.any(bad):
        raise ValueError(f"point {int(np.argmax(bad))} lies on a coil winding")
    return out


def B_and_gradient(field, points):
    """``field.B_and_gradient(points)`` as the numpy kernel computed it."""
    pts = as_points(points)
    n = pts.shape[0]
    B = np.empty((n, 3))
    G = np.empty((n, 3, 3))
    R = field.rotation
    RR = np.kron(R, R)
    for start in range(0, n, _CHUNK):
        sl = slice(start, min(start + _CHUNK, n))
        b, g = _local_kernel(field, pts[sl], loop_B_and_gradient_local, True)
        B[sl] = (_MU0_SCALE * b) @ R.T
        G[sl] = (g.reshape(-1, 9) @ (_MU0_SCALE * RR.T)).reshape(-1, 3, 3)
    return B, G


def _hessian_unique(local, filaments, nearest):
    return loop_hessian_local(local, filaments, nearest, unique_only=True)


def hessian(field, points):
    """``field.hessian(points)`` as the numpy kernel computed it."""
    pts = as_points(points)
    n = pts.shape[0]
    H = np.empty((n, 3, 3, 3))
    R = field.rotation
    RRR = _MU0_SCALE * np.einsum("ai,bj,cl->ijlabc", R, R, R).reshape(27, 27)
    to_global = SYMMETRIC_EXPANSION @ RRR
    step = max(1, _CHUNK // len(field.filaments))
    for start in range(0, n, step):
        sl = slice(start, min(start + step, n))
        h = _local_kernel(field, pts[sl], _hessian_unique)
        H[sl] = (h @ to_global).reshape(-1, 3, 3, 3)
    return H
