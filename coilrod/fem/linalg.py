"""Sparse linear algebra of the FEM tangent: factorisation, solves, determinant sign, inertia.

The tangent ``K`` (free dofs, N/m) is symmetric and keeps one sparsity pattern for the whole
solve.  :class:`SymmetricFactorizer` computes a fill-reducing ordering ``p`` of that pattern
once (the cheaper of reverse Cuthill-McKee and SuperLU's minimum degree on ``A^T + A``, judged
on the first matrix) and then factorises every tangent as

    K[p][:, p] = L U,    U = D L^T     (SuperLU, natural order, symmetric mode, diagonal pivots)

so that, by Sylvester's law of inertia, the number of negative eigenvalues of ``K`` is the
number of negative entries of ``diag U``.  A zero pivot makes SuperLU pivot off the diagonal
for that column (the rows and columns are then permuted differently: the inertia is not
revealed, :func:`negative_eigenvalues` returns None); a tiny pivot that spoils the solve (its
backward error above :data:`BACKWARD_ERROR_LIMIT`) is replaced by threshold pivoting.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "BACKWARD_ERROR_LIMIT",
    "LU_OPTIONS",
    "SYMMETRIC_OPTIONS",
    "Factorization",
    "SymmetricFactorizer",
    "determinant_sign",
    "factorize",
    "fill_reducing_ordering",
    "negative_eigenvalues",
]

#: SuperLU options of the stateless :func:`factorize` (general LU, partial pivoting).
LU_OPTIONS = {"permc_spec": "COLAMD"}

#: SuperLU options of a factorisation in a precomputed symmetric ordering: natural column
#: order, symmetric mode and diagonal pivots (``P K P^T = L D L^T``).
SYMMETRIC_OPTIONS = {
    "permc_spec": "NATURAL",
    "diag_pivot_thresh": 0.0,
    "options": {"SymmetricMode": True},
}

#: Threshold pivoting used when the diagonal pivots are too small (SuperLU still prefers the
#: diagonal entry when it is within this fraction of the column's largest entry).
_THRESHOLD_OPTIONS = {
    "permc_spec": "NATURAL",
    "diag_pivot_thresh": 0.1,
    "options": {"SymmetricMode": True},
}

#: Largest normwise backward error ``|K x - b| / (|K| |x| + |b|)`` (infinity norms) accepted
#: for the first solve with diagonal pivots; above it the matrix is refactorised with threshold
#: pivoting.
BACKWARD_ERROR_LIMIT = 1e-9


def _superlu(A, options):
    from scipy.sparse.linalg import splu

    return splu(A, **options)


class Factorization:
    """LU factorisation of a symmetric matrix ``K`` in a symmetric ordering ``p``.

    ``K[p][:, p] = Pr^T L U Pc^T`` (SuperLU); with diagonal pivots ``Pr = Pc`` and
    ``U = D L^T``.  Use :meth:`solve`, :func:`determinant_sign` and
    :func:`negative_eigenvalues`.

    Parameters
    ----------
    lu : scipy.sparse.linalg.SuperLU
        Factorisation of the permuted matrix.
    perm : ndarray of int, shape (n,), or None
        The symmetric ordering ``p`` (None: identity).
    matrix : scipy.sparse.csr_matrix, optional
        ``K`` itself, kept to measure the backward error of the first solve.
    refactor : callable, optional
        Returns a threshold-pivoted :class:`scipy.sparse.linalg.SuperLU` of the permuted
        matrix; called once if the first solve's backward error is too large.
    """

    def __init__(self, lu, perm=None, matrix=None, refactor=None):
        self.lu = lu
        self.perm = None if perm is None else np.asarray(perm)
        self.shape = lu.shape
        self._matrix = matrix
        self._refactor = refactor
        self._checked = matrix is None or refactor is None
        self._negative = None
        self._sign = None

    @property
    def pivoted(self) -> bool:
        """True if some pivot left the diagonal (then the inertia is not revealed)."""
        return not np.array_equal(self.lu.perm_r, self.lu.perm_c)

    def _solve_permuted(self, b: np.ndarray) -> np.ndarray:
        if self.perm is None:
            return self.lu.solve(b)
        x = np.empty_like(b)
        x[self.perm] = self.lu.solve(b[self.perm])
        return x

    def solve(self, b) -> np.ndarray:
        """Solve ``K x = b``.

        Parameters
        ----------
        b : array_like, shape (n,) or (n, k)
            Right-hand side(s), in the units of the residual (N).

        Returns
        -------
        x : ndarray, same shape as ``b``
            Solution(s), m.
        """
        b = np.asarray(b, dtype=float)
        x = self._solve_permuted(b)
        if not self._checked:
            self._checked = True
            K = self._matrix
            absK = type(K)((np.abs(K.data), K.indices, K.indptr), shape=K.shape)
            norm_k = float((absK @ np.ones(K.shape[1])).max())
            r = K @ x - b
            eta = np.abs(r).max() / (norm_k * np.abs(x).max() + np.abs(b).max() + 1e-300)
            if not eta <= BACKWARD_ERROR_LIMIT:
                self.lu = self._refactor()
                self._negative = self._sign = None
                x = self._solve_permuted(b)
            self._matrix = self._refactor = None
        return x

    def negative_eigenvalues(self) -> int | None:
        """Number of negative eigenvalues of ``K`` if the pivots stayed on the diagonal."""
        if self._negative is None and not self.pivoted:
            self._negative = int(np.count_nonzero(self.lu.U.diagonal() < 0))
        return self._negative

    def determinant_sign(self) -> int:
        """Sign of ``det K``, +1 or -1 (the symmetric ordering does not change it)."""
        if self._sign is None:
            self._sign = _superlu_determinant_sign(self.lu)
        return self._sign


def fill_reducing_ordering(K, method: str = "rcm") -> np.ndarray:
    """A symmetric fill-reducing ordering of the sparsity pattern of ``K``.

    Parameters
    ----------
    K : scipy.sparse matrix, shape (n, n)
        Structurally symmetric matrix (only its pattern is used for "rcm"; "mmd" factorises
        it once).
    method : {"rcm", "mmd"}
        Reverse Cuthill-McKee (banded; near-optimal on slender meshes) or SuperLU's multiple
        minimum degree on ``A^T + A``.

    Returns
    -------
    p : ndarray of int, shape (n,)
        ``K[p][:, p]`` is the reordered matrix.
    """
    import scipy.sparse as sp

    if method == "rcm":
        from scipy.sparse.csgraph import reverse_cuthill_mckee

        return np.asarray(reverse_cuthill_mckee(sp.csr_matrix(K), symmetric_mode=True))
    if method == "mmd":
        options = dict(SYMMETRIC_OPTIONS, permc_spec="MMD_AT_PLUS_A")
        lu = _superlu(sp.csc_matrix(K), options)
        # perm_c[j] is the new position of column j
        return np.argsort(lu.perm_c)
    msg = f"method must be 'rcm' or 'mmd'; got {method!r}"
    raise ValueError(msg)


def _cholesky_flops(lu) -> float:
    """Operation count of a Cholesky factor with the structure of ``lu.L``: sum of squared
    column counts (the cost model by which orderings are compared)."""
    counts = np.diff(lu.L.tocsc().indptr) - 1
    return float(np.dot(counts.astype(float), counts))


class SymmetricFactorizer:
    """Factorises symmetric matrices that share one sparsity pattern (the FEM tangent).

    The first call orders the pattern (each of ``methods``; the one with the cheaper
    factor is kept) and builds the index map from ``K.data`` to the permuted matrix's CSC
    data; later calls with the same pattern only gather and factorise.

    Parameters
    ----------
    methods : tuple of str
        Orderings to try on the first matrix (see :func:`fill_reducing_ordering`).

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> K = sp.csr_matrix(np.array([[2.0, -1, 0], [-1, 2, -1], [0, -1, -3]]))
    >>> f = SymmetricFactorizer()(K)
    >>> np.allclose(K @ f.solve(np.ones(3)), 1.0), negative_eigenvalues(f)
    (True, 1)
    """

    def __init__(self, methods=("rcm", "mmd")):
        self.methods = tuple(methods)
        self.perm = None
        self.method = None
        self._pattern = None
        self._map = None
        self._indptr = self._indices = None

    def _same_pattern(self, K) -> bool:
        if self._pattern is None:
            return False
        indptr, indices = self._pattern
        if K.indptr is indptr and K.indices is indices:
            return True
        return np.array_equal(K.indptr, indptr) and np.array_equal(K.indices, indices)

    def _analyse(self, K) -> None:
        import scipy.sparse as sp

        K = sp.csr_matrix(K)
        K.sort_indices()
        best = None
        for method in self.methods:
            p = fill_reducing_ordering(K, method)
            try:
                lu = _superlu(sp.csc_matrix(K[p][:, p]), SYMMETRIC_OPTIONS)
            except RuntimeError:  # exactly singular in this ordering: not a candidate
                lu = None
            cost = _cholesky_flops(lu) if lu is not None else np.inf
            if best is None or cost < best[0]:
                best = (cost, method, p)
        _, self.method, p = best
        # index map: data of K (CSR) -> data of K[p][:, p] (CSC; symmetric pattern)
        index = sp.csr_matrix(
            (np.arange(1, K.nnz + 1, dtype=float), K.indices, K.indptr), shape=K.shape
        )
        Kp = sp.csc_matrix(index[p][:, p])
        Kp.sort_indices()
        self._map = Kp.data.astype(np.int64) - 1
        self._indptr, self._indices = Kp.indptr, Kp.indices
        self._pattern = (K.indptr, K.indices)
        self.perm = p

    def permuted(self, K):
        """``K[p][:, p]`` as a CSC matrix (a gather of ``K.data``), shape (n, n)."""
        import scipy.sparse as sp

        if not self._same_pattern(K):
            self._analyse(K)
        K = sp.csr_matrix(K)
        return sp.csc_matrix((K.data[self._map], self._indices, self._indptr), shape=K.shape)

    def __call__(self, K) -> Factorization:
        """Factorise ``K`` (CSR, symmetric, the pattern of the previous calls or a new one)."""
        Kp = self.permuted(K)
        try:
            lu = _superlu(Kp, SYMMETRIC_OPTIONS)
        except RuntimeError:  # exactly singular with the diagonal pivots: try threshold pivots
            lu = _superlu(Kp, _THRESHOLD_OPTIONS)
            return Factorization(lu, self.perm)
        return Factorization(lu, self.perm, K, lambda: _superlu(Kp, _THRESHOLD_OPTIONS))


def factorize(K) -> Factorization:
    """Sparse LU of the symmetric matrix ``K`` (CSR, whose arrays are also its CSC arrays).

    Stateless (general LU with partial pivoting and COLAMD); the FEM assembler keeps a
    :class:`SymmetricFactorizer` instead, which reuses the ordering of its fixed pattern and
    reveals the inertia.
    """
    return Factorization(_superlu(K.T, LU_OPTIONS))


def _permutation_parity(perm: np.ndarray) -> int:
    """Parity (0 even, 1 odd) of a permutation: (n - number of cycles) mod 2."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = perm.size
    graph = coo_matrix((np.ones(n), (np.arange(n), perm)), shape=(n, n))
    cycles = connected_components(graph, directed=True, connection="weak")[0]
    return (n - cycles) % 2


def _superlu_determinant_sign(lu) -> int:
    negative = int(np.count_nonzero(lu.U.diagonal() < 0))
    if np.array_equal(lu.perm_r, lu.perm_c):
        return -1 if negative % 2 else 1
    odd = (negative + _permutation_parity(lu.perm_r) + _permutation_parity(lu.perm_c)) % 2
    return -1 if odd else 1


def determinant_sign(factor) -> int:
    """Sign (+1 or -1) of the determinant of the factorised matrix.

    Parameters
    ----------
    factor : Factorization or scipy.sparse.linalg.SuperLU
        ``Pr A Pc = L U`` with unit-diagonal L: the sign is that of prod(diag U) times the
        parities of the two permutations (a symmetric reordering ``p`` does not change it).

    Returns
    -------
    int
        For a symmetric tangent, a change of sign along the path means an odd number of
        eigenvalues crossed zero: a loss (or gain) of stability.
    """
    if isinstance(factor, Factorization):
        return factor.determinant_sign()
    return _superlu_determinant_sign(factor)


def negative_eigenvalues(factor) -> int | None:
    """Number of negative eigenvalues of the factorised symmetric matrix, or None.

    Sylvester's law of inertia: ``P K P^T = L U`` with diagonal pivots (``Pr = Pc``) and a
    symmetric ``K`` has ``U = D L^T``, so ``K`` and ``D = diag U`` have the same number of
    negative eigenvalues.  When the factorisation pivoted off the diagonal the count is not
    revealed and None is returned (use :func:`determinant_sign` for its parity).

    Parameters
    ----------
    factor : Factorization or scipy.sparse.linalg.SuperLU
        Factorisation of a symmetric matrix.

    Returns
    -------
    int or None
        Unlike the determinant's sign, this count sees two eigenvalues crossing zero
        together (the double bending eigenvalues of a square section in 3D).
    """
    if isinstance(factor, Factorization):
        return factor.negative_eigenvalues()
    if not np.array_equal(factor.perm_r, factor.perm_c):
        return None
    return int(np.count_nonzero(factor.U.diagonal() < 0))
