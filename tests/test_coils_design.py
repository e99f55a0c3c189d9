"""Coil design helpers, uniformity reports and field maps."""

import math

import numpy as np
import pytest
from scipy.constants import mu_0

import coils
from coils import deviation, uniformity
from coils.design import (
    COPPER_RESISTIVITY,
    current_for_field,
    current_for_gradient,
    turns_for_field,
    turns_for_gradient,
    winding_power,
)


def test_current_for_helmholtz_field_matches_closed_form():
    R, N, B = 0.12, 150, 7e-3
    current = current_for_field(coils.HelmholtzPair(R, N, 1.0), B)
    assert current == pytest.approx(B * R / ((4 / 5) ** 1.5 * mu_0 * N), rel=1e-13)
    turns = turns_for_field(coils.HelmholtzPair(R, 1, 3.0), B)
    assert turns == pytest.approx(B * R / ((4 / 5) ** 1.5 * mu_0 * 3.0), rel=1e-13)


def test_current_for_maxwell_gradient_matches_closed_form():
    R, N, g = 0.08, 200, 0.5
    current = current_for_gradient(coils.MaxwellPair(R, N, 1.0), g)
    assert current == pytest.approx(g * R**2 / (48 * math.sqrt(3) / 7**2.5 * mu_0 * N), rel=1e-13)
    assert turns_for_gradient(coils.MaxwellPair(R, 1, 2.0), g) == pytest.approx(
        g * R**2 / (48 * math.sqrt(3) / 7**2.5 * mu_0 * 2.0), rel=1e-13
    )


def test_current_for_field_holds_for_finite_winding():
    pair = coils.HelmholtzPair(0.1, 100, 1.0, axis="x", winding=(0.02, 0.03))
    current = current_for_field(pair, 5e-3)
    scaled = coils.HelmholtzPair(0.1, 100, current, axis="x", winding=(0.02, 0.03))
    assert scaled.B([0, 0, 0])[0, 0] == pytest.approx(5e-3, rel=1e-13)


def test_design_targets_impossible():
    with pytest.raises(ValueError, match="no gradient"):
        current_for_gradient(coils.HelmholtzPair(0.1, 10, 1.0), 0.1)
    with pytest.raises(ValueError, match="no field"):
        current_for_field(coils.MaxwellPair(0.1, 10, 1.0), 1e-3)


def test_winding_power_against_hand_calculation():
    R, N, current, d = 0.1, 100, 3.0, 1e-3
    pair = coils.HelmholtzPair(R, N, current, winding=(0.02, 0.02))
    power = winding_power(pair, d)
    length = 2 * N * 2 * math.pi * R
    resistance = COPPER_RESISTIVITY * length / (math.pi * d**2 / 4)
    assert power.wire_length == pytest.approx(length)
    assert power.resistance == pytest.approx(resistance, rel=1e-14)
    assert power.power == pytest.approx(current**2 * resistance, rel=1e-14)
    hot = winding_power(pair, d, temperature=80.0)
    assert hot.resistance == pytest.approx(resistance * (1 + 0.00393 * 60), rel=1e-14)
    with pytest.raises(ValueError, match="do not fit"):
        winding_power(coils.HelmholtzPair(R, 1000, 1.0, winding=(0.01, 0.01)), 1e-3)
    with pytest.raises(ValueError, match="wire_diameter must be positive"):
        winding_power(pair, 0.0)


def test_uniformity_report_over_robot_reach():
    pair = coils.HelmholtzPair(0.1, 100, 2.0, axis="y")
    s = np.linspace(0, 0.04, 41)
    reach = np.column_stack([s, 0 * s, 0 * s])  # a 40 mm robot from the centre along x
    rep = uniformity(pair, 0.01, points=reach)
    # along the mid-plane the 1% region ends at 0.378 R = 37.8 mm: the tip is outside
    assert not rep.within_tol
    assert rep.max_deviation == pytest.approx(deviation(pair, [[0.04, 0, 0]])[0], rel=1e-12)
    assert rep.max_deviation > 0.01
    assert "OUTSIDE" in str(rep)
    short = uniformity(pair, 0.01, points=reach[:30])
    assert short.within_tol


def test_uniformity_of_maxwell_uses_gradient():
    rep = uniformity(coils.MaxwellPair(0.1, 100, 2.0, axis="y"), 0.01)
    assert rep.quantity == "gradient"
    assert 0 < rep.sphere <= rep.axial < 0.1


def test_field_map_draws_uniformity_contour():
    import matplotlib.pyplot as plt

    from coils.plot import plot_field_map

    pair = coils.HelmholtzPair(0.1, 100, 2.0, axis="y", winding=(0.01, 0.01))
    ax = plot_field_map(pair, "xy", half_width=0.12, n=61)
    # the 1% contour is drawn where the closed-form extents put it: 37.8 mm in the mid-plane
    # (x) and 31.4 mm along the axis (y) for a filament pair; the winding shifts it slightly
    from matplotlib.contour import ContourSet

    contour = [c for c in ax.collections if isinstance(c, ContourSet)]
    assert len(contour) == 1
    verts = np.vstack([p.vertices for p in contour[0].get_paths()])
    assert 35 < verts[:, 0].max() < 41
    assert -41 < verts[:, 0].min() < -35
    assert 29 < verts[:, 1].max() < 34
    assert -34 < verts[:, 1].min() < -29
    plt.close(ax.figure)
    with pytest.raises(ValueError, match="plane must be one of"):
        plot_field_map(pair, "ab")
