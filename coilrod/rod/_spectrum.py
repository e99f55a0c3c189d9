"""Smallest eigenvalue of a rod's second variation from its inverse (shared by the planar rod,
its out-of-plane block and the spatial rod)."""

from __future__ import annotations

import numpy as np

__all__ = ["closest_to_zero", "lowest_from_inverse"]


def closest_to_zero(matvec, size: int, sign: float) -> float:
    """Eigenvalue mu closest to zero of H z = mu W z from products ``matvec(v)`` with
    ``S = W^1/2 H^-1 W^1/2`` (size ``size``), by ARPACK on S's dominant eigenvalue 1 / mu;
    ``sign`` < 0 (an unstable state) makes a positive result negative (its closest-to-zero
    eigenvalue may be positive while another is negative)."""
    from scipy.sparse.linalg import LinearOperator, eigsh

    op = LinearOperator((size, size), matvec=matvec, dtype=float)
    sigma = eigsh(op, k=1, which="LM", tol=1e-10, return_eigenvectors=False)[0]
    mu = 1.0 / sigma
    if mu > 0 and sign < 0:
        return -abs(mu)
    return float(mu)


def lowest_from_inverse(S: np.ndarray) -> float:
    """Smallest eigenvalue mu of H z = mu W z from S = W^1/2 H^-1 W^1/2 (sigma = 1/mu), dense:
    the negative sigma closest to zero gives the most negative mu; sigma of |sigma| below
    1e-10 sigma_max are round-off (they would be eigenvalues mu beyond any physical load) and
    are ignored."""
    ev = np.linalg.eigvalsh(S)
    big = np.max(np.abs(ev))
    neg = ev[ev < -1e-10 * big]
    if neg.size:
        return float(1.0 / np.max(neg))
    pos = ev[ev > 0]
    return float(1.0 / np.max(pos)) if pos.size else float("nan")
