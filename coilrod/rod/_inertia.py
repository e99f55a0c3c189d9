"""Inertia of symmetric block-tridiagonal matrices (numba, cached on disk).

The spatial rod's second variation can have double eigenvalues (a circular section in a load
symmetric about the rod's axis): two of them cross zero together and the sign of the
determinant does not change.  The number of negative eigenvalues does; block LDL^T
elimination ``D'_1 = D_1``, ``D'_{j+1} = D_{j+1} - E_j^T D'_j^-1 E_j`` gives it by Sylvester's
law of inertia as the sum of the negative eigenvalues of the pivots ``D'_j`` (each a small
dense symmetric block, diagonalised).  Cost O(n b^3) per member.  Compiled with numba once
that pays; until then the same computation runs block by block in numpy, with bitwise the same
counts (:func:`_inertia_numpy`).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from coils._numba_cache import Rental

__all__ = ["block_tridiagonal_inertia"]


_ALPHA = (1.0 + np.sqrt(17.0)) / 8.0  # Bunch-Kaufman's pivot threshold


@nb.njit(cache=True)
def _eliminate(W, b, m, rtol):
    """Symmetric elimination of the first ``b`` unknowns of ``W[:m, :m]`` (the pivot block
    and, below and right of it, its coupling to the next block) with Bunch-Kaufman 1x1 / 2x2
    pivots chosen inside the block; ``W[b:m, b:m]`` becomes the Schur complement.  Returns the
    negative and zero pivot counts, (-1, 0) if a block entry is not finite."""
    scale = 0.0
    for i in range(b):
        for j in range(b):
            if not np.isfinite(W[i, j]):
                return -1, 0
            scale = max(scale, abs(W[i, j]))
    tiny = rtol * scale
    neg = 0
    zero = 0
    k = 0
    while k < b:
        akk = abs(W[k, k])
        lam = 0.0
        r = k
        for i in range(k + 1, b):
            if abs(W[i, k]) > lam:
                lam = abs(W[i, k])
                r = i
        two = False
        if akk == 0.0 and lam == 0.0:
            zero += 1  # an exactly zero row inside the block: left as is (pseudo-inverse)
            k += 1
            continue
        if akk < _ALPHA * lam:
            sigma = 0.0
            for j in range(k, b):
                if j != r and abs(W[j, r]) > sigma:
                    sigma = abs(W[j, r])
            if akk * sigma < _ALPHA * lam * lam:
                two = abs(W[r, r]) < _ALPHA * sigma
                t = k + 1 if two else k
                if t != r:  # symmetric swap of rows and columns t and r
                    for i in range(m):
                        W[t, i], W[r, i] = W[r, i], W[t, i]
                    for i in range(m):
                        W[i, t], W[i, r] = W[i, r], W[i, t]
        if not two:
            d = W[k, k]
            if abs(d) <= tiny:
                zero += 1
            elif d < 0.0:
                neg += 1
            if d != 0.0:
                for i in range(k + 1, m):
                    f = W[i, k] / d
                    if f != 0.0:
                        for j in range(k + 1, m):
                            W[i, j] -= f * W[k, j]
            k += 1
            continue
        a, c, o = W[k, k], W[k + 1, k + 1], W[k, k + 1]
        det = a * c - o * o
        if det < 0.0:
            neg += 1
        elif det > 0.0:
            if a + c < 0.0:
                neg += 2
        for i in range(k + 2, m):
            # row i of [W_ik, W_ik1] P^-1
            u = (c * W[i, k] - o * W[i, k + 1]) / det
            v = (a * W[i, k + 1] - o * W[i, k]) / det
            for j in range(k + 2, m):
                W[i, j] -= u * W[k, j] + v * W[k + 1, j]
        k += 2
    return neg, zero


@nb.njit(cache=True)
def _inertia(D, E, out_neg, out_zero, rtol):
    k, n, b = D.shape[0], D.shape[1], D.shape[2]
    W = np.empty((2 * b, 2 * b))
    for mem in range(k):
        for i in range(b):
            for j in range(b):
                W[i, j] = 0.5 * (D[mem, 0, i, j] + D[mem, 0, j, i])
        neg = 0
        zero = 0
        for blk in range(n):
            m = b
            if blk < n - 1:
                m = 2 * b
                for i in range(b):
                    for j in range(b):
                        W[i, b + j] = E[mem, blk, i, j]
                        W[b + j, i] = E[mem, blk, i, j]
                        W[b + i, b + j] = 0.5 * (D[mem, blk + 1, i, j] + D[mem, blk + 1, j, i])
            ng, zr = _eliminate(W, b, m, rtol)
            if ng < 0:
                neg = -1
                break
            neg += ng
            zero += zr
            if blk < n - 1:  # the Schur complement is the next pivot block
                for i in range(b):
                    for j in range(b):
                        W[i, j] = 0.5 * (W[b + i, b + j] + W[b + j, b + i])
        out_neg[mem] = neg
        out_zero[mem] = zero


def _inertia_numpy(D, E, out_neg, out_zero, rtol):
    """:func:`_inertia` in numpy, a block at a time: the same LAPACK eigensolver (``dsyevd``,
    lower triangle, as numba's ``eigh`` calls it) and the same sums in the same order, so the
    pivots and counts are bitwise those of the compiled version."""
    from scipy.linalg.lapack import dsyevd

    k, n, b = D.shape[0], D.shape[1], D.shape[2]
    for m in range(k):
        piv = 0.5 * (D[m, 0] + D[m, 0].T)
        neg = 0
        zero = 0
        for blk in range(n):
            if not np.all(np.isfinite(piv)):
                neg = -1
                break
            w, V, _ = dsyevd(piv, compute_v=1, lower=1)
            big = np.abs(w).max()
            small = np.abs(w) <= rtol * big
            zero += int(np.count_nonzero(small))
            neg += int(np.count_nonzero(~small & (w < 0.0)))
            if blk == n - 1:
                break
            Y = np.zeros((b, b))  # V^T E, summed over q in order
            for q in range(b):
                Y += V[q, :, None] * E[m, blk, q, None, :]
            with np.errstate(divide="ignore"):
                inv = np.where(w != 0.0, 1.0 / w, 0.0)
            Y *= np.where(inv != 0.0, np.sqrt(np.abs(inv)), 0.0)[:, None]
            sgn = np.sign(w)
            acc = np.zeros((b, b))
            for q in range(b):
                acc += (Y[q, :, None] * sgn[q]) * Y[q, None, :]
            piv = 0.5 * (D[m, blk + 1] + D[m, blk + 1].T) - acc
        out_neg[m] = neg
        out_zero[m] = zero


#: Estimated CPU seconds of numpy counts after which the compiled :func:`_inertia` is used
#: (ski rental: about what compiling it costs on a cold cache, README "Cold start").
COMPILE_AFTER = 1.5
# measured cost of the numpy count: per call, and per block of size b: 5e-5 + 1e-5 b
_NUMPY_CALL_S, _NUMPY_BLOCK_S, _NUMPY_BLOCK_ROW_S = 1e-4, 5e-5, 1e-5
#: The ski rental of :func:`_inertia` (:class:`coils._numba_cache.Rental`).
_rental = Rental(__name__, lambda: _inertia)


def _numpy_cost(blocks: int, b: int) -> float:
    """Estimated CPU seconds of one numpy count of ``blocks`` blocks of size ``b``."""
    return _NUMPY_CALL_S + (_NUMPY_BLOCK_S + _NUMPY_BLOCK_ROW_S * b) * blocks


def _compiled_pays(blocks: int, b: int) -> bool:
    """True if the compiled count should run: it is compiled (or in numba's cache), or the
    numpy counts so far plus this one would cost more than :data:`COMPILE_AFTER`."""
    if not _rental.ready:
        cost = _numpy_cost(blocks, b)
        if not _rental.pays(cost):
            _rental.charge(cost)
            return False
    return True


def expect_counts(calls: int, blocks: int, b: int) -> None:
    """Announce ``calls`` counts of ``blocks`` blocks of size ``b`` to come (an insertion
    makes one per step).  Ski rental with a known horizon: if the numpy counts so far plus
    the announced ones would cost more than :data:`COMPILE_AFTER`, the compiled count runs
    from the next count on (compiling once is cheaper than renting to the end).  The counts
    are the same either way (:func:`_inertia_numpy` is bitwise :func:`_inertia`)."""
    if calls > 0:
        _rental.expect(calls * _numpy_cost(blocks, b))


def block_tridiagonal_inertia(D: np.ndarray, E: np.ndarray, rtol: float = 1e-13):
    """Negative and (numerically) zero eigenvalue counts of symmetric block-tridiagonal
    matrices.

    Parameters
    ----------
    D : ndarray, shape (k, n, b, b)
        Diagonal blocks (symmetrised here).
    E : ndarray, shape (k, n - 1, b, b)
        Blocks above the diagonal (row block j, column block j + 1); the blocks below are
        their transposes.
    rtol : float
        A pivot eigenvalue below ``rtol`` times its block's largest counts as zero.

    Returns
    -------
    neg, zero : ndarray of int, shape (k,)
        Counts per member; ``neg`` is -1 where a block is not finite.
    """
    D = np.ascontiguousarray(D, dtype=float)
    E = np.ascontiguousarray(E, dtype=float)
    k = D.shape[0]
    neg = np.zeros(k, dtype=np.int64)
    zero = np.zeros(k, dtype=np.int64)
    if E.shape[1] == 0:
        E = np.zeros((k, 1) + D.shape[2:])
    if _compiled_pays(D.shape[0] * D.shape[1], D.shape[2]):
        _inertia(D, E, neg, zero, float(rtol))
    else:
        _inertia_numpy(D, E, neg, zero, float(rtol))
    return neg, zero
