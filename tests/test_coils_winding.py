"""Finite windings: Gauss-Legendre filaments against turn-by-turn models of the same coil."""

import numpy as np
import pytest

import coils
from coils.winding import gauss_filaments, turn_filaments

R, W = 0.1, (0.02, 0.02)


@pytest.fixture(scope="module")
def points():
    return np.random.default_rng(5).uniform(-0.03, 0.03, (300, 3))


@pytest.fixture(scope="module")
def uniform_density_reference(points):
    """Richardson extrapolation of turn-by-turn models (10x10 and 20x20 turns): the midpoint rule
    error is O(h^2), so (4 B_20 - B_10)/3 is the field of a uniform current density to O(h^4)."""
    fine = coils.HelmholtzPair(R, 400, 0.25, winding=W, turn_layout=(20, 20))
    coarse = coils.HelmholtzPair(R, 100, 1.0, winding=W, turn_layout=(10, 10))
    return (4 * fine.B(points) - coarse.B(points)) / 3, coarse.B(points), fine.B(points)


def test_ampere_turns_conserved():
    fil = gauss_filaments(0.0, R, 250.0, 0.01, 0.02, 3, 4)
    assert fil[:, 2].sum() == pytest.approx(250.0, rel=1e-14)
    assert fil[:, 0].min() > -0.005
    assert fil[:, 0].max() < 0.005
    assert fil[:, 1].min() > R - 0.01
    assert fil[:, 1].max() < R + 0.01
    turns = turn_filaments(0.0, R, 2.0, 0.01, 0.02, 5, 4)
    assert turns.shape == (20, 3)
    assert np.all(turns[:, 2] == 2.0)


def test_gauss_filaments_converge_to_uniform_winding(points, uniform_density_reference):
    ref, _, _ = uniform_density_reference
    errors = []
    for n in (1, 2, 3, 4):
        B = coils.HelmholtzPair(R, 100, 1.0, winding=W, filaments=(n, n)).B(points)
        errors.append(np.abs(B - ref).max() / np.abs(ref).max())
    # each refinement gains at least an order of magnitude until the reference's own accuracy
    assert errors[1] < errors[0] / 10
    assert errors[2] < errors[1] / 10
    assert errors[3] < 2e-7
    # and the finite winding differs measurably from a single filament per coil
    assert errors[0] > 1e-4


def test_turn_by_turn_differs_by_midpoint_rule_error(points, uniform_density_reference):
    ref, coarse, fine = uniform_density_reference
    gauss = coils.HelmholtzPair(R, 100, 1.0, winding=W, filaments=(4, 4)).B(points)
    e10 = np.abs(coarse - gauss).max() / np.abs(gauss).max()
    e20 = np.abs(fine - gauss).max() / np.abs(gauss).max()
    # second order in the turn pitch: halving the pitch divides the difference by 4
    assert e10 / e20 == pytest.approx(4.0, rel=0.05)
