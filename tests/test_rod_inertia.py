"""Block LDL^T inertia count (coilrod.rod._inertia) against dense eigenvalues.

Reference: ``np.linalg.eigvalsh`` of the assembled dense symmetric block-tridiagonal matrix
(LAPACK, independent of the block elimination).  Pivot blocks of the rods' sizes (2, 4, 12),
indefinite, nearly singular (an eigenvalue 1e-9 of the block's scale, either sign) and badly
scaled (couplings 1e3 times the diagonal), several members at once.
"""

import numpy as np
import pytest

from coilrod.rod._inertia import block_tridiagonal_inertia


def _dense(D, E):
    n, b = D.shape[0], D.shape[1]
    A = np.zeros((n * b, n * b))
    for j in range(n):
        A[j * b : (j + 1) * b, j * b : (j + 1) * b] = D[j]
        if j < n - 1:
            A[j * b : (j + 1) * b, (j + 1) * b : (j + 2) * b] = E[j]
            A[(j + 1) * b : (j + 2) * b, j * b : (j + 1) * b] = E[j].T
    return A


@pytest.mark.parametrize("b", [2, 4, 12])
def test_count_matches_dense_eigenvalues(b):
    rng = np.random.default_rng(b)
    for n in (1, 2, 5):
        k = 6
        D = rng.standard_normal((k, n, b, b))
        D = D + D.transpose(0, 1, 3, 2)
        w, V = np.linalg.eigh(D[:, 0])
        w[:, 0] = 1e-9 * np.abs(w).max(axis=1) * np.array([1, -1, 1, -1, 1, -1])
        D[:, 0] = np.einsum("kij,kj,klj->kil", V, w, V)  # nearly singular first pivot
        E = rng.standard_normal((k, max(n - 1, 0), b, b))
        E[1] *= 1e3  # couplings large against the pivots
        E[2] *= 1e-3
        D[3] += 5.0 * np.eye(b)  # positive definite member
        neg, zero = block_tridiagonal_inertia(D, E)
        ref = [int((np.linalg.eigvalsh(_dense(D[m], E[m])) < 0).sum()) for m in range(k)]
        assert neg.tolist() == ref
        assert (zero == 0).all()


def test_zero_and_not_finite():
    b, n = 4, 3
    D = np.tile(np.diag([1.0, -2.0, 0.0, 3.0]), (2, n, 1, 1))
    E = np.zeros((2, n - 1, b, b))
    D[1, 1, 0, 0] = np.nan
    neg, zero = block_tridiagonal_inertia(D, E)
    assert neg.tolist() == [n, -1]  # one negative and one exact zero per block
    assert zero[0] == n


def test_announced_counts_compile_at_once_only_when_renting_costs_more(monkeypatch):
    """Ski rental with a known horizon (an insertion announces one count per step): the
    compiled count is chosen at once when the announced numpy counts plus the rent so far
    cost more than COMPILE_AFTER (the cost model's closed form), and not otherwise."""
    from coilrod.rod import _inertia as mod

    monkeypatch.setattr(mod, "COMPILE_AFTER", 1.5)
    monkeypatch.setattr(mod._rental, "ready", False)
    monkeypatch.setattr(mod._rental, "spent", 0.0)
    per_call = mod._NUMPY_CALL_S + (mod._NUMPY_BLOCK_S + mod._NUMPY_BLOCK_ROW_S * 10) * 49
    few = int(1.5 / per_call)  # their cost stays under the purchase price
    mod.expect_counts(few, 49, 10)
    assert not mod._rental.ready
    monkeypatch.setattr(mod._rental, "spent", 1.5 - 0.5 * per_call)  # rent paid so far tips it
    mod.expect_counts(1, 49, 10)
    assert mod._rental.ready
    monkeypatch.setattr(mod._rental, "ready", False)
    monkeypatch.setattr(mod._rental, "spent", 0.0)
    mod.expect_counts(few + 1, 49, 10)
    assert mod._rental.ready
