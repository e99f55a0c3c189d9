"""The closed-form magnetic elastica (coilrod.elastica) against independent references.

Cross-checks:
* scipy solve_bvp at tol 1e-9 on theta'' = -lambda sin(phi_B - theta) (several angles, lambda
  up to 200);
* linear beam theory: tip deflection lambda L / 3 for a perpendicular field;
* buckling of the antiparallel field at pi^2 / 4 (the branch's lambda(p) tends to it);
* the fold of the complementary branch is a minimum of lambda(p) (checked by sampling).
"""

import math

import numpy as np
import pytest
from scipy.integrate import solve_bvp

from coilrod.rod.elastica import (
    BUCKLING_LAMBDA,
    elastica,
    elastica_branch,
    elastica_fold,
    small_deflection_tip,
)


def _bvp_elastica(lam, phi_b, clamp_angle=0.0):
    """theta'' = -lam sin(phi_b - theta), L = 1, tip by solve_bvp; guess theta = phi_b s."""

    def rhs(s, y):
        return np.vstack([y[1], -lam * np.sin(phi_b - y[0]), np.cos(y[0]), np.sin(y[0])])

    def bc(a, b):
        return np.array([a[0] - clamp_angle, b[1], a[2], a[3]])

    s = np.linspace(0.0, 1.0, 400)
    th = clamp_angle + (phi_b - clamp_angle) * (1 - np.exp(-math.sqrt(lam) * s))
    y = np.vstack(
        [th, np.gradient(th, s), np.cumsum(np.cos(th)) / 400, np.cumsum(np.sin(th)) / 400]
    )
    sol = solve_bvp(rhs, bc, s, y, tol=1e-9, max_nodes=100000)
    assert sol.status == 0
    return sol.sol(1.0)


@pytest.mark.parametrize(
    ("lam", "phi_b"),
    [
        (0.5, math.pi / 2),
        (10.0, math.pi / 3),
        (30.0, 2.5),
        (50.0, math.pi / 2),
        (5.0, -2.0),
        (20.0, 3.0),
        (200.0, 1.0),
    ],
)
def test_closed_form_matches_bvp(lam, phi_b):
    st = elastica(lam, phi_b)
    ref = _bvp_elastica(lam, phi_b)
    assert np.allclose(st.tip, ref[2:4], atol=2e-8)
    assert st.tip_angle == pytest.approx(ref[0], abs=2e-8)


def test_clamp_angle_and_length_rotate_and_scale():
    st = elastica(7.0, 2.0, clamp_angle=0.4, length=0.04)
    ref = _bvp_elastica(7.0, 2.0, clamp_angle=0.4)
    assert np.allclose(st.tip / 0.04, ref[2:4], atol=2e-8)


def test_small_deflection_is_lambda_over_three():
    lam = 1e-5
    st = elastica(lam, math.pi / 2, length=2.0)
    assert st.tip[1] == pytest.approx(small_deflection_tip(lam, 2.0), rel=1e-4)
    assert small_deflection_tip(3.0) == 1.0


def test_antiparallel_buckles_at_pi_squared_over_four():
    assert np.allclose(elastica(0.99 * BUCKLING_LAMBDA, math.pi).tip, [1.0, 0.0])
    # lambda(p) of the buckled branch tends to pi^2/4 as p -> 0 (K(0) = pi / 2)
    st = elastica_branch(1e-6, math.pi)[0]
    assert st.lam == pytest.approx(BUCKLING_LAMBDA, rel=1e-10)
    bent = elastica(1.01 * BUCKLING_LAMBDA, math.pi)
    assert bent.tip_angle > 0.05


def test_complementary_branch_has_a_fold_at_min_lambda():
    phi_b = math.pi + 0.05
    fold = elastica_fold(phi_b)
    low = math.sin(0.025)
    lams = [st.lam for st in elastica_branch(np.linspace(low + 1e-6, 0.99, 4000), phi_b)]
    assert fold.lam == pytest.approx(min(lams), rel=1e-6)
    assert BUCKLING_LAMBDA < fold.lam < 1.2 * BUCKLING_LAMBDA
    # the fold state itself solves the BVP bent the long way round (ccw, field cw of -x)
    ref = _bvp_elastica(fold.lam, phi_b - 2 * math.pi)  # same field direction
    # solve_bvp from its guess finds the natural (cw) state: the fold state is a different one
    assert ref[0] < 0 < fold.tip_angle


@pytest.mark.parametrize("bad", [{"lam": -1.0}, {"lam": float("nan")}, {"length": 0.0}])
def test_bad_input(bad):
    kwargs = {"lam": 1.0, "field_angle": 1.0} | bad
    lam = kwargs.pop("lam")
    with pytest.raises(ValueError, match="lam|length"):
        elastica(lam, **kwargs)
