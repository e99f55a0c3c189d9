"""Field of one circular current loop near its wire: closed form, compiled (tier 1).

A filament of radius ``a`` in the plane ``z = 0``, centred on the origin, carries current ``I``
counter-clockwise about +z.  Everything is a function of ``u = rho^2`` and ``z`` through

    s = a^2 + u + z^2,    t = 2 a rho / s  (0 <= t <= 1, 1 on the wire),    w = t^2,

and the field follows from six *invariants*, each regular on the axis and summed over coaxial
filaments, from which :mod:`coils._compiled` assembles B, its gradient and its hessian:

    Q  = B_rho / rho,   Bz                       (B)
    b1 = dQ/dz,         q1 = (dQ/drho) / rho     (gradient, with Q)
    c1 = d2Q/dz2,       d1 = dq1/dz              (hessian, with b1 and q1)

(the hessian's last radial derivative ``(dq1/drho)/rho = -(4 q1 + c1)/rho^2`` follows from
Laplace's equation, which keeps the computed hessian traceless to rounding).

Field of the loop
-----------------
Expanding ``1 / |x - x'|`` in the Biot-Savart vector potential in powers of ``t cos(phi')``
gives ``A_phi = rho psi`` with

    psi(u, z) = (mu0 I a^2 / 4) s^(-3/2) F(w),    F = 2F1(3/4, 5/4; 2; w),

so that ``Q = -d psi/dz`` and ``Bz = 2 d(u psi)/du``:

    Q  = mu0 I a^2 z s^(-5/2) phi(w),                  phi = (3 F + 4 w F') / 4,
    Bz = (mu0 I a^2 / 2) s^(-3/2) [(1 - 3u/(2s)) F + w (h/s) F'],   h = a^2 + z^2 - u.

``b1, q1, c1, d1`` are derivatives of ``Q`` in ``(u, z)`` (``q1 = 2 dQ/du``), written out in
:func:`loop_point` with ``P = s^(-5/2) phi(w)`` and the chain rule through
``w(u, z) = 4 a^2 u / s^2``.  Nothing in these expressions cancels except at genuine zeros of
the result, and far from the loop (``w -> 0``) they keep full relative precision, unlike
Simpson's brackets ``(a^2 - r^2) E + alpha^2 K``, which lose ``(r/a)^2`` relative (``Bz = 0``
at 10^8 a in the former kernel).

Two evaluations of ``F`` and its first three derivatives (``phi' = (7 F' + 4 w F'')/4``,
``phi'' = (11 F'' + 4 w F''')/4``), switched at ``w = W_SERIES = 3/4`` (``t = 0.866``):

* ``w < 3/4`` (near the axis, and everywhere beyond ``r = sqrt(3) a``): power series.
  Below ``W_TAYLOR = 2^-8`` the series about ``w = 0`` (all coefficients positive), with the
  number of terms read from the binary exponent of ``w`` (``SERIES_TERMS``: 9 terms below
  ``2^-8``, 4 below ``2^-20``); above, the Taylor series about the centre of the interval that
  holds ``w`` (1/64 wide in ``[1/2, 3/4)``, eighths of ``[1/4, 1/2)``, quarters of the binades
  below), chosen from the exponent and the leading mantissa bits of ``w``: at most 15 terms.
  Every table is cut where its tail, bounded over its interval, is below ``2^-60`` of the
  smallest value of the series (coefficients ``F^(j)(w0)/j! = (a)_j (b)_j/((c)_j j!)
  2F1(a+j, b+j; c+j; w0)``, sums of positive terms).
* ``w >= 3/4`` (a torus around the wire, ``m >= 0.93``): closed forms in ``K = K(m)``,
  ``E = E(m)`` with ``m = 2t/(1 + t)`` and ``1 - m = (1 - t)/(1 + t)``, where
  ``1 - t = alpha^2 / s`` comes from ``alpha^2 = (rho - a)^2 + z^2`` without cancellation
  (the squared distance to the wire)::

      phi   = 2 (E/v - K) / (pi t^2 p^(1/2))                                    (v = 1 - t,
      phi'  = ((2 - 5 t^2/2) K + 2 (2 t^2 - 1) E/v) / (pi v t^4 p^(3/2))          p = 1 + t)
      phi'' = ((93 t^4 - 93 t^2 + 32) E/v - (45 t^4 - 69 t^2 + 32) K) / (8 pi v^2 t^6 p^(5/2))
      Bz    = (mu0 I / 2 pi) [((a - rho)(a + rho) - z^2) E + alpha^2 K] / (alpha^2 beta)

  (the last is Simpson, Lane, Immer, Youngquist, NASA 2001; ``beta^2 = s + 2 a rho``).
  ``K`` and ``E`` are scipy's own C functions (``scipy.special.cython_special.ellipkm1`` and
  ``ellipe``, Cephes, 2e-16 relative), linked into the compiled code by symbol name (so that
  numba can cache it): the values agree with ``scipy.special`` to the last bit, and ``K`` is
  evaluated from ``1 - m`` directly.

Far from a coaxial *group* of filaments the group's multipole series takes over
(:mod:`coils.multipole`); this module serves the near zone.  The functions are compiled with
numba on first use (``cache=True``); :mod:`coils.coaxial` imports this module only when a coil
is evaluated.
"""

from __future__ import annotations

import math

import llvmlite.binding as _llvm
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import get_cython_function_address, intrinsic

from ._immutable import kernel_input

__all__ = ["W_SERIES", "W_TAYLOR", "SERIES_TERMS", "loop_point", "loop_invariants"]

# -- K(m) and E(m): scipy's C implementations, linked by symbol name (cacheable) ----------------
for _name in ("ellipkm1", "ellipe"):
    _llvm.add_symbol(
        "coils_" + _name, get_cython_function_address("scipy.special.cython_special", _name)
    )
#: K(m) from ``1 - m`` (scipy.special.ellipkm1).
ellipkm1 = types.ExternalFunction("coils_ellipkm1", types.float64(types.float64))
#: E(m) (scipy.special.ellipe).
ellipe = types.ExternalFunction("coils_ellipe", types.float64(types.float64))


@intrinsic
def _float_bits(typingctx, x):
    """The IEEE-754 bits of a float64 as an int64 (inlined bit cast)."""
    sig = types.int64(types.float64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return sig, codegen


#: Power series below this w = t^2 = (2 a rho / s)^2, closed forms in K, E above.
W_SERIES = 0.75
#: Relative truncation error of the series.
_SERIES_TOL = 2.0**-60
#: Below this w the series about w = 0 is used; above, expansions about sub-interval centres.
W_TAYLOR = 2.0**-8
# F = 2F1(a, b; c; w)
_A, _B, _C = 0.75, 1.25, 2.0
_N_DERIV = 48


def _taylor(w0: float, n: int = _N_DERIV, m: int = 600) -> np.ndarray:
    """``F^(j)(w0) / j!`` for j < n: ``(a)_j (b)_j / ((c)_j j!) 2F1(a + j, b + j; c + j; w0)``,
    each a sum of ``m`` positive terms (enough for w0 < 3/4 and j < 48)."""
    j = np.arange(n)[:, None]
    k = np.arange(m - 1)[None, :]
    ratio = (_A + j + k) * (_B + j + k) / ((_C + j + k) * (k + 1.0)) * w0
    hyp = 1.0 + np.cumprod(ratio, axis=1).sum(axis=1)
    jj = np.arange(n - 1)
    pre = np.concatenate([[1.0], np.cumprod((_A + jj) * (_B + jj) / ((_C + jj) * (jj + 1.0)))])
    return pre * hyp


def _chains(d: np.ndarray) -> np.ndarray:
    """Coefficients, shape (n - 3, 4), of F and its first three derivatives in powers of
    ``w - w0``, from the Taylor coefficients ``d_j`` of F about ``w0``."""
    j = np.arange(len(d) - 3, dtype=float)
    return np.column_stack(
        [
            d[:-3],
            (j + 1) * d[1:-2],
            (j + 1) * (j + 2) * d[2:-1],
            (j + 1) * (j + 2) * (j + 3) * d[3:],
        ]
    )


def _terms_needed(coef: np.ndarray, radius: float) -> int:
    """Smallest N whose tail ``sum_{j >= N} |c_j| radius^j`` is below ``_SERIES_TOL`` times the
    smallest value of every chain (its value at w = 0: the chains increase with w)."""
    floor = _chains(_taylor(0.0))[0]
    tail = np.cumsum((np.abs(coef) * radius ** np.arange(len(coef))[:, None])[::-1], axis=0)[::-1]
    return max(1, int(np.argmax(np.all(tail < _SERIES_TOL * floor, axis=1))))


def _series_intervals():
    """(low end, half width) of the intervals of w with a table of their own, in table order:
    sixteen 1/64-wide intervals covering ``[1/2, 3/4)``, the eighths of ``[1/4, 1/2)``, the
    quarters of ``[2^-(k+1), 2^-k)`` for k = 2 .. 7; the series about 0 follows them."""
    out = [(0.5 + i / 64.0, 1.0 / 128.0) for i in range(16)]
    out += [(0.25 * (1.0 + i / 8.0), 0.25 / 16.0) for i in range(8)]
    for k in range(2, 8):
        out += [(2.0 ** (-k - 1) * (1.0 + i / 4.0), 2.0 ** (-k - 4)) for i in range(4)]
    return out


def _series_tables():
    """Coefficient tables of the series of F, F', F'', F''' (shape (49, n, 4)), their centres
    w0 (49,) and lengths (49,), in the order of :func:`_series_intervals`; index 48 holds the
    series about 0 (``w < W_TAYLOR``, length from ``SERIES_TERMS``)."""
    centres, tables, lengths = [], [], []
    for low, half in _series_intervals():
        coef = _chains(_taylor(low + half))
        centres.append(low + half)
        tables.append(coef)
        lengths.append(_terms_needed(coef, half))
    centres.append(0.0)
    tables.append(_chains(_taylor(0.0)))
    lengths.append(0)
    n = max(max(lengths), _series_terms()[8])
    return (
        np.ascontiguousarray(np.stack([t[:n] for t in tables])),
        np.array(centres),
        np.array(lengths, dtype=np.int64),
    )


def _series_terms(max_exponent: int = 64) -> np.ndarray:
    """Terms of the series about 0 needed for ``w < 2^-k``, k = 0 .. max_exponent."""
    coef = _chains(_taylor(0.0))
    return np.array([_terms_needed(coef, 2.0**-k) for k in range(max_exponent + 1)], dtype=np.int64)


#: SERIES_TERMS[k]: terms of the series about w = 0 used when w < 2^-k (k capped at 64).
SERIES_TERMS = _series_terms()
SERIES, SERIES_CENTRES, SERIES_LENGTHS = _series_tables()

_INV_PI = 1.0 / math.pi


@njit(cache=True, inline="always")
def _series_table(w):
    """Row ``idx`` of ``SERIES`` for ``0 <= w < W_SERIES`` and its term count ``n``: chosen by
    the binary exponent E and the leading mantissa bits of w (w in [2^(E-1023), 2^(E-1022));
    E = 0 for w = 0)."""
    bits = _float_bits(w)
    E = bits >> 52
    if E == 1022:
        idx = (bits >> 47) & 31
        return idx, SERIES_LENGTHS[idx]
    if E == 1021:
        idx = 16 + ((bits >> 49) & 7)
        return idx, SERIES_LENGTHS[idx]
    if w >= W_TAYLOR:
        idx = 24 + 4 * (1020 - E) + ((bits >> 50) & 3)
        return idx, SERIES_LENGTHS[idx]
    return 48, SERIES_TERMS[min(1022 - E, 64)]


@njit(cache=True, error_model="numpy")
def loop_point(a, A, C2, u, rho, z, want_B, want_G, want_H):
    """Invariants of one filament at one point (scalar; compiled, no checks).

    Parameters
    ----------
    a : float
        Loop radius (any length unit L).
    A, C2 : float
        ``mu0 I a^2`` and ``mu0 I / (2 pi)`` (T L^3 and T L; I in A, counter-clockwise about +z).
    u, rho, z : float
        ``rho^2``, ``rho`` and ``z`` of the point in the loop frame (L^2, L, L).
    want_B, want_G, want_H : bool
        Which of B, gradient, hessian the caller needs (unneeded invariants are returned as 0).

    Returns
    -------
    Q, Bz, b1, q1, c1, d1 : float
        The invariants of the module docstring, in T/L, T, T/L^2, T/L^3, T/L^3, T/L^4.
    alpha2 : float
        Squared distance to the wire, L^2.
    """
    z2 = z * z
    a2 = a * a
    s = a2 + u + z2
    inv_s = 1.0 / s
    alpha2 = (rho - a) * (rho - a) + z2
    t = min(2.0 * a * rho * inv_s, 1.0)
    w = t * t
    h = (a - rho) * (a + rho) + z2  # a^2 + z^2 - u without cancellation near the wire
    Bz = 0.0
    if w < W_SERIES:
        # F, F', F'', F''' from a table chosen by the binary exponent E and the leading
        # mantissa bits of w (w in [2^(E-1023), 2^(E-1022)); E = 0 for w = 0)
        idx, n = _series_table(w)
        delta = w - SERIES_CENTRES[idx]
        F0 = 0.0
        F1 = 0.0
        F2 = 0.0
        F3 = 0.0
        if want_H:
            for j in range(n - 1, -1, -1):
                F0 = F0 * delta + SERIES[idx, j, 0]
                F1 = F1 * delta + SERIES[idx, j, 1]
                F2 = F2 * delta + SERIES[idx, j, 2]
                F3 = F3 * delta + SERIES[idx, j, 3]
        else:
            for j in range(n - 1, -1, -1):
                F0 = F0 * delta + SERIES[idx, j, 0]
                F1 = F1 * delta + SERIES[idx, j, 1]
                F2 = F2 * delta + SERIES[idx, j, 2]
        f0 = 0.75 * F0 + w * F1  # phi = (3 F + 4 w F') / 4 and its first two derivatives
        f1 = 1.75 * F1 + w * F2
        f2 = 2.75 * F2 + w * F3
        if want_B:
            Bz = (
                0.5
                * A
                * inv_s
                * math.sqrt(inv_s)
                * ((1.0 - 1.5 * u * inv_s) * F0 + w * h * inv_s * F1)
            )
    else:
        v = alpha2 * inv_s  # 1 - t without cancellation near the wire
        p = 1.0 + t
        K = ellipkm1(v / p)
        E = ellipe(2.0 * t / p)
        Ev = E / v
        sp = math.sqrt(p)
        f0 = 2.0 * _INV_PI * (Ev - K) / (w * sp)
        f1 = ((2.0 - 2.5 * w) * K + 2.0 * (2.0 * w - 1.0) * Ev) * _INV_PI / (v * w * w * p * sp)
        f2 = 0.0
        if want_H:
            f2 = ((93.0 * w * (w - 1.0) + 32.0) * Ev - (45.0 * w * w - 69.0 * w + 32.0) * K) / (
                8.0 * math.pi * v * v * w * w * w * p * p * sp
            )
        if want_B:
            Bz = (
                C2
                * (((a - rho) * (a + rho) - z2) * E + alpha2 * K)
                / (alpha2 * math.sqrt(s + 2.0 * a * rho))
            )
    # P = S phi(w) with S = s^(-5/2); w_u = dw/du etc.
    inv_s3 = inv_s * inv_s * inv_s
    S = inv_s * inv_s * math.sqrt(inv_s)
    S7 = S * inv_s
    P = S * f0
    Q = A * z * P
    if not (want_G or want_H):
        return Q, Bz, 0.0, 0.0, 0.0, 0.0, alpha2
    w_u = 4.0 * a2 * h * inv_s3
    w_z = -16.0 * a2 * u * z * inv_s3
    S_u = -2.5 * S7
    S_z = -5.0 * z * S7
    P_u = S_u * f0 + S * f1 * w_u
    P_z = S_z * f0 + S * f1 * w_z
    b1 = A * (P + z * P_z)
    q1 = 2.0 * A * z * P_u
    c1 = 0.0
    d1 = 0.0
    if want_H:
        S9 = S7 * inv_s
        inv_s4 = inv_s3 * inv_s
        w_uz = 16.0 * a2 * z * (2.0 * u - a2 - z2) * inv_s4
        w_zz = -16.0 * a2 * u * (s - 6.0 * z2) * inv_s4
        S_zz = -5.0 * S7 + 35.0 * z2 * S9
        S_uz = 17.5 * z * S9
        P_zz = S_zz * f0 + 2.0 * S_z * f1 * w_z + S * (f2 * w_z * w_z + f1 * w_zz)
        P_uz = S_uz * f0 + S_u * f1 * w_z + S_z * f1 * w_u + S * (f2 * w_u * w_z + f1 * w_uz)
        c1 = A * (2.0 * P_z + z * P_zz)
        d1 = 2.0 * A * (P_u + z * P_uz)
    return Q, Bz, b1, q1, c1, d1, alpha2


@njit(cache=True, error_model="numpy")
def _invariants(rho, z, a, current, mu0, out):
    A = mu0 * current * a * a
    C2 = mu0 * current / (2.0 * math.pi)
    # True, but a run-time bool as the coil pass passes: literal True would compile
    # loop_point a second time (for Literal[bool] arguments)
    on = out.shape[1] > 0
    for k in range(rho.shape[0]):
        r = rho[k]
        res = loop_point(a, A, C2, r * r, r, z[k], on, on, on)
        for j in range(7):
            out[k, j] = res[j]


def loop_invariants(rho, z, a: float, current: float = 1.0, mu0: float = 4e-7 * math.pi):
    """The invariants of one loop at many points (for tests and inspection).

    Parameters
    ----------
    rho, z : array-like, shape (n,)
        Cylindrical coordinates in the loop frame, m (rho >= 0, points off the wire).
    a : float
        Loop radius, m.
    current : float
        Current, A (counter-clockwise about +z).
    mu0 : float
        Vacuum permeability used, T m / A.

    Returns
    -------
    ndarray, shape (n, 7)
        Columns ``Q`` (T/m), ``Bz`` (T), ``b1`` (T/m^2), ``q1``, ``c1`` (T/m^3), ``d1`` (T/m^4)
        and ``alpha2`` (squared distance to the wire, m^2).
    """
    # read-only inputs: one compiled version whatever the arrays' flags (z may be broadcast)
    rho = kernel_input(rho)
    z = kernel_input(np.broadcast_to(z, rho.shape))
    out = np.empty((rho.shape[0], 7))
    _invariants(rho, z, float(a), float(current), float(mu0), out)
    return out
