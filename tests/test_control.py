"""Currents for a target tip position (coilrod.solve_currents), grouped by property.

Targets are made reachable by construction: the tip of an independent forward solve with known
currents.  Every answer is checked by a fresh forward solve (solve_rod at tolerance 1e-11) with
the returned currents; the ideal controller's currents are checked against the uniform-field
answer made at the centre, and its reported miss against the independent real-field solve.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import coils
from coilrod import ConvergenceError, presets, solve_currents, solve_rod, workspace

ROD = presets.seed_rod(presets.M1())
L = ROD.length
SCALES = np.linspace(0.1, 1.0, 10)
LARGE = coils.presets.three_axis_helmholtz()
COMPACT = coils.presets.three_axis_helmholtz(radii=(0.04, 0.05, 0.06), max_current=50.0)


def _tip(system, currents, rod=ROD):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return solve_rod(rod, system.with_currents(currents), SCALES, tol=1e-11).tip[-1, :2]


def _copper_power(system, currents):
    """sum R I^2 by hand: each channel a pair of coils of round copper wire (the presets'
    2 mm), R = rho * 2 coils * N 2 pi a / (pi d^2 / 4), rho = 1.7241e-8 ohm m (IACS)."""
    rho, d = 1.7241e-8, 2e-3
    R = [rho * 2 * p.turns * 2 * np.pi * p.radius / (np.pi * d**2 / 4) for p in system.parts]
    return float(np.sum(np.asarray(R) * np.asarray(currents) ** 2))


def _target(system, B, rod=ROD):
    currents = system.currents_for(B=B)
    return _tip(system, currents, rod), currents


# one field per quadrant across the two systems (each system in two; the same property --
# the made currents found again -- in every one)
CASES = [
    ("large", LARGE, (0.003, 0.006, 0.0)),
    ("large", LARGE, (-0.002, -0.008, 0.0)),
    ("compact", COMPACT, (0.0, 0.004, 0.0)),
    ("compact", COMPACT, (-0.006, 0.004, 0.0)),
]


class TestRealModel:
    @pytest.mark.parametrize(
        ("name", "system", "B"), CASES, ids=[f"{c[0]}-{c[2][:2]}" for c in CASES]
    )
    def test_lands_on_reachable_targets(self, name, system, B):
        target, made = _target(system, B)
        out = solve_currents(ROD, system, target)
        # an independent forward solve with the returned currents
        assert np.linalg.norm(_tip(system, out.currents) - target) <= 1e-6 * L
        assert out.miss <= 1e-6 * L
        # the currents that made the target are a solution of minimum power (the z channel
        # idle, the x-y ones unique for a two-component target): they are found again
        np.testing.assert_allclose(out.currents, made, atol=1e-6 * np.abs(made).max())
        assert out.solves + out.start_solves <= 15
        assert out.power == pytest.approx(_copper_power(system, out.currents), rel=1e-12)

    def test_minimum_power_with_redundant_channels(self):
        """Two Helmholtz pairs along y (in series would double the field): the solution splits
        the current in proportion to 1/R (minimum sum R I^2 for a fixed sum of fields)."""
        pairs = [
            coils.HelmholtzPair(0.1, 200, 0.0, axis="x", wire_diameter=2e-3),
            coils.HelmholtzPair(0.1, 200, 0.0, axis="y", wire_diameter=2e-3),
            coils.HelmholtzPair(0.12, 200, 0.0, axis="y", wire_diameter=1.5e-3),
        ]
        system = coils.CoilSystem(pairs, max_current=20.0)
        target, _ = _target(system, (0.002, 0.005, 0.0))
        out = solve_currents(ROD, system, target)
        assert out.miss <= 1e-6 * L
        # first-order optimality of min sum R I^2 on the constraint tip(I) = target: R I lies
        # in the row space of the tip's Jacobian, i.e. is orthogonal to its null direction.
        # The Jacobian by central differences of forward solves (independent of the adjoint)
        h = 1e-3
        J = np.column_stack(
            [
                (_tip(system, out.currents + h * e) - _tip(system, out.currents - h * e)) / (2 * h)
                for e in np.eye(3)
            ]
        )
        null = np.linalg.svd(J)[2][-1]
        RI = system.resistance * out.currents
        assert abs(null @ RI) <= 1e-4 * np.linalg.norm(RI)
        # and the two y pairs share the work (neither idle)
        assert abs(out.currents[1]) > 0.1
        assert abs(out.currents[2]) > 0.1


class TestIdealModel:
    def test_ideal_controller_misses_in_the_real_field(self):
        target, _ = _target(COMPACT, (0.003, 0.006, 0.0))
        ideal = solve_currents(ROD, COMPACT, target, model="ideal")
        real = solve_currents(ROD, COMPACT, target, model="real")
        # the ideal currents make the uniform-field answer at the centre: the tip of the rod
        # in the uniform centre field of those currents is on the target
        Bc = COMPACT.with_currents(ideal.currents).B(np.zeros((1, 3)))[0]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tip_u = solve_rod(ROD, coils.UniformField(B=Bc), SCALES, tol=1e-11).tip[-1, :2]
        assert np.linalg.norm(tip_u - target) <= 1e-5 * L
        # the reported miss is the real-field tip's distance (independent solve)
        assert ideal.miss == pytest.approx(
            np.linalg.norm(_tip(COMPACT, ideal.currents) - target), rel=1e-6
        )
        assert ideal.miss > 0.005 * L  # compact coils: the ideal controller is off by > 0.5 % L
        assert real.miss <= 1e-6 * L
        assert ideal.model == "ideal"


class TestUnreachable:
    @pytest.fixture(scope="class")
    @classmethod
    def beyond(cls):
        """The one solve the limit tests read: a target the compact system cannot reach within
        0.5 A (the ConvergenceError it raises), from a warm start that cannot reach it either
        (then a fresh one), and the forward solves counted where they are made."""
        import coilrod.control.currents as currents

        calls = []
        forward = currents._forward
        target, _ = _target(COMPACT, (0.004, 0.012, 0.0))
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(currents, "_forward", lambda *a: calls.append(1) or forward(*a))
            with pytest.raises(ConvergenceError) as info:
                solve_currents(
                    ROD, COMPACT, target, max_current=0.5, initial=(0.5, 0.0, 0.0), nodes=16
                )
        return info.value, len(calls)

    def test_beyond_the_current_limits(self, beyond):
        assert "beyond the current limits: not reachable within them" in str(beyond[0])
        out = beyond[0].result
        assert np.all(np.abs(out.currents) <= 0.5 + 1e-9)
        # the closest tip reported is where those currents really put it
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            field = COMPACT.with_currents(out.currents)
            tip = solve_rod(ROD, field, SCALES, tol=1e-11, nodes=16).tip[-1, :2]
        np.testing.assert_allclose(out.tip[:2], tip, atol=1e-8 * L)

    def test_the_limits_named_when_they_bind(self, beyond):
        out = beyond[0].result
        at_limit = np.flatnonzero(np.abs(out.currents) >= 0.5 - 1e-9).tolist()
        assert at_limit
        assert out.active == at_limit
        message = str(beyond[0])
        assert f"channels {', '.join(map(str, at_limit))} at their limit" in message
        assert "outside the robot's reachable set" not in message

    def test_a_restarted_search_counts_both_searches(self, beyond):
        """A warm start that cannot reach the target is followed by a fresh one: the error's
        result counts the forward solves of both (the old code reported the second's only).
        Reference: the forward solves counted where they are made (the start's uniform-field
        solves are start_solves - 1: its workspace grid counts one)."""
        out, calls = beyond[0].result, beyond[1]
        assert out.start_solves > 0  # the fresh start was taken
        assert out.solves + out.start_solves - 1 == calls
        assert len(out.history) == out.solves

    def test_outside_the_reachable_set_without_a_limit_active(self):
        """(20, 0) mm: no stable tip of the M(1) rod comes closer than the straight rod's
        (checked on an independent workspace grid of uniform fields up to 50 mT, every
        direction); the currents are far below the limits, and the message says so instead of
        blaming the limits."""
        target = np.array([0.02, 0.0])
        with pytest.raises(ConvergenceError) as info:
            solve_currents(ROD, LARGE, target, nodes=16)
        message, out = str(info.value), info.value.result
        assert "outside the robot's reachable set" in message
        assert "current limits" not in message
        assert out.active == []
        assert np.all(np.abs(out.currents) < 0.5 * LARGE.max_current)
        assert out.result.stable[-1]
        assert out.optimal
        # refined once: the closest stable tip is the straight rod's, 20 mm, as with the
        # default refinement (5x the cost); unrefined it is 20.006 mm
        ws = workspace(
            ROD, 0.05, directions=72, magnitudes=16, nodes=16, richardson=False, refine=1
        )
        dist = np.linalg.norm(ws.tips[:, 1:, :2] - target, axis=2)
        closest = np.where(ws.stable[:, 1:], dist, np.inf).min()
        assert out.miss <= closest + 1e-3 * L

    def test_beyond_the_rod_length(self):
        with pytest.raises(ConvergenceError, match="beyond the rod's length"):
            solve_currents(ROD, LARGE, (0.05, 0.0))


class TestLeastSquaresCompromise:
    """A target angle too: three conditions, two in-plane channels (the z pair idle by the
    mirror symmetry of the plane).  The uniform-field start is a nearly antiparallel field
    (x channel -2.09 A, y channel a few uA: the small current decides to which side the rod
    buckles); the old step control returned that start (1.09 mm, 1.07 deg off) after one
    overshooting step whose backtracks all failed.  scipy's least squares from there reaches
    0.674 mm, 0.278 deg."""

    TARGET, ANGLE = np.array([0.025, 0.028]), np.radians(75.0)

    def _residual(self, I):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = solve_rod(ROD, LARGE.with_currents(I), np.arange(1, 11) / 10, nodes=16)
        return np.r_[
            (res.tip[-1, :3] - np.r_[self.TARGET, 0.0]) / L, res.tip_angle[-1] - self.ANGLE
        ]

    def test_the_compromise_is_scipys_local_least_squares_optimum(self):
        from scipy.optimize import least_squares

        import coilrod.control.currents as currents

        with warnings.catch_warnings():
            warnings.simplefilter("error", currents.ControlWarning)
            out = solve_currents(ROD, LARGE, self.TARGET, angle=self.ANGLE, nodes=16)
        assert (out.status, out.optimal) == ("optimal", True)
        r = self._residual(out.currents)  # the same objective, by an independent solve
        assert out.miss == pytest.approx(np.linalg.norm(r[:3]) * L, rel=1e-6)
        # scipy's least squares (finite-difference Jacobian, its own trust region) from there
        # finds no better state nearby: within 1 % of the cost
        ref = least_squares(lambda I2: self._residual(np.r_[I2, 0.0]), out.currents[:2], max_nfev=8)
        assert ref.cost >= 0.99 * 0.5 * float(r @ r)
        # scipy from the start reaches 0.674 mm, 0.278 deg (the old answer: 1.09 mm, 1.07 deg)
        assert out.miss < 0.69e-3
        assert out.angle_miss < np.radians(0.29)

    def test_a_result_that_is_not_an_optimum_says_so(self, monkeypatch):
        import coilrod.control.currents as currents

        monkeypatch.setattr(currents, "_start", lambda *args: (np.array([1.0, 0.0, 0.0]), 0))
        with pytest.warns(currents.ControlWarning, match="not a local least-squares optimum"):
            out = solve_currents(ROD, LARGE, self.TARGET, angle=self.ANGLE, nodes=16, max_solves=2)
        assert (out.status, out.optimal) == ("max_solves", False)


def _tip_3d(system, currents, nodes=None):
    """Tip (x, y, z) of an independent forward solve (tolerance 1e-11; the spatial rod)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = solve_rod(ROD, system.with_currents(currents), SCALES, tol=1e-11, nodes=nodes)
    assert res.model == "spatial"
    return res.tip[-1]


EIGHT = coils.presets.eight_coil_hemisphere()


class TestSpatialTarget:
    """3D targets (x, y, z) on the spatial rod, made reachable by construction: the tip of an
    independent forward solve with currents that make a field with a B_z component."""

    def test_lands_on_reachable_3d_targets(self):
        # one field out of the plane (the 3D scene test lands on another, in CardioMag)
        made = LARGE.currents_for(B=(0.003, 0.005, -0.004))
        target = _tip_3d(LARGE, made)
        assert abs(target[2]) > 0.2 * L  # well out of the plane
        out = solve_currents(ROD, LARGE, target)
        assert np.linalg.norm(_tip_3d(LARGE, out.currents) - target) <= 1e-6 * L
        assert out.miss <= 1e-6 * L
        assert out.result.model == "spatial"
        # three channels, three conditions: the currents that made the target, found again
        np.testing.assert_allclose(out.currents, made, atol=1e-6 * np.abs(made).max())
        assert out.solves + out.start_solves <= 15
        assert out.target.shape == (3,)

    def test_ideal_controller_in_3d(self):
        """The ideal controller's currents make, at the centre, the uniform field that puts the
        tip on the 3D target (an independent solve in that uniform field), and its reported miss
        is the real-field tip's distance (independent solve)."""
        target = _tip_3d(COMPACT, COMPACT.currents_for(B=(0.003, 0.005, -0.004)), nodes=16)
        ideal = solve_currents(ROD, COMPACT, target, model="ideal", nodes=16)
        Bc = COMPACT.with_currents(ideal.currents).B(np.zeros((1, 3)))[0]
        assert abs(Bc[2]) > 0.3 * np.linalg.norm(Bc)  # a field well out of the plane
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = solve_rod(ROD, coils.UniformField(B=Bc), SCALES, tol=1e-11, nodes=16)
        assert np.linalg.norm(res.tip[-1] - target) <= 1e-5 * L
        real_tip = _tip_3d(COMPACT, ideal.currents, nodes=16)
        assert ideal.miss == pytest.approx(np.linalg.norm(real_tip - target), rel=1e-6)
        assert ideal.miss > 0.01 * L  # compact coils: the ideal controller is off

    def test_minimum_power_with_eight_coils(self):
        """Eight channels, three conditions: first-order optimality of min sum R I^2 on
        tip(I) = target -- R I orthogonal to the null space of the tip's Jacobian, by central
        differences of forward solves (independent of the adjoint) -- and no more power than
        the currents that made the target."""
        made = EIGHT.currents_for(B=(0.002, 0.004, 0.003))
        target = _tip_3d(EIGHT, made, nodes=16)
        out = solve_currents(ROD, EIGHT, target, nodes=16)
        assert np.linalg.norm(_tip_3d(EIGHT, out.currents, nodes=16) - target) <= 1e-6 * L
        h = 1e-3
        J = np.column_stack(
            [
                _tip_3d(EIGHT, out.currents + h * e, 16) - _tip_3d(EIGHT, out.currents - h * e, 16)
                for e in np.eye(8)
            ]
        ) / (2 * h)
        null = np.linalg.svd(J)[2][3:]
        RI = EIGHT.resistance * out.currents
        assert np.linalg.norm(null @ RI) <= 1e-4 * np.linalg.norm(RI)
        assert out.power < EIGHT.power(made)

    def test_beyond_the_current_limits_in_3d(self):
        """A calibrated eMNS model (Navion, coils.MPEM) in place of air coils: a target made
        with currents beyond the lowered limits is told apart from one out of reach."""
        navion = coils.presets.navion()
        target = _tip_3d(navion, navion.currents_for(B=(0.003, 0.005, -0.004)), nodes=8)
        with pytest.raises(
            ConvergenceError, match="beyond the current limits: not reachable within them"
        ) as info:
            solve_currents(ROD, navion, target, max_current=1.0, nodes=8)
        out = info.value.result
        assert out.active
        assert np.all(np.abs(out.currents) <= 1.0 + 1e-9)
        assert "outside the robot's reachable set" not in str(info.value)
        np.testing.assert_allclose(out.tip, _tip_3d(navion, out.currents, 8), atol=1e-8 * L)

    def test_a_branch_bound_is_no_limit(self):
        """Navion at 10 A, tip to (20, 30) mm: the damped search once kept channels on their
        side of zero (bounds narrowed after a step to another branch), stopped against such
        a bound (no limit active) and called the target outside the reachable set.  It is
        reachable within the limits: the currents returned put the tip on it in an
        independent forward solve."""
        navion = coils.presets.navion()
        out = solve_currents(ROD, navion, (0.020, 0.030), max_current=10.0, nodes=8, steps=3)
        assert out.status == "converged"
        assert np.all(np.abs(out.currents) <= 10.0)
        tip = _tip_3d(navion, out.currents, nodes=8)
        np.testing.assert_allclose(tip, (0.020, 0.030, 0.0), atol=1e-6 * L)

    def test_the_ideal_controller_stops_at_a_branch_edge(self):
        """Navion at 10 A, the ideal controller, (20, 30) mm: the miss left in its own model
        lies across an edge of the rod's branch (every small step along it snaps the rod to
        another branch, the tip ~1 L away).  The old search alternated such a jump with a
        0.3-0.7 % gain and spent all 40 solves (from this warm start on the branch, 0.25 mm
        off); it now stops at the edge within a handful, says so, and returns the closest
        state on the branch.  Its misses are those of independent forward solves at the
        returned currents: in the real field, and in the centre field's linearisation made
        by coils (``MPEM.ideal``) rather than by the controller's per-ampere maps."""
        import re

        from coilrod.control.currents import ControlWarning

        navion = coils.presets.navion()
        target = np.array([0.020, 0.030, 0.0])
        with pytest.warns(ControlWarning, match="edge of the rod's branch") as record:
            out = solve_currents(
                ROD, navion, target[:2], max_current=10.0, model="ideal", nodes=8, steps=3,
                initial=[-1.1636, 5.0124, -2.1141],
            )  # fmt: skip
        assert (out.status, out.optimal) == ("branch_edge", False)
        assert out.solves <= 8  # the old search: 40
        said = str(record[0].message)
        assert f"after {out.solves} solves" in said
        own = float(re.search(r"model is (\S+) m", out.message).group(1))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = navion.with_currents(out.currents).ideal()
            tip = solve_rod(ROD, model, SCALES, tol=1e-11, nodes=8).tip[-1]
        assert own == pytest.approx(np.linalg.norm(tip - target), rel=1e-3)
        assert own == pytest.approx(min(out.history), rel=1e-3)  # the closest state returned
        assert 1e-7 * L < own < 2e-3 * L  # near the target, but not on it
        assert out.miss == pytest.approx(np.linalg.norm(_tip_3d(navion, out.currents, 8) - target))

    def test_a_3d_target_needs_three_field_directions(self):
        planar = coils.CoilSystem(
            [
                coils.HelmholtzPair(0.1, 200, 0.0, axis="x"),
                coils.HelmholtzPair(0.1, 200, 0.0, axis="y"),
            ]
        )
        with pytest.raises(ValueError, match="3D target needs"):
            solve_currents(ROD, planar, (0.03, 0.02, 0.01))

    def test_beyond_the_rod_length_in_3d(self):
        with pytest.raises(ConvergenceError, match="beyond the rod's length"):
            solve_currents(ROD, LARGE, (0.03, 0.02, 0.02))


class TestBadInput:
    @pytest.mark.parametrize(
        ("kwargs", "match"),
        [
            ({"target": (0.03, np.nan)}, "target"),
            ({"target": (0.03, 0.02, 0.0, 0.0)}, "target"),
            ({"target": (0.03, 0.02, 0.01), "angle": 0.5}, "angle"),
            ({"max_current": 0.0}, "max_current"),
            ({"max_current": -1.0}, "max_current"),
            ({"max_current": np.nan}, "max_current"),
            ({"model": "linear"}, "model"),
            ({"max_solves": 0}, "max_solves"),
            ({"max_solves": 2.5}, "max_solves"),
            ({"steps": 0}, "steps"),
            ({"max_iter": True}, "max_iter"),
            ({"initial": (1.0, np.nan, 0.0)}, "initial"),
            ({"initial": (1.0, 2.0)}, "initial"),
            ({"initial": (20.0, 0.0, 0.0)}, "initial"),
        ],
    )
    def test_bad_arguments(self, kwargs, match):
        args = {"target": (0.03, 0.02)} | kwargs
        with pytest.raises(ValueError, match=match):
            solve_currents(ROD, LARGE, **args)

    def test_system_without_in_plane_channels(self):
        z_only = coils.CoilSystem([coils.HelmholtzPair(0.1, 200, 0.0, axis="z")])
        with pytest.raises(ValueError, match="cannot make every in-plane field"):
            solve_currents(ROD, z_only, (0.03, 0.02))

    def test_not_a_system(self):
        with pytest.raises(ValueError, match="current control"):
            solve_currents(ROD, coils.UniformField(B=(0, 0.01, 0)), (0.03, 0.02))


def test_minimum_power_on_near_singular_channels():
    """coils.currents.minimum_power on a CardioMag-like rank-deficient map (5 targets, 8
    channels, rank 3 plus two round-off singular values ~1e-10): instances 37 and 100 of this
    stream raised RuntimeError (the least-distance program in the exact null space failed on
    targets the limits allow).  Now: the currents make the target, within the limits, with no
    more power than the feasible currents of an independent linear program (linprog)."""
    from scipy.optimize import linprog

    from coils.currents import minimum_power

    rng = np.random.default_rng(0)
    for t in range(101):
        U = np.linalg.qr(rng.normal(size=(5, 5)))[0]
        V = np.linalg.qr(rng.normal(size=(8, 8)))[0]
        s = np.r_[rng.uniform(0.1, 1, 3), 1e-10 * rng.uniform(size=2)]
        A = (U * s) @ V[:5]
        b = A @ (15 * rng.uniform(-1, 1, 8))
        lim = np.full(8, 20.0) * rng.uniform(0.5, 1.0)
        if t not in (0, 37, 100):
            continue
        sol = minimum_power(A, b, np.ones(8), lim)
        assert np.linalg.norm(A @ sol.currents - b) <= 1e-9 * np.linalg.norm(b)
        assert np.all(np.abs(sol.currents) <= lim)
        lp = linprog(np.zeros(8), A_eq=A, b_eq=b, bounds=list(zip(-lim, lim, strict=True)))
        assert lp.status == 0
        assert sol.currents @ sol.currents <= lp.x @ lp.x * (1 + 1e-9)


def test_a_failed_least_distance_program_falls_back(monkeypatch):
    """coils.currents.minimum_power raises RuntimeError when its NNLS solver fails (met on
    CardioMag with a position and direction target): the minimum-power step then falls back to
    the least-squares step within the limits, which here meets the linearised target exactly
    (a consistent system, checked by its residual) within the limits."""
    from types import SimpleNamespace

    from coilrod.control import currents

    def failing(*args):
        raise RuntimeError("the least-distance program failed on a feasible current target")

    monkeypatch.setattr(currents, "minimum_power", failing)
    rng = np.random.default_rng(3)
    J, I, r = rng.normal(size=(5, 8)), rng.uniform(-1, 1, 8), 0.1 * rng.normal(size=5)
    p = SimpleNamespace(resistance=np.ones(8), limits=np.full(8, 20.0))
    step = currents._least_power_step(J, r, I, p)
    np.testing.assert_allclose(J @ step, -r, atol=1e-12)
    assert np.all(np.abs(I + step) <= 20.0)


def test_a_warm_search_stops_where_the_stable_branch_ends(monkeypatch):
    """A toy search (misses r = I - (3, 0), exact Jacobian I; the rod stable only for
    I_0 < 1): its Gauss-Newton step lands on the target, unstable, so Levenberg-Marquardt
    starts from the closest stable state (the start).  A warm start's search stops after two
    trials that gain but leave the stable part (a fresh start follows it); a fresh search
    creeps to the stability boundary I_0 = 1 one solve at a time (the notebook's tip path:
    the last target's warm search took 39 solves instead of 14)."""
    from types import SimpleNamespace

    from coilrod.control import currents

    goal = np.array([3.0, 0.0])
    monkeypatch.setattr(
        currents, "_forward", lambda rod, I, steps, opts: SimpleNamespace(I=I, stable=[I[0] < 1])
    )
    p = SimpleNamespace(
        rod=None, steps=None, opts=None, length=1.0, limits=np.full(2, 10.0), model="real",
        resistance=np.ones(2), field_of=lambda I: np.array(I, float),
        residual=lambda res: res.I - goal, position_miss=lambda r: float(np.linalg.norm(r)),
        met=lambda r: np.linalg.norm(r) <= 1e-9, jacobian=lambda res: np.eye(2),
    )  # fmt: skip
    warm, I, _, status, edge = currents._search(p, np.zeros(2), 1, 200, fresh_next=True)
    assert (status, edge.unstable, warm.solves) == ("branch_edge", True, 4)
    np.testing.assert_array_equal(I, [0.0, 0.0])  # the closest stable state met
    assert "end of the stable part" in currents._ending(p, SimpleNamespace(I=I), 4, status, edge)
    fresh, I, _, status, _ = currents._search(p, np.zeros(2), 1, 200)
    assert fresh.solves > 10
    assert 0.99 < I[0] < 1.0  # crept to the boundary
