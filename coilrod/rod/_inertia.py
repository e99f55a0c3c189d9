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

__all__ = ["block_tridiagonal_inertia"]


@nb.njit(cache=True)
def _inertia(D, E, out_neg, out_zero, rtol):
    k, n, b = D.shape[0], D.shape[1], D.shape[2]
    for m in range(k):
        piv = np.empty((b, b))
        for i in range(b):
            for j in range(b):
                piv[i, j] = 0.5 * (D[m, 0, i, j] + D[m, 0, j, i])
        neg = 0
        zero = 0
        for blk in range(n):
            finite = True
            for i in range(b):
                for j in range(b):
                    if not np.isfinite(piv[i, j]):
                        finite = False
            if not finite:
                neg = -1
                break
            w, V = np.linalg.eigh(piv)
            big = 0.0
            for i in range(b):
                if abs(w[i]) > big:
                    big = abs(w[i])
            for i in range(b):
                if abs(w[i]) <= rtol * big:
                    zero += 1
                elif w[i] < 0.0:
                    neg += 1
            if blk == n - 1:
                break
            # next pivot: D_{blk+1} - E^T V diag(1/w) V^T E
            Y = np.empty((b, b))  # V^T E
            for i in range(b):
                for j in range(b):
                    acc = 0.0
                    for q in range(b):
                        acc += V[q, i] * E[m, blk, q, j]
                    Y[i, j] = acc
            for i in range(b):
                inv = 1.0 / w[i] if w[i] != 0.0 else 0.0
                for j in range(b):
                    Y[i, j] *= np.sqrt(abs(inv)) if inv != 0.0 else 0.0
            sgn = np.empty(b)
            for i in range(b):
                sgn[i] = 1.0 if w[i] > 0.0 else (-1.0 if w[i] < 0.0 else 0.0)
            for i in range(b):
                for j in range(b):
                    acc = 0.0
                    for q in range(b):
                        acc += Y[q, i] * sgn[q] * Y[q, j]
                    piv[i, j] = 0.5 * (D[m, blk + 1, i, j] + D[m, blk + 1, j, i]) - acc
        out_neg[m] = neg
        out_zero[m] = zero


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
_rent = 0.0
_compiled_ready = False


def _compiled_pays(blocks: int, b: int) -> bool:
    """True if the compiled count should run: it is compiled (or in numba's cache), or the
    numpy counts so far plus this one would cost more than :data:`COMPILE_AFTER`."""
    global _rent, _compiled_ready
    if not _compiled_ready:
        from ._compiled import _on_disk

        cost = _NUMPY_CALL_S + (_NUMPY_BLOCK_S + _NUMPY_BLOCK_ROW_S * b) * blocks
        if _rent + cost <= COMPILE_AFTER and not _on_disk(_inertia):
            _rent += cost
            return False
        _compiled_ready = True
    return True


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
