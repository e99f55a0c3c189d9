"""Compiled per-node algebra of the spatial rod (numba, cached on disk).

One pass over the members of a stack and the nodes of the mesh computes what
:meth:`coilrod.rod.spatial.SpatialRod._assemble` needs: the node frames, the bending terms of
every segment (``psi = log(R_i^T R_{i+1})``, the moment ``p`` it carries and its Hessian
block ``P``), the residual and its load derivative, the Jacobian blocks (world rotations,
times ``J_l(phi)``) and the symmetric blocks of the second variation.  The equations are
those of :mod:`coilrod.rod.spatial` (see there); this module only evaluates them without
numpy's per-call overhead.  Imported on the first spatial solve; :func:`spatial_pass` runs
the numpy version of :mod:`coilrod.rod._spatial_numpy` until compiling pays.  Compiled with
numba's numpy error model: a division by zero gives inf or NaN, as in the numpy version (the
Python model's ZeroDivisionError branches cost ~15 % more compile time).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from coils._numba_cache import Rental

from .so3 import _C_SERIES, _C_SMALL, _SMALL  # the same series and switch angles

#: The helpers and member passes are called from compiled code only: no Python or C-callable
#: wrappers (each would cost compile time in a fresh environment).
_inner = nb.njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True, error_model="numpy")


@_inner
def _hat(v, out):
    out[0, 0] = 0.0
    out[0, 1] = -v[2]
    out[0, 2] = v[1]
    out[1, 0] = v[2]
    out[1, 1] = 0.0
    out[1, 2] = -v[0]
    out[2, 0] = -v[1]
    out[2, 1] = v[0]
    out[2, 2] = 0.0


@_inner
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@_inner
def _log(R, out):
    v0 = 0.5 * (R[2, 1] - R[1, 2])
    v1 = 0.5 * (R[0, 2] - R[2, 0])
    v2 = 0.5 * (R[1, 0] - R[0, 1])
    s = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    theta = math.atan2(s, c)
    if theta > math.pi - 1e-3:  # axis from the symmetric part (R + R^T)/2 - cos(t) I
        best, col = -1.0, 0
        for i in range(3):
            d = R[i, i] - c
            if d > best:
                best, col = d, i
        for i in range(3):  # the axis, in out
            out[i] = 0.5 * (R[i, col] + R[col, i]) - (c if i == col else 0.0)
        nrm = math.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2)
        sign = 1.0 if out[0] * v0 + out[1] * v1 + out[2] * v2 >= 0 else -1.0
        for i in range(3):
            out[i] = sign * theta * out[i] / nrm
        return
    if theta < _SMALL:
        t2 = theta * theta
        f = 1 + t2 / 6 * (1 + 7 * t2 / 60 * (1 + 31 * t2 / 294))
    else:
        f = theta / s
    out[0] = f * v0
    out[1] = f * v1
    out[2] = f * v2


@_inner
def _c_coefficients(theta, with_dc):
    """c(theta) of J_r^-1 and, if ``with_dc``, dc/dtheta / theta (else 0)."""
    if theta < _C_SMALL:
        t2 = theta * theta
        c = 0.0
        dc = 0.0
        for k in range(_C_SERIES.size - 1, -1, -1):
            c = c * t2 + _C_SERIES[k]
            if k >= 1:
                dc = dc * t2 + 2 * k * _C_SERIES[k]
        return c, dc
    cot = math.cos(theta / 2) / math.sin(theta / 2)
    c = 1 / theta**2 - cot / (2 * theta)
    if not with_dc:
        return c, 0.0
    csc2 = 1.0 / math.sin(theta / 2) ** 2
    dc = (-2 / theta**3 + cot / (2 * theta**2) + csc2 / (4 * theta)) / theta
    return c, dc


@_inner
def _sym_term(a, b, scale, out, k):
    """out[k] += scale * ((a b^T + b a^T) / 2 - (a . b) I)."""
    d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    for i in range(3):
        for j in range(3):
            out[k, i, j] += scale * (0.5 * (a[i] * b[j] + b[i] * a[j]) - (d if i == j else 0.0))


#: Estimated CPU seconds of numpy passes after which the compiled pass is used (ski rental:
#: about what compiling it costs on a cold cache, README "Cold start"); 0 compiles at the
#: first call, ``math.inf`` never.
COMPILE_AFTER = 8.0
# measured cost of one numpy pass: per call and per node x member, without and with the tangent
_NUMPY_CALL_S, _NUMPY_NODE_S = (4e-4, 6e-4), (1.5e-6, 4.5e-6)
#: The ski rental of :func:`spatial_core` (:class:`coils._numba_cache.Rental`; compiled in
#: this process counts as held).
_rental = Rental(__name__, lambda: spatial_core, in_process=True)


def spatial_pass(*args):
    """:func:`spatial_core` (same arguments and outputs) by the vectorised numpy version
    (:mod:`coilrod.rod._spatial_numpy`, bitwise the same numbers) until its estimated cost
    reaches :data:`COMPILE_AFTER`, numba's cache holds the compiled pass or this process has
    compiled it; by the compiled pass from then on."""
    # the field inputs B, G, H C-contiguous (a copy only of a strided view, e.g. the magnet
    # pose's Hessian): one compiled version of the pass, not one per layout
    args = (*args[:4], *(np.ascontiguousarray(a) for a in args[4:7]), *args[7:])
    if not _rental.ready:
        phi, tangent = args[0], args[9]
        t = 1 if tangent else 0
        cost = _NUMPY_CALL_S[t] + _NUMPY_NODE_S[t] * phi.shape[0] * phi.shape[1]
        if not _rental.pays(cost):
            from ._spatial_numpy import spatial_core_numpy

            _rental.charge(cost)
            return spatial_core_numpy(*args)
    return spatial_core(*args)


@nb.njit(cache=True, error_model="numpy")
def spatial_core(
    phi, X, F, S, B, G, H, has_h, uniform, tangent, mu, K, h, w, R0, L,
    frames, R, R1, blk, diag, A_ab, m_out, ab, kv, band, econ, tol, floor, stats,
):  # fmt: skip
    """Frames (k, n, 3, 3), residual R and R1 (k, n, 9 or 3; moment, position and force
    slots), and with ``tangent``: the Jacobian blocks ``blk`` (k, n, 10, 3, 3) -- 0 m_prev,
    1 m_diag, 2 m_next, 3 p_phiprev, 4 p_phi, 5 m_x, 6 m_Fprev, 7 m_F, 8 f_xnext,
    9 f_phinext, each at the node of its row (m_next, m_F at row j: node j; f_* at row j - 1:
    node j) -- the world-rotation diagonal ``diag`` (k, n, 3, 3) and ``A_ab`` (k, n - 1, 3, 3)
    of the second variation, and the world magnetization ``m_out`` (k, n, 3).  With
    ``band``, ``tangent`` and ``uniform``, the blocks of ``blk`` are also written into the
    LAPACK band storage ``ab`` (2 kl + ku + 1, k 3 n; Fortran order; ``kv`` = kl + ku; its
    constant entries already in place): True is returned then (else False; the caller
    gathers the band from ``blk``).  With ``stats`` (k, 3) (else (0, 3)), each member's
    error, largest rotation-vector component and finiteness (:func:`_member_stats`; ``econ``,
    ``tol``, ``floor``: its constants).

    Member by member: :func:`_frames`, :func:`_bending`, :func:`_moment_rows`, and for a
    non-uniform field :func:`_position_force_rows`; with ``tangent`` :func:`_rotation_blocks`
    (and :func:`_band_blocks`) and, for a non-uniform field, :func:`_position_blocks`."""
    k, n = phi.shape[0], phi.shape[1]
    op = 0 if uniform else 3
    Jl = np.empty((n, 3, 3))
    p = np.empty((n - 1, 3))
    P = np.empty((n - 1, 3, 3))
    for m in range(k):
        _frames(phi[m], R0, mu, frames[m], Jl, m_out[m], tangent)
        _bending(frames[m], K, h, tangent, p, P)
        _moment_rows(phi[m], F[m], S[m], B[m], uniform, op, h, w, frames[m], m_out[m], p,
                     R[m], R1[m])  # fmt: skip
        if not uniform:
            _position_force_rows(X[m], F[m], S[m], G[m], h, w, L, frames[m], m_out[m],
                                 R[m], R1[m])  # fmt: skip
        if stats.shape[0] == k:
            _member_stats(phi[m], X[m], F[m], S[m], uniform, R[m], R1[m], econ, tol, floor,
                          stats[m])  # fmt: skip
        if not tangent:
            continue
        _rotation_blocks(F[m], S[m], B[m], uniform, op, h, w, frames[m], m_out[m], p, P, Jl,
                         R[m], blk[m], diag[m], A_ab[m])  # fmt: skip
        if not uniform:
            _position_blocks(S[m], G[m], H[m] if has_h else H[0], has_h, h, w, L, frames[m],
                             m_out[m], Jl, blk[m])  # fmt: skip
        elif band:
            _band_blocks(blk[m], ab, kv, 3 * n * m)
    return band and tangent and uniform


@_inner
def _nanmax(m, x):
    """max(m, x) for m, x >= 0 or NaN, NaN kept (as numpy's maximum)."""
    return x if x > m or x != x else m


@_inner
def _member_stats(phi, X, F, s_m, uniform, R, R1, econ, tol, floor, out):
    """One member's ``out`` = (error, max |phi_a|, 1 if every residual is finite else 0): the
    numbers of :meth:`coilrod.rod.spatial.SpatialRod.error` and the admissibility tests of
    ``linearize``, bitwise (the same products and quotients; maxima in any order are exact,
    NaN kept).  The error: max over equations of ``|R| s / (tol + floor (size b + load))``
    with ``s`` the row multipliers ``econ[:, :nv]`` (the clamp's rows and the tip's force
    row counted as 0), ``b`` the bending round-off scale ``econ[:, nv]``, size 1 + max |u|,
    load = max |R1| s times |scale|; inf where not finite."""
    n, nv = R.shape
    big = 0.0  # max |phi_a|
    size = 0.0  # max |x_a|, |F_a|
    load = 0.0
    bad = 0.0  # sum of R - R: NaN where a residual is inf or NaN
    for i in range(n):
        for a in range(3):
            big = _nanmax(big, abs(phi[i, a]))
            if not uniform:
                size = _nanmax(_nanmax(size, abs(X[i, a])), abs(F[i, a]))
        for a in range(nv):
            load = _nanmax(load, abs(R1[i, a]) * econ[i, a])
            bad += R[i, a] - R[i, a]
    load *= abs(s_m)
    size = 1.0 + _nanmax(size, big)
    clamp = 3 if uniform else 6
    e = 0.0
    for i in range(n):
        div = ((econ[i, nv] * size) + load) * floor + tol
        for a in range(nv):
            zero = (i == 0 and a < clamp) or (not uniform and i == n - 1 and a >= 6)
            # (a zeroed row: 0 / div, NaN where div is)
            e = _nanmax(e, (0.0 if zero else abs(R[i, a]) * econ[i, a]) / div)
    out[0] = e if e < math.inf else math.inf
    out[1] = big
    out[2] = 1.0 if bad == 0.0 else 0.0


@_inner
def _band_blocks(blk, ab, kv, off):
    """The uniform layout's moment blocks of one member (``blk`` 0 m_prev, 1 m_diag,
    2 m_next of node rows 1 .. n - 1) into the band storage ``ab``: entry (r, c) of the
    stacked Jacobian at ``ab[kv + r - c, c]``, the member's rows and columns from ``off``."""
    n = blk.shape[0]
    for i in range(1, n):
        for s in range(3):
            j = i - 1 + s  # the column node
            if j > n - 1:
                continue
            for a in range(3):
                r = off + 3 * i + a
                for b in range(3):
                    c = off + 3 * j + b
                    ab[kv + r - c, c] = blk[i, s, a, b]


@_inner
def _exp_jl_at(phi, i, Q, J, K, K2, with_j):
    """Q = exp(hat(phi[i])) and, if ``with_j``, J[i] = J_l(phi[i]) (K, K2: (3, 3) scratch)."""
    p0, p1, p2 = phi[i, 0], phi[i, 1], phi[i, 2]
    theta = math.sqrt(p0**2 + p1**2 + p2**2)
    t2 = theta * theta
    if theta < _SMALL:
        a = 1 - t2 / 6 * (1 - t2 / 20 * (1 - t2 / 42))
        b = 0.5 - t2 / 24 * (1 - t2 / 30 * (1 - t2 / 56))
        c = 1 / 6 - t2 / 120 * (1 - t2 / 42 * (1 - t2 / 72))
    else:
        a = math.sin(theta) / theta
        b = (1 - math.cos(theta)) / t2
        c = (theta - math.sin(theta)) / (t2 * theta)
    K[0, 0] = 0.0
    K[0, 1] = -p2
    K[0, 2] = p1
    K[1, 0] = p2
    K[1, 1] = 0.0
    K[1, 2] = -p0
    K[2, 0] = -p1
    K[2, 1] = p0
    K[2, 2] = 0.0
    for r in range(3):
        for s in range(3):
            acc = 0.0
            for q in range(3):
                acc += K[r, q] * K[q, s]
            K2[r, s] = acc
    for r in range(3):
        for s in range(3):
            eye = 1.0 if r == s else 0.0
            Q[r, s] = eye + a * K[r, s] + b * K2[r, s]
            if with_j:
                J[i, r, s] = eye + b * K[r, s] + c * K2[r, s]


@_inner
def _frames(phi, R0, mu, frames, Jl, m_out, tangent):
    """One member's node frames ``exp(hat(phi_i)) R0``, with ``tangent`` ``J_l(phi_i)``, and
    the world magnetization ``frames_i mu_i``."""
    mats = np.empty((3, 3, 3))
    Q, K, K2 = mats[0], mats[1], mats[2]
    for i in range(phi.shape[0]):
        _exp_jl_at(phi, i, Q, Jl, K, K2, tangent)
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for q in range(3):
                    acc += Q[a, q] * R0[q, b]
                frames[i, a, b] = acc
        for a in range(3):
            acc = 0.0
            for q in range(3):
                acc += frames[i, a, q] * mu[i, q]
            m_out[i, a] = acc


@_inner
def _bending(frames, K, h, tangent, p, P):
    """One member's segments: the moment ``p_i = R_{i+1} J_l^-1(psi_i) K psi_i / h_i`` of
    ``psi_i = log(R_i^T R_{i+1})`` and, with ``tangent``, its Hessian block ``P_i``."""
    mats = np.empty((9, 3, 3))  # (one allocation each for the 3x3 and 3-vector scratch)
    vecs = np.empty((5, 3))
    Delta, Psi, Psi2, Minv = mats[0], mats[1], mats[2], mats[3]
    Nm, Gh, M1, M2, KM = mats[4], mats[5], mats[6], mats[7], mats[8]
    psi, g, tmp, tmp2, Jg = vecs[0], vecs[1], vecs[2], vecs[3], vecs[4]
    for i in range(frames.shape[0] - 1):
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for q in range(3):
                    acc += frames[i, q, a] * frames[i + 1, q, b]
                Delta[a, b] = acc
        _log(Delta, psi)
        for a in range(3):
            g[a] = psi[a] * K[a] / h[i]
        theta = math.sqrt(psi[0] ** 2 + psi[1] ** 2 + psi[2] ** 2)
        cc, dc = _c_coefficients(theta, tangent)
        _cross(psi, g, tmp)  # psi x g
        _cross(psi, tmp, tmp2)
        for a in range(3):
            Jg[a] = g[a] - 0.5 * tmp[a] + cc * tmp2[a]
        for a in range(3):
            acc = 0.0
            for q in range(3):
                acc += frames[i + 1, a, q] * Jg[q]
            p[i, a] = acc
        if not tangent:
            continue
        _hat(psi, Psi)
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for q in range(3):
                    acc += Psi[a, q] * Psi[q, b]
                Psi2[a, b] = acc
        for a in range(3):
            for b in range(3):
                Minv[a, b] = (1.0 if a == b else 0.0) + 0.5 * Psi[a, b] + cc * Psi2[a, b]
        # N = -hat(g)/2 - c hat(g) hat(psi) - c hat(g x psi) + dc psi (psi^2 g)^T
        _hat(g, Gh)
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for q in range(3):
                    acc += Gh[a, q] * Psi[q, b]
                M1[a, b] = acc
        _cross(g, psi, tmp)
        _hat(tmp, M2)
        for a in range(3):
            acc = 0.0
            for q in range(3):
                acc += Psi2[a, q] * g[q]
            tmp2[a] = acc
        for a in range(3):
            for b in range(3):
                Nm[a, b] = -0.5 * Gh[a, b] - cc * (M1[a, b] + M2[a, b]) + dc * psi[a] * tmp2[b]
        # inner = Minv^T diag(K/h) Minv + sym(Minv^T N); KM = diag(K) Minv / h (each entry
        # once: the same products and quotients as inline)
        for q in range(3):
            for a in range(3):
                KM[q, a] = Minv[q, a] * K[q] / h[i]
        for a in range(3):
            for b in range(3):
                acc = 0.0
                acc2 = 0.0
                acc3 = 0.0
                for q in range(3):
                    acc += KM[q, a] * Minv[q, b]
                    acc2 += Minv[q, a] * Nm[q, b]
                    acc3 += Minv[q, b] * Nm[q, a]
                M1[a, b] = acc + 0.5 * (acc2 + acc3)
        # P = Rb inner Rb^T (Rb = frames[i + 1])
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for q in range(3):
                    acc += frames[i + 1, a, q] * M1[q, b]
                M2[a, b] = acc
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for q in range(3):
                    acc += M2[a, q] * frames[i + 1, b, q]
                P[i, a, b] = acc


@_inner
def _moment_rows(phi, F, s_m, B, uniform, op, h, w, frames, m_out, p, R, R1):
    """One member's moment rows (slots ``op:op+3``) of R and R1: bending, the magnetic
    torque, and (non-uniform field) the moments of the internal forces; the clamp row."""
    n = phi.shape[0]
    vecs = np.empty((4, 3))
    tau, hF, t, tmp = vecs[0], vecs[1], vecs[2], vecs[3]
    for i in range(n):
        for a in range(3):
            t[a] = frames[i, a, 0]
        _cross(m_out[i], B[i], tau)
        for a in range(3):
            r1 = -w[i] * tau[a]
            val = s_m * r1
            if i >= 1:
                val += p[i - 1, a]
            if i <= n - 2:
                val -= p[i, a]
            R1[i, op + a] = r1 if i > 0 else 0.0
            R[i, op + a] = val
        if not uniform:
            if i >= 1:
                for a in range(3):
                    hF[a] = 0.5 * h[i - 1] * F[i - 1, a]
                _cross(t, hF, tmp)
                for a in range(3):
                    R[i, op + a] -= tmp[a]
            if i <= n - 2:
                for a in range(3):
                    hF[a] = 0.5 * h[i] * F[i, a]
                _cross(t, hF, tmp)
                for a in range(3):
                    R[i, op + a] -= tmp[a]
    for a in range(3):
        R[0, op + a] = phi[0, a]


@_inner
def _position_force_rows(X, F, s_m, G, h, w, L, frames, m_out, R, R1):
    """One member's position (slots 0:3) and force (slots 6:9) rows of R and R1 (a
    non-uniform field)."""
    n = X.shape[0]
    for a in range(3):
        R[0, a] = X[0, a]
        R[n - 1, 6 + a] = F[n - 1, a]
        R1[n - 1, 6 + a] = 0.0
        R1[0, a] = 0.0
    for i in range(1, n):
        for a in range(3):
            R[i, a] = (
                X[i, a] - X[i - 1, a] - 0.5 * h[i - 1] * (frames[i - 1, a, 0] + frames[i, a, 0])
            )
            R1[i, a] = 0.0
        # force row i - 1: F_{i-1} - F_i - c w_i L G_i^T m_i
        for a in range(3):
            acc = 0.0
            for q in range(3):
                acc += G[i, q, a] * m_out[i, q]
            f1 = -w[i] * L * acc
            R1[i - 1, 6 + a] = f1
            R[i - 1, 6 + a] = F[i - 1, a] - F[i, a] + s_m * f1


@_inner
def _rotation_blocks(F, s_m, B, uniform, op, h, w, frames, m_out, p, P, Jl, R, blk, diag, A_ab):
    """One member's second-variation blocks ``diag`` and ``A_ab`` and the Jacobian blocks of
    the moment rows with respect to the rotations (``blk`` 0 m_prev, 1 m_diag, 2 m_next).
    (Every array indexed in place: a view or a call per node costs more than its
    arithmetic.)"""
    n = frames.shape[0]
    vecs = np.empty((3, 3))
    t, hF, tmp = vecs[0], vecs[1], vecs[2]
    M1 = np.empty((3, 3))
    for i in range(n):
        for a in range(3):
            t[a] = frames[i, a, 0]
        for a in range(3):
            for b in range(3):
                diag[i, a, b] = 0.0
        if i >= 1:
            for a in range(3):
                for b in range(3):
                    diag[i, a, b] += P[i - 1, a, b]
        if i <= n - 2:
            for a in range(3):
                for b in range(3):
                    diag[i, a, b] += P[i, a, b]
        # + (-s w) ((m B^T + B m^T) / 2 - (m . B) I) (_sym_term)
        scale = -s_m * w[i]
        d = m_out[i, 0] * B[i, 0] + m_out[i, 1] * B[i, 1] + m_out[i, 2] * B[i, 2]
        for a in range(3):
            for b in range(3):
                diag[i, a, b] += scale * (
                    0.5 * (m_out[i, a] * B[i, b] + B[i, a] * m_out[i, b]) - (d if a == b else 0.0)
                )
        if not uniform:
            if i >= 1:
                for a in range(3):
                    hF[a] = 0.5 * h[i - 1] * F[i - 1, a]
                _sym_term(t, hF, -1.0, diag, i)
            if i <= n - 2:
                for a in range(3):
                    hF[a] = 0.5 * h[i] * F[i, a]
                _sym_term(t, hF, -1.0, diag, i)
        # - hat(R_i) / 2
        for a in range(3):
            tmp[a] = R[i, op + a]
        _hat(tmp, M1)
        for a in range(3):
            for b in range(3):
                diag[i, a, b] -= 0.5 * M1[a, b]
    for i in range(n - 1):
        for a in range(3):
            tmp[a] = p[i, a]
        _hat(tmp, M1)
        for a in range(3):
            for b in range(3):
                A_ab[i, a, b] = -P[i, a, b] + 0.5 * M1[a, b]
    for i in range(1, n):
        # m_prev: A_ba(seg i-1) Jl_{i-1}; m_diag: diag_i Jl_i; m_next: A_ab(seg i) Jl_{i+1}
        for a in range(3):
            for b in range(3):
                M1[a, b] = -P[i - 1, a, b] - (A_ab[i - 1, a, b] + P[i - 1, a, b])
        for a in range(3):
            for b in range(3):
                acc = 0.0
                acc2 = 0.0
                for q in range(3):
                    acc += M1[a, q] * Jl[i - 1, q, b]
                    acc2 += diag[i, a, q] * Jl[i, q, b]
                blk[i, 0, a, b] = acc
                blk[i, 1, a, b] = acc2
        if i <= n - 2:
            for a in range(3):
                for b in range(3):
                    acc = 0.0
                    for q in range(3):
                        acc += A_ab[i, a, q] * Jl[i + 1, q, b]
                    blk[i, 2, a, b] = acc


@_inner
def _position_blocks(s_m, G, H, has_h, h, w, L, frames, m_out, Jl, blk):
    """One member's Jacobian blocks of a non-uniform field: ``blk`` 3 p_phiprev, 4 p_phi,
    5 m_x, 6 m_Fprev, 7 m_F, 8 f_xnext, 9 f_phinext (every array indexed in place, as in
    :func:`_rotation_blocks`)."""
    n = frames.shape[0]
    vecs = np.empty((2, 3))
    mats = np.empty((4, 3, 3))
    t, tmp = vecs[0], vecs[1]
    M1, M2, Nm, M0 = mats[0], mats[1], mats[2], mats[3]
    for i in range(1, n):
        hh = 0.5 * h[i - 1]
        for a in range(3):
            tmp[a] = frames[i - 1, a, 0]
        _hat(tmp, M0)
        for a in range(3):
            for b in range(3):
                M0[a, b] *= hh
        for a in range(3):
            t[a] = frames[i, a, 0]
        _hat(t, M2)
        for a in range(3):
            for b in range(3):
                M1[a, b] = hh * M2[a, b]
        for a in range(3):
            for b in range(3):
                acc = 0.0
                acc2 = 0.0
                for q in range(3):
                    acc += M0[a, q] * Jl[i - 1, q, b]
                    acc2 += M1[a, q] * Jl[i, q, b]
                blk[i, 3, a, b] = acc
                blk[i, 4, a, b] = acc2
        # m_x = -c w L hat(m) G ; m_Fprev = -(h_{i-1}/2) hat(t); m_F = -(h_i/2) hat(t)
        for a in range(3):
            tmp[a] = m_out[i, a]
        _hat(tmp, M1)
        cwL = s_m * w[i] * L
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for q in range(3):
                    acc += M1[a, q] * G[i, q, b]
                blk[i, 5, a, b] = -cwL * acc
                blk[i, 6, a, b] = -hh * M2[a, b]
                if i <= n - 2:
                    blk[i, 7, a, b] = -0.5 * h[i] * M2[a, b]
        # f_xnext (row i - 1, column x_i): -c w L^2 sum_q m_q H[q, a, b]
        # f_phinext: c w L G^T hat(m) Jl_i
        for a in range(3):
            for b in range(3):
                acc = 0.0
                if has_h:
                    for q in range(3):
                        acc += m_out[i, q] * H[i, q, a, b]
                blk[i, 8, a, b] = -cwL * L * acc
                acc2 = 0.0
                for q in range(3):
                    acc2 += G[i, q, a] * M1[q, b]
                Nm[a, b] = cwL * acc2
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for q in range(3):
                    acc += Nm[a, q] * Jl[i, q, b]
                blk[i, 9, a, b] = acc
