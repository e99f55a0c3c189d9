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

The kernel searches every point, then :func:`_derivatives` takes the gap's derivatives at the
chosen pairs; that helper is a plain Python function that numba compiles for the kernel
(``register_jitable``), so that ``closed_form_search.py_func`` runs it all as plain Python (the
tests check it so, without compiling it).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from numba.extending import register_jitable

from coils._numba_cache import Rental

__all__ = ["closed_form_search", "search_pays", "COMPILE_AFTER"]

#: Estimated CPU seconds of numpy searches after which the compiled search is used (ski
#: rental: about what compiling it costs on a cold cache, 1.6-2.3 s measured, README "Cold
#: start"); 0 compiles at the first call, ``math.inf`` never.
COMPILE_AFTER = 2.0
# measured cost of one numpy search and evaluation: per call and per point x candidate piece
# (65 points on a bend, 5 candidates: 155-240 us by order)
_NUMPY_CALL_S, _NUMPY_PAIR_S = 1.5e-4, 2e-7


#: The columns of the compiled search's ``geom`` (one row per candidate piece): the parameter
#: range and local origin, the vectors ``a``, ``b``, ``c`` (three columns each), the arc
#: radius, the round cone's slope and the ball radius ``value + slope (u - anchor)``.
LO, HI, REF, A, B, C, ARC, CONE, VALUE, SLOPE, ANCHOR = 0, 1, 2, 3, 6, 9, 12, 13, 14, 15, 16
#: Number of columns of ``geom``.
WIDTH = 17


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
    return _rental.ready or _rental.rent(_NUMPY_CALL_S + _NUMPY_PAIR_S * points * pieces)


@nb.njit(cache=True, error_model="numpy")
def closed_form_search(p, order, kind, geom, scale, on_line, g, col, u, grad, hess):
    """Nearest-point search and gap evaluation of points against candidate pieces in closed
    form, compiled (``closed_form_search.py_func``: the same in plain Python); the results
    are written into ``g``, ``col``, ``u``, ``grad`` and ``hess``.

    Parameters
    ----------
    p : ndarray, shape (n, 3)
        Points, m.
    order : int
        0: gaps; 1: and gradients; 2: and hessians.
    kind : ndarray of int64, shape (K,)
        The candidates' kinds (``LINE`` 0 or ``ARC`` 1), in the candidates' order (ties go to
        the first).
    geom : ndarray, shape (K, WIDTH)
        Each candidate's fields, columns :data:`LO` ... :data:`ANCHOR`: the parameter range
        (m; +-inf at a half-line's open side) and local origin; ``a``, ``b``, ``c`` (line:
        point and unit tangent, ``c`` unused; arc: centre and the unit vectors to angle 0
        and along the tangent there, :class:`coilrod.contact.centerline.Pieces`); the arc
        radius (m; unused for lines); the slope of a line's linear ball radius (the round
        cone's closed form, |slope| < 1); the ball radius ``value + slope (u - anchor)``
        (m, 1, m).
    scale : float
        The vessel's largest ball radius (m; the ranking's rounding tolerance).
    on_line : float
        Below this distance (m) a point is on the centreline (any unit normal is a gradient).
    g : ndarray, shape (n,)
        Out: gaps, m.
    col : ndarray of int64, shape (n,)
        Out: the chosen candidate of each point.
    u : ndarray, shape (n,)
        Out: its parameter, m.
    grad : ndarray, shape (n, 3)
        Out (order >= 1): the gap's gradient.
    hess : ndarray, shape (n, 3, 3)
        Out (order 2): the gap's hessian, 1/m.
    """
    n, K = p.shape[0], kind.shape[0]
    eps = 2.220446049250313e-16
    two_pi = 2.0 * math.pi
    G = np.empty(K)
    U = np.empty(K)
    for i in range(n):
        p0, p1, p2 = p[i, 0], p[i, 1], p[i, 2]
        # every candidate's maximiser and gap (the closed forms of Pieces.start_guess)
        for k in range(K):
            q0, q1, q2 = p0 - geom[k, A], p1 - geom[k, A + 1], p2 - geom[k, A + 2]
            b0, b1, b2 = geom[k, B], geom[k, B + 1], geom[k, B + 2]
            if kind[k] == 0:
                along = q0 * b0 + q1 * b1 + q2 * b2
                cone = geom[k, CONE]
                if cone != 0.0:
                    r0, r1, r2 = q0 - along * b0, q1 - along * b1, q2 - along * b2
                    across = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
                    along = along + cone * across / math.sqrt(1.0 - cone * cone)
                uk = min(max(geom[k, REF] + along, geom[k, LO]), geom[k, HI])
                t = uk - geom[k, REF]
                d0 = p0 - (geom[k, A] + b0 * t)
                d1 = p1 - (geom[k, A + 1] + b1 * t)
                d2 = p2 - (geom[k, A + 2] + b2 * t)
            else:
                c0, c1, c2 = geom[k, C], geom[k, C + 1], geom[k, C + 2]
                rho = geom[k, ARC]
                phi = math.atan2(q0 * c0 + q1 * c1 + q2 * c2, q0 * b0 + q1 * b1 + q2 * b2)
                if phi < 0.0:
                    phi = phi + two_pi
                span = (geom[k, HI] - geom[k, LO]) / rho
                if phi > span:  # outside the arc's angles: the end nearer along the circle
                    phi = 0.0 if two_pi - phi < phi - span else span
                uk = min(max(geom[k, LO] + rho * phi, geom[k, LO]), geom[k, HI])
                ang = (uk - geom[k, REF]) / rho
                cs, sn = math.cos(ang), math.sin(ang)
                d0 = p0 - (geom[k, A] + rho * (cs * b0 + sn * c0))
                d1 = p1 - (geom[k, A + 1] + rho * (cs * b1 + sn * c1))
                d2 = p2 - (geom[k, A + 2] + rho * (cs * b2 + sn * c2))
            U[k] = uk
            rho_k = geom[k, VALUE] + geom[k, SLOPE] * (uk - geom[k, ANCHOR])
            G[k] = rho_k - math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        # the ranking: a piece whose maximiser is interior, within rounding; else the best
        best = G[0]
        first = 0
        for k in range(1, K):
            if G[k] > best:
                best = G[k]
                first = k
        tol = 64 * eps * (abs(best) + scale + max(abs(p0), abs(p1), abs(p2)))
        kb = -1
        for k in range(K):
            if U[k] > geom[k, LO] and U[k] < geom[k, HI] and G[k] >= best - tol:
                if kb < 0 or G[k] > G[kb]:
                    kb = k
        if kb < 0:
            kb = first
        uk = U[kb]
        g[i] = G[kb]
        col[i] = kb
        u[i] = uk
    if order > 0:
        _derivatives(p, order, kind, geom, on_line, col, u, grad, hess)


@register_jitable(error_model="numpy", no_cpython_wrapper=True, no_cfunc_wrapper=True)
def _derivatives(p, order, kind, geom, on_line, col, u, grad, hess):
    """The gap's gradient (order >= 1) and hessian (order 2) at each point, from its chosen
    candidate ``col`` and parameter ``u`` (the search's): the centreline's point and
    derivatives there (``Pieces.curve``), minus the unit normal from it, and the hessian's
    cone and curvature terms (``Vessel._evaluate``).  Plain Python where called from Python
    (``closed_form_search.py_func``), compiled for the kernel where it calls it (numba's
    ``register_jitable``: no entry of its own)."""
    x = np.empty(3)  # the centreline's point and derivatives at the chosen pair
    xu = np.empty(3)
    xuu = np.empty(3)
    rh = np.empty(3)
    w = np.empty(3)
    for i in range(p.shape[0]):
        p0, p1, p2 = p[i, 0], p[i, 1], p[i, 2]
        kb = col[i]
        uk = u[i]
        # the centreline's point and derivatives at the chosen pair (Pieces.curve)
        if kind[kb] == 0:
            t = uk - geom[kb, REF]
            for e in range(3):
                x[e] = geom[kb, A + e] + geom[kb, B + e] * t
                xu[e] = geom[kb, B + e]
                xuu[e] = 0.0
        else:
            rho = geom[kb, ARC]
            ang = (uk - geom[kb, REF]) / rho
            cs, sn = math.cos(ang), math.sin(ang)
            for e in range(3):
                radial = cs * geom[kb, B + e] + sn * geom[kb, C + e]
                x[e] = geom[kb, A + e] + rho * radial
                xu[e] = cs * geom[kb, C + e] - sn * geom[kb, B + e]
                xuu[e] = -radial / rho
        # the gradient: minus the unit normal from the centreline (Vessel._evaluate)
        r0, r1, r2 = p0 - x[0], p1 - x[1], p2 - x[2]
        d = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        if d < on_line:  # on the centreline: a unit normal to the tangent, xu x e_axis
            v0, v1, v2 = abs(xu[0]), abs(xu[1]), abs(xu[2])
            if v0 <= v1 and v0 <= v2:
                w[0], w[1], w[2] = 0.0, xu[2], -xu[1]
            elif v1 <= v2:
                w[0], w[1], w[2] = -xu[2], 0.0, xu[0]
            else:
                w[0], w[1], w[2] = xu[1], -xu[0], 0.0
            nw = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
            for e in range(3):
                rh[e] = w[e] / nw
        else:
            rh[0], rh[1], rh[2] = r0 / d, r1 / d, r2 / d
        for e in range(3):
            grad[i, e] = -rh[e]
        if order == 1:
            continue
        # the hessian: the cone point's -P/d, and the curvature term where the maximiser is
        # interior and the gap concave in u
        ds = max(d, 1e-15 * (geom[kb, VALUE] + geom[kb, SLOPE] * (uk - geom[kb, ANCHOR])))
        for e in range(3):
            for f in range(3):
                hess[i, e, f] = -((1.0 if e == f else 0.0) - rh[e] * rh[f]) / ds
        for e in range(3):
            w[e] = (
                ((1.0 if e == 0 else 0.0) - rh[e] * rh[0]) * xu[0]
                + ((1.0 if e == 1 else 0.0) - rh[e] * rh[1]) * xu[1]
                + ((1.0 if e == 2 else 0.0) - rh[e] * rh[2]) * xu[2]
            )
        curv = rh[0] * xuu[0] + rh[1] * xuu[1] + rh[2] * xuu[2]
        dguu = ds * curv - (xu[0] * w[0] + xu[1] * w[1] + xu[2] * w[2])
        if uk > geom[kb, LO] and uk < geom[kb, HI] and dguu < 0.0:
            den = ds * dguu
            for e in range(3):
                for f in range(3):
                    hess[i, e, f] -= w[e] * w[f] / den
