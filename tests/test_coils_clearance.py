"""Exact clearance between boxes or segments and coil windings (coils.clearance), and its users:
the grid cache (coils.GriddedField; more in test_grid.py) and the scene planner.

Cross-checks, each independent of the code under test:

* geometry by hand for coils on a coordinate axis, with binary-exact dimensions so that
  "touching" and "one ulp clear" are exact statements (rational arithmetic where a hypot enters);
* the direct field raising at a point of the box that lies in a winding or on a wire, and
  evaluating where the box is clear;
* closed forms of the distance from a box or segment to a circle;
* for rotated coils: points placed in a winding's section through the coil frame, balls that
  the meridian distance (1-Lipschitz) proves clear, and, as an extra, dense sampling.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

import coils
from coilrod.scene.planner import _box_clear_of_windings
from coils import FieldSum, GriddedField
from coils.clearance import (
    Box,
    Segment,
    check_clear,
    filament_distances,
    meets_windings,
    winding_contacts,
)
from coils.coaxial import ON_WIRE_TOL, winding_mask

# A coil on the z axis with binary-exact winding: z in [-1/32, 1/32], rho in [5/16, 7/16] (m).
A, W, H = 0.375, 0.0625, 0.125
R_IN, R_OUT, Z_HALF = 0.3125, 0.4375, 0.03125


def _up(x, ulps=1):
    for _ in range(ulps):
        x = np.nextafter(x, np.inf)
    return float(x)


def _down(x, ulps=1):
    for _ in range(ulps):
        x = np.nextafter(x, -np.inf)
    return float(x)


@pytest.fixture(scope="module")
def coil():
    c = coils.Coil(A, 10, 1.0, axis="z", winding=(W, H))
    np.testing.assert_array_equal(c.windings, [[0.0, A, W, H]])
    return c


def _meridian_distance(part, pts, k=0):
    """Distance (m) of points to winding k's closed section, in the meridian plane."""
    local = part.to_local(np.atleast_2d(pts))
    rho, z = np.hypot(local[:, 0], local[:, 1]), local[:, 2]
    z0, a, w, h = part.windings[k]
    dr = np.maximum(np.maximum(a - h / 2 - rho, rho - a - h / 2), 0.0)
    dz = np.maximum(np.maximum(z0 - w / 2 - z, z - z0 - w / 2), 0.0)
    return np.hypot(dr, dz)


# -- windings: hand geometry, touching and a few ulp clear ----------------------------------------
def test_box_touching_the_flat_face_at_a_corner(coil):
    # the corner (A, 0, 1/32) lies on the winding's face z = +w/2 at rho = A; the rest is above
    lower, upper = np.array([A, 0.0, Z_HALF]), np.array([0.5, 0.1, 0.1])
    assert meets_windings(coil, Box(lower, upper)).tolist() == [True]
    assert meets_windings(coil, Box(lower + [0, 0, 0], upper)).tolist() == [True]
    # one ulp higher every point has z > w/2: outside the slab
    lifted = lower.copy()
    lifted[2] = _up(Z_HALF)
    assert meets_windings(coil, Box(lifted, upper)).tolist() == [False]
    assert winding_contacts(coil, Box(lifted, upper)) == []


def test_box_touching_the_outer_cylinder_along_an_edge(coil):
    # the edge x = 7/16, z = 0 .. 0.01 meets rho = 7/16 at y = 0; elsewhere rho >= x > R_OUT
    lower, upper = np.array([R_OUT, -0.0625, 0.0]), np.array([0.5, 0.0625, 0.01])
    assert meets_windings(coil, Box(lower, upper)).tolist() == [True]
    lower[0] = _up(R_OUT)
    assert meets_windings(coil, Box(lower, upper)).tolist() == [False]


@pytest.mark.parametrize("ulps", [0, 2, 3, 8])
def test_box_in_the_bore_reaching_the_inner_cylinder(coil, ulps):
    # corners (+-x, +-1/4): rho = hypot(3/16, 1/4) = 5/16 = R_IN exactly (a 3-4-5 triangle)
    x = _down(0.1875, ulps)
    box = Box((-x, -0.25, -0.01), (x, 0.25, 0.01))
    exact = Fraction(x) ** 2 + Fraction(0.25) ** 2 >= Fraction(R_IN) ** 2
    assert exact == (ulps == 0)
    assert meets_windings(coil, box).tolist() == [exact]


def test_box_crossing_the_ring_with_every_vertex_outside(coil):
    # vertices at rho >= 1/2 > R_OUT, yet the box holds the whole ring
    box = Box((-0.5, -0.5, -0.01), (0.5, 0.5, 0.01))
    assert np.all(np.hypot(box.vertices[:, 0], box.vertices[:, 1]) > R_OUT)
    assert meets_windings(coil, box).tolist() == [True]
    with pytest.raises(ValueError, match="inside a coil winding"):
        coil.B([[0.0, A + H / 4, 0.005]])  # a point of the box (off the filaments)


def test_box_above_the_winding_with_an_edge_through_its_slab_only_outside(coil):
    # edges cross the slab, but at rho > R_OUT: the cut's rho interval misses the section
    box = Box((0.45, -0.01, -0.1), (0.5, 0.01, 0.1))
    assert meets_windings(coil, box).tolist() == [False]
    d = _meridian_distance(coil, box.vertices)
    assert d.min() > 0


def test_segments_against_a_winding_by_hand(coil):
    # along the axis: never reaches rho = 5/16
    assert meets_windings(coil, Segment((0, 0, -1), (0, 0, 1))).tolist() == [False]
    # radial through the section, and stopping one ulp short of it
    assert meets_windings(coil, Segment((0, 0, 0), (1, 0, 0))).tolist() == [True]
    assert meets_windings(coil, Segment((0, 0, 0), (_down(R_IN), 0, 0))).tolist() == [False]
    # a chord of the plane z = 0 whose nearest point to the axis is at rho = 0.3 < R_IN but
    # whose ends are at rho = hypot(0.3, 0.4) = 0.5 > R_OUT: it crosses the section
    assert meets_windings(coil, Segment((0.3, -0.4, 0), (0.3, 0.4, 0))).tolist() == [True]
    # parallel to the axis at rho = 0.4 through the slab
    assert meets_windings(coil, Segment((0.4, 0, -1), (0.4, 0, 1))).tolist() == [True]
    assert meets_windings(coil, Segment((0.4, 0, _up(Z_HALF)), (0.4, 0, 1))).tolist() == [False]


# -- filaments: closed-form distances -------------------------------------------------------------
@pytest.fixture(scope="module")
def loop():
    return coils.Coil(0.1, 1, 1.0, axis="z")  # one bare filament, radius 0.1 m


def test_box_to_filament_distance_by_hand(loop):
    a = 0.1
    # beside the wire: nearest points (a + d, 0, 0) and (a, 0, 0)
    d = 0.013
    assert filament_distances(loop, Box((a + d, -0.01, -0.01), (0.3, 0.01, 0.01)))[0] == (
        pytest.approx(d, rel=1e-14)
    )
    # a square below the ring plane: the ring is nearest to the square's corners (rho = a/sqrt2)
    box = Box((-0.05, -0.05, -0.1), (0.05, 0.05, -0.04))
    expected = np.hypot(0.04, a - 0.05 * np.sqrt(2))
    assert filament_distances(loop, box)[0] == pytest.approx(expected, rel=1e-14)
    # a box holding a stretch of the wire, one touching it at a corner, one around the centre
    assert filament_distances(loop, Box((0.09, -0.01, -0.01), (0.11, 0.01, 0.01)))[0] == 0.0
    assert filament_distances(loop, Box((0.1, 0.0, 0.0), (0.2, 0.1, 0.1)))[0] < 1e-16  # rounding
    centre = Box((-0.02, -0.02, -0.02), (0.02, 0.02, 0.02))
    assert filament_distances(loop, centre)[0] == pytest.approx(a - 0.02 * np.sqrt(2), rel=1e-14)


def test_segment_to_filament_distance_by_hand(loop):
    a = 0.1
    cases = [
        (Segment((0, 0, -1), (0, 0, 1)), a),  # the axis
        (Segment((0.13, 0, -1), (0.13, 0, 1)), 0.03),  # parallel to the axis
        (Segment((0.06, -0.05, 0), (0.06, 0.05, 0)), a - np.hypot(0.06, 0.05)),  # inner chord
        (Segment((0.06, -0.2, 0), (0.06, 0.2, 0)), 0.0),  # a secant
        (Segment((0.2, -0.3, 0.02), (0.2, 0.3, 0.02)), np.hypot(0.1, 0.02)),  # outside, above
        (Segment((0.07, 0.0, 0.04), (0.07, 0.0, 0.04)), np.hypot(0.03, 0.04)),  # a point
    ]
    for seg, expected in cases:
        assert filament_distances(loop, seg)[0] == pytest.approx(expected, rel=1e-13, abs=1e-16)


def test_wire_tolerance_agrees_with_the_direct_field(loop):
    a = 0.1
    for factor, refused in ((0.5, True), (2.0, False)):
        x = a * (1 + factor * ON_WIRE_TOL)
        box = Box((x, -0.01, -0.01), (0.2, 0.01, 0.01))
        assert filament_distances(loop, box)[0] == pytest.approx(factor * ON_WIRE_TOL * a, rel=1e-6)
        if refused:
            with pytest.raises(ValueError, match="lies on a coil winding"):
                loop.B([[x, 0.0, 0.0]])  # the box's nearest point
            with pytest.raises(ValueError, match=r"meets filament 0 .*shrink"):
                GriddedField(loop, box.lower, box.upper, shape=3)
        else:
            assert np.all(np.isfinite(loop.B([[x, 0.0, 0.0]])))
            assert winding_contacts(loop, box) == []


def test_filament_distances_against_dense_sampling_on_tilted_coils():
    """Extra check: the exact distance is never above the sampled minimum over the circle, and
    at most the circle's sampling step (x radius) below it."""
    rng = np.random.default_rng(3)
    phi = np.linspace(0.0, 2 * np.pi, 100_001)
    for _ in range(60):
        a = rng.uniform(0.05, 0.2)
        coil = coils.Coil(a, 1, 1.0, axis=rng.normal(size=3), center=rng.uniform(-0.05, 0.05, 3))
        R = coil.rotation
        ring = coil.center + a * (np.cos(phi)[:, None] * R[:, 0] + np.sin(phi)[:, None] * R[:, 1])
        lower = rng.uniform(-0.2, 0.1, 3)
        upper = lower + rng.uniform(0.0, 0.15, 3) * (rng.uniform(size=3) > 0.2)
        for shape in (Box(lower, upper), Segment(lower, upper)):
            exact = filament_distances(coil, shape)[0]
            sampled = np.sqrt(shape.squared_distance(ring).min())
            assert exact <= sampled * (1 + 1e-12) + 1e-16
            assert sampled - exact <= a * (phi[1] - phi[0])


# -- rotated axes, several pairs, sums and scalings -----------------------------------------------
@pytest.fixture(scope="module")
def tilted_pair():
    return coils.MaxwellPair(
        0.1, 50, 1.0, axis=(1.0, 2.0, 3.0), center=(0.01, -0.02, 0.005), winding=(0.012, 0.008)
    )


def _point_in_frame(part, z, rho, t):
    R = part.rotation
    return part.center + z * R[:, 2] + rho * (np.cos(t) * R[:, 0] + np.sin(t) * R[:, 1])


def test_tilted_pair_box_around_a_point_of_a_winding(tilted_pair):
    z0, a, w, h = tilted_pair.windings[1]
    p = _point_in_frame(tilted_pair, z0 + w / 4, a - h / 4, 2.0)  # inside winding 1 only
    with pytest.raises(ValueError, match="inside a coil winding"):
        tilted_pair.B(p)
    box = Box(p - 1e-6, p + 1e-6)
    assert meets_windings(tilted_pair, box).tolist() == [False, True]
    with pytest.raises(ValueError, match=r"meets winding 1 \(12 mm x 8 mm section"):
        GriddedField(tilted_pair, p - 0.01, p + 0.01, shape=4)


def test_tilted_pair_boxes_in_clear_balls(tilted_pair):
    """A cube of half-side s lies in the ball of radius s sqrt(3) about its centre; a centre that
    far from the section (meridian distance, 1-Lipschitz) makes the cube clear."""
    z0, a, w, h = tilted_pair.windings[1]
    gap = 1e-3
    for z, rho in ((z0, a + h / 2 + gap), (z0 + w / 2 + gap, a), (z0, a - h / 2 - gap)):
        p = _point_in_frame(tilted_pair, z, rho, 0.7)
        assert _meridian_distance(tilted_pair, p, 1)[0] == pytest.approx(gap, rel=1e-9)
        s = 0.99 * gap / np.sqrt(3)
        box = Box(p - s, p + s)
        assert meets_windings(tilted_pair, box).tolist() == [False, False]
        # while a cube reaching the section (half-side gap) meets it
        assert meets_windings(tilted_pair, Box(p - gap, p + gap))[1]
    # the direct field is defined all over the clear cube: the cache builds, exact at its nodes
    grid = GriddedField(tilted_pair, p - s, p + s, shape=4)
    corners = Box(grid.lower, grid.upper).vertices
    B = tilted_pair.B(corners)
    assert np.abs(grid.B(corners) - B).max() <= 1e-12 * np.abs(B).max()


def test_tilted_windings_against_dense_sampling():
    """Extra check on random tilted pairs and boxes: a box reported clear has no sample in the
    section; one reported meeting has a sample within half a grid diagonal of it."""
    rng = np.random.default_rng(5)
    n = 25
    for trial in range(40):
        pair = coils.HelmholtzPair(
            0.1,
            10,
            1.0,
            axis=rng.normal(size=3),
            center=rng.uniform(-0.02, 0.02, 3),
            winding=(rng.uniform(0.002, 0.03), rng.uniform(0.002, 0.05)),
        )
        lower = rng.uniform(-0.15, 0.1, 3)
        extent = rng.uniform(0.0, 0.1, 3) * (rng.uniform(size=3) > 0.15)
        axes = [np.linspace(lo, lo + e, n) for lo, e in zip(lower, extent, strict=True)]
        samples = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        meets = meets_windings(pair, Box(lower, lower + extent))
        step = 0.5 * np.linalg.norm(extent / (n - 1))
        for k in range(2):
            d = _meridian_distance(pair, samples, k).min()
            assert (d <= step * (1 + 1e-9) + 1e-15) if meets[k] else (d > 0), (trial, k)


def test_systems_of_several_pairs_name_the_part_met():
    x_pair = coils.HelmholtzPair(0.12, 50, 1.0, axis="x", winding=(0.01, 0.01))
    y_pair = coils.HelmholtzPair(0.14, 50, 1.0, axis="y", winding=(0.01, 0.01))
    z_pair = coils.MaxwellPair(0.16, 50, 1.0, axis="z", winding=(0.01, 0.01))
    system = coils.CoilSystem([x_pair, y_pair, z_pair, coils.UniformField((0, 0, 1e-3))])
    # the z pair's upper winding: z in 0.16 sqrt(3)/2 +- 0.005, rho in 0.16 +- 0.005
    zc = 0.16 * np.sqrt(3) / 2
    box = Box((0.158, -0.001, zc - 0.001), (0.159, 0.001, zc + 0.001))
    contacts = winding_contacts(system, box)
    assert [(c.part, c.kind, c.index) for c in contacts] == [(z_pair, "winding", 1)]
    with pytest.raises(ValueError, match="inside a coil winding"):
        system.B(box.lower)
    # far from all: clear; the three pairs' windings are all checked
    assert winding_contacts(system, Box((-0.03,) * 3, (0.03,) * 3)) == []
    # y pair's lower winding through a scaled sum
    yb = Box((-0.001, -0.07 - 0.001, 0.139), (0.001, -0.07 + 0.001, 0.141))
    for field in (2.0 * y_pair + x_pair, FieldSum([x_pair, -1.5 * y_pair]), 0.5 * system):
        found = [(c.part, c.kind, c.index) for c in winding_contacts(field, yb)]
        assert found[0] == (y_pair, "winding", 0)
        assert all(part is y_pair for part, _, _ in found)


def test_cache_inside_a_cache_keeps_the_windings(coil):
    inner = GriddedField(coil, (-0.05,) * 3, (0.05,) * 3, shape=3, outside="direct")
    with pytest.raises(ValueError, match=r"meets winding 0 .* of Coil\(radius=0.375"):
        GriddedField(inner, (-0.5, -0.5, -0.01), (0.5, 0.5, 0.01), shape=3)


def test_margin_and_shape_validation(coil):
    with pytest.raises(ValueError, match="margin must be >= 0"):
        winding_contacts(coil, Box((0, 0, 0), (1, 1, 1)), margin=-0.1)
    with pytest.raises(ValueError, match="margin must be finite"):
        winding_contacts(coil, Box((0, 0, 0), (1, 1, 1)), margin=np.nan)
    with pytest.raises(ValueError, match="lower must not exceed upper"):
        Box((0, 0, 1), (1, 1, 0))
    with pytest.raises(ValueError, match="upper must be finite"):
        Box((0, 0, 0), (1, np.inf, 1))
    with pytest.raises(ValueError, match=r"start must have shape \(3,\)"):
        Segment((0, 0), (1, 1, 1))
    check_clear(coil, Box((-0.1,) * 3, (0.1,) * 3))  # clear: returns quietly


# -- the scene planner ----------------------------------------------------------------------------
def _old_planner_check(field, lo, hi):
    """The planner's former test: 9 samples per axis plus the corners, 5% of R from a wire."""
    axes = [np.linspace(a, b, 9) for a, b in zip(lo, hi, strict=True)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return not np.any(winding_mask(field, pts, 0.05))


def test_planner_sees_a_winding_between_its_old_samples():
    # a thin coil at z = 0.025, midway between the old sample planes z = 0 and z = 0.05
    thin = coils.Coil(0.15, 10, 1.0, axis="z", center=(0, 0, 0.025), winding=(0.01, 0.01))
    lo, hi = np.full(3, -0.2), np.full(3, 0.2)
    assert _old_planner_check(thin, lo, hi)  # the sampling missed it
    with pytest.raises(ValueError, match="inside a coil winding"):
        thin.B([[0.15, 0.002, 0.027]])  # a point of the box
    assert not _box_clear_of_windings(thin, (lo, hi))
    # corners at rho = 0.09 sqrt(2) = 0.127 m; innermost filament at rho = 0.15 - 0.0039 m,
    # 0.019 m > 5% of 0.15 m away
    assert _box_clear_of_windings(thin, (np.full(3, -0.09), np.full(3, 0.09)))
    assert not _box_clear_of_windings(thin, (np.full(3, -0.1), np.full(3, 0.1)))  # 0.0047 m


def test_planner_keeps_five_percent_of_the_radius_from_a_wire(loop):
    a = 0.1
    for gap, clear in ((0.049, False), (0.051, True)):
        box = (np.array([a * (1 + gap), -0.01, -0.01]), np.array([0.3, 0.01, 0.01]))
        assert _box_clear_of_windings(loop, box) == clear
