"""Compiled per-node algebra of the planar rod's mixed layout (numba, cached on disk).

One pass over the members of a stack and the nodes of the mesh computes the residual, its
derivative with respect to the load scale and the banded Jacobian, written straight into
LAPACK's band storage of the stacked (block-diagonal) matrix: entry ``(r, c)`` of member ``j``
at ``ab[KL + KU + r - c, j size + c]`` (KL = KU = 5), ready for ``gbtrf``.  The equations
are those of :mod:`coilrod.rod.planar`; in the notation there, for
node ``i`` with ``t = (cos, sin)(theta_i)``, ``t_perp = (-sin, cos)``, ``m = R(theta_i) mu_i``,
``m_perp = dm/dtheta``, ``c_i = h_{i-1} / 2``:

* residual ``g_i = bend_i - c w_i tau_i - t_perp . (w_i F_i + c c_i w_i f_i)`` (row 0: the
  clamp), positions ``x_i - x_{i-1} - h_{i-1} (t_{i-1} + t_i) / 2`` (row 0: ``x_0``), forces
  ``F_i - F_{i+1} - c w_{i+1} f_{i+1}`` (last: ``F_N``), ``tau = m_perp . b``,
  ``f_l = G_al m_a``;
* Jacobian ``dg_i/dtheta_i = 1/h_{i-1} + 1/h_i + c w_i m.b + t.(w_i F_i + c c_i w_i f_i)
  - c c_i w_i t_perp . (G^T m_perp)``, ``dg_i/dx_i = -c (w_i G^T m_perp + c_i w_i t_perp . df/dx)``
  with ``df_l/dx_q = H_alq m_a``, ``dg_i/dF_i = -w_i t_perp``, the position rows'
  ``-h_{i-1}/2 t_perp`` and the force rows' ``-c w_{i+1} (G^T m_perp, df/dx)``.

Imported on the first evaluation of a rod in a non-uniform field; a uniform field never
compiles it.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

# the ski rental of each compiled kernel (its look at numba's cache: once per process), as coils'
from coils._numba_cache import Rental

__all__ = ["mixed_assembly", "KL", "KU"]

#: Sub- and super-diagonals of the mixed Jacobian.  Unknowns per node (x, y, theta, Fx, Fy)
#: at 5i .. 5i + 4, equations (position x, position y, moment, force x, force y) in the same
#: rows: the order that gives the narrowest band.
KL, KU = 5, 5
_D = KL + KU  # row of the diagonal in band storage


# rows of the per-node terms (_node_terms): cos and sin of theta, m = R(theta) mu, tau = m_perp . b,
# m . b, f = G^T m and g = G^T m_perp (times L), df/dx = H m (times L^2)
_CS, _SN, _M0, _M1, _TAU, _MB, _F0, _F1, _G0, _G1, _D00, _D01, _D10, _D11 = range(14)


@nb.njit(cache=True)
def _node_terms(U, B, G, H, has_h, L, mu, j, T):
    """Fill T (14, n) with the per-node terms of member j (rows ``_CS`` ..); False if one of
    them or of the unknowns is not finite (the band entries are products of these)."""
    n = T.shape[1]
    L2 = L * L
    ok = True
    for i in range(n):
        p = j * n + i
        th = U[j, 5 * i + 2]
        c = math.cos(th)
        si = math.sin(th)
        a0 = c * mu[i, 0] - si * mu[i, 1]
        a1 = si * mu[i, 0] + c * mu[i, 1]
        p0 = -a1  # m_perp
        p1 = a0
        T[_CS, i] = c
        T[_SN, i] = si
        T[_M0, i] = a0
        T[_M1, i] = a1
        T[_TAU, i] = p0 * B[p, 0] + p1 * B[p, 1]
        T[_MB, i] = a0 * B[p, 0] + a1 * B[p, 1]
        T[_F0, i] = L * (G[p, 0, 0] * a0 + G[p, 1, 0] * a1)
        T[_F1, i] = L * (G[p, 0, 1] * a0 + G[p, 1, 1] * a1)
        T[_G0, i] = L * (G[p, 0, 0] * p0 + G[p, 1, 0] * p1)
        T[_G1, i] = L * (G[p, 0, 1] * p0 + G[p, 1, 1] * p1)
        for q in range(4):  # d00, d01, d10, d11: H[., a, b] m with (a, b) = divmod(q, 2)
            a = q // 2
            b = q % 2
            T[_D00 + q, i] = L2 * (H[p, 0, a, b] * a0 + H[p, 1, a, b] * a1) if has_h else 0.0
        total = 0.0
        for r in range(_TAU, _D11 + 1):
            total += T[r, i]
        for r in (0, 1, 3, 4):
            total += U[j, 5 * i + r]
        if not math.isfinite(total):
            ok = False
    return ok


@nb.njit(cache=True)
def _residual(U, s, j, T, h, w, theta0, R, R1):
    """Rows of R and R1 of member j (equations of the module docstring); False if one is
    not finite."""
    n = T.shape[1]
    nm = n - 1
    for i in range(n):
        r = 5 * i  # x_i, y_i at r, r + 1; theta_i at r + 2; F_i at r + 3, r + 4
        th = U[j, r + 2]
        Fx = U[j, r + 3]
        Fy = U[j, r + 4]
        # position equations (rows r, r + 1)
        if i == 0:
            R[j, r] = U[j, r]
            R[j, r + 1] = U[j, r + 1]
        else:
            hh = 0.5 * h[i - 1]
            R[j, r] = U[j, r] - U[j, r - 5] - hh * (T[_CS, i - 1] + T[_CS, i])
            R[j, r + 1] = U[j, r + 1] - U[j, r - 4] - hh * (T[_SN, i - 1] + T[_SN, i])
        R1[j, r] = 0.0
        R1[j, r + 1] = 0.0
        # moment equation (row r + 2)
        if i == 0:
            R[j, r + 2] = th - theta0
            R1[j, r + 2] = 0.0
        else:
            bend = (th - U[j, r - 3]) / h[i - 1]
            if i < nm:
                bend -= (U[j, r + 7] - th) / h[i]
            cw = 0.5 * h[i - 1] * w[i]
            tp0 = -T[_SN, i]
            tp1 = T[_CS, i]
            r1 = -w[i] * T[_TAU, i] - (tp0 * cw * T[_F0, i] + tp1 * cw * T[_F1, i])
            R1[j, r + 2] = r1
            R[j, r + 2] = bend + s * r1 - (tp0 * w[i] * Fx + tp1 * w[i] * Fy)
        # force equations (rows r + 3, r + 4)
        if i == nm:
            R[j, r + 3] = Fx
            R[j, r + 4] = Fy
            R1[j, r + 3] = 0.0
            R1[j, r + 4] = 0.0
        else:
            r1x = -w[i + 1] * T[_F0, i + 1]
            r1y = -w[i + 1] * T[_F1, i + 1]
            R1[j, r + 3] = r1x
            R1[j, r + 4] = r1y
            R[j, r + 3] = Fx - U[j, r + 8] + s * r1x
            R[j, r + 4] = Fy - U[j, r + 9] + s * r1y
    ok = True
    for q in range(5 * n):
        if not math.isfinite(R[j, q]):
            ok = False
    return ok


@nb.njit(cache=True)
def _tangent(U, s, j, T, h, w, ab):
    """Band storage of member j's Jacobian (module docstring): entry (r, c) at
    ``ab[_D + r - c, 5 n j + c]``."""
    n = T.shape[1]
    nm = n - 1
    off = j * 5 * n - _D  # ab[r - c + _D, off + _D + c]: row index r - c + _D
    # clamp rows: x_0, theta_0, and the free end's force F_N
    for q in (0, 1, 2, 5 * nm + 3, 5 * nm + 4):
        ab[_D, off + _D + q] = 1.0
    for i in range(1, n):
        r = 5 * i
        g = r + 2  # moment row and theta_i column
        cw = 0.5 * h[i - 1] * w[i]
        tp0 = -T[_SN, i]
        tp1 = T[_CS, i]
        Fx = U[j, r + 3]
        Fy = U[j, r + 4]
        # moment row g_i: columns g - 5, g, g + 5, r, r + 1, r + 3, r + 4
        c0 = off + _D
        bend = 1.0 / h[i - 1]
        ab[_D + 5, c0 + g - 5] = -1.0 / h[i - 1]
        if i < nm:
            bend += 1.0 / h[i]
            ab[_D - 5, c0 + g + 5] = -1.0 / h[i]
        ab[_D, c0 + g] = (
            bend
            + s * w[i] * T[_MB, i]
            + T[_CS, i] * (w[i] * Fx + s * cw * T[_F0, i])
            + T[_SN, i] * (w[i] * Fy + s * cw * T[_F1, i])
            - s * cw * (tp0 * T[_G0, i] + tp1 * T[_G1, i])
        )
        ab[_D + 2, c0 + r] = -s * (w[i] * T[_G0, i] + cw * (tp0 * T[_D00, i] + tp1 * T[_D10, i]))
        ab[_D + 1, c0 + r + 1] = -s * (
            w[i] * T[_G1, i] + cw * (tp0 * T[_D01, i] + tp1 * T[_D11, i])
        )
        ab[_D - 1, c0 + r + 3] = -w[i] * tp0
        ab[_D - 2, c0 + r + 4] = -w[i] * tp1
        # position rows r, r + 1 of node i
        hh = 0.5 * h[i - 1]
        ab[_D, c0 + r] = 1.0
        ab[_D, c0 + r + 1] = 1.0
        ab[_D + 5, c0 + r - 5] = -1.0
        ab[_D + 5, c0 + r - 4] = -1.0
        ab[_D + 3, c0 + g - 5] = hh * T[_SN, i - 1]  # theta_{i-1}
        ab[_D + 4, c0 + g - 5] = -hh * T[_CS, i - 1]
        ab[_D - 2, c0 + g] = hh * T[_SN, i]
        ab[_D - 1, c0 + g] = -hh * T[_CS, i]
        # force rows rf, rf + 1 of node i - 1 act on node i
        rf = r - 2  # 5 (i - 1) + 3
        sw = s * w[i]
        ab[_D, c0 + rf] = 1.0
        ab[_D, c0 + rf + 1] = 1.0
        ab[_D - 5, c0 + rf + 5] = -1.0
        ab[_D - 5, c0 + rf + 6] = -1.0
        ab[_D - 4, c0 + g] = -sw * T[_G0, i]
        ab[_D - 3, c0 + g] = -sw * T[_G1, i]
        ab[_D - 2, c0 + r] = -sw * T[_D00, i]
        ab[_D - 3, c0 + r + 1] = -sw * T[_D01, i]
        ab[_D - 1, c0 + r] = -sw * T[_D10, i]
        ab[_D - 2, c0 + r + 1] = -sw * T[_D11, i]


#: Estimated CPU seconds of numpy assemblies after which the compiled kernel is used (ski
#: rental: about what compiling it costs on a cold cache, README "Cold start"); 0 compiles at
#: the first call, ``math.inf`` never.
COMPILE_AFTER = 2.0
# measured cost of one numpy assembly (with the Jacobian): per call and per node x member
_NUMPY_CALL_S, _NUMPY_NODE_S = 5e-4, 1e-6
#: The ski rental of :func:`_mixed_compiled` (:class:`coils._numba_cache.Rental`).
_rental = Rental(__name__, lambda: _mixed_compiled)


def mixed_assembly(U, S, B, G, H, has_h, L, mu, h, w, theta0, tangent, R, R1, ab, finite):
    """Fill R, R1 (k, 5n), the band storage ab (2 KL + KU + 1, 5 n k; zero on entry) and
    finite (k,) for the stack U (k, 5n).

    B (k n, 3) T, G (k n, 3, 3) T/m and H (k n, 3, 3, 3) T/m^2 (read only if ``has_h``) are
    the field at scale 1 at the nodes (member-major); only in-plane components act, lengths
    are scaled by L (m).  mu (n, 2), h (n - 1,), w (n,) describe the mesh.

    The vectorised numpy version (:mod:`coilrod.rod._mixed_numpy`, the same arithmetic) runs
    until its estimated cost reaches :data:`COMPILE_AFTER` or numba's cache holds the
    compiled kernel; the compiled one from then on.
    """
    # the field inputs C-contiguous (a copy only of a strided view, e.g. the magnet pose's
    # Hessian): one compiled version of the kernel, not one per layout
    B, G, H = np.ascontiguousarray(B), np.ascontiguousarray(G), np.ascontiguousarray(H)
    args = (U, S, B, G, H, has_h, L, mu, h, w, theta0, tangent, R, R1, ab, finite)
    if not _rental.ready:
        cost = _NUMPY_CALL_S + _NUMPY_NODE_S * U.shape[0] * w.shape[0]
        if not _rental.pays(cost):
            from ._mixed_numpy import mixed_assembly_numpy

            _rental.charge(cost)
            return mixed_assembly_numpy(*args)
    return _mixed_compiled(*args)


@nb.njit(cache=True)
def _mixed_compiled(U, S, B, G, H, has_h, L, mu, h, w, theta0, tangent, R, R1, ab, finite):
    """The compiled :func:`mixed_assembly`."""
    T = np.empty((14, w.shape[0]))
    for j in range(U.shape[0]):
        ok = _node_terms(U, B, G, H, has_h, L, mu, j, T)
        ok = _residual(U, S[j], j, T, h, w, theta0, R, R1) and ok
        if tangent:
            _tangent(U, S[j], j, T, h, w, ab)
        finite[j] = ok


@nb.njit(cache=True)
def mixed_error(R, U, inv_w, inv_h, bend_scale, tol, floor, out):
    """Convergence measure of each member (see :meth:`PlanarRod.error`): the largest scaled
    residual over (tol + its round-off floor) of the moment (per w), position (per h) and force
    (per w) equations; floor = 32 eps times the size of each equation's terms.  out (k,)."""
    k = R.shape[0]
    n = inv_w.shape[0]
    for j in range(k):
        th_max = 0.0
        x_max = 0.0
        F_max = 0.0
        for i in range(n):
            x_max = max(x_max, abs(U[j, 5 * i]), abs(U[j, 5 * i + 1]))
            th_max = max(th_max, abs(U[j, 5 * i + 2]))
            F_max = max(F_max, abs(U[j, 5 * i + 3]), abs(U[j, 5 * i + 4]))
        size_th = 1.0 + th_max
        e = 0.0
        for i in range(1, n):
            r = 5 * i
            g = abs(R[j, r + 2]) * inv_w[i] / (tol + floor * (size_th * bend_scale[i] + F_max))
            ex = abs(R[j, r]) * inv_h[i - 1] / (tol + floor * (1.0 + x_max) * inv_h[i - 1])
            ey = abs(R[j, r + 1]) * inv_h[i - 1] / (tol + floor * (1.0 + x_max) * inv_h[i - 1])
            q = r - 2  # force equations of node i - 1
            ef = (1.0 + F_max) * inv_w[i]
            fx = abs(R[j, q]) * inv_w[i] / (tol + floor * ef)
            fy = abs(R[j, q + 1]) * inv_w[i] / (tol + floor * ef)
            m = max(g, ex, ey, fx, fy)
            if not m <= e:  # also propagates NaN
                e = m
        out[j] = e


#: Threshold partial pivoting of :func:`band_lu`: the diagonal stays the pivot unless it is
#: smaller than this fraction of the largest entry below it in its column (a constant of the
#: compiled code: numba reads it when it compiles the kernel).
PIVOT_THRESHOLD = 0.1


@nb.njit(cache=True)
def band_lu(ab, kl, ku, ipiv, start):
    """LU factorisation with threshold partial pivoting of a band matrix, in place (LAPACK
    ``gbtf2``, except that a row is exchanged only where the diagonal is smaller than
    :data:`PIVOT_THRESHOLD` times the largest entry below it: the multipliers stay below
    1 / PIVOT_THRESHOLD = 10 in magnitude), from column ``start`` on (0: all of it).

    The planar rod's mixed Jacobian needs few exchanges (its position and force rows have unit
    diagonals), and without them U keeps ku upper diagonals instead of kl + ku, so the
    elimination updates half as many columns (measured: about 30 % less time than partial
    pivoting at 64-128 segments).  The spatial rod's band Jacobian is factorised here too.

    ``ab`` (2 kl + ku + 1, n) holds A(i, j) at ``ab[kl + ku + i - j, j]`` (rows 0..kl-1 are
    workspace, zero on entry); on return it holds U (upper kl + ku diagonals) and the
    multipliers of L below, and ``ipiv`` (n,) the 0-based row interchanges.  Returns 0, or
    1 + the index of the first exactly zero pivot (the factorisation is then completed).

    A restart (``start`` > 0, at most n): on entry the columns before ``start`` (and
    ``ipiv[:start]``) hold this function's factors of a matrix whose columns before
    ``start`` are this one's, the others this matrix's entries.  Column j of the factors
    depends on columns 0..j of the matrix alone (its updates and exchanges come from the
    earlier columns' multipliers and pivots), so those columns are kept; the earlier steps'
    exchanges and updates are replayed, in the same order, on the later columns they reach,
    and the elimination goes on from ``start``: bitwise the factors of a factorisation from
    column 0 (the contact predictor's rates, one switched contact row from the last one)."""
    n = ab.shape[1]
    kv = ku + kl
    info = 0
    ju = 0
    for j in range(start):  # replay: the kept steps on the columns from start they reach
        if ab[kv, j] == 0.0:  # (an exactly zero pivot: that step did nothing)
            if info == 0:
                info = j + 1
            continue
        jp = ipiv[j] - j
        km = min(kl, n - 1 - j)
        ju = max(ju, min(j + ku + jp, n - 1))
        for c in range(start, ju + 1):
            if jp != 0:
                r1 = kv + j + jp - c
                r0 = kv + j - c
                tmp = ab[r1, c]
                ab[r1, c] = ab[r0, c]
                ab[r0, c] = tmp
            u = ab[kv + j - c, c]
            if u != 0.0:
                for i in range(1, km + 1):
                    ab[kv + i + j - c, c] -= ab[kv + i, j] * u
    for j in range(n):  # (over all columns, the kept ones skipped: range(start, n) made the
        if j < start:  # compiled elimination ~3 % slower from column 0)
            continue
        km = min(kl, n - 1 - j)
        jp = 0
        diag = abs(ab[kv, j])
        big = diag
        for i in range(1, km + 1):
            a = abs(ab[kv + i, j])
            if a > big:
                big = a
                jp = i
        if diag >= PIVOT_THRESHOLD * big:
            jp = 0
        ipiv[j] = j + jp
        if ab[kv + jp, j] == 0.0:
            if info == 0:
                info = j + 1
            continue
        ju = max(ju, min(j + ku + jp, n - 1))
        if jp != 0:
            for c in range(j, ju + 1):
                r1 = kv + j + jp - c
                r0 = kv + j - c
                tmp = ab[r1, c]
                ab[r1, c] = ab[r0, c]
                ab[r0, c] = tmp
        piv = ab[kv, j]
        for i in range(1, km + 1):
            ab[kv + i, j] /= piv
        for c in range(j + 1, ju + 1):
            u = ab[kv + j - c, c]
            if u != 0.0:
                for i in range(1, km + 1):
                    ab[kv + i + j - c, c] -= ab[kv + i, j] * u
    return info


@nb.njit(cache=True)
def band_solve(ab, kl, ku, ipiv, b):
    """Solve A x = b with the factors of :func:`band_lu`; b (n, m) is overwritten by x.
    Right-hand side by right-hand side, each through its column's one-dimensional view (the
    same operations in the same order as all of them at once: the columns are independent);
    the usual one (m = 1) then runs without an inner loop over the right-hand sides (about a
    fifth less time at 650-1290 unknowns)."""
    n = ab.shape[1]
    kv = ku + kl
    for q in range(b.shape[1]):
        x = b[:, q]
        for j in range(n - 1):  # L, with the row interchanges as they were made
            lm = min(kl, n - 1 - j)
            p = ipiv[j]
            if p != j:
                tmp = x[p]
                x[p] = x[j]
                x[j] = tmp
            xj = x[j]
            for i in range(1, lm + 1):
                f = ab[kv + i, j]
                if f != 0.0:
                    x[j + i] -= f * xj
        for j in range(n - 1, -1, -1):  # U, bandwidth kl + ku
            x[j] /= ab[kv, j]
            xj = x[j]
            for i in range(max(0, j - kv), j):
                f = ab[kv + i - j, j]
                if f != 0.0:
                    x[i] -= f * xj


@nb.njit(cache=True)
def band_solve_transposed(ab, kl, ku, ipiv, b):
    """Solve A^T x = b with the factors of :func:`band_lu` (LAPACK ``gbtrs`` with TRANS = 'T');
    b (n, m) is overwritten by x.  The adjoint sensitivities need it: one solve per output
    instead of one per parameter."""
    n = ab.shape[1]
    m = b.shape[1]
    kv = ku + kl
    for j in range(n):  # U^T y = b: U^T is lower triangular with bandwidth kl + ku
        for q in range(m):
            acc = b[j, q]
            for i in range(max(0, j - kv), j):
                acc -= ab[kv + i - j, j] * b[i, q]
            b[j, q] = acc / ab[kv, j]
    for j in range(n - 2, -1, -1):  # L^T, undoing the row interchanges in reverse order
        lm = min(kl, n - 1 - j)
        for q in range(m):
            acc = b[j, q]
            for i in range(1, lm + 1):
                acc -= ab[kv + i, j] * b[j + i, q]
            b[j, q] = acc
        p = ipiv[j]
        if p != j:
            for q in range(m):
                tmp = b[p, q]
                b[p, q] = b[j, q]
                b[j, q] = tmp


#: Estimated CPU seconds of numpy out-of-plane block assemblies (``OutOfPlane.odd_blocks``,
#: mixed layout) after which :func:`_odd_blocks_compiled` is used (ski rental: about what
#: compiling it costs on a cold cache); 0 compiles at the first call, ``math.inf`` never.
ODD_COMPILE_AFTER = 1.0
# measured cost of one numpy assembly: per call and per free node x member
_ODD_CALL_S, _ODD_NODE_S = 1e-4, 3e-7
#: The ski rental of :func:`_odd_blocks_compiled` (:class:`coils._numba_cache.Rental`).
_odd_rental = Rental(__name__, lambda: _odd_blocks_compiled, "ODD_COMPILE_AFTER")


def odd_blocks_pays(k: int, n: int) -> bool:
    """True if :func:`odd_blocks_mixed` should assemble the out-of-plane blocks of ``k``
    states of ``n`` nodes: the kernel is compiled (or in numba's cache), or the numpy
    assemblies so far plus this one would cost more than :data:`ODD_COMPILE_AFTER` (then the
    caller's numpy assembly is charged here instead)."""
    if not _odd_rental.ready:
        cost = _ODD_CALL_S + _ODD_NODE_S * k * n
        if not _odd_rental.pays(cost):
            _odd_rental.charge(cost)
            return False
    return True


def odd_blocks_mixed(U, S, mu, h, w, inv_h, k1, k2, L, B, G, H, D, E):
    """The out-of-plane blocks of the mixed layout (``OutOfPlane.odd_blocks``: D (k, n - 1,
    4, 4) and E (k, n - 2, 4, 4), zero on entry) of the states U (k, 5 n) at scales S (k,),
    from the field at the nodes B (k n, 3) T, G (k n, 9) T/m and H (k n, 27) T/m^2 (None for
    a linear field); stiffnesses k1, k2 = (GJ, EI_y) / EI_z, L in m.  The same arithmetic
    in the same order as the numpy assembly, libm's sin and cos for numpy's."""
    has_h = H is not None

    def arr(a, cols=None):  # (writable C-contiguous float arrays: one compiled version)
        a = np.require(a, float, ["C", "W"])
        return a if cols is None else a.reshape(-1, cols)

    _odd_blocks_compiled(
        arr(U), arr(S), arr(mu), arr(h), arr(w), arr(inv_h), float(k1), float(k2), float(L),
        arr(B, 3), arr(G, 9), arr(H, 27) if has_h else np.zeros((1, 27)), has_h, D, E,
    )  # fmt: skip


@nb.njit(cache=True)
def _odd_blocks_compiled(U, S, mu, h, w, inv_h, k1, k2, L, B, G, H, has_h, D, E):
    """The compiled :func:`odd_blocks_mixed` (per member: the segments' bending terms, then
    the free nodes' blocks; the equations of :mod:`coilrod.rod.out_of_plane`)."""
    k = U.shape[0]
    n = w.shape[0]
    nf = n - 1
    Ap = np.empty(nf)
    Am = np.empty(nf)
    q = np.empty(nf)
    pz = np.empty(nf)
    cs = np.empty(nf)
    sn = np.empty(nf)
    fx = np.empty(nf)
    fy = np.empty(nf)
    kp = 0.5 * (k1 + k2)
    km = 0.5 * (k1 - k2)
    for j in range(k):
        for f in range(nf):  # segment f: nodes f and f + 1 (free node f + 1)
            th = U[j, 5 * (f + 1) + 2]
            c = math.cos(th)
            s = math.sin(th)
            cs[f] = c
            sn[f] = s
            b = 0.5 * (th - U[j, 5 * f + 2])
            sb = math.sin(b)
            a = b * math.cos(b) / sb if sb != 0.0 else 1.0
            aa = a * a
            bb = b * b
            alpha = (kp * (aa + bb) + a - aa - bb) * inv_h[f]
            zr = aa - bb
            zi = -2.0 * a * b
            c2 = c * c - s * s
            s2 = 2.0 * c * s
            fac = km * inv_h[f]
            r = fac * (zr * c2 - zi * s2)
            q[f] = fac * (zr * s2 + zi * c2)
            pz[f] = 2.0 * b * inv_h[f]
            Ap[f] = alpha + r
            Am[f] = alpha - r
            fx[f] = 0.5 * h[f] * U[j, 5 * f + 3]
            fy[f] = 0.5 * h[f] * U[j, 5 * f + 4]
        for f in range(nf - 1):  # (the numpy assembly's in-place sums read the old values)
            fx[f] += fx[f + 1]
            fy[f] += fy[f + 1]
        for f in range(nf):
            i = f + 1
            p = j * n + i
            c = cs[f]
            s = sn[f]
            mx = c * mu[i, 0] - s * mu[i, 1]
            my = s * mu[i, 0] + c * mu[i, 1]
            bx = B[p, 0]
            by = B[p, 1]
            Sw = S[j] * w[i]
            dxx = Sw * (my * by) + Ap[f]
            dyy = Sw * (mx * bx) + Am[f]
            dxy = q[f] - 0.5 * Sw * (mx * by + my * bx)
            Mz = pz[f] - Sw * (mx * by - my * bx)
            if f < nf - 1:
                dxx += Ap[f + 1]
                dyy += Am[f + 1]
                dxy += q[f + 1]
                Mz -= pz[f + 1]
            Mz -= c * fy[f] - s * fx[f]
            dxx += s * fy[f]
            dyy += c * fx[f]
            dxy -= 0.5 * (c * fy[f] + s * fx[f])
            D[j, f, 2, 2] = dxx
            D[j, f, 3, 3] = dyy
            D[j, f, 2, 3] = dxy + 0.5 * Mz
            D[j, f, 3, 2] = dxy - 0.5 * Mz
            cwL = Sw * L
            if has_h:
                D[j, f, 0, 0] = -cwL * L * (mx * H[p, 8] + my * H[p, 17])
            D[j, f, 0, 1] = 1.0
            D[j, f, 1, 0] = 1.0
            gz = G[p, 8]
            D[j, f, 0, 2] = -cwL * gz * my
            D[j, f, 2, 0] = D[j, f, 0, 2]
            D[j, f, 0, 3] = cwL * gz * mx
            D[j, f, 3, 0] = D[j, f, 0, 3]
            hh = 0.5 * h[f]
            D[j, f, 1, 2] = -hh * s
            D[j, f, 2, 1] = D[j, f, 1, 2]
            D[j, f, 1, 3] = hh * c
            D[j, f, 3, 1] = D[j, f, 1, 3]
            if f < nf - 1:
                E[j, f, 2, 2] = -Ap[f + 1]
                E[j, f, 3, 3] = -Am[f + 1]
                E[j, f, 2, 3] = -q[f + 1] - 0.5 * pz[f + 1]
                E[j, f, 3, 2] = -q[f + 1] + 0.5 * pz[f + 1]
                E[j, f, 0, 1] = -1.0
                hn = 0.5 * h[f + 1]
                E[j, f, 2, 1] = -hn * s
                E[j, f, 3, 1] = hn * c


#: Estimated CPU seconds of the contact predictor's numpy event steps
#: (:func:`coilrod.rod.contact_predictor._event_step`) after which :func:`event_step` is
#: used (ski rental, its own); 0 compiles at the first call, ``math.inf`` never.
EVENTS_COMPILE_AFTER = 1.0
#: Measured cost of one numpy event step, s (~40 numpy calls).
_EVENT_STEP_S = 5e-5
#: The ski rental of :func:`event_step`.
_events_rental = Rental(__name__, lambda: event_step, "EVENTS_COMPILE_AFTER", in_process=True)


def events_pay() -> bool:
    """Whether :func:`event_step`, :func:`rate_step` and :func:`rate_solve` should run a
    contact prediction's event loop (decided once per prediction): True once compiling
    pays, else the numpy twin's estimated cost of one event step is charged
    (:func:`events_charge` the others')."""
    return _events_rental.ready or _events_rental.rent(_EVENT_STEP_S)


def events_charge() -> None:
    """Charge the estimated cost of one numpy event step to :func:`events_pay`'s rental."""
    _events_rental.charge(_EVENT_STEP_S)


@nb.njit(cache=True, error_model="numpy")
def event_step(gaps, x, r, scale, active, g0, g1, xd, lin, cols, c, nv, nc, kappa, f_rel,
               f_close, flipped):  # fmt: skip
    """One segment of the contact predictor's event loop, compiled: the numpy twin is
    :func:`coilrod.rod.contact_predictor._event_step` (the same steps; see there for the
    arguments and the codes returned).  Returns ``(code, f, count)``."""
    size, npts = x.shape[0], active.shape[0]
    inf = math.inf
    if not gaps:
        least = inf
        for p in range(npts):
            i = (p // nc + 1) * nv + 9 + p % nc
            l0 = x[i]
            l1 = l0 + scale * r[i]
            v = l0 / (l0 - l1) if active[p] and l1 < 0.0 and l1 < l0 else inf
            f_rel[p] = v
            least = min(least, v)
        if not least > 0.0:  # (np.clip where the least is not positive)
            least = inf
            for p in range(npts):
                if f_rel[p] < inf:
                    f_rel[p] = min(max(f_rel[p], 0.0), 1.0)
                least = min(least, f_rel[p])
        f = least
        if f < 1.0 and c.shape[0] > 0:
            clear = True
            for j in range(1, size // nv):
                b = j * nv
                dx = 0.0
                dp = 0.0
                for e in range(3):
                    dx += (scale * r[b + e]) ** 2
                    dp += (scale * r[b + 3 + e]) ** 2
                reach = math.sqrt(dx) + c[j - 1] * math.sqrt(dp)
                for o in range(nc):
                    p = (j - 1) * nc + o
                    if not active[p] and g0[p] <= f * reach:
                        clear = False
                if not clear:
                    break
            if clear:  # a release first: the gaps at it from their linearization
                for p in range(npts):
                    s = 0.0
                    for e in range(lin.shape[1]):
                        s += lin[p, e] * (scale * r[cols[p, e]])
                    g0[p] = g0[p] + f * s / kappa
                return 2, f, _event_apply(x, r, scale, f, active, f_rel, f_close, False, nv,
                                          nc, flipped)  # fmt: skip
        for i in range(size):
            xd[i] = x[i] + scale * r[i]
        return 1, f, 0
    least = inf
    for p in range(npts):
        v = inf
        if not active[p] and g1[p] < 0.0 and g1[p] < g0[p]:
            v = g0[p] / (g0[p] - g1[p])
        f_close[p] = v
        least = min(least, v)
    if not least > 0.0:
        least = inf
        for p in range(npts):
            if f_close[p] < inf:
                f_close[p] = min(max(f_close[p], 0.0), 1.0)
            least = min(least, f_close[p])
    f = least
    for p in range(npts):
        f = min(f, f_rel[p])
    if not f < 1.0:
        return 0, f, 0
    for p in range(npts):
        g0[p] = g0[p] + f * (g1[p] - g0[p])
    return 2, f, _event_apply(x, r, scale, f, active, f_rel, f_close, True, nv, nc, flipped)


@nb.njit(cache=True, error_model="numpy")
def _event_apply(x, r, scale, f, active, f_rel, f_close, closings, nv, nc, flipped):
    """:func:`event_step`'s event at the fraction f of the segment: the state moved there,
    the points whose fractions are f switched (their flat indices into ``flipped``, their
    count returned), the released points' multipliers zeroed."""
    for i in range(x.shape[0]):
        x[i] = x[i] + f * (scale * r[i])
    count = 0
    for p in range(active.shape[0]):
        released = f_rel[p] <= f
        if released or (closings and f_close[p] <= f):
            flipped[count] = p
            count += 1
            active[p] = not active[p]
        if released:
            x[(p // nc + 1) * nv + 9 + p % nc] = 0.0
    return count


@nb.njit(cache=True, error_model="numpy")
def rate_step(band, ab, ipiv, bf, cf, rows, active, flipped, count, kl, ku, rhs, x, keep):
    """The contact predictor's rate after an event, compiled (the numpy twin: the same steps
    in :func:`coilrod.rod.contact_predictor.piecewise_prediction`'s ``rate``; under
    :func:`events_pay`'s rental): the rows of the ``count`` points ``flipped`` (flat indices)
    rewritten in the unfactorised ``band`` (entries ``bf``, ``cf`` (npts, w) of each point's
    row; ``rows[1]`` where ``active``, ``rows[0]`` elsewhere), the factors ``ab``, ``ipiv``
    restarted at the first column those rows reach (:func:`band_lu`), and the solve of the
    right-hand side ``rhs`` (size, 1) into ``x`` (size, 1) restarted there too
    (:func:`rate_solve`, ``keep`` the last solve's).  Returns band_lu's info, or -1 if x is
    not finite."""
    n = band.shape[1]
    start = n
    for k in range(count):
        p = flipped[k]
        a = 1 if active[p] else 0
        for e in range(bf.shape[1]):
            band[bf[p, e], cf[p, e]] = rows[a, p, e]
        start = min(start, cf[p, 0])
    for col in range(start, n):
        for i in range(band.shape[0]):
            ab[i, col] = band[i, col]
    info = band_lu(ab, kl, ku, ipiv, start)
    if info > 0:
        return info
    return rate_solve(ab, kl, ku, ipiv, rhs, x, start, keep)


@nb.njit(cache=True, error_model="numpy")
def rate_solve(ab, kl, ku, ipiv, rhs, x, start, keep):
    """:func:`band_solve` of one right-hand side ``rhs`` (size, 1) into ``x`` (size, 1) that
    keeps its forward sweep and restarts it (the contact predictor's rates, under
    :func:`events_pay`'s rental; band_solve itself is unchanged: one compiled version for
    its callers).  ``keep`` (2, n): on return ``keep[0]`` holds the forward result
    (L^-1 P rhs) and ``keep[1, j]`` the value the row exchange of step j sent to row
    ``ipiv[j]``.  A restart (``start`` > 0, at most n, after a :func:`band_lu` restarted
    there; the same rhs, ``keep`` the last solve's, the factors' columns and pivots before
    ``start`` unchanged since) keeps the forward result's rows before ``start``, replays the
    last kl steps before it on the rows from ``start`` on (the exchanges into them and the
    updates with the kept results, in the same order) and sweeps on from ``start``: bitwise
    the solve from column 0.  The back substitution runs over every row.  Returns 0, or -1
    if x is not finite."""
    n = ab.shape[1]
    kv = ku + kl
    b = x[:, 0]
    for i in range(n):
        b[i] = rhs[i, 0]
    y, c = keep[0], keep[1]
    j0 = 0
    if start > 0:
        j0 = min(start, n - 1)
        for i in range(start):
            b[i] = y[i]
        for j in range(max(0, start - kl), j0):  # replay: the steps reaching rows >= start
            lm = min(kl, n - 1 - j)
            p = ipiv[j]
            if p != j and p >= start:
                b[p] = c[j]
            xj = y[j]
            for i in range(start - j, lm + 1):
                f = ab[kv + i, j]
                if f != 0.0:
                    b[j + i] -= f * xj
    for j in range(j0, n - 1):  # L, with the row interchanges as they were made
        lm = min(kl, n - 1 - j)
        p = ipiv[j]
        if p != j:
            tmp = b[p]
            b[p] = b[j]
            b[j] = tmp
            c[j] = b[p]
        xj = b[j]
        for i in range(1, lm + 1):
            f = ab[kv + i, j]
            if f != 0.0:
                b[j + i] -= f * xj
    for i in range(start, n):
        y[i] = b[i]
    for j in range(n - 1, -1, -1):  # U, bandwidth kl + ku
        b[j] /= ab[kv, j]
        xj = b[j]
        for i in range(max(0, j - kv), j):
            f = ab[kv + i - j, j]
            if f != 0.0:
                b[i] -= f * xj
    total = 0.0
    for i in range(n):
        total += b[i]
    return 0 if math.isfinite(total) else -1
