"""Exact sensitivities of rod states (coilrod.sensitivities), grouped by property.

The reference for every derivative is an independent one: central differences (five-point,
fourth order) of separate solve_rod runs at tolerance 1e-12 with the parameter moved, or a
closed form (small-deflection theory, tip = lambda L / 3).
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

import coils
from coilrod import Circle, ConvergenceError, Magnetization, Rod, solve_rod
from coilrod.design.sensitivity import SingularStateError, sensitivities

L = 0.04
LENGTHS = [0.01, 0.015, 0.015]
MAGS = np.array([100e3, 150e3, 80e3])
ANGLES = np.array([0.0, 0.5, -0.3])


def _rod(mags=MAGS, angles=ANGLES, E=1e6):
    return Rod(L, E, Circle(1e-3), Magnetization.segments(LENGTHS, mags, angles))


FIELDS = {
    "uniform": coils.UniformField(B=(0.0, 0.01, 0.002)),
    "linear": coils.LinearField(
        B0=(0.002, 0.008, 0.0),
        gradient=[[0.3, 0.1, 0.0], [0.1, -0.2, 0.0], [0.0, 0.0, -0.1]],
        origin=(0.01, 0.0, 0.0),
    ),
    "helmholtz": coils.HelmholtzPair(0.05, 100, 3.0, axis="y"),
    # two orthogonal pairs of a three-axis system (x, y channels; z at zero), a fixed
    # uniform part on top: only the channels are parameters
    "system": coils.presets.three_axis_helmholtz(radii=(0.06, 0.08, 0.1)).with_currents(
        [1.5, 2.5, 0.0]
    ),
}
SCALES = [0.4, 0.8, 1.0]
STATE = 1  # the middle state of a three-state sweep: the batched rows must be the right ones


def _solve(rod, field, scales=SCALES, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return solve_rod(rod, field, scales, tol=1e-12, **kw)


def _outputs(res, k=STATE):
    return np.r_[res.tip[k], res.tip_angle[k]]


def _central(build, h):
    """Five-point central difference of the tip outputs of ``build(delta)``."""
    f = {d: _outputs(build(d * h)) for d in (-2, -1, 1, 2)}
    return (8 * (f[1] - f[-1]) - (f[2] - f[-2])) / (12 * h)


def _perturbations(kind, field):
    """(label, build(delta) -> RodResult, step) for every parameter of the case."""
    rod = _rod()
    out = []
    # every segment's magnetization in each layout (uniform: "uniform"; mixed, with the force
    # terms: "linear"); the coil fields, solved in the same mixed layout, add their own
    # parameters and the tip segment's (their segment rows are the same code as "linear"'s)
    for j in range(3) if kind in ("uniform", "linear") else (2,):
        for group, base, step in (("magnitudes", MAGS, 2e3), ("angles", ANGLES, 2e-3)):

            def build(d, j=j, group=group, base=base):
                moved = base.copy()
                moved[j] += d
                if group == "magnitudes":
                    return _solve(_rod(mags=moved), field)
                return _solve(_rod(angles=moved), field)

            out.append((f"{group}[{j}]", build, step))
    out.append(
        (
            "youngs_modulus",
            lambda d: _solve(dataclasses.replace(rod, youngs_modulus=1e6 + d), field),
            2e4,
        )
    )
    out.append(("scale", lambda d: _solve(rod, field, [0.4, 0.8 + d, 1.0]), 2e-3))
    if kind == "uniform":
        for i in range(2):
            e = np.eye(3)[i]

            def build(d, e=e):
                return _solve(rod, coils.UniformField(B=field.B0 + d * e))

            out.append((f"B[{i}]", build, 1e-4))
    if kind == "helmholtz":

        def build(d):
            return _solve(rod, field.with_current(field.current + d))

        out.append(("currents[0]", build, 1e-3))
    if kind == "system":
        for i in range(3):
            e = np.eye(3)[i]

            def build(d, e=e):
                return _solve(rod, field.with_currents(field.currents + d * e))

            out.append((f"currents[{i}]", build, 1e-3))
    if kind == "linear":
        for i in range(2):
            e = np.eye(3)[i]

            def build(d, e=e):
                return _solve(rod, coils.LinearField(field.B0 + d * e, field.G, field.origin))

            out.append((f"B0[{i}]", build, 1e-4))
        for a in range(2):
            for b in range(2):
                E = np.zeros((3, 3))
                E[a, b] = 1.0

                def build(d, E=E):
                    return _solve(rod, coils.LinearField(field.B0, field.G + d * E, field.origin))

                out.append((f"gradient[{a},{b}]", build, 2e-3))
    return out


CASES = [
    (kind, label, build, step)
    for kind, field in FIELDS.items()
    for label, build, step in _perturbations(kind, field)
]


@pytest.fixture(scope="module")
def adjoint():
    """Sensitivities of the middle state of each field's sweep (computed once)."""
    return {kind: sensitivities(_solve(_rod(), field), STATE) for kind, field in FIELDS.items()}


class TestAgainstCentralDifferences:
    @pytest.mark.parametrize(
        ("kind", "label", "build", "step"), CASES, ids=[f"{c[0]}-{c[1]}" for c in CASES]
    )
    def test_derivative(self, adjoint, kind, label, build, step):
        sens = adjoint[kind]
        i = sens.parameters.index(label)
        got = np.r_[sens.tip[i], sens.tip_angle[i]]
        ref = _central(build, step)
        # positions (m) and angle (rad) on their own scales
        for sl in (slice(0, 3), slice(3, 4)):
            scale = np.max(np.abs(ref[sl]))
            if scale == 0.0:
                assert np.all(got[sl] == 0.0)
                continue
            assert np.max(np.abs(got[sl] - ref[sl])) <= 1e-6 * scale, (label, got, ref)

    def test_without_richardson(self):
        field = FIELDS["helmholtz"]
        sens = sensitivities(_solve(_rod(), field, richardson=False), STATE, wrt="angles")
        moved = ANGLES.copy()

        def build(d):
            moved2 = moved.copy()
            moved2[2] += d
            return _solve(_rod(angles=moved2), field, richardson=False)

        ref = _central(build, 2e-3)
        got = np.r_[sens["angles"].tip[2], sens["angles"].tip_angle[2]]
        assert np.max(np.abs(got - ref)) <= 1e-6 * np.max(np.abs(ref))

    def test_gradient_sensitivity_in_a_uniform_field(self):
        """A zero-gradient LinearField is solved in the uniform layout; its gradient
        sensitivity needs the force terms (mixed layout)."""
        field = coils.LinearField(B0=(0.0, 0.01, 0.0), gradient=np.zeros((3, 3)))
        rod = _rod()
        sens = sensitivities(_solve(rod, field), STATE, wrt="gradient")
        E = np.zeros((3, 3))
        E[1, 0] = 1.0  # dB_y/dx

        def build(d):
            return _solve(rod, coils.LinearField(field.B0, d * E, field.origin))

        ref = _central(build, 2e-3)
        i = sens.parameters.index("gradient[1,0]")
        got = np.r_[sens.tip[i], sens.tip_angle[i]]
        assert np.max(np.abs(got - ref)) <= 1e-6 * np.max(np.abs(ref))


class TestClosedForm:
    """Small deflections: tip y = lambda L / 3, lambda = A |M| B L^2 / (E I)."""

    def test_small_deflection_derivatives(self):
        rod = Rod(L, 1e6, Circle(2e-3), Magnetization(128e3, 0.0))
        lam = 1e-4
        B = rod.field_for_lambda(lam)
        res = solve_rod(rod, coils.UniformField(B=(0.0, B, 0.0)), [1.0], tol=1e-12)
        sens = sensitivities(res, 0)
        y = lam * L / 3
        # a constant magnetization is one segment: magnitudes[0], angles[0]
        assert sens["magnitudes"].tip[0, 1] == pytest.approx(y / 128e3, rel=1e-3)
        assert sens["youngs_modulus"].tip[0, 1] == pytest.approx(-y / 1e6, rel=1e-3)
        assert sens["B"].tip[1, 1] == pytest.approx(y / B, rel=1e-3)
        assert sens["scale"].tip[0, 1] == pytest.approx(y, rel=1e-3)
        # first order vanishes: B_x acts on m = M (cos theta, sin theta) only through
        # sin(theta) ~ lambda, and turning M by a in a field along y changes the torque by
        # cos(a) - 1 ~ a^2
        assert sens["B"].tip[0, 1] == pytest.approx(0.0, abs=1e-3 * y / B)
        assert sens["angles"].tip[0, 1] == pytest.approx(0.0, abs=1e-3 * y)


class TestSingularStates:
    def test_at_the_buckling_load_the_derivative_does_not_exist(self):
        """A straight rod in an antiparallel field is at a pitchfork at the critical load."""
        rod = Rod(L, 1e6, Circle(1e-3), Magnetization(100e3, 0.0))
        field = coils.UniformField(B=(-0.01, 0.0, 0.0))
        res0 = solve_rod(rod, field, [1e-3])
        problem = res0._solution.problems[0]
        mu0 = problem.mu0
        lin = problem.linearize(problem.straight(), 1.0)
        mu1 = float(problem.stability(lin, precise=True)[0])
        critical = mu0 / (mu0 - mu1)  # the straight rod's eigenvalue is linear in the scale
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                res = solve_rod(rod, field, [critical])
            except ConvergenceError:  # pragma: no cover - the straight branch converges
                pytest.fail("the straight branch should converge at the critical load")
        with pytest.raises(SingularStateError, match="bifurcation or limit point"):
            sensitivities(res, 0)

    def test_away_from_it_the_derivative_exists(self):
        rod = Rod(L, 1e6, Circle(1e-3), Magnetization(100e3, 0.0))
        res = solve_rod(rod, coils.UniformField(B=(-0.01, 0.0, 0.0)), [0.01])
        assert np.all(np.isfinite(sensitivities(res, 0).tip))


@pytest.fixture(scope="module")
def res():
    return _solve(_rod(), FIELDS["uniform"])


class TestBadInput:
    def test_unknown_group(self, res):
        with pytest.raises(ValueError, match="unknown parameter group 'stiffness'"):
            sensitivities(res, 0, wrt="stiffness")

    @pytest.mark.parametrize("group", ["currents", "B0", "gradient"])
    def test_group_the_state_does_not_have(self, res, group):
        with pytest.raises(ValueError, match=f"has no parameter '{group}'"):
            sensitivities(res, 0, wrt=[group])

    def test_segments_of_a_function_profile(self):
        rod = Rod(L, 1e6, Circle(1e-3), Magnetization(lambda s: 1e5 + 0 * s, 0.0))
        res = solve_rod(rod, FIELDS["uniform"], [0.5])
        with pytest.raises(ValueError, match="has no parameter 'magnitudes'"):
            sensitivities(res, 0, wrt="magnitudes")
        assert np.isfinite(sensitivities(res, 0, wrt="youngs_modulus").tip).all()

    @pytest.mark.parametrize("k", [3, -4, 1.0, True, "0"])
    def test_bad_index(self, res, k):
        with pytest.raises(ValueError, match="k"):
            sensitivities(res, k)

    def test_empty_wrt(self, res):
        with pytest.raises(ValueError, match="at least one"):
            sensitivities(res, 0, wrt=[])

    def test_not_a_rod_result(self):
        with pytest.raises(ValueError, match="RodResult"):
            sensitivities(object(), 0)

    def test_group_lookup(self, res):
        sens = sensitivities(res, -1, wrt=("scale", "B"))
        assert sens.index == 2
        assert sens["B"].tip.shape == (3, 3)
        assert sens.matrix.shape == (4, 4)
        with pytest.raises(KeyError, match="no parameter group 'angles'"):
            sens["angles"]


class TestFEM:
    """FEM states (direct method: one solve with the state's tangent per parameter) against
    central differences of independent solve_fem runs at a tight tolerance."""

    KW = dict(dim=2, elements=(16, 1))

    @pytest.fixture(scope="class")
    @classmethod
    def case(cls):
        from coilrod import solve_fem

        rod = Rod(
            L, 1e6, Circle(2e-3), Magnetization.segments([0.02, 0.02], [1e5, 1.5e5], [0.0, 0.4])
        )
        fields = {
            "uniform": coils.UniformField(B=(0.0, 0.004, 0.0)),
            "pair": coils.HelmholtzPair(0.06, 100, 2.0, axis="y"),
        }
        return (
            rod,
            fields,
            {
                k: sensitivities(solve_fem(rod, f, [0.5, 1.0], **cls.KW), 1)
                for k, f in fields.items()
            },
        )

    def _solve(self, rod, field, s=1.0):
        from coilrod import solve_fem

        r = solve_fem(rod, field, [0.5, s], rtol=1e-11, **self.KW)
        return np.r_[r.tip[1], r.tip_angle[1]]

    def _moved_rod(self, rod, mags=(1e5, 1.5e5), angles=(0.0, 0.4)):
        return dataclasses.replace(
            rod, magnetization=Magnetization.segments([0.02, 0.02], mags, angles)
        )

    @pytest.mark.parametrize("kind", ["uniform", "pair"])
    def test_against_central_differences(self, case, kind):
        rod, fields, sens = case
        field, sens = fields[kind], sens[kind]
        builds = {
            "scale": (lambda d: self._solve(rod, field, 1.0 + d), 1e-4),
            "youngs_modulus": (
                lambda d: self._solve(dataclasses.replace(rod, youngs_modulus=1e6 + d), field),
                1e2,
            ),
            "magnitudes[1]": (
                lambda d: self._solve(self._moved_rod(rod, (1e5, 1.5e5 + d)), field),
                1e2,
            ),
            "angles[0]": (
                lambda d: self._solve(self._moved_rod(rod, angles=(d, 0.4)), field),
                1e-4,
            ),
        }
        if kind == "uniform":
            builds["B[0]"] = (
                lambda d: self._solve(rod, coils.UniformField(B=(d, 0.004, 0.0))),
                1e-6,
            )
        else:
            builds["currents[0]"] = (lambda d: self._solve(rod, field.with_current(2.0 + d)), 1e-4)
        for label, (build, h) in builds.items():
            ref = (build(h) - build(-h)) / (2 * h)
            i = sens.parameters.index(label)
            got = np.r_[sens.tip[i], sens.tip_angle[i]]
            assert np.max(np.abs(got - ref)) <= 1e-6 * np.max(np.abs(ref)), label

    def test_bad_group(self, case):
        from coilrod import solve_fem

        rod, fields, _ = case
        res = solve_fem(rod, fields["uniform"], [0.5], **self.KW)
        with pytest.raises(ValueError, match="has no parameter 'currents'"):
            sensitivities(res, 0, wrt="currents")
        with pytest.raises(ValueError, match="out of range"):
            sensitivities(res, 1)


class TestSpatialStates:
    """Sensitivities of spatial states (adjoint of the spatial rod's Jacobian) against central
    differences of independent solves; and of planar states to out-of-plane parameters, whose
    first-order effect (the tip leaving the plane) only the spatial model has."""

    FIELDS3 = {
        "uniform": coils.UniformField(B=(0.0, 0.01, 0.002)),
        "linear": coils.LinearField(
            B0=(0.002, 0.008, 0.001),
            gradient=[[0.3, 0.1, 0.05], [0.1, -0.2, 0.0], [0.05, 0.0, -0.1]],
            origin=(0.01, 0.0, 0.0),
        ),
        "system": coils.presets.three_axis_helmholtz(radii=(0.06, 0.08, 0.1)).with_currents(
            [1.5, 2.5, 0.8]
        ),
    }

    @staticmethod
    def _check(sens, label, build, step):
        i = sens.parameters.index(label)
        got = np.r_[sens.tip[i], sens.tip_angle[i]]
        ref = _central(build, step)
        for sl in (slice(0, 3), slice(3, 4)):
            scale = np.max(np.abs(ref[sl]))
            assert np.max(np.abs(got[sl] - ref[sl])) <= 1e-6 * max(scale, 1e-12), (label, got, ref)

    @pytest.mark.parametrize("kind", ["uniform", "linear", "system"])
    def test_against_central_differences(self, kind):
        field = self.FIELDS3[kind]
        rod = _rod()
        res = _solve(rod, field)
        assert res.model == "spatial"
        sens = sensitivities(res, STATE)

        def mags(d):
            m = MAGS.copy()
            m[1] += d
            return _solve(_rod(mags=m), field)

        def angles(d):
            a = ANGLES.copy()
            a[2] += d
            return _solve(_rod(angles=a), field)

        self._check(sens, "magnitudes[1]", mags, 2e3)
        self._check(sens, "angles[2]", angles, 2e-3)
        self._check(
            sens,
            "youngs_modulus",
            lambda d: _solve(dataclasses.replace(rod, youngs_modulus=1e6 + d), field),
            2e4,
        )
        if kind == "uniform":
            self._check(
                sens,
                "B[2]",
                lambda d: _solve(rod, coils.UniformField(B=field.B0 + [0, 0, d])),
                1e-4,
            )
        if kind == "linear":
            E = np.zeros((3, 3))
            E[2, 0] = 1.0

            def grad(d):
                return _solve(rod, coils.LinearField(field.B0, field.G + d * E, field.origin))

            self._check(sens, "gradient[2,0]", grad, 2e-3)
        if kind == "system":

            def cur(d):
                return _solve(rod, field.with_currents(field.currents + [0, 0, d]))

            self._check(sens, "currents[2]", cur, 1e-3)

    def test_planar_state_out_of_plane_parameter(self):
        field = coils.UniformField(B=(0.0, 0.01, 0.0))
        rod = _rod()
        res = _solve(rod, field)
        assert res.model == "planar"
        sens = sensitivities(res, STATE, wrt="B")
        self._check(
            sens, "B[2]", lambda d: _solve(rod, coils.UniformField(B=field.B0 + [0, 0, d])), 1e-4
        )
        assert abs(sens.tip[sens.parameters.index("B[2]")][2]) > 0  # the tip leaves the plane
