"""Sums of point dipoles (tier 1: a compiled kernel with no checks).

A point dipole of moment ``p`` at ``c`` (``p`` already scaled by mu0/4pi, T m^3) makes, with
``r = x - c``, ``s = p . r``,

    B_i     = 3 r_i s / r^5 - p_i / r^3,
    G_ij    = 3 (d_ij s + r_i p_j + p_i r_j) / r^5 - 15 r_i r_j s / r^7,
    H_ijl   = 3 (d_ij p_l + d_il p_j + d_jl p_i) / r^5
                        - 15 s (d_ij r_l + d_il r_j + d_jl r_i) / r^7
              - 15 (p_i r_j r_l + p_j r_i r_l + p_l r_i r_j) / r^7
              + 105 s r_i r_j r_l / r^9,

all three exact (``G[i, j] = dB_i/dx_j``, ``H[i, j, l] = d2B_i/(dx_j dx_l)``, symmetric in
all indices, traceless).  :func:`dipole_sum` adds them over sources and points in one compiled
pass (numba, imported on first use), the first point found on a source reported instead of an
infinite field.  The public sources are :class:`coils.MPEM` and :class:`coils.Dipole`.
"""

from __future__ import annotations

import numpy as np

from ._immutable import kernel_input

__all__ = ["dipole_sum"]

_KERNEL = None


def _build():
    import numba

    @numba.njit(cache=True, nogil=True, fastmath=True)
    def kernel(pts, pos, mom, tol2, want_B, want_G, want_H, B, G, H):  # pragma: no cover
        n = pts.shape[0]
        S = pos.shape[0]
        for k in range(n):
            # a point on a source first (the sums below then have no exit: they vectorise)
            for q in range(S):
                r0 = pts[k, 0] - pos[q, 0]
                r1 = pts[k, 1] - pos[q, 1]
                r2 = pts[k, 2] - pos[q, 2]
                if r0 * r0 + r1 * r1 + r2 * r2 <= tol2:
                    return k * S + q
            x0, x1, x2 = pts[k, 0], pts[k, 1], pts[k, 2]
            b0 = b1 = b2 = 0.0
            g00 = g01 = g02 = g11 = g12 = g22 = 0.0
            # unique hessian entries (fully symmetric): 000 001 002 011 012 022 111 112 122 222
            h000 = h001 = h002 = h011 = h012 = h022 = h111 = h112 = h122 = h222 = 0.0
            for q in range(S):
                r0 = x0 - pos[q, 0]
                r1 = x1 - pos[q, 1]
                r2 = x2 - pos[q, 2]
                rr = r0 * r0 + r1 * r1 + r2 * r2
                p0, p1, p2 = mom[q, 0], mom[q, 1], mom[q, 2]
                inv2 = 1.0 / rr
                inv3 = inv2 / np.sqrt(rr)
                inv5 = inv3 * inv2
                s = p0 * r0 + p1 * r1 + p2 * r2
                if want_B:
                    t = 3.0 * s * inv5
                    b0 += t * r0 - p0 * inv3
                    b1 += t * r1 - p1 * inv3
                    b2 += t * r2 - p2 * inv3
                if want_G:
                    a = 3.0 * inv5
                    c = 15.0 * s * inv5 * inv2
                    g00 += a * (s + 2.0 * r0 * p0) - c * r0 * r0
                    g11 += a * (s + 2.0 * r1 * p1) - c * r1 * r1
                    g22 += a * (s + 2.0 * r2 * p2) - c * r2 * r2
                    g01 += a * (r0 * p1 + p0 * r1) - c * r0 * r1
                    g02 += a * (r0 * p2 + p0 * r2) - c * r0 * r2
                    g12 += a * (r1 * p2 + p1 * r2) - c * r1 * r2
                if want_H:
                    a = 3.0 * inv5
                    e = 15.0 * inv5 * inv2
                    f = 105.0 * s * inv5 * inv2 * inv2
                    # (i, j, l) with d_ij terms; the formula of the module docstring
                    h000 += (
                        a * 3.0 * p0 - e * (3.0 * s * r0 + 3.0 * p0 * r0 * r0) + f * r0 * r0 * r0
                    )
                    h111 += (
                        a * 3.0 * p1 - e * (3.0 * s * r1 + 3.0 * p1 * r1 * r1) + f * r1 * r1 * r1
                    )
                    h222 += (
                        a * 3.0 * p2 - e * (3.0 * s * r2 + 3.0 * p2 * r2 * r2) + f * r2 * r2 * r2
                    )
                    # (0,0,1): d00 p1 ; s d00 r1 ; p0 r0 r1 + p0 r0 r1 + p1 r0 r0
                    h001 += (
                        a * p1 - e * (s * r1 + 2.0 * p0 * r0 * r1 + p1 * r0 * r0) + f * r0 * r0 * r1
                    )
                    h002 += (
                        a * p2 - e * (s * r2 + 2.0 * p0 * r0 * r2 + p2 * r0 * r0) + f * r0 * r0 * r2
                    )
                    h011 += (
                        a * p0 - e * (s * r0 + 2.0 * p1 * r1 * r0 + p0 * r1 * r1) + f * r0 * r1 * r1
                    )
                    h022 += (
                        a * p0 - e * (s * r0 + 2.0 * p2 * r2 * r0 + p0 * r2 * r2) + f * r0 * r2 * r2
                    )
                    h112 += (
                        a * p2 - e * (s * r2 + 2.0 * p1 * r1 * r2 + p2 * r1 * r1) + f * r1 * r1 * r2
                    )
                    h122 += (
                        a * p1 - e * (s * r1 + 2.0 * p2 * r2 * r1 + p1 * r2 * r2) + f * r1 * r2 * r2
                    )
                    h012 += -e * (p0 * r1 * r2 + p1 * r0 * r2 + p2 * r0 * r1) + f * r0 * r1 * r2
            if want_B:
                B[k, 0] += b0
                B[k, 1] += b1
                B[k, 2] += b2
            if want_G:
                G[k, 0] += g00
                G[k, 1] += g01
                G[k, 2] += g02
                G[k, 3] += g01
                G[k, 4] += g11
                G[k, 5] += g12
                G[k, 6] += g02
                G[k, 7] += g12
                G[k, 8] += g22
            if want_H:
                u = (h000, h001, h002, h011, h012, h022, h111, h112, h122, h222)
                for f in range(27):  # flat index 9 i + 3 j + l
                    H[k, f] += u[_SLOT[f]]
        return -1

    return kernel


#: flat index ``9 i + 3 j + l`` of a hessian entry -> position of its sorted index triple in
#: the kernel's tuple of the ten distinct entries (000 001 002 011 012 022 111 112 122 222)
_SLOT = np.array(
    [
        [(0, 0, 0), (0, 0, 1), (0, 0, 2), (0, 1, 1), (0, 1, 2), (0, 2, 2), (1, 1, 1), (1, 1, 2),
         (1, 2, 2), (2, 2, 2)].index(tuple(sorted((i, j, m))))
        for i in range(3)
        for j in range(3)
        for m in range(3)
    ],
    dtype=np.int64,
)  # fmt: skip


def _build_fast():
    """B and gradient only: points in blocks, sources outer, points inner (SoA, vectorised).

    The kernel reaches ``inner`` as the module global ``_INNER``, not as a closure variable:
    numba's disk-cache key includes the pickled closure, and a dispatcher pickles differently
    in every process (the kernel would be compiled again in each)."""
    global _INNER
    import numba

    @numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
    def inner(x0, x1, x2, c, p, b0, b1, b2, g00, g11, g22, g01, g02, g12, dmin):  # pragma: no cover
        c0, c1, c2 = c[0], c[1], c[2]
        p0, p1, p2 = p[0], p[1], p[2]
        for i in range(x0.shape[0]):
            r0 = x0[i] - c0
            r1 = x1[i] - c1
            r2 = x2[i] - c2
            rr = r0 * r0 + r1 * r1 + r2 * r2
            dmin[i] = min(dmin[i], rr)
            inv1 = 1.0 / np.sqrt(rr)
            inv2 = inv1 * inv1
            inv3 = inv2 * inv1
            inv5 = inv3 * inv2
            s = p0 * r0 + p1 * r1 + p2 * r2
            t = 3.0 * s * inv5
            b0[i] += t * r0 - p0 * inv3
            b1[i] += t * r1 - p1 * inv3
            b2[i] += t * r2 - p2 * inv3
            a = 3.0 * inv5
            e = 5.0 * t * inv2
            g00[i] += a * (s + 2.0 * r0 * p0) - e * r0 * r0
            g11[i] += a * (s + 2.0 * r1 * p1) - e * r1 * r1
            g22[i] += a * (s + 2.0 * r2 * p2) - e * r2 * r2
            g01[i] += a * (r0 * p1 + p0 * r1) - e * r0 * r1
            g02[i] += a * (r0 * p2 + p0 * r2) - e * r0 * r2
            g12[i] += a * (r1 * p2 + p1 * r2) - e * r1 * r2

    _INNER = inner

    @numba.njit(cache=True, nogil=True)
    def kernel(pts, pos, mom, want_B, want_G, B, G):  # pragma: no cover
        n = pts.shape[0]
        x = np.empty((3, _BLOCK))
        o = np.empty((10, _BLOCK))
        closest = np.inf
        for st in range(0, n, _BLOCK):
            m = min(n - st, _BLOCK)
            for i in range(m):
                x[0, i] = pts[st + i, 0]
                x[1, i] = pts[st + i, 1]
                x[2, i] = pts[st + i, 2]
            o[:9, :m] = 0.0
            o[9, :m] = np.inf
            for q in range(pos.shape[0]):
                _INNER(
                    x[0, :m], x[1, :m], x[2, :m], pos[q], mom[q], o[0, :m], o[1, :m],
                    o[2, :m], o[3, :m], o[4, :m], o[5, :m], o[6, :m], o[7, :m], o[8, :m], o[9, :m],
                )  # fmt: skip
            for i in range(m):
                k = st + i
                closest = min(closest, o[9, i])
                if want_B:
                    B[k, 0] += o[0, i]
                    B[k, 1] += o[1, i]
                    B[k, 2] += o[2, i]
                if want_G:
                    G[k, 0] += o[3, i]
                    G[k, 4] += o[4, i]
                    G[k, 8] += o[5, i]
                    G[k, 1] += o[6, i]
                    G[k, 3] += o[6, i]
                    G[k, 2] += o[7, i]
                    G[k, 6] += o[7, i]
                    G[k, 5] += o[8, i]
                    G[k, 7] += o[8, i]
        return closest

    return kernel


#: Points per block of the B + gradient kernel (its accumulators stay in the L1 cache).
_BLOCK = 256
_FAST = None
_INNER = None  # the per-source pass of the B + gradient kernel (set by _build_fast)


def dipole_sum(pts, pos, mom, tol, B=None, G=None, H=None) -> int:
    """Add the field of point dipoles to the arrays given (tier 1: no checks).

    Parameters
    ----------
    pts : ndarray, shape (n, 3)
        Points, m (C-contiguous float64).
    pos, mom : ndarray, shape (S, 3)
        Dipole positions (m) and moments scaled by mu0/4pi (T m^3).
    tol : float
        A point closer than ``tol`` (m) to a source is "on" it.
    B, G, H : ndarray, shapes (n, 3), (n, 3, 3), (n, 3, 3, 3), or None
        Accumulated into (C-contiguous); None: not wanted.

    Returns
    -------
    int
        -1, or ``k * S + q`` for the first point ``k`` found on source ``q`` (then the arrays
        hold a partial sum).
    """
    global _KERNEL, _FAST
    # read-only views: one compiled version whether the caller's arrays are sealed or not
    pts, pos, mom = kernel_input(pts), kernel_input(pos), kernel_input(mom)
    n = pts.shape[0]
    if n == 0:  # nothing to add (and no row to check)
        return -1
    if H is None and n >= 64:
        # B and/or G: the vectorised kernel; the exact kernel only to name a point on a source
        if _FAST is None:
            _FAST = _build_fast()
        dummy = np.empty((0, 3))
        tol2 = float(tol) ** 2
        if B is None and G is None:
            return -1
        closest = _FAST(
            pts,
            pos,
            mom,
            B is not None,
            G is not None,
            B if B is not None else dummy,
            G.reshape(n, 9) if G is not None else dummy,
        )
        if closest > tol2:
            _check_finite(pts, pos, B, G, None)
            return -1
        B = G = None  # only find the point (the caller raises)
    if _KERNEL is None:
        _KERNEL = _build()
    dummy = np.empty((0, 3))
    hit = int(
        _KERNEL(
            pts,
            pos,
            mom,
            float(tol) ** 2,
            B is not None,
            G is not None,
            H is not None,
            B if B is not None else dummy,
            G.reshape(n, 9) if G is not None else dummy,
            H.reshape(n, 27) if H is not None else dummy,
        )
    )
    if hit < 0:
        _check_finite(pts, pos, B, G, H)
    return hit


def _check_finite(pts, pos, B, G, H) -> None:
    """ValueError naming the first point whose sums are not finite: a distance to a source
    whose powers (up to ``r^-9``) leave float64 (below about 1e-34 m or beyond 1e154 m; the
    field itself overflows near a source) -- never a silent NaN or inf."""
    bad = None
    for arr in (B, G, H):
        if arr is not None:
            row = ~np.isfinite(arr.reshape(arr.shape[0], -1)).all(axis=1)
            bad = row if bad is None else bad | row
    if bad is None or not bad.any():
        return
    k = int(np.nonzero(bad)[0][0])
    r = pts[k] - pos
    d = np.hypot(np.hypot(r[:, 0], r[:, 1]), r[:, 2])  # (no overflow)
    raise ValueError(
        f"points[{k}] = {pts[k].tolist()} m: the dipole field is not representable in float64 "
        f"there (distances to the sources {d.min():.3g} to {d.max():.3g} m; the sums need "
        f"about 1e-30 m to 1e150 m)"
    )
