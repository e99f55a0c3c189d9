"""Physics consistency of solve_rod (the planar hard-magnetic Kirchhoff rod, seed eq. 5).

Cross-checks, each against an independent reference:
* small deflection: tip deflection lambda L / 3 (linear beam theory);
* M(1) in a uniform field at several angles, lambda up to 50, default settings: tip within
  1e-6 L of the closed-form elliptic-integral elastica (coilrod.elastica);
* convergence order: log-log slopes ~2 (one mesh) and ~4 (Richardson) against the elastica,
  and for a gradient field against scipy solve_bvp at tol 1e-10;
* a pure-gradient case solved by hand (Maxwell gradient, transverse magnetization):
  y_tip = 11/48 gamma L, tip angle gamma / 3 (linear Euler-Bernoulli beam);
* scale invariance (metres vs millimetres, E and B scaled together) and mirror symmetry,
  rotated/translated clamp (exact symmetries of the equations);
* Jacobian against central finite differences of the residual (uniform, linear, nonlinear
  fields with an analytic Hessian, and a real coil pair);
* segments with jumps (M(4.1), M(4.2)) and gradients (M(3), Config B) against solve_bvp;
* coupling: a Helmholtz pair of radius 2L moves the tip measurably away from its ideal()
  field, and the coil solve agrees with solve_bvp on the same coil field;
* the mixed layout's band LU (threshold partial pivoting) against numpy's dense solve and
  slogdet.
"""

import math
import warnings

import numpy as np
import pytest
from rod_bvp_reference import solve_bvp_rod

import coils
from coilrod import Circle, Magnetization, Rod, presets, solve_rod
from coilrod.errors import UnitsWarning
from coilrod.rod.elastica import elastica
from coilrod.rod.solve import build_problem, make_mesh

with warnings.catch_warnings():  # a scale-free unit rod (L = E = D = |M| = 1): no units
    warnings.simplefilter("ignore", UnitsWarning)
    UNIT_ROD = Rod(1.0, 1.0, Circle(1.0), Magnetization(1.0, 0.0))


def _field_at_angle(rod, lam, phi):
    B = rod.field_for_lambda(lam)
    return coils.UniformField(B=(B * math.cos(phi), B * math.sin(phi), 0.0))


def test_small_deflection_lambda_over_three():
    rod = presets.seed_rod()
    lam = 1e-4
    res = solve_rod(rod, _field_at_angle(rod, lam, math.pi / 2), [1.0])
    # linear theory has relative error O(lambda^2) here: (tip - lambda L/3) / (lambda L/3)
    assert res.tip[0, 1] == pytest.approx(lam * rod.length / 3, rel=1e-6)
    assert res.tip_angle[0] == pytest.approx(lam / 2, rel=1e-6)


@pytest.mark.parametrize("phi", [math.pi / 6, math.pi / 2, 2.0, 2.8, 3.1, -math.pi / 2])
def test_elastica_sweep_to_lambda_50_default_settings(phi):
    lams = np.linspace(0.0, 50.0, 11)[1:]
    res = solve_rod(UNIT_ROD, _field_at_angle(UNIT_ROD, 1.0, phi), lams)
    assert res.converged.all()
    assert res.stable.all()
    for k, lam in enumerate(lams):
        ref = elastica(lam, phi)
        assert np.linalg.norm(res.tip[k, :2] - ref.tip) <= 1e-6
        assert res.tip_angle[k] == pytest.approx(ref.tip_angle, abs=1e-5)


def test_single_jump_to_lambda_50_with_physical_units():
    rod = presets.seed_rod()
    res = solve_rod(rod, _field_at_angle(rod, 50.0, 2.0), [1.0])
    ref = elastica(50.0, 2.0, length=rod.length)
    assert np.linalg.norm(res.tip[0, :2] - ref.tip) <= 1e-6 * rod.length
    assert res.centerline(0)[0] == pytest.approx([0, 0, 0])
    assert np.allclose(res.centerline(0)[-1], res.tip[0])
    assert res.s[-1] == pytest.approx(rod.length)


def _slope(ns, errs):
    return -np.polyfit(np.log(ns), np.log(errs), 1)[0]


def test_convergence_order_uniform_field():
    lam, phi = 20.0, 2.0
    ref = elastica(lam, phi).tip
    ns = np.array([16, 32, 64])
    err2 = [
        np.linalg.norm(
            solve_rod(
                UNIT_ROD, _field_at_angle(UNIT_ROD, lam, phi), [1.0], nodes=n, richardson=False
            ).tip[0, :2]
            - ref
        )
        for n in ns
    ]
    err4 = [
        np.linalg.norm(
            solve_rod(UNIT_ROD, _field_at_angle(UNIT_ROD, lam, phi), [1.0], nodes=n).tip[0, :2]
            - ref
        )
        for n in ns
    ]
    assert _slope(ns, err2) == pytest.approx(2.0, abs=0.1)
    assert _slope(ns, err4) == pytest.approx(4.0, abs=0.3)


def test_convergence_order_gradient_field():
    rod = presets.seed_rod(presets.M3())
    L = rod.length
    field = coils.LinearField(
        B0=(0.0, 8e-3, 0.0), gradient=coils.maxwell_gradient(0.4), origin=(0.5 * L, 0.0, 0.0)
    )
    start = solve_rod(rod, field, [1.0], nodes=8, richardson=False)  # picks the branch only
    ref = solve_bvp_rod(
        rod, field, tol=1e-10, guess=lambda s: np.interp(s, start.s, start.theta(0))
    )
    assert ref.status == 0
    tip = ref.sol(L)[2:4]
    ns = np.array([8, 16, 32])
    err2 = [
        np.linalg.norm(solve_rod(rod, field, [1.0], nodes=n, richardson=False).tip[0, :2] - tip) / L
        for n in ns
    ]
    err4 = [np.linalg.norm(solve_rod(rod, field, [1.0], nodes=n).tip[0, :2] - tip) / L for n in ns]
    assert err2[0] > 1e-5  # a real deflection (not the trivial state)
    assert _slope(ns, err2) == pytest.approx(2.0, abs=0.15)
    assert _slope(ns, err4) == pytest.approx(4.0, abs=0.4)


def test_pure_gradient_small_deflection_closed_form():
    """Maxwell gradient g diag(-1/2, 1, -1/2) at the clamp, B0 = 0, M transverse (theta_m =
    pi/2).  Linearised: torque A M g s / 2 and force A M g along y, so
    EI theta'' = -A M g (L - s/2): theta(L) = gamma/3, y(L) = 11 gamma L / 48,
    gamma = A M g L^3 / (EI)."""
    rod = Rod(0.04, 1e6, Circle(2e-3), Magnetization(128e3, math.pi / 2))
    gamma = 1e-4
    g = gamma * rod.bending_stiffness / (rod.area * 128e3 * rod.length**3)
    field = coils.LinearField(gradient=coils.maxwell_gradient(g))
    res = solve_rod(rod, field, [1.0])
    assert res.tip[0, 1] == pytest.approx(11 * gamma * rod.length / 48, rel=1e-3)
    assert res.tip_angle[0] == pytest.approx(gamma / 3, rel=1e-3)


def test_scale_invariance_metres_millimetres_and_E_B():
    rod_m = presets.seed_rod(presets.M2(variant="b"))
    field_m = coils.LinearField(
        B0=(2e-3, 6e-3, 0.0), gradient=coils.maxwell_gradient(0.3), origin=(0.01, 0.004, 0.0)
    )
    res_m = solve_rod(rod_m, field_m, [0.5, 1.0], nodes=24)
    # millimetres, newtons, amperes: E in N/mm^2, M in A/mm, B in N/(A mm), G in N/(A mm^2)
    L_mm = 40.0
    with pytest.warns(UnitsWarning):  # (the units check sees mm as metres: it warns)
        rod_mm = Rod(
            L_mm,
            1e6 * 1e-6,
            Circle(L_mm / 20),
            presets.M2(length=L_mm, variant="b", M0=640e3 * 1e-3),
        )
    field_mm = coils.LinearField(
        B0=(2e-6, 6e-6, 0.0), gradient=coils.maxwell_gradient(0.3e-6), origin=(10.0, 4.0, 0.0)
    )
    res_mm = solve_rod(rod_mm, field_mm, [0.5, 1.0], nodes=24)
    assert np.allclose(res_mm.tip * 1e-3, res_m.tip, rtol=0, atol=1e-12 * rod_m.length)
    # E and B scaled by the same factor: same shape
    rod_e = Rod(rod_m.length, 7.0 * rod_m.youngs_modulus, rod_m.section, rod_m.magnetization)
    field_e = coils.LinearField(
        B0=7.0 * field_m.B0, gradient=7.0 * field_m.G, origin=field_m.origin
    )
    res_e = solve_rod(rod_e, field_e, [0.5, 1.0], nodes=24)
    assert np.allclose(res_e.tip, res_m.tip, rtol=0, atol=1e-12 * rod_m.length)


def test_mirror_symmetry():
    L = 0.04
    P = np.diag([1.0, -1.0, 1.0])
    G = np.array([[0.1, 0.3, 0.0], [0.3, 0.2, 0.05], [0.0, 0.05, -0.3]])
    rod = presets.seed_rod(presets.M2(variant="a"))
    angle = rod.magnetization.angle
    rod_mirror = Rod(
        rod.length,
        rod.youngs_modulus,
        rod.section,
        Magnetization(rod.magnetization.magnitude, lambda s: -angle(s)),
    )
    field = coils.LinearField(B0=(3e-3, 5e-3, 1e-3), gradient=G, origin=(0.3 * L, 0.1 * L, 0))
    field_mirror = coils.LinearField(B0=P @ field.B0, gradient=P @ G @ P, origin=P @ field.origin)
    res = solve_rod(rod, field, [1.0], nodes=24, clamp_angle=0.2, clamp_position=(0, 0.1 * L, 0))
    mir = solve_rod(
        rod_mirror, field_mirror, [1.0], nodes=24, clamp_angle=-0.2, clamp_position=(0, -0.1 * L, 0)
    )
    assert abs(res.tip[0, 1] - 0.1 * L) > 0.05 * L  # bent
    assert np.allclose(mir.tip[0], P @ res.tip[0], rtol=0, atol=1e-13)
    assert mir.tip_angle[0] == pytest.approx(-res.tip_angle[0], abs=1e-12)


def test_rotated_translated_clamp():
    """Rotating the clamp and the field together rotates the solution (frame indifference)."""
    L = 0.04
    a = 0.7
    R = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    x0 = np.array([0.01, -0.02, 0.003])
    rod = presets.seed_rod(presets.M42())
    G = coils.maxwell_gradient(0.5)
    field = coils.LinearField(B0=(1e-3, 8e-3, 0.0), gradient=G, origin=(0.5 * L, 0, 0))
    rfield = coils.LinearField(B0=R @ field.B0, gradient=R @ G @ R.T, origin=x0 + R @ field.origin)
    res = solve_rod(rod, field, [1.0], nodes=32)
    rot = solve_rod(rod, rfield, [1.0], nodes=32, clamp_position=x0, clamp_angle=a)
    assert np.allclose(rot.tip[0], x0 + R @ res.tip[0], rtol=0, atol=1e-13)
    assert rot.tip_angle[0] == pytest.approx(res.tip_angle[0] + a, abs=1e-12)


class QuadraticField(coils.Field):
    """Curl- and divergence-free B = c (x^2 - y^2, -2xy, 0) with closed-form derivatives."""

    def __init__(self, c):
        self.c = c

    def _B(self, p):
        x, y = p[:, 0], p[:, 1]
        return self.c * np.stack([x * x - y * y, -2 * x * y, 0 * x], axis=1)

    def _gradient(self, p):
        x, y = p[:, 0], p[:, 1]
        G = np.zeros((p.shape[0], 3, 3))
        G[:, 0, 0], G[:, 0, 1] = 2 * x, -2 * y
        G[:, 1, 0], G[:, 1, 1] = -2 * y, -2 * x
        return self.c * G

    def _hessian(self, p):
        H = np.zeros((p.shape[0], 3, 3, 3))
        H[:, 0, 0, 0], H[:, 0, 1, 1] = 2.0, -2.0
        H[:, 1, 0, 1] = H[:, 1, 1, 0] = -2.0
        return self.c * H


@pytest.mark.parametrize("kind", ["uniform", "linear", "quadratic", "helmholtz"])
def test_jacobian_matches_finite_differences(kind):
    rod = presets.seed_rod(presets.M42())
    L = rod.length
    field = {
        "uniform": coils.UniformField(B=(3e-3, 8e-3, 0.0)),
        "linear": coils.LinearField(
            B0=(2e-3, 8e-3, 0.0), gradient=coils.maxwell_gradient(0.5), origin=(0.01, 0.005, 0.0)
        ),
        "quadratic": QuadraticField(20.0) + coils.UniformField(B=(0.0, 5e-3, 0.0)),
        "helmholtz": coils.HelmholtzPair(
            radius=1.5 * L, turns=300, current=2.0, axis="y", center=(0.3 * L, 0.1 * L, 0.0)
        ),
    }[kind]
    problem = build_problem(rod, field, make_mesh(rod, 10), np.zeros(3), 0.1)
    rng = np.random.default_rng(3)
    theta = 0.1 + np.cumsum(rng.normal(scale=0.2, size=problem.n))
    u = problem.from_theta(theta, 1.3) + (
        0 if problem.uniform else rng.normal(scale=1e-3, size=problem.size)
    )
    J = problem.dense_jacobian(u, 1.3)
    eps = 1e-6
    Jfd = np.empty_like(J)
    for j in range(problem.size):
        e = np.zeros(problem.size)
        e[j] = eps
        Jfd[:, j] = (problem.residual(u + e, 1.3) - problem.residual(u - e, 1.3)) / (2 * eps)
    tol = 1e-6 if kind == "helmholtz" else 1e-8  # coil Hessian: central difference of G
    assert np.abs(J - Jfd).max() <= tol * np.abs(J).max()


@pytest.mark.parametrize("case", ["M41", "M42", "M3_configB"])
def test_profiles_and_gradients_against_solve_bvp(case):
    L = presets.SEED_LENGTH
    if case == "M3_configB":
        rod = presets.seed_rod(presets.M3())
        field = coils.LinearField(B0=(0.0, 5e-3, 0.0), gradient=coils.maxwell_gradient(0.6))
    else:
        rod = presets.seed_rod(getattr(presets, case)())
        field = coils.UniformField(B=(0.0, 0.02, 0.0))
    res = solve_rod(rod, field, [0.5, 1.0])
    ref = solve_bvp_rod(rod, field, tol=1e-9, guess=lambda s: np.interp(s, res.s, res.theta(1)))
    assert ref.status == 0
    assert abs(res.tip_angle[1]) > 0.2  # large deflection
    assert np.linalg.norm(res.tip[1, :2] - ref.sol(L)[2:4]) <= 1e-6 * L


def test_helmholtz_pair_differs_from_ideal_and_matches_solve_bvp():
    rod = presets.seed_rod()
    L = rod.length
    pair = coils.HelmholtzPair(radius=2 * L, turns=200, current=1.0, axis="y")
    ideal = pair.ideal()
    scale = 5.0 / rod.magnetoelastic_number(ideal.B0[1])  # lambda = 5 at the centre
    res = solve_rod(rod, pair, [0.5 * scale, scale])
    res_ideal = solve_rod(rod, ideal, [0.5 * scale, scale])
    shift = np.linalg.norm(res.tip[1] - res_ideal.tip[1])
    assert shift > 1e-3 * L  # the real field moves the tip measurably
    ref = solve_bvp_rod(
        rod, pair, scale, tol=1e-9, guess=lambda s: np.interp(s, res.s, res.theta(1))
    )
    assert ref.status == 0
    assert np.linalg.norm(res.tip[1, :2] - ref.sol(L)[2:4]) <= 1e-3 * shift
    assert np.linalg.norm(res.tip[1, :2] - ref.sol(L)[2:4]) <= 1e-6 * L


@pytest.fixture
def mixed_pass(monkeypatch):
    """``mixed_pass("numpy")`` or ``mixed_pass("compiled")``: which mixed kernel assembles from
    now on (coilrod.rod._compiled decides otherwise by the cost of the numpy calls so far)."""
    import coilrod.rod._compiled as rc

    def force(name, after=math.inf):
        monkeypatch.setattr(rc._rental, "held", lambda: False)
        monkeypatch.setattr(rc._rental, "spent", 0.0)
        monkeypatch.setattr(rc._rental, "ready", name == "compiled")
        monkeypatch.setattr(rc, "COMPILE_AFTER", after)

    return force


def test_numpy_and_compiled_mixed_kernels_agree(mixed_pass):
    # the numpy kernel (cold start) and the compiled one: the same residual and Jacobian to
    # the last bit, with a real coil pair (hessian terms)
    import coilrod.rod._compiled as rc

    rod = presets.seed_rod(presets.M42())
    L = rod.length
    field = coils.HelmholtzPair(1.5 * L, 300, 2.0, axis="y", center=(0.3 * L, 0.1 * L, 0.0))
    problem = build_problem(rod, field, make_mesh(rod, 10), np.zeros(3), 0.1)
    rng = np.random.default_rng(3)
    theta = 0.1 + np.cumsum(rng.normal(scale=0.2, size=problem.n))
    u = problem.from_theta(theta, 1.3) + rng.normal(scale=1e-3, size=problem.size)
    out = {}
    for name in ("compiled", "numpy"):
        mixed_pass(name)
        out[name] = (problem.residual(u, 1.3), problem.dense_jacobian(u, 1.3))
    assert not rc._rental.ready  # the numpy kernel did run
    for x, ref in zip(out["numpy"], out["compiled"], strict=True):
        np.testing.assert_array_equal(x, ref)  # bitwise: numbers do not change on compiling
    # an infinite angle is a non-finite residual on both paths (math.cos raised ValueError)
    u_inf = u.copy()
    u_inf[2 + 5 * 3] = np.inf
    for name in ("compiled", "numpy"):
        mixed_pass(name)
        assert not np.isfinite(problem.residual(u_inf, 1.3)).all()
    # (the compiled Jacobian at this very state is checked against central finite differences
    # by test_jacobian_matches_finite_differences[helmholtz]: bitwise equal, so the numpy one is)
    # compiling starts once the numpy calls' estimated cost passes COMPILE_AFTER
    mixed_pass("numpy", after=2.5 * (rc._NUMPY_CALL_S + rc._NUMPY_NODE_S * problem.n))
    problem.residual(u, 1.3)
    problem.residual(u, 1.3)
    assert not rc._rental.ready
    np.testing.assert_allclose(problem.residual(u, 1.3), out["compiled"][0], rtol=0, atol=0)
    assert rc._rental.ready


def _band_storage(A, kl, ku):
    n = A.shape[0]
    ab = np.zeros((2 * kl + ku + 1, n), order="F")
    for i in range(n):
        for j in range(max(0, i - kl), min(n, i + ku + 1)):
            ab[kl + ku + i - j, j] = A[i, j]
    return ab


@pytest.mark.parametrize("diagonal", [0.5, 0.05])
def test_band_lu_exchanges_rows_only_where_the_diagonal_is_weak(diagonal):
    # threshold partial pivoting (coilrod.rod._compiled.band_lu, which factorises the mixed
    # layout's band Jacobian): the first column's largest entry is 2.0 three rows below the
    # diagonal; a diagonal of 0.5 (>= PIVOT_THRESHOLD 0.1 of it) stays the pivot, 0.05 does
    # not.  Solves and transposed solves against numpy's dense solve, the determinant's sign
    # (negative pivots + exchanges) against slogdet.
    from coilrod.rod._compiled import PIVOT_THRESHOLD, band_lu, band_solve, band_solve_transposed

    n, kl, ku = 24, 5, 5
    rng = np.random.default_rng(11)
    A = sum(np.diag(rng.uniform(-1.0, 1.0, n - abs(d)), d) for d in range(-kl, ku + 1))
    A += np.diag(np.full(n, 3.0))
    A[0, 0], A[3, 0] = diagonal, 2.0
    ab = _band_storage(A, kl, ku)
    ipiv = np.empty(n, dtype=np.int64)
    assert band_lu(ab, kl, ku, ipiv, 0) == 0
    assert ipiv[0] == (0 if diagonal >= PIVOT_THRESHOLD * 2.0 else 3)
    b = rng.normal(size=(n, 2))
    x = b.copy()
    band_solve(ab, kl, ku, ipiv, x)
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-12, atol=1e-12)
    y = b.copy()
    band_solve_transposed(ab, kl, ku, ipiv, y)
    np.testing.assert_allclose(y, np.linalg.solve(A.T, b), rtol=1e-12, atol=1e-12)
    swaps = np.count_nonzero(ipiv != np.arange(n))
    negative = np.count_nonzero(ab[kl + ku] < 0)
    assert (-1) ** (swaps + negative) == np.linalg.slogdet(A)[0]


def test_band_lu_restarts_from_a_column_bitwise():
    # band_lu from a column (the contact predictor's rates after an event): the factors of a
    # matrix whose rows from r on changed, restarted at the first column those rows reach
    # with the earlier factors' leading columns kept, are bitwise (factors, pivots, info) the
    # factorisation from column 0; weak diagonals make row exchanges before and after the
    # restart (their fill reaching past it); restarts at both edges; a zero column before it
    # keeps its info.  One right-hand side is solved bitwise as the first of two (and both
    # against numpy's dense solve).  Plain Python (.py_func): no compiled version for the test.
    from coilrod.rod._compiled import band_lu, band_solve

    lu, solve = band_lu.py_func, band_solve.py_func
    n, kl, ku = 28, 3, 2
    rng = np.random.default_rng(5)

    def matrix():
        # the lower diagonals 4x the others: row exchanges in a third of the columns
        return sum(
            np.diag(rng.uniform(-1.0, 1.0, n - abs(d)) * (4.0 if d < 0 else 1.0), d)
            for d in range(-kl, ku + 1)
        )

    def factor(A, start=0, kept=None):
        ab, ipiv = _band_storage(A, kl, ku), np.zeros(n, dtype=np.int64)
        if kept is not None:
            ab[:, :start], ipiv[:start] = kept[0][:, :start], kept[1][:start]
        info = lu(ab, kl, ku, ipiv, start)
        return ab, ipiv, info

    for zero_column in (None, 4):
        A = matrix()
        if zero_column is not None:
            A[:, zero_column] = 0.0
        old = factor(A)
        assert np.count_nonzero(old[1] != np.arange(n)) >= 3
        for r in (0, 1, 9, 17, n - 1):
            B = A.copy()
            B[r:] = matrix()[r:]
            if zero_column is not None:
                B[:, zero_column] = 0.0
            start = max(0, r - kl)  # the first column the changed rows reach
            full, again = factor(B), factor(B, start, old)
            for a, b in zip(full, again, strict=True):
                assert np.array_equal(a, b)
            assert full[2] == (0 if zero_column is None else zero_column + 1)
        assert factor(A, n, old)[2] == old[2]  # (every column kept: nothing to do)
    A = matrix()
    ab, ipiv, _ = factor(A)
    b = rng.normal(size=(n, 2))
    x1, x2 = b[:, :1].copy(), b.copy()
    solve(ab, kl, ku, ipiv, x1)
    solve(ab, kl, ku, ipiv, x2)
    assert np.array_equal(x1[:, 0], x2[:, 0])
    np.testing.assert_allclose(x2, np.linalg.solve(A, b), rtol=1e-10, atol=1e-12)


def test_rate_step_restarts_the_factors_and_the_solve_bitwise(monkeypatch):
    # the contact predictor's compiled rate after an event (coilrod.rod._compiled.rate_step,
    # and rate_solve in it; their .py_func, band_lu's too: no compiled version for the test):
    # a point's row of a band matrix switched (its entries rewritten in the unfactorised
    # band), the factors restarted at the row's first column and the solve restarted there
    # (the last solve's forward sweep kept) are bitwise band_lu from column 0 and band_solve
    # of the new matrix (rows exchanged before and after the restart), and numpy's dense solve
    import coilrod.rod._compiled as rc

    monkeypatch.setattr(rc, "band_lu", rc.band_lu.py_func)
    monkeypatch.setattr(rc, "rate_solve", rc.rate_solve.py_func)
    n, kl, ku = 20, 3, 2
    rng = np.random.default_rng(7)
    A = sum(
        np.diag(rng.uniform(-1.0, 1.0, n - abs(d)) * (4.0 if d < 0 else 1.0), d)
        for d in range(-kl, ku + 1)
    )
    rhs = rng.normal(size=(n, 1))
    points = np.array([[5, 6, 7], [12, 13, 14]])  # (the rows 6 and 13: their entries' columns)
    bf, cf = kl + ku + points.mean(axis=1, keepdims=True).astype(np.int64) - points, points
    rows = np.stack([A[[6, 13]][np.arange(2)[:, None], points], rng.normal(size=(2, 3))])
    band = _band_storage(A, kl, ku)
    ab, ipiv = band.copy(order="F"), np.zeros(n, np.int64)
    assert rc.band_lu(ab, kl, ku, ipiv, 0) == 0
    keep, x = np.full((2, n), np.nan), np.empty((n, 1))
    assert rc.rate_solve(ab, kl, ku, ipiv, rhs, x, 0, keep) == 0
    x_ref = rhs.copy()
    rc.band_solve.py_func(ab, kl, ku, ipiv, x_ref)
    assert np.array_equal(x, x_ref)  # (the solve from row 0: band_solve's)
    active = np.array([False, True])  # point 1 switched to its other row
    flipped = np.array([1])
    assert rc.rate_step.py_func(band, ab, ipiv, bf, cf, rows, active, flipped, 1, kl, ku, rhs,
                                x, keep) == 0  # fmt: skip
    B = A.copy()
    B[13, 12:15] = rows[1, 1]
    assert np.array_equal(band, _band_storage(B, kl, ku))
    ab_ref, ipiv_ref = _band_storage(B, kl, ku), np.zeros(n, np.int64)
    assert rc.band_lu(ab_ref, kl, ku, ipiv_ref, 0) == 0
    assert np.count_nonzero(ipiv_ref != np.arange(n)) >= 3
    assert np.array_equal(ab, ab_ref)
    assert np.array_equal(ipiv, ipiv_ref)
    x_ref = rhs.copy()
    rc.band_solve.py_func(ab_ref, kl, ku, ipiv_ref, x_ref)
    assert np.array_equal(x, x_ref)
    np.testing.assert_allclose(x, np.linalg.solve(B, rhs), rtol=1e-10, atol=1e-12)
    # point 0 back (and no switch at all: the solve alone, every row kept)
    active[:] = False
    B[6, 5:8] = rows[0, 0]
    for flips in (np.array([0]), np.array([], np.int64)):
        assert rc.rate_step.py_func(band, ab, ipiv, bf, cf, rows, active, flips, flips.size,
                                    kl, ku, rhs, x, keep) == 0  # fmt: skip
        np.testing.assert_allclose(x, np.linalg.solve(B, rhs), rtol=1e-10, atol=1e-12)


def test_band_kernels_compile_once_for_either_band_order():
    # issue 19: a C-ordered band (a member sliced out of a stack) and the assembled
    # Fortran-ordered one reach band_lu / band_solve in one layout (one compiled version each);
    # the solve against scipy's banded solver
    from scipy.linalg import solve_banded

    from coilrod.rod._compiled import band_lu, band_solve
    from coilrod.rod.planar import RodTangent

    rng = np.random.default_rng(2)
    n, kl, ku = 12, 2, 3
    band = rng.normal(size=(kl + ku + 1, n))
    band[ku] += 8.0  # diagonally dominant
    i = np.arange(kl + ku + 1)[:, None] - ku + np.arange(n)[None, :]  # row of each entry
    band[(i < 0) | (i >= n)] = 0.0
    rhs = rng.normal(size=(1, n))
    expected = solve_banded((kl, ku), band, rhs[0])
    for order in "CF":
        ab = np.zeros((2 * kl + ku + 1, n), order=order)
        ab[kl:] = band
        x = RodTangent(1, n, False, ab, None, kl, ku).solve(rhs)[0]
        np.testing.assert_allclose(x, expected, rtol=1e-12, atol=1e-12)
    assert len(band_lu.signatures) == 1
    assert len(band_solve.signatures) == 1
