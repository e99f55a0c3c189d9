"""Compiled contact terms of the spatial rod's linearization (numba, cached on disk).

One pass over the members of a stack and the nodes of the mesh adds what the contact at the
corners of the rod's polygon contributes to a linearization of
:class:`coilrod.rod.spatial.SpatialRod` (mixed layout, frictionless, round section): the
force and moment rows of the normal forces, the complementarity rows of the multipliers,
their Jacobian blocks (the gap's hessian terms, times ``J_l(phi)``), and writes every
state-dependent block of the band storage (the free rod's blocks of the spatial pass's
``blk`` with the contact terms added, and the contact rows' own) in the same call.  The
nearest-point search stays outside: the kernel takes the multipliers, the surface gaps, the
normals and the gap hessians at the contact points as arrays.

The numpy twin is :meth:`SpatialRod._contact_rows`, :meth:`SpatialRod._contact_blocks` and
:meth:`SpatialRod._scatter` (the same arithmetic; the band agrees to rounding, ~1e-16
relative): it runs until compiling pays (:data:`COMPILE_AFTER`, ski rental) or numba's cache
holds the kernel.  Compiled with numba's numpy error model (inf and NaN as in numpy).

A second kernel, :func:`round_points`, forms the contact points of a round section's
states for their surface gaps (:meth:`SpatialRod._state_gaps`: the contact predictor's event
loop asks once per event): the node tangents by Rodrigues' formula and the points after the
numpy operations whose roundings numpy owns, bitwise :func:`coilrod.rod.spatial._tangents`
and the points; its own ski rental (:data:`POINTS_COMPILE_AFTER`).

The small helpers come from :mod:`coilrod.rod._compiled_spatial`: numba's cache checks only
the defining file, so the kernel's cache entry is tied to both files' contents
(:func:`coils._numba_cache.tie_to_sources`): a change of either compiles it anew.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from numba.extending import register_jitable

from coils._numba_cache import Rental, tie_to_sources

from . import _compiled_spatial
from ._compiled_spatial import _cross, _hat, _inner
from .so3 import _SMALL  # the spatial pass's series switch

__all__ = [
    "COMPILE_AFTER",
    "MODES",
    "POINTS_COMPILE_AFTER",
    "compiled_pays",
    "contact_core",
    "points_pay",
    "round_points",
]


# the 3x3 products, exp/J_l and symmetric term of the contact terms (the spatial pass now
# indexes its arrays in place instead: these stay the contact kernel's own)
@_inner
def _mm(A, B, out):
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for q in range(3):
                acc += A[i, q] * B[q, j]
            out[i, j] = acc


@_inner
def _exp_and_jl(phi, Q, J, K, K2, with_j):
    """Q = exp(hat(phi)) and, if ``with_j``, J = J_l(phi) (K, K2: (3, 3) scratch)."""
    theta = math.sqrt(phi[0] ** 2 + phi[1] ** 2 + phi[2] ** 2)
    t2 = theta * theta
    if theta < _SMALL:
        a = 1 - t2 / 6 * (1 - t2 / 20 * (1 - t2 / 42))
        b = 0.5 - t2 / 24 * (1 - t2 / 30 * (1 - t2 / 56))
        c = 1 / 6 - t2 / 120 * (1 - t2 / 42 * (1 - t2 / 72))
    else:
        a = math.sin(theta) / theta
        b = (1 - math.cos(theta)) / t2
        c = (theta - math.sin(theta)) / (t2 * theta)
    _hat(phi, K)
    _mm(K, K, K2)
    for i in range(3):
        for j in range(3):
            eye = 1.0 if i == j else 0.0
            Q[i, j] = eye + a * K[i, j] + b * K2[i, j]
            if with_j:
                J[i, j] = eye + b * K[i, j] + c * K2[i, j]


@_inner
def _sym_term(a, b, scale, out):
    """out += scale * ((a b^T + b a^T) / 2 - (a . b) I)."""
    d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    for i in range(3):
        for j in range(3):
            out[i, j] += scale * (0.5 * (a[i] * b[j] + b[i] * a[j]) - (d if i == j else 0.0))


#: Estimated CPU seconds of numpy contact terms after which the compiled kernel is used (ski
#: rental: about what compiling it costs on a cold cache, benchmarks/results/contact.md);
#: 0 compiles at the first call, ``math.inf`` never.
COMPILE_AFTER = 4.0
#: Measured cost of the numpy twin with the tangent: per call and per node x member, s.
_NUMPY_CALL_S, _NUMPY_NODE_S = 3.5e-4, 1.5e-6
#: The complementarity function's codes: the min function, Fischer-Burmeister, and every
#: row taken as active (partials 0 in lam and 1 in kappa g: the gap's gradient rows).
MODES = {"min": 0, "fb": 1, "every": 2}
#: The ski rental of :func:`contact_core` (compiled in this process counts as held).
_rental = Rental(__name__, lambda: contact_core, in_process=True)


def compiled_pays(k: int, n: int) -> bool:
    """Whether the compiled kernel should add the contact terms of a stack of ``k`` states
    of ``n`` nodes (with the tangent): True once compiling pays (:class:`Rental`), else the
    numpy twin's estimated cost is charged and False is returned (the caller runs it)."""
    return _rental.ready or _rental.rent(_NUMPY_CALL_S + _NUMPY_NODE_S * k * n)


@nb.njit(cache=True, error_model="numpy")
def contact_core(
    lam, gaps, normals, hess, frames, phi, blk, cc, om, kappa, L, mode, tangent, R, ab, kv,
    var, m_c, turn,
):  # fmt: skip
    """Add the contact terms of a stack to the residual and write the band.

    Parameters
    ----------
    lam, gaps : ndarray, shape (k, n, nc)
        Multipliers (force per length, EI_z / L^3 units) and surface gaps (units of L).
    normals : ndarray, shape (k, n, nc, 3)
        Unit normals (the gap gradients) at the contact points.
    hess : ndarray, shape (k, n, nc, 3, 3)
        Gap hessians (1/m; per unit of L after the factor ``L``); unused without tangent.
    frames : ndarray, shape (k, n, 3, 3)
        Node frames; ``phi`` (k, n, 3) the rotation vectors (rad).
    blk : ndarray, shape (k, n, 10, 3, 3)
        The free rod's Jacobian blocks of the spatial pass (read only).
    cc, om : ndarray, shape (n,)
        Offsets of the contact points along the tangents and their weights (units of L).
    kappa, L : float
        Gap scale of the complementarity function; the rod's length, m.
    mode : int
        :data:`MODES`: 0 min, 1 Fischer-Burmeister, 2 every row the gap's.
    tangent : bool
        Also the Jacobian: the band storage ``ab`` (2 kl + ku + 1, k size; Fortran order;
        ``kv`` = kl + ku; its constant blocks already in place) gets every state-dependent
        block (entry (r, c) of the stacked Jacobian at ``ab[kv + r - c, c]``).
    R : ndarray, shape (k, n, nv)
        The residual, the contact terms added in place (the multipliers' rows set).
    var, m_c, turn : ndarray, shapes (k, n, 3, 3, 3), (k, n, 3), (k, n, nc, 3)
        Outputs for the second variation (``SpatialRod._second_variation``; node 0's
        entries not written): ``var[:, j]`` the force row's block in the world rotation,
        the symmetric part of the moment row's, the force row's block in x_j (contact
        included); ``m_c`` the contact moments (rows too); ``turn`` the moment rows'
        derivatives in the multipliers (transposed).  With ``tangent`` only (``m_c``
        always).
    """
    k, n, nc = lam.shape
    nv = R.shape[2]
    size = n * nv
    f_c = np.empty((n, 3))
    d_lam = np.empty((n, nc))
    d_gap = np.empty((n, nc))
    vecs = np.empty((4, 3))
    t, tmp, tn, gd = vecs[0], vecs[1], vecs[2], vecs[3]
    mats = np.empty((11, 3, 3))
    Q, Jl, K, K2, That, LH, M1, M2, mc_d, out, S = (
        mats[0], mats[1], mats[2], mats[3], mats[4], mats[5], mats[6], mats[7], mats[8],
        mats[9], mats[10],
    )  # fmt: skip
    for m in range(k):
        _contact_rows(
            lam[m], gaps[m], normals[m], frames[m], cc, om, kappa, mode, R[m], m_c[m], f_c, d_lam,
            d_gap, vecs,
        )  # fmt: skip
        if not tangent:
            continue
        # -- the band: the clamp's and the constant blocks are the template's
        off = m * size
        for j in range(1, n):
            for a in range(3):
                t[a] = frames[m, j, a, 0]
            _exp_and_jl(phi[m, j], Q, Jl, K, K2, True)
            _hat(t, That)
            for a in range(3):
                for b in range(3):
                    acc = 0.0
                    for o in range(nc):
                        acc += lam[m, j, o] * hess[m, j, o, a, b]
                    LH[a, b] = L * acc
            oc = om[j] * cc[j]
            r0, rp, rf = off + nv * j, off + nv * j + 3, off + nv * (j - 1) + 6
            cx, cp, cf, cl = off + nv * j, off + nv * j + 3, off + nv * j + 6, off + nv * j + 9
            # the free rod's blocks of this node, unchanged
            _put(ab, kv, rp, cp - nv, blk[m, j, 0])  # m_prev
            if j <= n - 2:
                _put(ab, kv, rp, cp + nv, blk[m, j, 2])  # m_next
                _put(ab, kv, rp, cf, blk[m, j, 7])  # m_F
            _put(ab, kv, r0, cp - nv, blk[m, j, 3])  # p_phiprev
            _put(ab, kv, r0, cp, blk[m, j, 4])  # p_phi
            _put(ab, kv, rp, cf - nv, blk[m, j, 6])  # m_Fprev
            # force row j - 1 wrt x_j and phi_j: - om LH; + oc (LH That) J_l
            _mm(LH, That, M1)  # fc_d / oc
            for a in range(3):
                for b in range(3):
                    M1[a, b] = oc * M1[a, b]
                    var[m, j, 0, a, b] = M1[a, b]
                    out[a, b] = blk[m, j, 8, a, b] - om[j] * LH[a, b]
                    var[m, j, 2, a, b] = out[a, b]
            _put(ab, kv, rf, cx, out)  # f_xnext
            _mm(M1, Jl, M2)
            for a in range(3):
                for b in range(3):
                    out[a, b] = blk[m, j, 9, a, b] + M2[a, b]
            _put(ab, kv, rf, cp, out)  # f_phinext
            # moment row j wrt x_j: - oc That LH
            _mm(That, LH, M1)
            for a in range(3):
                for b in range(3):
                    out[a, b] = blk[m, j, 5, a, b] - oc * M1[a, b]
            _put(ab, kv, rp, cx, out)  # m_x
            # moment row j wrt phi_j: (-oc sym(t, f_c) + oc c That LH That - hat(m_c)/2) J_l
            for a in range(3):
                for b in range(3):
                    S[a, b] = 0.0
            _sym_term(t, f_c[j], 1.0, S)
            _mm(M1, That, M2)  # That LH That
            _hat(m_c[m, j], K)
            occ = oc * cc[j]
            for a in range(3):
                for b in range(3):
                    sym = -oc * S[a, b] + occ * M2[a, b]
                    var[m, j, 1, a, b] = sym
                    mc_d[a, b] = sym - 0.5 * K[a, b]
            _mm(mc_d, Jl, M1)
            for a in range(3):
                for b in range(3):
                    out[a, b] = blk[m, j, 1, a, b] + M1[a, b]
            _put(ab, kv, rp, cp, out)  # m_diag
            # the multipliers' columns and the contact rows
            for o in range(nc):
                for a in range(3):
                    tmp[a] = normals[m, j, o, a]
                _cross(t, tmp, tn)
                ck = d_gap[j, o] * kappa
                for a in range(3):
                    ab[kv + rf + a - (cl + o), cl + o] = -om[j] * tmp[a]  # f_lamnext
                    turn[m, j, o, a] = -oc * tn[a]
                    ab[kv + rp + a - (cl + o), cl + o] = turn[m, j, o, a]  # m_lam
                    gd[a] = ck * (cc[j] * tn[a])
                rc = cl + o
                for b in range(3):
                    ab[kv + rc - (cx + b), cx + b] = ck * tmp[b]  # c_x
                    acc = 0.0
                    for q in range(3):
                        acc += gd[q] * Jl[q, b]
                    ab[kv + rc - (cp + b), cp + b] = acc  # c_phi
                for p in range(nc):
                    ab[kv + rc - (cl + p), cl + p] = d_lam[j, o] if p == o else 0.0  # c_lam


def _helper(fn):
    """``fn`` as a helper of :func:`contact_core`: plain Python where called from Python (so
    ``contact_core.py_func`` runs as Python, nothing compiled), compiled for the kernel where
    it calls it (numba's ``register_jitable``; no Python entry and no cache entry of its own:
    the kernel's holds it)."""
    return register_jitable(error_model="numpy", no_cpython_wrapper=True, no_cfunc_wrapper=True)(fn)


@_helper
def _contact_rows(lam, gaps, normals, frames, cc, om, kappa, mode, R, m_c, f_c, d_lam, d_gap, vecs):
    """One member's contact rows: the normal forces f_c (n, 3) at the corners, their moments
    ``m_c``, both added to the force and moment rows of R (n, nv), and the complementarity
    rows with their partials in the multiplier and the gap (d_lam, d_gap; vecs: scratch)."""
    n, nc = lam.shape
    t, tmp = vecs[0], vecs[1]
    for j in range(n):
        for a in range(3):
            acc = 0.0
            for o in range(nc):
                acc += lam[j, o] * normals[j, o, a]
            f_c[j, a] = acc
            t[a] = frames[j, a, 0]
        _cross(t, f_c[j], tmp)
        oc = om[j] * cc[j]
        for a in range(3):
            m_c[j, a] = -oc * tmp[a]
        if j >= 1:
            for a in range(3):
                R[j - 1, 6 + a] -= om[j] * f_c[j, a]
                R[j, 3 + a] += m_c[j, a]
        for o in range(nc):
            x = lam[j, o]
            g = gaps[j, o]
            y = kappa * g
            if mode == 1:  # Fischer-Burmeister
                r = math.hypot(x, y)
                if r > 0:
                    val, dl, dg = x + y - r, 1.0 - x / r, 1.0 - y / r
                else:
                    val, dl, dg = x + y - r, 1.0 - 2**-0.5, 1.0 - 2**-0.5
            elif mode == 0:  # min (NaN propagates, as np.minimum)
                pick = y < x
                val = y if (pick or y != y) else x
                dl, dg = (0.0, 1.0) if pick else (1.0, 0.0)
            else:  # every row the gap's (the value unused: min(lam, g))
                val = g if (g < x or g != g) else x
                dl, dg = 0.0, 1.0
            d_lam[j, o], d_gap[j, o] = dl, dg
            R[j, 9 + o] = val if j >= 1 else x


@_inner
def _put(ab, kv, r0, c0, M):
    """The 3x3 block M at rows r0.., columns c0.. of the stacked Jacobian into band storage."""
    for a in range(3):
        for b in range(3):
            ab[kv + r0 + a - (c0 + b), c0 + b] = M[a, b]


#: Estimated CPU seconds of numpy contact points (:func:`coilrod.rod.spatial._tangents` and
#: the points) after which :func:`round_points` is used (ski rental, its own: its cache entry
#: is not :func:`contact_core`'s); 0 compiles at the first call, ``math.inf`` never.
POINTS_COMPILE_AFTER = 0.5
#: Measured cost of the numpy twin (the tangents and points): per call and per node, s.
_POINTS_CALL_S, _POINTS_NODE_S = 4e-5, 5e-8
#: The ski rental of :func:`round_points`.
_points_rental = Rental(__name__, lambda: round_points, "POINTS_COMPILE_AFTER", in_process=True)


def points_pay(nodes: int) -> bool:
    """Whether :func:`round_points` should form the contact points of ``nodes`` nodes in
    all: True once compiling pays, else the numpy twin's estimated cost is charged."""
    return _points_rental.ready or _points_rental.rent(_POINTS_CALL_S + _POINTS_NODE_S * nodes)


@nb.njit(cache=True, error_model="numpy")
def round_points(phi, x, t2, ts, cos, sin, pm, pr, small, r, c, clamp, scale, out):
    """Contact points ``clamp + scale (x + c t)`` (m) of nodes with positions x and tangents
    ``t = expm(phi) r`` (Rodrigues' formula; so3's series where ``small``), written into out,
    compiled (``round_points.py_func``: the same in plain Python): the arithmetic after the
    numpy operations of :func:`coilrod.rod.spatial._tangents` whose roundings numpy owns (its
    sums, square root, trigonometry and products with the cross matrix), in the same order.

    Parameters
    ----------
    phi, x : ndarray, shape (m, 3)
        Rotation vectors (rad) and node positions (units of L) of m = k n nodes.
    t2, ts, cos, sin, pm, pr : ndarray
        ``|phi|^2``, the angle (1 where ``small``), its cosine and sine (m,), ``phi @ M``
        (m, 3) with ``v @ M = v x r``, and ``phi @ r`` (m,).
    small : ndarray of bool, shape (m,)
        Angle below so3's series switch.
    r : ndarray, shape (3,)
        The clamp frame's tangent.
    c : ndarray, shape (n,)
        Offsets of the contact points along the tangents (units of L); node i is c[i % n].
    clamp : ndarray, shape (3,)
        The clamp's position, m.
    scale : float
        The rod's length L, m.
    out : ndarray, shape (m, 3)
        Out: the points, m.
    """
    m, n = phi.shape[0], c.shape[0]
    for i in range(m):
        if small[i]:
            s2 = t2[i]
            b = 0.5 - s2 / 24 * (1 - s2 / 30 * (1 - s2 / 56))
            a = 1 - s2 / 6 * (1 - s2 / 20 * (1 - s2 / 42))
            cs = 1.0 - b * s2
        else:
            a = sin[i] / ts[i]
            b = (1.0 - cos[i]) / (ts[i] * ts[i])
            cs = cos[i]
        bp = b * pr[i]
        ci = c[i % n]
        for e in range(3):
            t = cs * r[e] + a * pm[i, e] + bp * phi[i, e]
            out[i, e] = clamp[e] + scale * (x[i, e] + ci * t)


# the cache entry also goes stale when the helpers of _compiled_spatial change (they are
# compiled into the kernel; numba checks only this file)
tie_to_sources(contact_core, __file__, _compiled_spatial.__file__)
