"""FEM linear algebra: factorisation, solves, determinant sign and inertia of the tangent.

Cross-checks (each against an independent reference):

* solves with one and several right-hand sides against ``scipy.sparse.linalg.spsolve``;
* the number of negative eigenvalues (Sylvester inertia of the LDL^T in a symmetric
  ordering) against ``numpy.linalg.eigvalsh`` of the dense tangent: a straight rod past its
  Euler load in an antiparallel field (3D square section: the two bending eigenvalues are
  negative together, which the determinant's sign cannot see), a rod in a compressive
  field gradient, the unloaded (positive definite) rod;
* the determinant's sign against ``numpy.linalg.slogdet``;
* zero and tiny diagonal pivots: the factorisation falls back to off-diagonal pivots, the
  solve stays accurate and the inertia is reported as unknown (None) or correct;
* a second matrix of the same pattern reuses the ordering, a new pattern is re-analysed;
* the level-by-level block Cholesky of slender matrices (a grid Laplacian numbered at random,
  the FEM tangent at a stable state) against ``spsolve``, its level structure against the
  grid's layers; indefinite slender matrices (Bunch-Kaufman levels) against ``spsolve``,
  ``eigvalsh`` and ``slogdet``, and the SuperLU fallback when a level's pivot is tiny (the
  exact dense solve).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

import coilrod
import coils
from coilrod import presets
from coilrod.fem.linalg import (
    BlockCholesky,
    BlockCholeskyFactor,
    SymmetricFactorizer,
    determinant_sign,
    factorize,
    fill_reducing_ordering,
    negative_eigenvalues,
)

L = 0.04
D = L / 20


def _dense_negatives(K) -> int:
    ev = np.linalg.eigvalsh(K.toarray())
    # the count is only meaningful if no eigenvalue sits at round-off level
    assert np.abs(ev).min() > 1e-12 * np.abs(ev).max()
    return int(np.count_nonzero(ev < 0))


def _equilibria(rod, field, scales, dim, elements):
    """The assembler and its evaluations at the converged states of ``scales``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", coilrod.StabilityWarning)
        res = coilrod.solve_fem(rod, field, scales, dim=dim, elements=elements)
    asm = res._asm
    return asm, [asm.evaluate(z, s) for z, s in zip(res._states, scales, strict=True)]


def _random_symmetric(n, negatives, seed=0, density=0.05):
    """Sparse symmetric matrix with a chosen number of negative eigenvalues."""
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=density, random_state=rng)
    A = A + A.T
    ev = np.linalg.eigvalsh(A.toarray())
    # shift so that exactly `negatives` eigenvalues lie below zero, away from it
    shift = -0.5 * (ev[negatives - 1] + ev[negatives]) if negatives else 1.0 - ev[0]
    return sp.csr_matrix(A + shift * sp.eye(n))


def test_solve_matches_spsolve_one_and_many_rhs():
    K = _random_symmetric(200, 7, seed=1)
    rng = np.random.default_rng(2)
    b, B = rng.normal(size=200), rng.normal(size=(200, 3))
    f = SymmetricFactorizer()(K)
    np.testing.assert_allclose(f.solve(b), spsolve(K.tocsc(), b), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(f.solve(B), spsolve(K.tocsc(), B), rtol=1e-9, atol=1e-12)
    assert f.solve(B).shape == (200, 3)
    # the stateless general LU agrees
    np.testing.assert_allclose(factorize(K).solve(B), spsolve(K.tocsc(), B), rtol=1e-9)


@pytest.mark.parametrize("block", [True, False])
@pytest.mark.parametrize("negatives", [0, 1, 2, 13])
def test_inertia_and_sign_of_random_symmetric_matrices(negatives, block):
    K = _random_symmetric(150, negatives, seed=negatives)
    f = SymmetricFactorizer(block=block)(K)
    assert negative_eigenvalues(f) == _dense_negatives(K) == negatives
    assert determinant_sign(f) == np.linalg.slogdet(K.toarray())[0]


@pytest.mark.parametrize("method", ["rcm", "mmd"])
def test_orderings_are_permutations_that_keep_the_inertia(method):
    K = _random_symmetric(120, 3, seed=5)
    p = fill_reducing_ordering(K, method)
    np.testing.assert_array_equal(np.sort(p), np.arange(120))
    f = SymmetricFactorizer(methods=(method,), block=False)(K)
    assert f.perm is not None
    assert negative_eigenvalues(f) == 3


def test_square_section_past_euler_load_has_two_negative_eigenvalues():
    """M along +x, B along -x: the straight rod is an equilibrium at every load; past the
    clamped-free Euler load lambda = pi^2/4 both bending modes of the square section are
    unstable.  Two eigenvalues cross zero together: det keeps its sign, the inertia does not."""
    rod = coilrod.Rod(L, 1e6, coilrod.Rectangle(D, D), presets.M1())
    field = coils.UniformField((-rod.field_for_lambda(1.0), 0.0, 0.0))
    asm, (ev_low, ev_high) = _equilibria(rod, field, [2.0, 3.5], 3, (8, 1, 1))
    low, high = asm.factorize(ev_low), asm.factorize(ev_high)
    K_low, K_high = ev_low.tangent, ev_high.tangent
    assert negative_eigenvalues(low) == _dense_negatives(K_low) == 0
    assert negative_eigenvalues(high) == _dense_negatives(K_high) == 2
    sign = np.linalg.slogdet(K_high.toarray())[0]
    assert determinant_sign(high) == determinant_sign(low) == sign == 1


def test_inertia_in_a_compressive_field_gradient():
    """Maxwell gradient with B antiparallel to M: the tangent at the straight configuration
    (which the solver, continued from the unloaded state, leaves for the stable bent branch)
    becomes indefinite as the compressive load grows."""
    rod = coilrod.Rod(L, 1e6, coilrod.Rectangle(D, D), presets.M1())
    g = 10 * rod.bending_stiffness / (rod.magnetization.max_magnitude(L) * rod.area * L**3)
    field = coils.LinearField(
        (0.0, 1e-2 * rod.field_for_lambda(1.0), 0.0), coils.maxwell_gradient(g), (0.0, 0.0, 0.0)
    )
    asm, _ = _equilibria(rod, field, [0.05], 2, (10, 1))
    evs = [asm.evaluate(np.zeros(asm.size), s) for s in (0.05, 2.0, 4.0)]
    counts = []
    for ev in evs:
        K, f = ev.tangent, asm.factorize(ev)
        counts.append(negative_eigenvalues(f))
        assert counts[-1] == _dense_negatives(K)
        assert determinant_sign(f) == np.linalg.slogdet(K.toarray())[0]
    assert counts[0] == 0
    assert counts[-1] >= 1


def test_zero_diagonal_pivot_falls_back_to_off_diagonal_pivots():
    # [[0, 1], [1, 0]] blocks: every diagonal pivot is zero; eigenvalues +-1
    K = sp.csr_matrix(sp.kron(sp.eye(5), np.array([[0.0, 1.0], [1.0, 0.0]])))
    f = SymmetricFactorizer()(K)
    b = np.arange(1.0, 11.0)
    np.testing.assert_allclose(f.solve(b), spsolve(K.tocsc(), b), rtol=1e-12)
    assert negative_eigenvalues(f) in (None, 5)  # None: the pivots left the diagonal
    assert determinant_sign(f) == np.linalg.slogdet(K.toarray())[0] == -1


def test_tiny_diagonal_pivots_are_refactorised_with_threshold_pivoting():
    # [[e, 1], [1, e]] blocks, e = 1e-20: well conditioned (eigenvalues ~ +-1), but LDL^T with
    # diagonal pivots computes d2 = e - 1/e and loses the solution entirely
    K = sp.csr_matrix(sp.kron(sp.eye(5), np.array([[1e-20, 1.0], [1.0, 1e-20]])))
    f = SymmetricFactorizer()(K)
    diagonal = f.lu
    b = np.tile([1.0, 2.0], 5)
    x = f.solve(b)
    assert f.lu is not diagonal  # refactorised
    np.testing.assert_allclose(x, np.linalg.solve(K.toarray(), b), rtol=1e-12)
    assert np.abs(K @ x - b).max() < 1e-12
    assert negative_eigenvalues(f) in (None, 5)
    assert determinant_sign(f) == np.linalg.slogdet(K.toarray())[0] == -1


def test_same_pattern_reuses_the_ordering_new_pattern_is_analysed():
    K1 = _random_symmetric(100, 2, seed=8)
    factorizer = SymmetricFactorizer()
    factorizer(K1)
    perm = factorizer.perm
    K2 = sp.csr_matrix((K1.data * 1.5 + 0.1, K1.indices, K1.indptr), shape=K1.shape)
    f2 = factorizer(K2)
    assert factorizer.perm is perm
    b = np.ones(100)
    np.testing.assert_allclose(f2.solve(b), spsolve(K2.tocsc(), b), rtol=1e-9, atol=1e-12)
    K3 = _random_symmetric(100, 4, seed=9)
    f3 = factorizer(K3)
    assert factorizer.perm is not perm
    np.testing.assert_allclose(f3.solve(b), spsolve(K3.tocsc(), b), rtol=1e-9, atol=1e-12)
    assert negative_eigenvalues(f3) == 4


def _slender_laplacian(nx=30, ny=3, nz=3, shift=0.0):
    """7-point Laplacian (+ shift I) of a slender nx x ny x nz grid, dofs numbered at random;
    the grid points of the x = 0 face are returned as the level-0 dofs."""
    n = nx * ny * nz
    idx = np.arange(n).reshape(nx, ny, nz)
    rows, cols = [np.arange(n)], [np.arange(n)]
    vals = [np.full(n, 6.0 + shift)]
    for axis in range(3):
        lo = np.take(idx, np.arange(idx.shape[axis] - 1), axis=axis).ravel()
        hi = np.take(idx, np.arange(1, idx.shape[axis]), axis=axis).ravel()
        rows += [lo, hi]
        cols += [hi, lo]
        vals += [-np.ones(lo.size), -np.ones(lo.size)]
    K = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))))
    p = np.random.default_rng(0).permutation(n)
    Kp = sp.csr_matrix(K[p][:, p])
    Kp.sort_indices()
    start = np.flatnonzero(np.isin(p, idx[0].ravel()))
    return Kp, start


@pytest.fixture
def always_block(monkeypatch):
    """Make the factorizer choose the block Cholesky whenever the levels allow it (the cost
    model would give small test matrices to SuperLU)."""
    from coilrod.fem import linalg

    monkeypatch.setattr(linalg, "BLOCK_FLOP_RATIO", np.inf)
    monkeypatch.setattr(linalg, "BLOCK_LEVEL_COST", 0.0)


@pytest.mark.usefixtures("always_block")
def test_block_cholesky_of_a_slender_positive_definite_matrix():
    K, start = _slender_laplacian(shift=0.1)
    block = BlockCholesky(K, start)
    # the x = 0 face starts the levels: one grid layer per level
    np.testing.assert_array_equal(block.sizes, np.full(30, 9))
    factorizer = SymmetricFactorizer(start=start)
    f = factorizer(K)
    assert isinstance(f, BlockCholeskyFactor)
    rng = np.random.default_rng(1)
    b, B = rng.normal(size=K.shape[0]), rng.normal(size=(K.shape[0], 3))
    np.testing.assert_allclose(f.solve(b), spsolve(K.tocsc(), b), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(f.solve(B), spsolve(K.tocsc(), B), rtol=1e-10, atol=1e-12)
    assert negative_eigenvalues(f) == _dense_negatives(K) == 0
    assert determinant_sign(f) == np.linalg.slogdet(K.toarray())[0] == 1
    # without start dofs: a pseudo-peripheral dof starts the levels
    g = SymmetricFactorizer()(K)
    np.testing.assert_allclose(g.solve(b), spsolve(K.tocsc(), b), rtol=1e-10, atol=1e-12)


@pytest.mark.usefixtures("always_block")
@pytest.mark.parametrize("shift", [-1.5, -2.5, -4.0])
def test_block_factor_of_indefinite_matrices_has_bunch_kaufman_levels(shift):
    K, start = _slender_laplacian(shift=shift)  # lowest Laplacian eigenvalue ~ 1.18
    factorizer = SymmetricFactorizer(start=start)
    f = factorizer(K)
    assert isinstance(f, BlockCholeskyFactor)
    assert not f.definite
    rng = np.random.default_rng(4)
    b, B = rng.normal(size=K.shape[0]), rng.normal(size=(K.shape[0], 3))
    np.testing.assert_allclose(f.solve(b), spsolve(K.tocsc(), b), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(f.solve(B), spsolve(K.tocsc(), B), rtol=1e-9, atol=1e-12)
    assert negative_eigenvalues(f) == _dense_negatives(K) > 0
    assert determinant_sign(f) == np.linalg.slogdet(K.toarray())[0]
    assert f._replacement is None  # accurate: no SuperLU
    # the next positive definite matrix of the pattern is a plain block Cholesky again
    spd = sp.csr_matrix(
        (
            K.data + 6.0 * (K.indices == np.repeat(np.arange(K.shape[0]), np.diff(K.indptr))),
            K.indices,
            K.indptr,
        ),
        shape=K.shape,
    )
    g = factorizer(spd)
    assert isinstance(g, BlockCholeskyFactor)
    assert g.definite
    assert negative_eigenvalues(g) == _dense_negatives(spd) == 0


@pytest.mark.usefixtures("always_block")
def test_block_factor_with_a_tiny_level_pivot_is_replaced_by_superlu():
    """A chain of [[e, 1], [1, e]] blocks (e = 1e-20) weakly coupled: well conditioned
    (eigenvalues ~ +-1) but its levels (one dof each from dof 0) have Schur complements e and
    e - 1/e: the block elimination loses the solution, the backward error of the first solve
    shows it and SuperLU takes over."""
    n = 10
    e = 1e-20
    main = np.full(n, e)
    off = np.where(np.arange(n - 1) % 2 == 0, 1.0, 1e-3)
    K = sp.csr_matrix(sp.diags([off, main, off], [-1, 0, 1]))
    K.sort_indices()
    f = SymmetricFactorizer(start=[0])(K)
    assert isinstance(f, BlockCholeskyFactor)
    b = np.arange(1.0, n + 1)
    x = f.solve(b)
    assert f._replacement is not None
    np.testing.assert_allclose(x, np.linalg.solve(K.toarray(), b), rtol=1e-10)
    assert negative_eigenvalues(f) in (None, _dense_negatives(K))
    assert determinant_sign(f) == np.linalg.slogdet(K.toarray())[0]


def test_fem_tangent_uses_the_block_cholesky_at_a_stable_state():
    # (chosen by the cost model itself: a 3D Q2 rod mesh)
    rod = coilrod.Rod(L, 1e6, coilrod.Rectangle(D, D), presets.M1())
    field = coils.UniformField((0.0, rod.field_for_lambda(1.0), 0.0))
    asm, (ev,) = _equilibria(rod, field, [3.0], 3, (6, 1, 1))
    f = asm.factorize(ev)
    assert isinstance(f, BlockCholeskyFactor)
    K = ev.tangent
    assert _dense_negatives(K) == 0
    rng = np.random.default_rng(3)
    b = rng.normal(size=(K.shape[0], 2))
    x = f.solve(b)
    ref = spsolve(K.tocsc(), b)
    # backward stable: normwise backward error at round-off level
    norm_k = abs(K).sum(axis=1).max()
    eta = np.abs(K @ x - b).max() / (norm_k * np.abs(x).max() + np.abs(b).max())
    assert eta < 1e-13
    # the tangent is ill conditioned (K/G ~ 1000, slender): the solves agree to cond * eps
    cond = np.linalg.cond(K.toarray())
    assert np.abs(x - ref).max() <= 1e-15 * cond * np.abs(ref).max()


def test_envelope_cost_bounds_the_rcm_factor_of_superlu():
    """The cost model's sparse figure, computed from the pattern alone, against the operation
    count of SuperLU's factor in the same RCM ordering: equal where the factor fills its
    envelope (the slender grid), never below it (a random pattern)."""
    from coilrod.fem.linalg import (
        SYMMETRIC_OPTIONS,
        _cholesky_flops,
        _envelope_flops,
        _superlu,
    )

    for K, equal in ((_slender_laplacian(shift=0.1)[0], True), (_random_symmetric(150, 0), False)):
        p = fill_reducing_ordering(K, "rcm")
        lu = _superlu(sp.csc_matrix(K[p][:, p]), SYMMETRIC_OPTIONS)
        exact = _cholesky_flops(lu)
        if equal:
            assert _envelope_flops(K) == pytest.approx(exact, rel=1e-12)
        else:
            assert _envelope_flops(K) >= exact
