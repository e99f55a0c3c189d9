"""Sparse linear algebra of the FEM tangent: factorisation, solves and the determinant's sign."""

from __future__ import annotations

import numpy as np

__all__ = ["LU_OPTIONS", "factorize", "determinant_sign"]

#: SuperLU options of the tangent factorisation (the tangent is symmetric).
LU_OPTIONS = {"permc_spec": "COLAMD"}


def factorize(K):
    """Sparse LU of the symmetric tangent ``K`` (CSR, whose arrays are also its CSC arrays)."""
    from scipy.sparse.linalg import splu

    return splu(K.T, **LU_OPTIONS)


def _permutation_parity(perm: np.ndarray) -> int:
    """Parity (0 even, 1 odd) of a permutation: (n - number of cycles) mod 2."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = perm.size
    graph = coo_matrix((np.ones(n), (np.arange(n), perm)), shape=(n, n))
    cycles = connected_components(graph, directed=True, connection="weak")[0]
    return (n - cycles) % 2


def determinant_sign(lu) -> int:
    """Sign (+1 or -1) of the determinant of the matrix factorised by ``scipy splu``.

    ``Pr A Pc = L U`` with unit-diagonal L: the sign is that of prod(diag U) times the
    parities of the two permutations.  For a symmetric tangent, a change of sign along the
    path means an odd number of eigenvalues crossed zero: a loss (or gain) of stability.
    """
    negative = int(np.count_nonzero(lu.U.diagonal() < 0))
    odd = (negative + _permutation_parity(lu.perm_r) + _permutation_parity(lu.perm_c)) % 2
    return -1 if odd else 1
