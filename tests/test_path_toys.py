"""The toy path problems of the engine's tests are what they claim to be.

Cross-checks (so a failing engine test points at the engine, not at its toy):
* the tangent and ``dR/dscale`` of every family against central finite differences, batched
  and one state at a time, with and without a rotation coupling the components;
* the closed-form branches are zeros of the residual (Cardano without cancellation, the
  roots of the pitchfork and the fold, ``tan`` for the arctangent);
* the stability indicator's sign is the definiteness of the tangent;
* the batched and one-by-one toys agree member by member.
"""

import math

import numpy as np
import pytest
from _toy_problems import (
    FOLD_SCALE,
    FOLD_STATE,
    arctan_problem,
    cubic_root,
    fold,
    fold_roots,
    linear,
    pitchfork,
    pitchfork_roots,
    rotation,
    smooth_cubic,
)

FAMILIES = {
    "cubic": lambda **kw: smooth_cubic([1.0, 0.5, 2.0], [1.0, 2.0, 0.3], [1.0, -1.5, 0.7], **kw),
    "pitchfork": lambda **kw: pitchfork(0.8, 0.05, amp=0.3, size=3, **kw),
    "fold": lambda **kw: fold(size=3, **kw),
    "arctan": lambda **kw: arctan_problem(size=3, **kw),
    "linear": lambda **kw: linear(size=3, **kw),
}


class TestDerivatives:
    @pytest.mark.parametrize("name", sorted(FAMILIES))
    @pytest.mark.parametrize("batched", [True, False])
    @pytest.mark.parametrize("coupled", [False, True])
    def test_tangent_and_load_rate_match_finite_differences(self, name, batched, coupled, rng):
        toy = FAMILIES[name](batched=batched, Q=rotation(3, seed=4) if coupled else None)
        u = rng.normal(scale=0.7, size=3)
        s = 0.37
        lin = toy.linearize(u, s)
        J = np.asarray(lin.tangent).reshape(3, 3)
        h = 1e-6
        fd = np.empty((3, 3))
        for j in range(3):
            e = np.zeros(3)
            e[j] = h
            fd[:, j] = (toy.residual_of(u + e, s) - toy.residual_of(u - e, s)) / (2 * h)
        np.testing.assert_allclose(J, fd, rtol=1e-7, atol=1e-8)
        rate = np.ravel(toy.d_residual_d_scale(lin))
        fd_s = (toy.residual_of(u, s + h) - toy.residual_of(u, s - h)) / (2 * h)
        np.testing.assert_allclose(rate, fd_s, rtol=1e-7, atol=1e-8)

    @pytest.mark.parametrize("name", sorted(FAMILIES))
    def test_solve_inverts_the_tangent(self, name, rng):
        toy = FAMILIES[name](Q=rotation(3, seed=1))
        u = rng.normal(size=(2, 3))
        lin = toy.linearize(u, np.array([0.2, -0.4]))
        rhs = rng.normal(size=(2, 3))
        x = toy.solve(lin, rhs)
        np.testing.assert_allclose(np.einsum("kij,kj->ki", lin.tangent, x), rhs, atol=1e-10)


class TestClosedForms:
    def test_cubic_root_solves_the_cubic_without_cancellation(self):
        a = np.array([0.0, 1.0, 1e-8, 3.0, 1.0])
        b = np.array([2.0, 1.0, 1.0, 0.1, 1.0])
        q = np.array([3.0, 10.0, 1e-3, -7.0, 1e-12])
        v = cubic_root(a, b, q)
        np.testing.assert_allclose(a * v**3 + b * v, q, rtol=1e-13, atol=0)
        assert v[1] == pytest.approx(2.0, rel=1e-15)

    @pytest.mark.parametrize("s", [-2.0, -FOLD_SCALE + 1e-6, 0.0, 0.3, 1.0])
    def test_fold_roots(self, s):
        roots = fold_roots(s)
        assert len(roots) == (3 if abs(s) < FOLD_SCALE else 1)
        np.testing.assert_allclose(roots**3 - roots + s, 0.0, atol=1e-14)

    def test_fold_is_where_the_tangent_vanishes(self):
        toy = fold()
        for sign in (1, -1):
            u, s = np.array([sign * FOLD_STATE]), sign * FOLD_SCALE
            assert toy.eigenvalues(u, s)[0, 0] == pytest.approx(0.0, abs=1e-15)
            assert toy.residual_of(u, s)[0] == pytest.approx(0.0, abs=1e-15)

    @pytest.mark.parametrize(("s", "eps"), [(0.0, 0.0), (2.0, 0.0), (2.0, 0.1), (0.5, -0.1)])
    def test_pitchfork_roots(self, s, eps):
        roots = pitchfork_roots(s, 1.0, eps)
        np.testing.assert_allclose(roots**3 - (s - 1.0) * roots - eps, 0.0, atol=1e-14)
        if eps == 0 and s > 1:
            np.testing.assert_allclose(roots, [-math.sqrt(s - 1), 0.0, math.sqrt(s - 1)])

    def test_curved_trivial_branch(self):
        toy = pitchfork(1.0, 0.0, amp=0.4)
        s = np.linspace(0, 3, 7)
        u = 0.4 * np.sin(s)[:, None]
        np.testing.assert_allclose(toy.residual_of(u, s), 0.0, atol=1e-16)

    def test_arctan_branch_and_smooth_cubic_exact(self):
        toy = arctan_problem()
        assert toy.residual_of(np.array([math.tan(0.9)]), 0.9)[0] == pytest.approx(0, abs=1e-15)
        cub = smooth_cubic([1.0, 2.0], [1.0, 0.5], [1.0, -1.0], Q=rotation(2))
        s = np.array([-3.0, 0.1, 5.0])
        np.testing.assert_allclose(cub.residual_of(cub.exact(s), s), 0.0, atol=1e-13)


class TestStabilityAndBatching:
    def test_stability_sign_is_the_definiteness_of_the_tangent(self, rng):
        for mode in ("eigenvalue", "sign"):
            toy = pitchfork(1.0, 0.0, size=2, Q=rotation(2), stability=mode)
            U = rng.normal(scale=0.5, size=(20, 2))
            S = rng.uniform(0, 2, 20)
            lin = toy.linearize(U, S)
            definite = np.all(np.linalg.eigvalsh(lin.tangent) > 0, axis=1)
            assert np.array_equal(toy.stability(lin) > 0, definite) or mode == "sign"
            assert np.array_equal(toy.stability(lin, precise=True) > 0, definite)

    def test_batched_and_single_agree(self, rng):
        kw = {"Q": rotation(3, seed=2)}
        a, b = FAMILIES["fold"](batched=True, **kw), FAMILIES["fold"](batched=False, **kw)
        U = rng.normal(size=(4, 3))
        S = rng.normal(size=4)
        lb = a.linearize(U, S)
        for j in range(4):
            lj = b.linearize(U[j], S[j])
            np.testing.assert_allclose(lb.residual[j], lj.residual, rtol=1e-14, atol=1e-15)
            assert a.error(lb, None)[j] == pytest.approx(b.error(lj, None), rel=1e-14)
            assert a.stability(lb)[j] == pytest.approx(b.stability(lj), rel=1e-14)

    def test_inadmissible_states_are_flagged_not_raised(self):
        toy = smooth_cubic(1, 1, 1, admissible=lambda v, s: np.all(v < 1, axis=1))
        lin = toy.linearize(np.array([[0.5], [1.5], [np.nan]]), np.zeros(3))
        assert lin.ok.tolist() == [True, False, False]
        assert np.isfinite(toy.error(lin, None)).tolist() == [True, False, False]
