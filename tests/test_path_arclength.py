"""Pseudo-arclength continuation (:class:`coilrod.path.ArcLength`) on toy problems.

Properties checked against closed forms (toys in ``_toy_problems``):
* the trace of ``u^3 - u + s`` from (1, 0) passes both folds: every point is on the curve,
  ``u`` decreases all along (the orientation is kept through the turning points), the scale
  turns exactly twice, at ``+-2/(3 sqrt 3)`` to the resolution of the sampling
  (``sqrt(3) (du/2)^2`` for points spaced ``du`` on ``s = u - u^3``), at ``u = +-1/sqrt 3``;
* the path tangent is the closed-form ``du/ds = -1/(3u^2 - 1)``, oriented to increasing scale,
  unit in the weighted norm; ``direction = -1`` follows decreasing scale;
* a point with an exactly singular tangent (the trivial branch of a pitchfork at ``s_c``) is
  passed on the secant;
* the trace stops where the model becomes inadmissible.
"""

import math

import numpy as np
import pytest
from _toy_problems import FOLD_SCALE, FOLD_STATE, fold, pitchfork, rotation, smooth_cubic

from coilrod.path import ArcLength
from coilrod.path.arclength import MAX_TURN

BATCHED = pytest.mark.parametrize("batched", [True, False], ids=["batched", "one-by-one"])


def trace(toy, u0, c0, direction=1, span=1.0, step=None, stop=None, max_steps=2000):
    tracer = ArcLength(toy, span, step=step)
    us, cs = [np.asarray(u0, float)], [c0]
    for u, c, err, _lin in tracer.follow(np.asarray(u0, float), c0, direction, max_steps):
        assert err <= 1.0
        us.append(u)
        cs.append(c)
        if stop is not None and stop(u, c):
            break
    return np.array(us), np.array(cs)


class TestThroughFolds:
    @BATCHED
    @pytest.mark.parametrize("coupled", [False, True])
    @pytest.mark.parametrize("step", [None, 0.01])
    def test_both_turning_points_at_the_closed_form(self, batched, coupled, step):
        Q = rotation(2, seed=9) if coupled else None
        toy = fold(size=2, Q=Q, batched=batched)
        u0 = toy.to_u(np.ones((1, 2)))[0]  # v = (1, 1) on the upper branch at s = 0
        U, c = trace(toy, u0, 0.0, step=step, stop=lambda u, c: toy.to_v(u)[0] < -1.5)
        v = toy.to_v(U)[:, 0]
        assert v[-1] < -1.5  # reached the lower branch beyond the lower fold
        np.testing.assert_allclose(toy.to_v(U)[:, 1], v, atol=1e-9)  # symmetric in v
        # on the curve, oriented: v decreases all along (through both turning points)
        np.testing.assert_allclose(v**3 - v + c, 0.0, atol=toy.tol)
        assert np.all(np.diff(v) < 0)
        assert np.all(np.abs(np.diff(U, axis=0)).max(axis=1) <= MAX_TURN + 1e-12)
        # the scale turns exactly twice: at the upper fold (a maximum), then the lower one
        dc = np.diff(c)
        turns = np.flatnonzero(np.sign(dc[1:]) != np.sign(dc[:-1])) + 1
        assert len(turns) == 2
        for i, sign in zip(turns, (1, -1), strict=True):
            assert sign * dc[i - 1] > 0 > sign * dc[i]  # the extreme sample
            gap = max(abs(v[i] - v[i - 1]), abs(v[i + 1] - v[i]))
            # the extreme sample of s = u - u^3 lies within the larger adjacent gap of the
            # turning point: s_f - s = sqrt(3) d^2 + d^3 with d <= gap
            bound = math.sqrt(3) * gap * gap + gap**3
            assert -toy.tol <= sign * (sign * FOLD_SCALE - c[i]) <= bound
            assert abs(v[i] - sign * FOLD_STATE) <= gap

    @BATCHED
    def test_fine_steps_locate_the_folds_to_second_order(self, batched):
        toy = fold(batched=batched)
        U, c = trace(toy, np.ones(1), 0.0, step=0.002, stop=lambda u, c: u[0] < -0.7)
        v = U[:, 0]
        gap = np.abs(np.diff(v)).max()
        bound = math.sqrt(3) * gap * gap + gap**3
        assert bound < 2e-4
        assert FOLD_SCALE - bound <= c.max() <= FOLD_SCALE + toy.tol
        assert -FOLD_SCALE - toy.tol <= c.min() <= -FOLD_SCALE + bound

    @BATCHED
    def test_direction_minus_one_follows_decreasing_scale(self, batched):
        toy = fold(batched=batched)
        U, c = trace(toy, np.ones(1), 0.0, direction=-1, max_steps=30)
        assert len(c) == 31
        assert np.all(np.diff(c) < 0)
        assert np.all(np.diff(U[:, 0]) > 0)  # up the upper branch: u grows as s falls
        np.testing.assert_allclose(U[:, 0] ** 3 - U[:, 0] + c, 0.0, atol=toy.tol)


class TestTangent:
    @BATCHED
    @pytest.mark.parametrize(("u", "c"), [(1.0, 0.0), (0.0, 0.0), (-1.2, 0.528)])
    def test_closed_form_and_orientation(self, batched, u, c):
        toy = fold(batched=batched)
        span = 2.0
        tracer = ArcLength(toy, span)
        du, dc = tracer.tangent(np.array([u]), c)
        rate = -1.0 / (3 * u * u - 1)  # du/ds on s = u - u^3
        assert dc > 0
        assert du[0] / dc == pytest.approx(rate, rel=1e-12)
        assert math.sqrt(du[0] ** 2 + (dc / span) ** 2) == pytest.approx(1.0, rel=1e-12)

    @BATCHED
    def test_singular_tangent_is_none(self, batched):
        toy = smooth_cubic(1.0, 0.0, 1.0, batched=batched)  # u^3 = s: J = 0 at u = 0
        assert ArcLength(toy, 1.0).tangent(np.zeros(1), 0.0) is None


class TestSingularPoint:
    @BATCHED
    def test_secant_passes_an_exactly_singular_point(self, batched):
        """On the trivial branch of ``u^3 - (s - 0.625) u`` the steps of scale 0.25, then
        0.375 land exactly on s_c = 0.625, where the tangent is singular."""
        toy = pitchfork(0.625, batched=batched)
        U, c = trace(toy, np.zeros(1), 0.0, step=0.25, max_steps=6)
        assert c[2] == 0.625
        assert ArcLength(toy, 1.0).tangent(np.zeros(1), 0.625) is None
        assert len(c) == 7
        assert np.all(np.diff(c) > 0)
        assert np.all(U == 0.0)


class TestInadmissible:
    @BATCHED
    def test_trace_stops_at_the_end_of_the_admissible_branch(self, batched):
        toy = smooth_cubic(
            1.0, 1.0, 1.0, batched=batched, admissible=lambda v, s: v[:, 0] < 1.0
        )  # u^3 + u = s, admissible up to s = 2
        U, c = trace(toy, np.zeros(1), 0.0, span=2.0, max_steps=400)
        assert len(c) < 401
        assert np.all(U[:, 0] < 1.0)
        assert c[-1] > 1.99
        np.testing.assert_allclose(U[:, 0] ** 3 + U[:, 0] - c, 0.0, atol=toy.tol)
