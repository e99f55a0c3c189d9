"""The compiled Newton corrector of the planar rod in a uniform field
(:mod:`coilrod.rod._planar_newton`) against the engine's numpy corrector
(:func:`coilrod.path.corrector.newton`): the same iteration, so the same states, errors,
iteration counts, residuals and tangents to the last bit, and the ski-rental switch."""

from __future__ import annotations

import numpy as np
import pytest

import coils
from coilrod import presets
from coilrod.path.corrector import NewtonOptions, newton
from coilrod.rod.solve import build_problem, make_mesh


@pytest.fixture
def corrector(monkeypatch):
    """``corrector("numpy")`` or ``corrector("compiled")``: which corrector runs from now on."""
    import coilrod.rod._planar_newton as pn

    def force(name, after=np.inf):
        monkeypatch.setattr(pn._rental, "held", lambda: False)
        monkeypatch.setattr(pn._rental, "spent", 0.0)
        monkeypatch.setattr(pn._rental, "ready", name == "compiled")
        monkeypatch.setattr(pn, "COMPILE_AFTER", after)

    return force


def _problem(direction=(0.0, 1.0)):
    rod = presets.seed_rod(presets.M42())
    lam1 = rod.field_for_lambda(1.0)
    field = coils.UniformField(B=(lam1 * direction[0], lam1 * direction[1], 0.0))
    problem = build_problem(rod, field, make_mesh(rod, 12), np.zeros(3), 0.0)
    return problem.with_out_of_plane((0.8, 1.3, 1.0))  # (GJ, EI_y, EI_z) / EI_z


def test_compiled_corrector_matches_numpy(corrector):
    # converging from the straight rod (line search, step limit), from a stack of scattered
    # starts (one member per outcome: converged, stagnating at a huge load, not finite) and
    # near the antiparallel field (indefinite Jacobians: pivoting), with few iterations
    import coilrod.rod._planar_newton as pn

    rng = np.random.default_rng(5)
    cases = []
    p = _problem()
    cases.append((p, p.straight(), 5.0, NewtonOptions()))
    U = p.straight() + rng.normal(scale=0.6, size=(4, p.size))
    U[0] = p.straight() + 1e-3  # converges
    U[2, 3] = np.nan
    cases.append((p, U, np.array([0.3, 1e6, 1.0, 30.0]), NewtonOptions(max_iter=6, backtracks=2)))
    q = _problem((-1.0, 0.05))
    cases.append(
        (q, q.straight() + rng.normal(scale=0.05, size=(2, q.size)), 12.0, NewtonOptions())
    )
    outcomes = []
    for problem, u0, scale, opts in cases:
        out = {}
        for name in ("numpy", "compiled"):
            corrector(name)
            out[name] = newton(problem, u0, scale, opts)
        assert pn._rental.ready
        a, b = out["numpy"], out["compiled"]
        np.testing.assert_array_equal(b.u, a.u)  # bitwise: numbers do not change on compiling
        np.testing.assert_array_equal(b.error, a.error)
        np.testing.assert_array_equal(b.ok, a.ok)
        np.testing.assert_array_equal(b.iterations, a.iterations)
        np.testing.assert_array_equal(b.lin.residual, a.lin.residual)
        np.testing.assert_array_equal(b.lin.tangent.parts[0], a.lin.tangent.parts[0])
        np.testing.assert_array_equal(b.lin.tangent.load_rate, a.lin.tangent.load_rate)
        np.testing.assert_array_equal(b.lin.tangent.det_signs(), a.lin.tangent.det_signs())
        # the path rate du/dscale from the same factorisation, as the engine's numpy solve
        with np.errstate(all="ignore"):
            rate = -problem.solve(a.lin, a.lin.load_rate)
        np.testing.assert_array_equal(b.lin.path_rate, rate)
        for j in range(len(rate)):  # the stacked solve: each member as if alone
            one = problem.take(a.lin, [j])
            with np.errstate(all="ignore"):
                np.testing.assert_array_equal(rate[j], -problem.solve(one, one.load_rate)[0])
        # 3D stability: det J's sign and the out-of-plane Cholesky test from the compiled
        # corrector, the same counts as from the numpy factorisations
        assert b.lin.tangent.signs is not None
        assert a.lin.tangent.signs is None
        for x, ref in zip(
            problem.negative_counts(b.lin), problem.negative_counts(a.lin), strict=True
        ):
            np.testing.assert_array_equal(x, ref)
        np.testing.assert_array_equal(problem.stability(b.lin), problem.stability(a.lin))
        outcomes.append((np.atleast_1d(a.ok), np.atleast_1d(a.error), problem.stability(a.lin)))
    # the cases reach what they are there for: convergence, failures (a finite and an infinite
    # error), converged indefinite states
    assert outcomes[0][0].all()
    assert outcomes[1][0].any()
    assert np.isinf(outcomes[1][1]).any()
    assert np.isfinite(outcomes[1][1][~outcomes[1][0]]).any()
    assert outcomes[2][0].all()
    assert (outcomes[2][2] < 0).all()


def test_corrector_compiles_when_it_pays(corrector):
    import coilrod.rod._planar_newton as pn

    p = _problem()
    corrector("numpy", after=pn._NUMPY_CALL_S + pn._NUMPY_ITER_S)
    first = newton(p, p.straight(), 3.0)
    assert first.ok
    assert first.iterations >= 2
    assert not pn._rental.ready  # the numpy corrector ran and charged its iterations
    again = newton(p, p.straight(), 3.0)
    assert pn._rental.ready
    np.testing.assert_array_equal(again.u, first.u)
