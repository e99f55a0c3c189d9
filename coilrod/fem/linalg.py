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

Slender bodies (the rod meshes) have a level structure: ordered by breadth-first levels from
the clamped end, ``K`` is block tridiagonal and each level couples forward only through its
last rows.  :class:`BlockCholesky` factorises such a matrix level by level with dense LAPACK
(``potrf``, ``trsm``, ``syrk``), several times faster than SuperLU's sparse LU there; a level
whose Schur complement is indefinite (a Newton iterate off the path, an unstable state) is
factorised by Bunch-Kaufman (``sytrf``) instead, 2-4 times faster than SuperLU's LDL^T of the
whole matrix.  The levels' pivots reveal the inertia; the first solve with an indefinite factor
checks its backward error and SuperLU takes over if it is too large (a nearly singular level).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "BACKWARD_ERROR_LIMIT",
    "BLOCK_FLOP_RATIO",
    "BLOCK_LEVEL_COST",
    "BLOCK_MAX_LEVEL",
    "SPARSE_DOF_COST",
    "BlockCholesky",
    "BlockCholeskyFactor",
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

#: Cost model of the choice between the level-by-level dense Cholesky and SuperLU, in units
#: of one SuperLU operation (measured on a 2-core AMD EPYC, single-threaded OpenBLAS): dense
#: BLAS-3 runs this many times faster per operation, ...
BLOCK_FLOP_RATIO = 6.0
#: ... each level costs about this much in call overhead (factorisation and one solve), ...
BLOCK_LEVEL_COST = 6e4
#: ... and SuperLU about this much per dof besides its operations.
SPARSE_DOF_COST = 2.7e3

#: Largest level (dofs) of the block Cholesky: bounds the dense blocks' memory and time.
BLOCK_MAX_LEVEL = 4000


def backward_error(K, x: np.ndarray, b: np.ndarray) -> float:
    """Normwise backward error ``|K x - b| / (|K| |x| + |b|)`` (infinity norms) of a solve."""
    absK = type(K)((np.abs(K.data), K.indices, K.indptr), shape=K.shape)
    norm_k = float((absK @ np.ones(K.shape[1])).max())
    r = K @ x - b
    return float(np.abs(r).max() / (norm_k * np.abs(x).max() + np.abs(b).max() + 1e-300))


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
            if not backward_error(self._matrix, x, b) <= BACKWARD_ERROR_LIMIT:
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


class BlockCholesky:
    """Level-by-level dense Cholesky of a matrix that is block tridiagonal in its level order.

    Analysis (once per sparsity pattern): breadth-first levels of the matrix graph from the
    ``start`` dofs; inside a level, the rows that couple to the next level come last.  Then
    ``K`` (in that order) has diagonal blocks ``A_k`` (``m_k`` square) and forward couplings
    ``C_k`` that are nonzero only in the last ``q_k`` rows of level ``k``, and

        S_0 = A_0,   S_k = L_k L_k^T,   W_k = (L_k)_qq^-1 (C_k)_q,   S_k+1 = A_k+1 - W_k^T W_k,

    with ``(L_k)_qq`` the trailing ``q_k x q_k`` block of ``L_k``: the Cholesky factor of the
    Schur complement that the next level sees.  An indefinite ``S_k`` is factorised by
    Bunch-Kaufman instead, ``S_k = P L D L^T P^T``, and passes on
    ``S_k+1 = A_k+1 - C_q^T (S_k^-1)_qq C_q`` (:meth:`factor`).

    Parameters
    ----------
    K : scipy.sparse matrix, shape (n, n)
        Structurally symmetric; only its pattern is used.
    start : array_like of int
        Dofs of level 0 (the clamped end of a rod).

    Attributes
    ----------
    perm : ndarray of int, shape (n,)
        Level order: ``K[perm][:, perm]`` is block tridiagonal.
    sizes, couplings : ndarray of int, shape (n_levels,)
        ``m_k`` and ``q_k``.
    flops : float
        Operation count of one factorisation (``sum m^3/3 + q^2 m' + q m'^2``).
    """

    def __init__(self, K, start):
        import scipy.sparse as sp
        from scipy.sparse.csgraph import dijkstra

        K = sp.csr_matrix(K)
        n = K.shape[0]
        rows = np.repeat(np.arange(n), np.diff(K.indptr))
        cols = K.indices
        graph = sp.csr_matrix((np.ones(cols.size), cols, K.indptr), shape=K.shape)
        dist = dijkstra(graph, indices=np.asarray(start), min_only=True, unweighted=True)
        if not np.all(np.isfinite(dist)):
            msg = "the matrix graph is not connected to the start dofs"
            raise ValueError(msg)
        level = dist.astype(np.int64)
        n_levels = int(level.max()) + 1
        forward = np.zeros(n, bool)
        forward[rows[level[cols] == level[rows] + 1]] = True
        order = np.lexsort((forward, level))
        pos = np.empty(n, np.int64)
        pos[order] = np.arange(n)
        starts = np.searchsorted(level[order], np.arange(n_levels + 1))
        sizes = np.diff(starts)
        q = np.bincount(level[forward], minlength=n_levels)
        self.n, self.perm, self.starts = n, order, starts
        self.sizes, self.couplings = sizes, q
        m, m2, qq = sizes.astype(float), sizes[1:].astype(float), q[:-1].astype(float)
        self.flops = float((m**3 / 3).sum() + (qq**2 * m2).sum() + (qq * m2**2).sum())
        # scatter maps from K.data: the lower triangle of each diagonal block, stored column-
        # major (a Fortran view of the C buffer), and each coupling block C_k (q_k x m_k+1),
        # column-major
        lr, lc = level[rows], level[cols]
        i, j = pos[rows] - starts[lr], pos[cols] - starts[lc]
        self._doff = np.concatenate([[0], np.cumsum(sizes**2)])
        diag = np.flatnonzero((lr == lc) & (i >= j))
        self._dsrc = diag
        self._ddst = self._doff[lr[diag]] + j[diag] * sizes[lr[diag]] + i[diag]
        self._coff = np.concatenate([[0], np.cumsum(q[:-1] * sizes[1:])])
        up = np.flatnonzero(lc == lr + 1)
        k = lr[up]
        ci = i[up] - (sizes[k] - q[k])  # row among the q_k coupling rows
        self._csrc = up
        self._cdst = self._coff[k] + j[up] * q[k] + ci

    def factor(self, K) -> BlockCholeskyFactor | None:
        """Factorise ``K`` (CSR with the analysed pattern) level by level.

        Each Schur complement ``S_k`` is factorised by Cholesky (``potrf``) when it is
        positive definite and otherwise by Bunch-Kaufman (``sytrf``, ``S_k = P L D L^T P^T``):
        ``K`` is then congruent to ``diag(S_k)``, so its number of negative eigenvalues is the
        sum over the levels (Sylvester).  Returns None if some ``S_k`` is exactly singular.
        """
        D = np.zeros(self._doff[-1])
        D[self._ddst] = K.data[self._dsrc]
        C = np.zeros(self._coff[-1])
        C[self._cdst] = K.data[self._csrc]
        sizes, q = self.sizes, self.couplings
        levels = []
        update = None
        for k in range(sizes.size):
            m = sizes[k]
            S = D[self._doff[k] : self._doff[k + 1]].reshape(m, m).T  # column-major view
            if update is not None:
                S -= update
            Ck = None
            if k + 1 < sizes.size and q[k] > 0:
                Ck = C[self._coff[k] : self._coff[k + 1]].reshape(sizes[k + 1], q[k]).T
            level = _CholeskyLevel.make(S, Ck)
            if level is None:
                level = _LDLLevel.make(S, Ck)
                if level is None:
                    return None
            levels.append(level)
            update = level.update
            level.update = None
        return BlockCholeskyFactor(self, levels)


class _CholeskyLevel:
    """A positive definite level: ``S = L L^T``; ``W = L_qq^-1 C_q`` couples it forward."""

    negatives = 0

    @classmethod
    def make(cls, S, Ck):
        from scipy.linalg.blas import dsyrk, dtrmm
        from scipy.linalg.lapack import dpotrf, dtrtri

        L, info = dpotrf(S, lower=1, clean=0, overwrite_a=0)
        if info != 0:
            return None
        self = cls()
        self.L, self.W, self.update = L, None, None
        if Ck is not None:
            m, qk = L.shape[0], Ck.shape[0]
            # W = L_qq^-1 C_q through the triangular inverse (trtri + trmm: half the time of
            # OpenBLAS's trsm here; a well-conditioned Cholesky factor)
            Li, info = dtrtri(L[m - qk :, m - qk :], lower=1)
            if info != 0:
                return None
            self.W = dtrmm(1.0, Li, Ck, lower=1)
            self.update = dsyrk(1.0, self.W, trans=1, lower=1)  # lower triangle of W^T W
        return self

    def forward(self, v):
        """``y = L^-1 v`` and the next level's correction ``C^T S^-1 v = W^T y_q``."""
        from scipy.linalg.blas import dtrsm

        y = dtrsm(1.0, self.L, v, lower=1)
        if self.W is None:
            return y, None
        return y, self.W.T @ y[y.shape[0] - self.W.shape[0] :]

    def backward(self, y, x_next):
        """``x = S^-1 v - S^-1 C x_next`` from the forward's ``y``."""
        from scipy.linalg.blas import dtrsm

        if x_next is not None and self.W is not None:
            y = y.copy()
            y[y.shape[0] - self.W.shape[0] :] -= self.W @ x_next
        return dtrsm(1.0, self.L, y, lower=1, trans_a=1)


class _LDLLevel:
    """An indefinite level: ``S = P L D L^T P^T`` (Bunch-Kaufman); ``X = S^-1 E_q`` (the
    columns of ``S^-1`` of the coupling rows) couples it forward."""

    @classmethod
    def make(cls, S, Ck):
        from scipy.linalg.lapack import dsytrf, dsytrf_lwork, dsytrs

        m = S.shape[0]
        lwork, _ = dsytrf_lwork(m, lower=1)
        lu, ipiv, info = dsytrf(S, lower=1, lwork=int(lwork), overwrite_a=0)
        if info != 0:  # an exactly zero pivot
            return None
        self = cls()
        self.lu, self.ipiv = lu, ipiv
        self.negatives = _bunch_kaufman_negatives(lu, ipiv)
        self.C, self.X, self.update = Ck, None, None
        if Ck is not None:
            qk = Ck.shape[0]
            E = np.zeros((m, qk), order="F")
            E[m - qk :] = np.eye(qk)
            X, info = dsytrs(lu, ipiv, E, lower=1)
            self.X = X
            self.update = Ck.T @ (X[m - qk :] @ Ck)
        return self

    def _solve(self, v):
        from scipy.linalg.lapack import dsytrs

        x, _ = dsytrs(self.lu, self.ipiv, v, lower=1)
        return x

    def forward(self, v):
        """``t = S^-1 v`` and the next level's correction ``C^T t_q``."""
        t = self._solve(v)
        if self.C is None:
            return t, None
        return t, self.C.T @ t[t.shape[0] - self.C.shape[0] :]

    def backward(self, t, x_next):
        """``x = t - S^-1 C x_next = t - X (C_q x_next)``."""
        if x_next is None or self.C is None:
            return t
        return t - self.X @ (self.C @ x_next)


def _bunch_kaufman_negatives(lu, ipiv) -> int:
    """Negative eigenvalues of the block diagonal ``D`` of a lower ``sytrf`` factorisation:
    1x1 pivots where ``ipiv > 0``, 2x2 pivots on rows ``i, i+1`` where ``ipiv[i] < 0``."""
    d = np.diag(lu).copy()
    ip = np.asarray(ipiv)
    count = 0
    i = 0
    n = d.size
    two = np.flatnonzero(ip < 0)
    if two.size == 0:
        return int(np.count_nonzero(d < 0))
    single = np.ones(n, bool)
    while i < n:
        if ip[i] < 0:
            a, b, c = d[i], lu[i + 1, i], d[i + 1]
            det = a * c - b * b
            count += 1 if det < 0 else (2 if a + c < 0 else 0)
            single[i : i + 2] = False
            i += 2
        else:
            i += 1
    return count + int(np.count_nonzero(d[single] < 0))


class BlockCholeskyFactor:
    """A :class:`BlockCholesky` factorisation ``K = L diag(S_k) L^T`` (block unit lower
    bidiagonal ``L``), each ``S_k`` by Cholesky or, where indefinite, Bunch-Kaufman."""

    def __init__(self, analysis: BlockCholesky, levels):
        self.analysis = analysis
        self.levels = levels
        self.shape = (analysis.n, analysis.n)
        self._negative = int(sum(level.negatives for level in levels))
        self._matrix = self._fallback = self._replacement = None

    @property
    def pivoted(self) -> bool:
        """False: the levels' pivots reveal the inertia (unless SuperLU replaced them)."""
        return self._replacement is not None and self._replacement.pivoted

    @property
    def definite(self) -> bool:
        """True if every level is positive definite (then ``K`` is)."""
        return self._negative == 0 and all(isinstance(v, _CholeskyLevel) for v in self.levels)

    def solve(self, b) -> np.ndarray:
        """Solve ``K x = b`` for ``b`` of shape (n,) or (n, k); returns the same shape."""
        b = np.asarray(b, dtype=float)
        if self._replacement is not None:
            return self._replacement.solve(b)
        x = self._solve(b)
        if self._matrix is not None:
            K, self._matrix = self._matrix, None
            if not backward_error(K, x, b) <= BACKWARD_ERROR_LIMIT:
                self._replacement = self._fallback()
                x = self._replacement.solve(b)
            self._fallback = None
        return x

    def _solve(self, b: np.ndarray) -> np.ndarray:
        an = self.analysis
        B = b.reshape(an.n, -1)[an.perm]
        Y = []
        correction = None
        for k, level in enumerate(self.levels):
            rhs = B[an.starts[k] : an.starts[k + 1]]
            if correction is not None:
                rhs = rhs - correction
            y, correction = level.forward(rhs)
            Y.append(y)
        X = np.empty_like(B)
        x = None
        for k in range(len(self.levels) - 1, -1, -1):
            x = self.levels[k].backward(Y[k], x)
            X[an.starts[k] : an.starts[k + 1]] = x
        out = np.empty_like(X)
        out[an.perm] = X
        return out.reshape(b.shape)

    def check(self, K, fallback) -> None:
        """Measure the backward error of the first solve against ``K``; above
        :data:`BACKWARD_ERROR_LIMIT`, that solve and every later one (and the inertia) come
        from ``fallback()`` (a :class:`Factorization`)."""
        self._matrix, self._fallback = K, fallback

    def negative_eigenvalues(self) -> int | None:
        """Number of negative eigenvalues: the sum over the levels' pivots (Sylvester)."""
        if self._replacement is not None:
            return self._replacement.negative_eigenvalues()
        return self._negative

    def determinant_sign(self) -> int:
        """Sign of ``det K``: ``(-1)^(negative eigenvalues)``."""
        if self._replacement is not None:
            return self._replacement.determinant_sign()
        return -1 if self._negative % 2 else 1


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


def _envelope_flops(K) -> float:
    """Operation count (sum of squared off-diagonal column counts) of a Cholesky factor that
    fills the envelope of ``K`` in the reverse Cuthill-McKee ordering: the cost model's figure
    for the sparse factorisation, an upper bound of the RCM factor's (:func:`_cholesky_flops`)
    obtained without factorising."""
    import scipy.sparse as sp

    n = K.shape[0]
    p = fill_reducing_ordering(K, "rcm")
    Kp = sp.csr_matrix(sp.csr_matrix(K)[p][:, p])
    Kp.sort_indices()
    rows = np.arange(n)
    nonempty = np.diff(Kp.indptr) > 0
    first = rows.copy()
    first[nonempty] = np.minimum(Kp.indices[Kp.indptr[:-1][nonempty]], rows[nonempty])
    # row i fills columns first[i] .. i-1 of the factor
    counts = np.cumsum(np.bincount(first, minlength=n + 1) - np.bincount(rows, minlength=n + 1))
    counts = counts[:n].astype(float)
    return float(np.dot(counts, counts))


def _cholesky_flops(lu) -> float:
    """Operation count of a Cholesky factor with the structure of ``lu.L``: sum of squared
    column counts (the cost model by which orderings are compared)."""
    counts = np.diff(lu.L.tocsc().indptr) - 1
    return float(np.dot(counts.astype(float), counts))


class SymmetricFactorizer:
    """Factorises symmetric matrices that share one sparsity pattern (the FEM tangent).

    The first call analyses the pattern; the first SuperLU factorisation orders it (each of
    ``methods``; the one with the cheaper factor is kept) and builds the index map from
    ``K.data`` to the permuted matrix's CSC data; later calls with the same pattern only
    gather and factorise.

    When a level structure from ``start`` makes the matrix block tridiagonal with a dense
    factorisation cheaper than the sparse one in the RCM envelope (:data:`BLOCK_FLOP_RATIO`,
    :data:`BLOCK_LEVEL_COST`, :data:`SPARSE_DOF_COST`: a model of the time of each;
    :func:`_envelope_flops`), matrices are factorised by
    :class:`BlockCholesky` (Cholesky levels, Bunch-Kaufman where a level is indefinite); the
    others -- and an indefinite block factor whose first solve has a backward error above
    :data:`BACKWARD_ERROR_LIMIT` -- by SuperLU in symmetric mode.

    Parameters
    ----------
    methods : tuple of str
        Orderings to try on the first matrix (see :func:`fill_reducing_ordering`).
    start : array_like of int, optional
        Level-0 dofs of the block Cholesky (the clamped end); None: a pseudo-peripheral dof.
    block : bool
        Allow the block Cholesky.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> K = sp.csr_matrix(np.array([[2.0, -1, 0], [-1, 2, -1], [0, -1, -3]]))
    >>> f = SymmetricFactorizer()(K)
    >>> np.allclose(K @ f.solve(np.ones(3)), 1.0), negative_eigenvalues(f)
    (True, 1)
    """

    def __init__(self, methods=("rcm", "mmd"), start=None, block: bool = True):
        self.methods = tuple(methods)
        self.start = None if start is None else np.asarray(start)
        self.allow_block = bool(block)
        self._perm = None
        self.method = None
        self.block = None
        self._pattern = None
        self._pending = None  # the pattern's matrix while its SuperLU ordering is not computed
        self._map = None
        self._indptr = self._indices = None

    @property
    def perm(self):
        """The SuperLU fill-reducing ordering of the pattern (computed on first use: the
        block factorisation does not need it)."""
        if self._perm is None and self._pending is not None:
            self._order(self._pending)
        return self._perm

    def _same_pattern(self, K) -> bool:
        if self._pattern is None:
            return False
        indptr, indices = self._pattern
        if K.indptr is indptr and K.indices is indices:
            return True
        return np.array_equal(K.indptr, indptr) and np.array_equal(K.indices, indices)

    def _analyse(self, K) -> None:
        """A new pattern: the block analysis now, the SuperLU ordering when first needed."""
        import scipy.sparse as sp

        K = sp.csr_matrix(K)
        K.sort_indices()
        self._pattern = (K.indptr, K.indices)
        self._perm = self.method = self._map = None
        self._pending = K
        self.block = None
        if self.allow_block:
            self.block = self._block_analysis(K, _envelope_flops(K))

    def _order(self, K) -> None:
        """The cheapest of ``methods`` (by the factor's operation count) and the index map."""
        import scipy.sparse as sp

        best = None
        for method in self.methods:
            try:
                if method == "mmd":  # one factorisation gives the ordering and its cost
                    options = dict(SYMMETRIC_OPTIONS, permc_spec="MMD_AT_PLUS_A")
                    lu = _superlu(sp.csc_matrix(K), options)
                    p = np.argsort(lu.perm_c)
                else:
                    p = fill_reducing_ordering(K, method)
                    lu = _superlu(sp.csc_matrix(K[p][:, p]), SYMMETRIC_OPTIONS)
                cost = _cholesky_flops(lu)
            except RuntimeError:  # exactly singular in this ordering: not a candidate
                continue
            if best is None or cost < best[0]:
                best = (cost, method, p)
        if best is None:
            best = (np.inf, "rcm", fill_reducing_ordering(K, "rcm"))
        _, self.method, p = best
        # index map: data of K (CSR) -> data of K[p][:, p] (CSC; symmetric pattern)
        index = sp.csr_matrix(
            (np.arange(1, K.nnz + 1, dtype=float), K.indices, K.indptr), shape=K.shape
        )
        Kp = sp.csc_matrix(index[p][:, p])
        Kp.sort_indices()
        self._map = Kp.data.astype(np.int64) - 1
        self._indptr, self._indices = Kp.indptr, Kp.indices
        self._perm = p
        self._pending = None

    def _block_analysis(self, K, sparse_flops: float):
        start = self.start
        if start is None:  # pseudo-peripheral: the last dof reached from dof 0
            from scipy.sparse.csgraph import breadth_first_order

            start = [breadth_first_order(K, 0, directed=False, return_predecessors=False)[-1]]
        try:
            block = BlockCholesky(K, start)
        except ValueError:  # not connected
            return None
        block_cost = block.flops / BLOCK_FLOP_RATIO + BLOCK_LEVEL_COST * block.sizes.size
        sparse_cost = sparse_flops + SPARSE_DOF_COST * K.shape[0]
        if block.sizes.max() > BLOCK_MAX_LEVEL or block_cost > sparse_cost:
            return None
        return block

    def permuted(self, K):
        """``K[p][:, p]`` as a CSC matrix (a gather of ``K.data``), shape (n, n)."""
        import scipy.sparse as sp

        if not self._same_pattern(K):
            self._analyse(K)
        if self._map is None:
            self._order(self._pending)
        K = sp.csr_matrix(K)
        return sp.csc_matrix((K.data[self._map], self._indices, self._indptr), shape=K.shape)

    def __call__(self, K):
        """Factorise ``K`` (CSR, symmetric, the pattern of the previous calls or a new one).

        Returns a :class:`BlockCholeskyFactor` or a :class:`Factorization`; both have
        ``solve(b)`` and are read by :func:`determinant_sign` and :func:`negative_eigenvalues`.
        """
        if not self._same_pattern(K):
            self._analyse(K)
        if self.block is not None:
            factor = self.block.factor(K)
            if factor is not None:
                if not factor.definite:  # check the first solve (nearly singular levels)
                    factor.check(K, lambda: self._superlu(K))
                return factor
        return self._superlu(K)

    def _superlu(self, K):
        """SuperLU LDL^T in the analysed ordering (threshold pivots if exactly singular)."""
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
    factor : Factorization, BlockCholeskyFactor or scipy.sparse.linalg.SuperLU
        ``Pr A Pc = L U`` with unit-diagonal L: the sign is that of prod(diag U) times the
        parities of the two permutations (a symmetric reordering ``p`` does not change it).

    Returns
    -------
    int
        For a symmetric tangent, a change of sign along the path means an odd number of
        eigenvalues crossed zero: a loss (or gain) of stability.
    """
    if hasattr(factor, "determinant_sign"):
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
    factor : Factorization, BlockCholeskyFactor or scipy.sparse.linalg.SuperLU
        Factorisation of a symmetric matrix (a Cholesky factor: 0).

    Returns
    -------
    int or None
        Unlike the determinant's sign, this count sees two eigenvalues crossing zero
        together (the double bending eigenvalues of a square section in 3D).
    """
    if hasattr(factor, "negative_eigenvalues"):
        return factor.negative_eigenvalues()
    if not np.array_equal(factor.perm_r, factor.perm_c):
        return None
    return int(np.count_nonzero(factor.U.diagonal() < 0))
