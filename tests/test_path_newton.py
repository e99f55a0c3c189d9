"""Newton's method of the path engine (:func:`coilrod.path.newton`) on toy problems.

Properties checked against closed forms (toys in ``_toy_problems``), batched and one state at a
time:
* quadratic convergence: the residual obeys ``|R+| <= C |R|^2`` with ``C`` from the toy's
  second derivative, and the iteration count is the textbook Newton count;
* the line search rescues a start from which full Newton steps diverge (``atan``), and a full
  step that raises the error by at most ``full_step_growth`` is taken;
* the stagnation stop: an inexact tangent contracting the error by exactly 2/3 stops after
  ``stagnation`` iterations; one contracting by 1/5 converges in the predicted count;
* batched members converge independently: a NaN start, an inadmissible start and a singular
  tangent fail alone, the others converge in the iterations they take alone;
* chord iterations (``chord``, ``chord_start``) reach the same solution with fewer tangents;
* the returned linearization describes the returned states (``tangent_at_end``);
* :class:`NewtonOptions` validation.
"""

import math

import numpy as np
import pytest
from _toy_problems import (
    arctan_problem,
    branch_tolerance,
    fold,
    linear,
    rotation,
    smooth_cubic,
)
from hypothesis import given, settings
from hypothesis import strategies as st

from coilrod.path import NewtonOptions, newton

BATCHED = pytest.mark.parametrize("batched", [True, False], ids=["batched", "one-by-one"])


def textbook_newton(f, df, u, tol, max_iter=50):
    """Plain Newton ``u <- u - f/df`` until ``|f| <= tol``: (iterations, iterates)."""
    its = [u]
    for k in range(max_iter):
        if abs(f(u)) <= tol:
            return k, its
        u = u - f(u) / df(u)
        its.append(u)
    return max_iter, its


def residual_history(toy, scale):
    """2-norms of the residuals of the logged states (in evaluation order)."""
    return [float(np.linalg.norm(toy.residual_of(U[0], scale))) for U, _, _ in toy.log]


class TestQuadraticConvergence:
    @BATCHED
    def test_residual_squares_and_count_is_textbook(self, batched):
        # u^3 + u = 10 (u* = 2) from u0 = 3: convex and increasing, every full step is taken
        toy = smooth_cubic(1.0, 1.0, 1.0, batched=batched)
        res = newton(toy, np.array([3.0]), 10.0, NewtonOptions(chord=0.0))
        assert res.ok
        assert res.u[0] == pytest.approx(2.0, abs=branch_tolerance(toy, np.array([2.0]), 10.0))
        count, _ = textbook_newton(lambda u: u**3 + u - 10, lambda u: 3 * u**2 + 1, 3.0, toy.tol)
        assert res.iterations == count
        r = residual_history(toy, 10.0)
        assert len(r) == count + 1  # the start, then one tangent per iteration
        # |R+| <= max f'' / (2 min f'^2) |R|^2 on [2, 3]: f'' = 6u <= 18, f' = 3u^2 + 1 >= 13
        C = 18.0 / (2 * 13.0**2)
        for a, b in zip(r[:-1], r[1:], strict=True):
            assert b <= C * a * a + 1e-13

    @settings(max_examples=30, deadline=None, derandomize=True)
    @given(
        a=st.lists(st.floats(0.1, 2.0), min_size=3, max_size=3),
        b=st.lists(st.floats(0.5, 2.0), min_size=3, max_size=3),
        scale=st.floats(-3.0, 3.0),
        offset=st.lists(st.floats(-0.3, 0.3), min_size=3, max_size=3),
        batched=st.booleans(),
    )
    def test_quadratic_for_random_coupled_cubics(self, a, b, scale, offset, batched):
        """Newton on ``Q f(Q^T u)`` is componentwise Newton in ``v = Q^T u``:
        ``|R+|_2 <= 3 max(a) V / min(b)^2 |R|_2^2`` with ``V`` the largest |v| visited."""
        toy = smooth_cubic(a, b, 1.0, Q=rotation(3, seed=7), batched=batched)
        exact = toy.exact(scale)
        res = newton(toy, exact + np.array(offset), scale, NewtonOptions(chord=0.0))
        assert res.ok
        np.testing.assert_allclose(res.u, exact, atol=branch_tolerance(toy, exact, scale))
        V = max(np.abs(toy.to_v(U)).max() for U, _, _ in toy.log)
        C = 3 * max(a) * V / min(b) ** 2
        r = residual_history(toy, scale)
        for x, y in zip(r[:-1], r[1:], strict=True):
            assert y <= C * x * x + 1e-13
        assert res.iterations <= 6


class TestLineSearch:
    @BATCHED
    def test_rescues_a_diverging_start(self, batched):
        u0 = 2.0  # |u0| > 1.3917: full Newton steps on atan(u) = 0 diverge
        _, its = textbook_newton(np.arctan, lambda u: 1 / (1 + u * u), u0, 1e-10, max_iter=5)
        assert all(abs(y) > abs(x) for x, y in zip(its[:-1], its[1:], strict=True))
        toy = arctan_problem(batched=batched)
        res = newton(toy, np.array([u0]), 0.0)
        assert res.ok
        assert abs(res.u[0]) <= branch_tolerance(toy, np.zeros(1), 0.0)
        # the full step (to u0 - 5 atan 2) was tried and rejected for the half step
        full = u0 - (1 + u0**2) * math.atan(u0)
        trials = [U[0, 0] for U, _, _ in toy.log]
        assert trials[1] == pytest.approx(full, rel=1e-14)
        assert trials[2] == pytest.approx(u0 + 0.5 * (full - u0), rel=1e-14)

    @BATCHED
    def test_full_step_within_growth_is_taken(self, batched):
        u0 = 2.0
        full = u0 - (1 + u0**2) * math.atan(u0)
        growth = abs(math.atan(full)) / abs(math.atan(u0))  # the full step raises the error by
        assert 1.0 < growth < 1.2  # this factor: taken when full_step_growth allows it
        toy = arctan_problem(batched=batched, full_step_growth=1.2)
        newton(toy, np.array([u0]), 0.0, NewtonOptions(max_iter=1))
        trials = [U[0, 0] for U, _, _ in toy.log]
        assert trials[1] == pytest.approx(full, rel=1e-14)
        assert len(trials) == 2  # accepted: no backtracking

    @BATCHED
    def test_backtracks_out_of_inadmissible_trials(self, batched):
        # u^3 = 1 from 0.1: the full step lands at 33.4, beyond the admissible u < 10
        toy = smooth_cubic(1.0, 0.0, 1.0, batched=batched, admissible=lambda v, s: v[:, 0] < 10)
        res = newton(toy, np.array([0.1]), 1.0)
        assert res.ok
        assert res.u[0] == pytest.approx(1.0, abs=branch_tolerance(toy, np.ones(1), 1.0))
        assert any(U[0, 0] >= 10 for U, _, _ in toy.log)


class TestStagnation:
    """``R = u - s`` solved with ``k J`` instead of ``J``: the error contracts by exactly
    ``1 - 1/k`` per iteration."""

    @BATCHED
    @pytest.mark.parametrize("stagnation", [3, 5])
    def test_slow_contraction_stops_after_stagnation_iterations(self, batched, stagnation):
        toy = linear(batched=batched, tangent_factor=3.0)  # contraction 2/3 > 1/2
        e0 = 1e4
        res = newton(toy, np.array([e0 * toy.tol]), 0.0, NewtonOptions(stagnation=stagnation))
        assert not res.ok
        assert res.iterations == stagnation
        assert res.error == pytest.approx(e0 * (2 / 3) ** stagnation, rel=1e-9)

    @BATCHED
    def test_fast_linear_contraction_converges_in_predicted_count(self, batched):
        toy = linear(batched=batched, tangent_factor=1.25)  # contraction 1/5 < 1/2
        e0 = 1e4
        res = newton(toy, np.array([e0 * toy.tol]), 0.0)
        assert res.ok
        assert res.iterations == math.ceil(math.log(e0) / math.log(5.0))  # 6

    @BATCHED
    def test_max_iter_caps_the_attempt(self, batched):
        # 1e3 * (1/5)^3 = 8: close to, but above, the tolerance -- not converged
        toy = linear(batched=batched, tangent_factor=1.25)
        res = newton(toy, np.array([1e3 * toy.tol]), 0.0, NewtonOptions(max_iter=3))
        assert not res.ok
        assert res.iterations == 3
        assert res.error == pytest.approx(8.0, rel=1e-9)


class TestBatchedMembers:
    """``u^3 = s`` (tangent ``3u^2``, singular at 0), admissible for ``u < 10``."""

    def toy(self, batched):
        return smooth_cubic(1.0, 0.0, 1.0, batched=batched, admissible=lambda v, s: v[:, 0] < 10)

    @BATCHED
    @pytest.mark.parametrize("chord", [0.0, 0.125])
    def test_failing_members_do_not_spoil_the_others(self, batched, chord):
        """Members: converging, NaN start, inadmissible start, singular tangent at the start,
        converging, converging, and s = 0 (triple root: linear convergence, still
        unconverged after max_iter).  Without chord iterations every member's iterates are
        its own; with them the switch to chord steps is taken for the stack, so only the
        solutions are compared."""
        U0 = np.array([[1.5], [np.nan], [20.0], [0.0], [5.0], [-0.5], [1.0]])
        S = np.array([2.0, 1.0, 1.0, 1.0, 3.0, -8.0, 0.0])
        opts = NewtonOptions(chord=chord)
        toy = self.toy(batched)
        res = newton(toy, U0, S, opts)
        assert res.ok.tolist() == [True, False, False, False, True, True, False]
        assert np.isinf(res.error[[1, 2]]).all()  # NaN and inadmissible starts
        assert np.isfinite(res.error[[3, 6]]).all()  # stopped, their error still known
        assert res.iterations[6] == opts.max_iter
        for row in (0, 4, 5, 6):
            alone = newton(toy, U0[row], S[row], opts)
            assert alone.ok == res.ok[row]
            if chord == 0:
                assert alone.iterations == res.iterations[row]
                assert alone.u[0] == res.u[row, 0]
            if alone.ok:
                exact = np.cbrt(S[row : row + 1])
                assert res.u[row, 0] == pytest.approx(
                    exact[0], abs=branch_tolerance(toy, exact, S[row])
                )


class TestOneState:
    """One state runs a scalar copy of the stacked iteration (``corrector._One``): the same
    evaluations, iterates and outcome, bitwise, as the stacked iteration on that state."""

    CASES = {
        "line search": (lambda: arctan_problem(), [2.0], 0.0, {}),
        "growth": (lambda: arctan_problem(full_step_growth=1.2), [2.0], 0.0, {}),
        "inadmissible trial": (
            lambda: smooth_cubic(1.0, 0.0, 1.0, admissible=lambda v, s: v[:, 0] < 10),
            [0.1], 1.0, {},
        ),
        "stagnation": (lambda: linear(tangent_factor=3.0), [1e-6], 0.0, {}),
        "chord": (lambda: smooth_cubic(1.0, 1.0, 1.0), [3.0], 10.0, {}),
        "chord start": (lambda: arctan_problem(), [2.0], 0.0, {"chord_start": True}),
        "failed search": (lambda: arctan_problem(), [10.0], 0.0, {"backtracks": 1}),
    }  # fmt: skip

    @pytest.mark.parametrize("case", CASES)
    def test_same_iterates_as_the_stacked_iteration(self, case, monkeypatch):
        from coilrod.path import corrector

        make, u0, s, kw = self.CASES[case]
        out = []
        for one in (True, False):
            if not one:  # the stacked iteration for the one state

                class Stacked(corrector._Iteration):
                    def finish(self):  # (the one state's numbers, as _One.finish leaves them)
                        self.e, self.n_iter = float(self.err[0]), int(self.iters[0])
                        return self

                monkeypatch.setattr(corrector, "_One", Stacked)
            toy = make()
            res = newton(toy, np.array(u0), s, NewtonOptions(**kw))
            out.append((toy.log, res))
        (log1, r1), (log2, r2) = out
        assert [(U.tolist(), S.tolist(), t) for U, S, t in log1] == [
            (U.tolist(), S.tolist(), t) for U, S, t in log2
        ]
        assert (r1.ok, r1.error, r1.iterations, r1.u.tolist()) == (
            r2.ok, r2.error, r2.iterations, r2.u.tolist()
        )  # fmt: skip
        assert r1.lin.residual.tolist() == r2.lin.residual.tolist()


class TestChord:
    @BATCHED
    @pytest.mark.parametrize("u0", [0.0, 1.9, 3.0])
    def test_chord_reaches_the_newton_solution_with_fewer_tangents(self, batched, u0):
        exact = np.array([2.0])
        toy = smooth_cubic(1.0, 1.0, 1.0, batched=batched)
        plain = newton(toy, np.array([u0]), 10.0, NewtonOptions(chord=0.0))
        tangents_plain = toy.evaluations(tangent=True)
        toy.clear()
        chord = newton(toy, np.array([u0]), 10.0, NewtonOptions(chord=0.125))
        assert plain.ok
        assert chord.ok
        tol = branch_tolerance(toy, exact, 10.0)
        assert plain.u[0] == pytest.approx(2.0, abs=tol)
        assert chord.u[0] == pytest.approx(2.0, abs=tol)
        assert toy.evaluations(tangent=True) <= tangents_plain
        if u0 != 1.9:  # long enough for the quadratic regime to start chord steps
            assert toy.evaluations(tangent=False) > 0

    @BATCHED
    def test_chord_start_uses_the_start_tangent_first(self, batched):
        toy = smooth_cubic([1.0, 2.0], [1.0, 0.5], [1.0, -1.0], Q=rotation(2), batched=batched)
        exact = toy.exact(1.5)
        res = newton(toy, exact + 1e-4, 1.5, NewtonOptions(chord_start=True))
        assert res.ok
        np.testing.assert_allclose(res.u, exact, atol=branch_tolerance(toy, exact, 1.5))
        assert toy.log[0][2] is True  # the start's tangent ...
        assert toy.log[1][2] is False  # ... serves the first trial

    @BATCHED
    def test_chord_start_falls_back_on_fresh_tangents_far_away(self, batched):
        toy = arctan_problem(batched=batched)
        res = newton(toy, np.array([2.0]), 0.0, NewtonOptions(chord_start=True))
        assert res.ok
        assert abs(res.u[0]) <= branch_tolerance(toy, np.zeros(1), 0.0)
        assert toy.evaluations(tangent=True) > 1


class TestReturnedLinearization:
    @BATCHED
    @pytest.mark.parametrize("chord", [0.0, 0.125])
    @pytest.mark.parametrize("u0", [0.0, 3.0])
    def test_tangent_at_end_gives_the_path_rate(self, batched, chord, u0):
        toy = smooth_cubic(1.0, 1.0, 1.0, batched=batched)
        res = newton(toy, np.array([u0]), 10.0, NewtonOptions(chord=chord), tangent_at_end=True)
        assert res.lin.tangent is not None
        rate = -np.ravel(toy.solve(res.lin, toy.d_residual_d_scale(res.lin)))
        # du/ds = 1/(3u^2 + 1) = 1/13 at u = 2; a chord tangent is that of an earlier iterate
        # of the contracting chord sequence: within a few per cent
        assert rate[0] == pytest.approx(1 / 13, rel=1e-12 if chord == 0 else 0.05)

    @BATCHED
    @pytest.mark.parametrize("tangent_at_end", [True, False])
    def test_linearization_describes_the_returned_states(self, batched, tangent_at_end):
        toy = fold(size=2, Q=rotation(2), batched=batched)
        rng = np.random.default_rng(5)
        U0 = rng.normal(scale=1.5, size=(6, 2))
        S = rng.uniform(-1, 1, 6)
        res = newton(toy, U0, S, tangent_at_end=tangent_at_end)
        lin = res.lin
        views = [(np.asarray(lin.u), np.asarray(lin.residual))]
        if isinstance(lin.tangent, list):  # the one-by-one adapter: the model's own objects
            views.append((np.array([p.u for p in lin.tangent]), [p.residual for p in lin.tangent]))
        ok = res.ok
        for U, R in views:
            np.testing.assert_array_equal(U, res.u)
            R = np.asarray(R)
            np.testing.assert_allclose(R[ok], toy.residual_of(res.u[ok], S[ok]), atol=1e-14)

    @BATCHED
    def test_chord_start_linearization_is_of_the_returned_states(self, batched):
        # u^3 - u = 0 at s = 0: member 0 starts 1e-7 from the root 1 (one chord step
        # converges it), member 1 at (1 + sqrt 41)/10, where the full Newton step overshoots
        # (|R| grows from 0.33 to 0.74) and the half step lands exactly on the root 1
        toy = fold(batched=batched)
        U0 = np.array([[1.0 + 1e-7], [(1.0 + math.sqrt(41.0)) / 10.0]])
        res = newton(toy, U0, np.zeros(2), NewtonOptions(chord_start=True))
        assert res.ok.all()
        np.testing.assert_allclose(res.u[:, 0], 1.0, atol=1e-12)
        assert res.iterations.tolist() == [1, 1]
        lin = res.lin
        R = (
            np.array([p.residual for p in lin.tangent])
            if isinstance(lin.tangent, list)
            else np.asarray(lin.residual)
        )
        np.testing.assert_allclose(R, toy.residual_of(res.u, np.zeros(2)), atol=1e-12)


class TestOptions:
    @pytest.mark.parametrize(
        ("kwargs", "name"),
        [
            ({"max_iter": 0}, "max_iter"),
            ({"max_iter": 2.5}, "max_iter"),
            ({"max_iter": True}, "max_iter"),
            ({"backtracks": -1}, "backtracks"),
            ({"stagnation": 0}, "stagnation"),
            ({"chord": 1.0}, "chord"),
            ({"chord": -0.1}, "chord"),
            ({"chord": float("nan")}, "chord"),
        ],
    )
    def test_bad_values_raise_naming_them(self, kwargs, name):
        with pytest.raises(ValueError, match=name):
            NewtonOptions(**kwargs)
