"""The rod's silent-wrong results of 0.1, each checked against an independent reference.

Grouped by property:
* magnetization jumps are integrated exactly wherever the breakpoint falls: tips against
  solve_bvp with exact jumps (a multipoint BVP, tests/rod_bvp_reference.py), continuous in the
  breakpoint position down to single ulps, fourth-order mesh convergence kept;
* the load path is followed from zero, the first step included: one huge step lands on the
  stable branch of the closed-form elastica, as many small steps do;
* very short segments (1e-4 L) converge to solve_bvp, and the unloaded rod's smallest
  second-variation eigenvalue stays the clamped-free pi^2/4 (not a negative number);
* the signs of det J read off the factorisations agree with a dense determinant, and the
  unloaded straight rod's is +1 in both layouts;
* unreachable loads keep what was reached (ConvergenceError.result).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from rod_bvp_reference import solve_bvp_rod

import coils
from coilrod import (
    Circle,
    ConvergenceError,
    Magnetization,
    Rod,
    StabilityWarning,
    presets,
    solve_rod,
)
from coilrod.rod.elastica import BUCKLING_LAMBDA, elastica
from coilrod.rod.solve import build_problem, make_mesh

L = 0.04
AWKWARD = 0.010139330887976007  # lands a few ulp beside its mesh node (issue "Core hardening")


def _rod(magnetization):
    return Rod(L, 1e6, Circle(2e-3), magnetization)


def _two_segments(b, mags=(128e3, 16e3)):
    return _rod(Magnetization.segments([b, L - b], list(mags)))


def _field(rod, lam, phi=math.pi / 2):
    B = rod.field_for_lambda(lam)
    return coils.UniformField((B * math.cos(phi), B * math.sin(phi), 0.0))


def _bvp_tip(rod, field, res, k=-1, scale=1.0):
    ref = solve_bvp_rod(
        rod, field, scale, tol=1e-10, guess=lambda s: np.interp(s, res.s, res.theta(k))
    )
    assert ref.status == 0
    return ref.sol(rod.length)[2:4]


# -- magnetization jumps --------------------------------------------------------------------------
@pytest.mark.parametrize(
    "b",
    [
        AWKWARD,
        0.0101393,
        np.nextafter(L / 4, 1.0),
        np.nextafter(np.nextafter(L / 4, 0.0), 0.0),
        L / 4 + 3 * np.spacing(L / 4),
    ],
)
def test_breakpoint_anywhere_matches_exact_jumps(b):
    """Every breakpoint, round or a few ulp off a node, is integrated exactly: the tip agrees
    with the multipoint BVP (exact jumps) to the solver's accuracy, 1e-6 L (0.1 gave 2.4e-3 L
    for the awkward one)."""
    rod = _two_segments(b)
    field = _field(rod, 10.0)
    res = solve_rod(rod, field, np.linspace(0.1, 1.0, 10))
    assert np.linalg.norm(res.tip[-1, :2] - _bvp_tip(rod, field, res)) <= 1e-6 * L


def test_tip_is_continuous_in_the_breakpoint_position():
    """Moving the breakpoint by one to four ulps moves the tip by rounding only, and by the
    physical sensitivity for a macroscopic move (compared with solve_bvp's)."""
    tips = []
    bs = [AWKWARD]
    for _ in range(4):
        bs.append(np.nextafter(bs[-1], 1.0))
    for b in bs:
        rod = _two_segments(b)
        tips.append(solve_rod(rod, _field(rod, 10.0), np.linspace(0.1, 1.0, 10)).tip[-1, :2])
    tips = np.array(tips)
    assert np.abs(tips - tips[0]).max() <= 1e-12 * L
    # a 1e-6 L move: the solver's change agrees with the BVP's (a smooth dependence)
    db = 1e-6 * L
    moved = _two_segments(AWKWARD + db)
    field = _field(moved, 10.0)
    res = solve_rod(moved, field, np.linspace(0.1, 1.0, 10))
    base_rod = _two_segments(AWKWARD)
    base = solve_rod(base_rod, _field(base_rod, 10.0), np.linspace(0.1, 1.0, 10))
    d_solver = res.tip[-1, :2] - base.tip[-1, :2]
    d_bvp = _bvp_tip(moved, field, res) - _bvp_tip(base_rod, _field(base_rod, 10.0), base)
    assert np.linalg.norm(d_solver - d_bvp) <= 0.05 * np.linalg.norm(d_bvp) + 1e-9 * L


def test_fourth_order_with_an_awkward_breakpoint():
    """Richardson-extrapolated tips converge at fourth order in the segment length with the
    awkward breakpoint too (a jump read from the wrong side would drop it to first order)."""
    rod = _two_segments(AWKWARD)
    field = _field(rod, 10.0)
    scales = np.linspace(0.1, 1.0, 10)
    ref = _bvp_tip(rod, field, solve_rod(rod, field, scales, nodes=128))
    errs = [
        np.linalg.norm(solve_rod(rod, field, scales, nodes=n).tip[-1, :2] - ref)
        for n in (16, 32, 64)
    ]
    rates = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(rates > 3.3), (errs, rates)


# -- the load path from zero ----------------------------------------------------------------------
def test_one_huge_first_step_follows_the_stable_branch():
    """M(1) in a field pi - 1e-3 from its magnetization, lambda 0 -> 6 in one requested step:
    the stable bent state of the closed-form elastica (0.1 returned the unstable near-straight
    state with only stable=[False] to say so)."""
    rod = presets.seed_rod(presets.M1())
    phi = math.pi - 1e-3
    field = _field(rod, 1.0, phi)
    with warnings.catch_warnings():
        warnings.simplefilter("error", StabilityWarning)  # no change of stability on this path
        one = solve_rod(rod, field, [6.0])
        many = solve_rod(rod, field, np.linspace(0.5, 6.0, 12))
    assert one.stable[0]
    ref = elastica(6.0, phi, length=rod.length)
    assert np.linalg.norm(one.tip[0, :2] - ref.tip) <= 1e-6 * rod.length
    assert np.linalg.norm(one.tip[0] - many.tip[-1]) <= 1e-8 * rod.length
    assert one.tip_angle[0] > 2.0


def test_symmetric_bifurcation_inside_the_first_step_is_reported():
    """Exactly antiparallel: the straight state stays an equilibrium; a single step from 0 to
    4 crosses the buckling load, which is reported (with its scale) rather than jumped."""
    rod = presets.seed_rod(presets.M1())
    field = _field(rod, 1.0, math.pi)
    with pytest.warns(StabilityWarning, match="lost stability between scales 0 and 4"):
        res = solve_rod(rod, field, [4.0])
    assert not res.stable[0]
    (event,) = res.instabilities
    assert event["kind"] == "bifurcation"
    assert event["scale"] == pytest.approx(BUCKLING_LAMBDA, rel=2e-3)


# -- very short segments --------------------------------------------------------------------------
@pytest.mark.parametrize("where", ["clamp", "middle", "tip"])
@pytest.mark.parametrize("field_kind", ["uniform", "helmholtz"])
def test_segment_of_1e_minus_4_length(where, field_kind):
    """A 1e-4 L segment: an easy load converges (0.1 failed at scale 0.04 with a residual
    floor fixed to the coarse segments) and agrees with solve_bvp."""
    s = 1e-4 * L
    lengths, mags = {
        "clamp": ([s, L - s], [128e3, 64e3]),
        "middle": ([0.5 * L, s, 0.5 * L - s], [128e3, 16e3, 128e3]),
        "tip": ([L - s, s], [128e3, 64e3]),
    }[where]
    rod = _rod(Magnetization.segments(lengths, mags))
    B = rod.field_for_lambda(1.0)
    if field_kind == "uniform":
        field = coils.UniformField((0.0, B, 0.0))
    else:
        unit = coils.HelmholtzPair(0.08, 200, 1.0, axis="y")
        field = coils.HelmholtzPair(0.08, 200, B / unit.center_field, axis="y")
    res = solve_rod(rod, field, np.linspace(0.02, 1.0, 50))
    assert res.converged.all()
    assert np.linalg.norm(res.tip[-1, :2] - _bvp_tip(rod, field, res)) <= 1e-6 * L
    # the unloaded rod: the clamped-free eigenvalue pi^2/4 (coarse mesh, O(h^2)), never < 0
    mu0 = solve_rod(rod, field, [1e-9]).min_eigenvalue_in_plane[0]
    assert mu0 == pytest.approx(math.pi**2 / 4, rel=1e-3)


# -- factorisations and stability -----------------------------------------------------------------
@pytest.mark.parametrize("field_kind", ["uniform", "helmholtz"])
def test_determinant_signs_from_the_factors_match_dense_determinants(field_kind):
    """det J's sign read off the (stacked, batched) factorisation against numpy's dense
    determinant, at the unloaded straight rod (+1: the reference of stability) and at random
    bent states."""
    rod = presets.seed_rod(presets.M42())
    field = (
        coils.UniformField((0.0, 8e-3, 0.0))
        if field_kind == "uniform"
        else coils.HelmholtzPair(radius=1.5 * L, turns=300, current=2.0, axis="y")
    )
    problem = build_problem(rod, field, make_mesh(rod, 12), np.zeros(3), 0.0)
    rng = np.random.default_rng(7)
    states = [problem.straight()]
    scales = [0.0]
    for _ in range(5):
        theta = np.cumsum(rng.normal(scale=0.6, size=problem.n))
        states.append(problem.from_theta(theta, 1.0))
        scales.append(float(rng.uniform(-1.0, 1.0)) * (300.0 if field_kind == "uniform" else 3.0))
    states = np.array(states)
    lin = problem.linearize(states, np.array(scales))
    signs = lin.tangent.det_signs()
    dense = [
        np.linalg.slogdet(problem.dense_jacobian(u, s))[0]
        for u, s in zip(states, scales, strict=True)
    ]
    np.testing.assert_array_equal(signs, dense)
    assert signs[0] == 1.0 == problem.det_reference()
    assert -1.0 in signs  # the random states include unstable ones: the test can tell


def test_unloaded_eigenvalue_of_the_clamped_free_rod():
    """In the plane pi^2 / 4 (bending) to O(h^2) in both layouts (uniform: bisection; coil:
    power iteration); in 3D the lowest mode of the circular rod is torsion, (GJ / EI) pi^2 / 4
    = pi^2 / (4 (1 + nu)) = pi^2 / 6 for nu = 1/2."""
    rod = presets.seed_rod(presets.M1())
    pair = coils.HelmholtzPair(radius=0.08, turns=200, current=1e-6, axis="y")
    for field in (coils.UniformField((0.0, 1e-9, 0.0)), pair):
        res = solve_rod(rod, field, [1.0], richardson=False)
        assert res.min_eigenvalue_in_plane[0] == pytest.approx(math.pi**2 / 4, rel=2e-4)
        assert res.min_eigenvalue[0] == pytest.approx(math.pi**2 / 6, rel=2e-4)


# -- what an unreachable load keeps ---------------------------------------------------------------
class _Walled(coils.Field):
    """Uniform B_y, refusing (like a coil winding) points with y > 0.75 L."""

    uniform = False
    linear = True

    def __init__(self, B):
        self.B0 = B

    def _B(self, pts):
        if np.any(pts[:, 1] > 0.75 * L):
            raise ValueError("point lies inside a coil winding")
        return np.tile([0.0, self.B0, 0.0], (pts.shape[0], 1))

    def _gradient(self, pts):
        self._B(pts)
        return np.zeros((pts.shape[0], 3, 3))


def test_convergence_error_keeps_the_reached_states():
    rod = presets.seed_rod(presets.M1())
    field = _Walled(rod.field_for_lambda(1.0))
    with pytest.raises(ConvergenceError, match="winding") as info:
        solve_rod(rod, field, [1.0, 2.0, 40.0])
    err = info.value
    assert err.target == 40.0
    assert 2.0 <= err.reached < 40.0
    kept = err.result
    np.testing.assert_array_equal(kept.scales, [1.0, 2.0])
    # the kept states are the converged ones (uniform field there: the closed-form elastica)
    for k, lam in enumerate((1.0, 2.0)):
        ref = elastica(lam, math.pi / 2, length=rod.length)
        assert np.linalg.norm(kept.tip[k, :2] - ref.tip) <= 1e-6 * rod.length


# -- bad numerical parameters ---------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kwargs", "name"),
    [({"tol": 0.0}, "tol"), ({"tol": -1e-9}, "tol"), ({"max_iter": 0}, "max_iter")],
)
def test_solver_parameters(kwargs, name):
    rod = presets.seed_rod()
    with pytest.raises(ValueError, match=name):
        solve_rod(rod, _field(rod, 1.0), [1.0], **kwargs)


def test_segments_must_span_the_rod():
    with pytest.raises(ValueError, match="segments add up"):
        _rod(Magnetization.segments([0.01, 0.02], [1e5, 2e5]))
    with pytest.raises(ValueError, match="breakpoints must lie on the rod"):
        _rod(Magnetization(1e5, 0.0, breakpoints=[0.05]))
