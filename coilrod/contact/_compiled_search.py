"""Compiled nearest-point search and gap evaluation of a vessel in closed form (numba, cached).

One pass over the points and, for each, over the vessel's candidate pieces computes what
:meth:`coilrod.contact.Vessel._evaluate` returns when every candidate is a line (a round cone
for a linear ball radius) or an arc of constant radius and there are few of them (the
all-pairs search, :meth:`~coilrod.contact.Vessel._locate_closed_form`): the best piece and
its parameter, the gap, and up to order 2 the gap's gradient and hessian.  The closed forms,
the ranking (a piece whose maximiser is interior preferred within rounding, ties to the first
candidate in the candidates' order) and the derivatives are those of the numpy search, which
stays its twin: the same piece and parameter, values to rounding (~1e-15 relative; the sums
are not numpy's).  The twin runs until compiling pays (:class:`coils._numba_cache.Rental`,
:data:`COMPILE_AFTER`) or numba's cache holds the kernel.

The kernel is one function with no compiled helpers, so that ``closed_form_search.py_func``
runs it as plain Python (the tests check it so, without compiling it).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from coils._numba_cache import Rental

__all__ = ["closed_form_search", "search_pays", "COMPILE_AFTER"]

#: Estimated CPU seconds of numpy searches after which the compiled search is used (ski
#: rental: about what compiling it costs on a cold cache, ~3 s measured, README "Cold
#: start"); 0 compiles at the first call, ``math.inf`` never.
COMPILE_AFTER = 3.0
# measured cost of one numpy search and evaluation: per call and per point x candidate piece
_NUMPY_CALL_S, _NUMPY_PAIR_S = 1.2e-4, 2e-7


#: The columns of the compiled search's ``geom`` (one row per candidate piece); ``a``, ``b``,
#: ``c`` take three columns each.
FIELDS = ("lo", "hi", "ref", "a", "b", "c", "arc", "cone", "value", "slope", "anchor")


def _kernel():
    """The compiled search's dispatcher."""
    return closed_form_search


#: The ski rental of the compiled search (:class:`coils._numba_cache.Rental`).
_rental = Rental(__name__, _kernel)


def search_pays(points: int, pieces: int) -> bool:
    """True if the compiled search should evaluate ``points`` points against ``pieces``
    candidate pieces: it is compiled in numba's cache (at this process's first look), or the
    numpy searches so far plus this one would cost more than :data:`COMPILE_AFTER`; else the
    numpy search's estimated cost (s of CPU) is charged."""
    if _rental.ready:
        return True
    cost = _NUMPY_CALL_S + _NUMPY_PAIR_S * points * pieces
    if _rental.pays(cost):
        return True
    _rental.charge(cost)
    return False


@nb.njit(cache=True, error_model="numpy")
def closed_form_search(p, order, kind, geom, scale, on_line):
    """Nearest-point search and gap evaluation of points against candidate pieces in closed
    form, compiled (``closed_form_search.py_func``: the same in plain Python).

    Parameters
    ----------
    p : ndarray, shape (n, 3)
        Points, m.
    order : int
        0: gaps; 1: and gradients; 2: and hessians.
    kind : ndarray of int64, shape (K,)
        The candidates' kinds (``LINE`` 0 or ``ARC`` 1), in the candidates' order (ties go to
        the first).
    geom : ndarray, shape (K, 17)
        Each candidate's fields (:data:`FIELDS`): the parameter range ``lo``, ``hi`` (m; +-inf
        at a half-line's open side) and local origin ``ref``; ``a``, ``b``, ``c`` (3 each;
        line: point and unit tangent, ``c`` unused; arc: centre and the unit vectors to
        angle 0 and along the tangent there, :class:`coilrod.contact.centerline.Pieces`);
        the arc radius (m; unused for lines); the slope of a line's linear ball radius (the
        round cone's closed form, |slope| < 1); the ball radius ``value + slope (u -
        anchor)`` (m, 1, m).
    scale : float
        The vessel's largest ball radius (m; the ranking's rounding tolerance).
    on_line : float
        Below this distance (m) a point is on the centreline (any unit normal is a gradient).

    Returns
    -------
    g : ndarray, shape (n,)
        Gaps, m.
    col : ndarray of int64, shape (n,)
        The chosen candidate of each point.
    u : ndarray, shape (n,)
        Its parameter, m.
    x, xu, xuu : ndarray, shape (n, 3)
        The centreline's point and derivatives there.
    grad : ndarray, shape (n, 3) (order >= 1; else (0, 3))
    hess : ndarray, shape (n, 3, 3) (order 2; else (0, 3, 3))
    """
    lo, hi, ref = geom[:, 0], geom[:, 1], geom[:, 2]
    a, b, c = geom[:, 3:6], geom[:, 6:9], geom[:, 9:12]
    arc, cone = geom[:, 12], geom[:, 13]
    value, slope, anchor = geom[:, 14], geom[:, 15], geom[:, 16]
    n, K = p.shape[0], kind.shape[0]
    eps = 2.220446049250313e-16
    two_pi = 2.0 * math.pi
    g = np.empty(n)
    col = np.empty(n, dtype=np.int64)
    u = np.empty(n)
    x = np.empty((n, 3))
    xu = np.empty((n, 3))
    xuu = np.empty((n, 3))
    grad = np.empty((n if order >= 1 else 0, 3))
    hess = np.empty((n if order >= 2 else 0, 3, 3))
    G = np.empty(K)
    U = np.empty(K)
    q = np.empty(3)
    r = np.empty(3)
    rh = np.empty(3)
    w = np.empty(3)
    for i in range(n):
        # every candidate's maximiser and gap (the closed forms of Pieces.start_guess)
        for k in range(K):
            q[0] = p[i, 0] - a[k, 0]
            q[1] = p[i, 1] - a[k, 1]
            q[2] = p[i, 2] - a[k, 2]
            if kind[k] == 0:
                along = q[0] * b[k, 0] + q[1] * b[k, 1] + q[2] * b[k, 2]
                if cone[k] != 0.0:
                    r0 = q[0] - along * b[k, 0]
                    r1 = q[1] - along * b[k, 1]
                    r2 = q[2] - along * b[k, 2]
                    across = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
                    along = along + cone[k] * across / math.sqrt(1.0 - cone[k] * cone[k])
                uk = min(max(ref[k] + along, lo[k]), hi[k])
                t = uk - ref[k]
                d0 = p[i, 0] - (a[k, 0] + b[k, 0] * t)
                d1 = p[i, 1] - (a[k, 1] + b[k, 1] * t)
                d2 = p[i, 2] - (a[k, 2] + b[k, 2] * t)
            else:
                rho = arc[k]
                x1 = q[0] * b[k, 0] + q[1] * b[k, 1] + q[2] * b[k, 2]
                x2 = q[0] * c[k, 0] + q[1] * c[k, 1] + q[2] * c[k, 2]
                phi = math.atan2(x2, x1)
                if phi < 0.0:
                    phi = phi + two_pi
                span = (hi[k] - lo[k]) / rho
                if phi > span:
                    phi = 0.0 if two_pi - phi < phi - span else span
                uk = min(max(lo[k] + rho * phi, lo[k]), hi[k])
                ang = (uk - ref[k]) / rho
                cs, sn = math.cos(ang), math.sin(ang)
                d0 = p[i, 0] - (a[k, 0] + rho * (cs * b[k, 0] + sn * c[k, 0]))
                d1 = p[i, 1] - (a[k, 1] + rho * (cs * b[k, 1] + sn * c[k, 1]))
                d2 = p[i, 2] - (a[k, 2] + rho * (cs * b[k, 2] + sn * c[k, 2]))
            U[k] = uk
            G[k] = value[k] + slope[k] * (uk - anchor[k]) - math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        # the ranking: a piece whose maximiser is interior, within rounding; else the best
        best = G[0]
        first = 0
        for k in range(1, K):
            if G[k] > best:
                best = G[k]
                first = k
        big = max(abs(p[i, 0]), abs(p[i, 1]), abs(p[i, 2]))
        tol = 64 * eps * (abs(best) + scale + big)
        kb = -1
        for k in range(K):
            if U[k] > lo[k] and U[k] < hi[k] and G[k] >= best - tol:
                if kb < 0 or G[k] > G[kb]:
                    kb = k
        if kb < 0:
            kb = first
        uk = U[kb]
        g[i] = G[kb]
        col[i] = kb
        u[i] = uk
        # the centreline's point and derivatives at the chosen pair (Pieces.curve)
        if kind[kb] == 0:
            t = uk - ref[kb]
            for e in range(3):
                x[i, e] = a[kb, e] + b[kb, e] * t
                xu[i, e] = b[kb, e]
                xuu[i, e] = 0.0
        else:
            rho = arc[kb]
            ang = (uk - ref[kb]) / rho
            cs, sn = math.cos(ang), math.sin(ang)
            for e in range(3):
                radial = cs * b[kb, e] + sn * c[kb, e]
                x[i, e] = a[kb, e] + rho * radial
                xu[i, e] = cs * c[kb, e] - sn * b[kb, e]
                xuu[i, e] = -radial / rho
        if order == 0:
            continue
        # the gradient: minus the unit normal from the centreline (Vessel._evaluate)
        for e in range(3):
            r[e] = p[i, e] - x[i, e]
        d = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
        if d < on_line:  # on the centreline: a unit normal to the tangent
            v0, v1, v2 = abs(xu[i, 0]), abs(xu[i, 1]), abs(xu[i, 2])
            ax = 0
            if v1 < v0:
                ax = 1
            if v2 < (v1 if ax == 1 else v0):
                ax = 2
            # w = xu x e_ax
            if ax == 0:
                w[0], w[1], w[2] = 0.0, xu[i, 2], -xu[i, 1]
            elif ax == 1:
                w[0], w[1], w[2] = -xu[i, 2], 0.0, xu[i, 0]
            else:
                w[0], w[1], w[2] = xu[i, 1], -xu[i, 0], 0.0
            nw = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
            for e in range(3):
                rh[e] = w[e] / nw
        else:
            for e in range(3):
                rh[e] = r[e] / d
        for e in range(3):
            grad[i, e] = -rh[e]
        if order == 1:
            continue
        # the hessian: the cone point's -P/d, and the curvature term where the maximiser is
        # interior and the gap concave in u
        rho_b = value[kb] + slope[kb] * (uk - anchor[kb])
        ds = max(d, 1e-15 * rho_b)
        for e in range(3):
            for f in range(3):
                hess[i, e, f] = -((1.0 if e == f else 0.0) - rh[e] * rh[f]) / ds
        for e in range(3):
            w[e] = (
                ((1.0 if e == 0 else 0.0) - rh[e] * rh[0]) * xu[i, 0]
                + ((1.0 if e == 1 else 0.0) - rh[e] * rh[1]) * xu[i, 1]
                + ((1.0 if e == 2 else 0.0) - rh[e] * rh[2]) * xu[i, 2]
            )
        curv = rh[0] * xuu[i, 0] + rh[1] * xuu[i, 1] + rh[2] * xuu[i, 2]
        dguu = ds * curv - (xu[i, 0] * w[0] + xu[i, 1] * w[1] + xu[i, 2] * w[2])
        if uk > lo[kb] and uk < hi[kb] and dguu < 0.0:
            den = ds * dguu
            for e in range(3):
                for f in range(3):
                    hess[i, e, f] -= w[e] * w[f] / den
    return g, col, u, x, xu, xuu, grad, hess
