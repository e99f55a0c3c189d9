"""Geometry of the contact obstacles (:mod:`coilrod.contact`): walls, vessels, networks.

Cross-checks, grouped by the property they test:

* closed forms -- a straight tube (R minus the radial distance, also beyond extended ends),
  round end caps, a circular bend (a point at distance D from the centre of curvature,
  in and out of the bend plane), a wall; a planar polyline against shapely's distance; round
  cones and the aneurysm: wall points at the given cross-section radius have gap 0; a spline
  against the distance to a dense sampling of the same spline;
* continuity -- the gap is 1-Lipschitz for every obstacle (a maximum of 1-Lipschitz
  functions), so continuous across polyline vertices, arc joints and junctions; the convex
  side of a corner is the vertex's sphere, the concave side the nearer segment's cylinder;
* derivatives -- gradient and hessian against central differences at random points away
  from kinks, for every kind of piece and radius; ``|grad| = 1`` and ``H grad = 0`` (an exact
  distance function), ``H`` symmetric;
* numerical stability -- points a few ulp off and exactly on the centreline, points 1e8 m
  away, tubes of radius 1e-6 m and 1 km (scale invariance), the KD-tree search against brute
  force;
* validation -- every refused input names its argument;
* API -- exports, shapes, bounds, check_start, plot, presets.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
import shapely

import coilrod
from coilrod.contact import Obstacle, Vessel, VesselNetwork, Wall, presets
from coilrod.contact import vessel as vessel_module

R = 1e-3
#: Rounding of distances between points with coordinates up to 0.1 m (a few ulp).
ATOL = 1e-16


# -- helpers ------------------------------------------------------------------------------------
def radial_points(vessel, s, rng, lo=0.2, hi=1.3):
    """Points at arc lengths ``s`` at a random distance in [lo, hi] R(s) from the centreline,
    in a random direction normal to it."""
    c, t = vessel.position(s), vessel.tangent(s)
    v = rng.normal(size=c.shape)
    v -= np.einsum("ij,ij->i", v, t)[:, None] * t
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    d = rng.uniform(lo, hi, len(s)) * vessel.radius_at(s)
    return c + d[:, None] * v


def central_differences(obstacle, points, h):
    """Gradient and hessian of the gap by central differences of the gap and the gradient."""
    grad = np.empty((len(points), 3))
    hess = np.empty((len(points), 3, 3))
    for i in range(3):
        dp = np.zeros(3)
        dp[i] = h
        plus, minus = obstacle.evaluate(points + dp, 1), obstacle.evaluate(points - dp, 1)
        grad[:, i] = (plus.gap - minus.gap) / (2 * h)
        hess[:, :, i] = (plus.gradient - minus.gradient) / (2 * h)
    return grad, hess


def polyline_distance(points, vertices):
    """Brute-force distance from points (n, 3) to a polyline (all segments, numpy)."""
    a, b = vertices[:-1], vertices[1:]
    ab = b - a
    t = np.einsum("nkj,kj->nk", points[:, None, :] - a, ab) / np.einsum("kj,kj->k", ab, ab)
    t = np.clip(t, 0, 1)
    foot = a + t[..., None] * ab
    return np.linalg.norm(points[:, None, :] - foot, axis=2).min(axis=1)


def quarter_bend():
    return Vessel.bend(10e-3, math.pi / 2, 2e-3, straight_before=10e-3, straight_after=10e-3)


@functools.cache
def obstacles():
    """One obstacle of every kind, with points where gap, gradient and hessian are smooth."""
    t = np.linspace(0, 2.5, 12)
    return {
        "straight": Vessel.straight(0.04, R),
        "bend": quarter_bend(),
        "polyline": Vessel([[0, 0, 0], [0.02, 0, 0], [0.035, 0.01, 0.004], [0.06, 0.01, 0]], R),
        "cones": Vessel([[0, 0, 0], [0.02, 0, 0], [0.04, 0.006, 0]], [1e-3, 2e-3, 1.5e-3]),
        "spline": Vessel(np.c_[0.02 * np.cos(t), 0.02 * np.sin(t), 0.002 * t], R, smooth=True),
        "aneurysm": Vessel.aneurysm(0.04, R, 2e-3),
        "callable": Vessel([[0, 0, 0], [0.04, 0, 0]], lambda s: R * (1.3 + 0.3 * np.sin(150 * s))),
        "spline_cones": Vessel(
            np.c_[0.02 * np.cos(t), 0.02 * np.sin(t), 0 * t],
            np.linspace(1e-3, 2e-3, 12),
            smooth=True,
        ),
    }


def smooth_points(name, vessel, rng, n=40):
    """Random points (inside and a little outside) whose nearest centreline point is interior
    to a piece and away from polyline corners."""
    if name == "polyline":
        s = np.concatenate([rng.uniform(3e-3, 0.017, n // 2), rng.uniform(0.023, 0.030, n // 2)])
    elif name == "cones":
        s = rng.uniform(2e-3, 0.016, n)
    elif name == "bend":
        s = rng.uniform(0.5e-3, vessel.length - 0.5e-3, n)
        s = s[np.abs(s - 0.01) > 1e-4]
        s = s[np.abs(s - 0.01 - 0.005 * math.pi) > 1e-4]
    else:
        s = rng.uniform(0.1 * vessel.length, 0.9 * vessel.length, n)
    return radial_points(vessel, s, rng, 0.25, 1.3)


# -- closed forms -------------------------------------------------------------------------------
class TestClosedForms:
    def test_straight_tube_is_radius_minus_radial_distance(self, rng):
        v = Vessel.straight(0.04, R, start=(0.01, -0.02, 0.003), direction=(1, 2, 2))
        d = np.array([1, 2, 2]) / 3
        # beyond both ends too: the extended tube is an infinite cylinder
        s = rng.uniform(-0.05, 0.09, 500)
        off = rng.normal(size=(500, 3)) * 2e-3
        p = np.array([0.01, -0.02, 0.003]) + s[:, None] * d + off
        radial = np.linalg.norm(off - (off @ d)[:, None] * d, axis=1)
        np.testing.assert_allclose(v.gap(p), R - radial, rtol=0, atol=ATOL)

    def test_round_ends_are_hemispherical_caps(self, rng):
        v = Vessel.straight(0.04, R, ends="round")
        p = rng.normal(size=(300, 3)) * 3e-3
        p[:, 0] = -np.abs(p[:, 0])  # before the first point
        np.testing.assert_allclose(v.gap(p), R - np.linalg.norm(p, axis=1), atol=ATOL)

    @pytest.mark.parametrize("z_scale", [0.0, 1.5e-3])
    def test_bend_matches_circle(self, rng, z_scale):
        rho, rad = 10e-3, 2e-3
        v = quarter_bend()
        center = np.array([10e-3, rho, 0.0])
        phi = rng.uniform(1e-3, math.pi / 2 - 1e-3, 1000)
        dist = rng.uniform(rho - 3 * rad, rho + 3 * rad, 1000)
        z = rng.uniform(-1, 1, 1000) * z_scale
        p = center + np.c_[dist * np.sin(phi), -dist * np.cos(phi), z]
        np.testing.assert_allclose(v.gap(p), rad - np.hypot(dist - rho, z), atol=ATOL)

    def test_bend_straight_parts_and_extensions(self, rng):
        v = quarter_bend()
        # before the arc: the line y = 0 (and its extension to -inf)
        x = rng.uniform(-0.1, 10e-3, 200)
        off = rng.normal(size=(200, 2)) * 1e-3
        p = np.c_[x, off]
        np.testing.assert_allclose(v.gap(p), 2e-3 - np.hypot(*off.T), atol=ATOL)
        # after it: the line x = 20 mm, y > 10 mm
        y = rng.uniform(10e-3, 0.1, 200)
        p = np.c_[20e-3 + off[:, 0], y, off[:, 1]]
        np.testing.assert_allclose(v.gap(p), 2e-3 - np.hypot(*off.T), atol=ATOL)

    def test_planar_polyline_matches_shapely(self, rng):
        pts = np.array(
            [[0, 0, 0], [0.02, 0, 0], [0.03, 0.01, 0], [0.05, 0.01, 0], [0.06, -0.01, 0]]
        )
        v = Vessel(pts, R, ends="round")
        p = rng.uniform(v.bounds[0], v.bounds[1], (5000, 3))
        p[:, 2] = 0.0
        dist = shapely.distance(shapely.LineString(pts[:, :2]), shapely.points(p[:, :2]))
        np.testing.assert_allclose(v.gap(p), R - dist, atol=ATOL)

    def test_polyline_in_3d_matches_brute_force(self, rng):
        pts = np.array([[0, 0, 0], [0.02, 0, 0], [0.035, 0.01, 0.004], [0.06, 0.01, 0]])
        v = Vessel(pts, R, ends="round")
        p = rng.uniform(v.bounds[0], v.bounds[1], (3000, 3))
        np.testing.assert_allclose(v.gap(p), R - polyline_distance(p, pts), atol=ATOL)

    def test_round_cones_have_the_given_section(self, rng):
        radii = np.array([1e-3, 2e-3, 1.5e-3])
        v = Vessel([[0, 0, 0], [0.02, 0, 0], [0.04, 0.006, 0]], radii)
        # wall points c(s) + R(s) n in the interior of each segment: on the cone
        s = np.concatenate([rng.uniform(1e-3, 0.019, 200), rng.uniform(0.0215, 0.0395, 200)])
        wall = radial_points(v, s, rng, 1.0, 1.0)
        np.testing.assert_allclose(v.gap(wall), 0.0, atol=ATOL)
        np.testing.assert_allclose(v.radius_at([0.0, 0.01, 0.02]), [1e-3, 1.5e-3, 2e-3])

    @pytest.mark.parametrize("bulge", [2.5e-3, 0.6e-3])  # an aneurysm and a stenosis
    def test_aneurysm_has_the_given_section(self, rng, bulge):
        v = Vessel.aneurysm(0.04, R, bulge)
        s = rng.uniform(0.0, 0.04, 400)
        wall = radial_points(v, s, rng, 1.0, 1.0)
        assert v.radius_error < 1e-12  # 1e-9 of the radius
        np.testing.assert_allclose(v.gap(wall), 0.0, atol=2 * v.radius_error + ATOL)
        sec = R + (bulge - R) * np.exp(-4 * math.log(2) * (s - 0.02) ** 2 / (2 * bulge) ** 2)
        np.testing.assert_allclose(v.radius_at(s), sec, rtol=1e-14)
        assert v.gap([0.02, 0.0, 0.0])[0] == pytest.approx(bulge, rel=1e-12)

    def test_callable_radius_section(self, rng):
        v = obstacles()["callable"]
        # not within 2 R of the ends, where R is continued by its end value with a kink in
        # slope: there the section is matched to O(R (dR/ds)^2) only (documented)
        s = rng.uniform(2 * 1.6e-3, 0.04 - 2 * 1.6e-3, 400)
        np.testing.assert_allclose(v.radius_at(s), R * (1.3 + 0.3 * np.sin(150 * s)), rtol=1e-9)
        assert v.radius_error < 2e-12
        wall = radial_points(v, s, rng, 1.0, 1.0)
        np.testing.assert_allclose(v.gap(wall), 0.0, atol=2 * v.radius_error + ATOL)

    def test_spline_distance_is_exact_to_the_spline(self, rng):
        """Against the distance to 2e5 samples of the same spline (error < 1e-13 m)."""
        t = np.linspace(0, 2.5, 12)
        v = Vessel(np.c_[0.02 * np.cos(t), 0.02 * np.sin(t), 0.002 * t], R, smooth=True)
        s = np.linspace(0, v.length, 200_001)
        samples = v.position(s)
        p = radial_points(v, rng.uniform(0.05 * v.length, 0.95 * v.length, 300), rng, 0.0, 3.0)
        from scipy.spatial import cKDTree

        dist = cKDTree(samples).query(p)[0]
        # the sampled distance exceeds the true one by at most (1 + d kappa) (h / 2)^2 / (2 d)
        # for a sample spacing h and curvature kappa (here <= 1/20 mm)
        bound = (1 + dist / 0.019) * (v.length / 200_000 / 2) ** 2 / (2 * dist)
        gap = v.gap(p)
        assert np.all(gap >= R - dist - ATOL)
        assert np.all(gap <= R - dist + bound + ATOL)

    def test_spline_through_a_circle_is_close_to_it(self):
        t = np.linspace(0, math.pi, 25)
        rho = 0.02
        v = Vessel(np.c_[rho * np.cos(t), rho * np.sin(t), 0 * t], R, smooth=True)
        # the spline deviates from the circle by its interpolation error, ~1e-8 m here
        phi = np.linspace(0.3, math.pi - 0.3, 200)
        dist = np.linspace(rho - R, rho + R, 200)
        p = np.c_[dist * np.cos(phi), dist * np.sin(phi), 0 * phi]
        np.testing.assert_allclose(v.gap(p), R - np.abs(dist - rho), atol=5e-8)
        assert v.length == pytest.approx(math.pi * rho, rel=1e-6)

    def test_spline_is_parametrised_by_arc_length(self):
        t = np.linspace(0, 2.5, 12)
        pts = np.c_[0.02 * np.cos(t), 0.02 * np.sin(t), 0.002 * t]
        v = Vessel(pts, R, smooth=True)
        s = np.linspace(0, v.length, 100_001)
        steps = np.linalg.norm(np.diff(v.position(s), axis=0), axis=1)
        assert np.cumsum(steps)[-1] == pytest.approx(v.length, rel=1e-8)
        np.testing.assert_allclose(steps / np.diff(s), 1.0, atol=2e-3)
        # the spline passes through the points
        knots = v.closest(pts)
        np.testing.assert_allclose(v.position(knots), pts, atol=1e-15)

    def test_wall_is_signed_distance(self, rng):
        wall = Wall(point=(0.01, -0.02, 0.003), normal=(1, -2, 2))
        n = np.array([1, -2, 2]) / 3
        p = rng.normal(size=(100, 3)) * 0.05
        np.testing.assert_allclose(wall.gap(p), (p - [0.01, -0.02, 0.003]) @ n, atol=ATOL)
        np.testing.assert_allclose(wall.gap_gradient(p), np.tile(n, (100, 1)))
        assert not wall.gap_hessian(p).any()
        assert wall.contains([0.01, -0.02, 0.003]).tolist() == [True]
        assert wall.contains(np.array([0.01, -0.02, 0.003]) - 1e-9 * n).tolist() == [False]

    def test_network_is_the_largest_member_gap(self, rng):
        net = Vessel.branch(0.04, 2e-3, 0.02, 1.5e-3, math.pi / 3)
        main, side = net.vessels
        p = rng.uniform(net.bounds[0], net.bounds[1], (2000, 3))
        np.testing.assert_allclose(net.gap(p), np.maximum(main.gap(p), side.gap(p)))
        ev, ev_side = net.evaluate(p), side.evaluate(p)
        won = side.gap(p) > main.gap(p)
        np.testing.assert_array_equal(ev.gradient[won], ev_side.gradient[won])
        np.testing.assert_array_equal(ev.hessian[won], ev_side.hessian[won])
        # the branch's round root adds nothing behind the junction
        behind = np.array([[0.02, -1.9e-3, 0.0], [0.02, -2.1e-3, 0.0]])
        np.testing.assert_allclose(net.gap(behind), main.gap(behind))

    @pytest.mark.parametrize("which", ["bend", "tapered"])
    def test_all_pairs_closed_form_is_the_generic_search(self, rng, which):
        # few pieces, all in closed form (lines with linear ball radii, constant-radius
        # arcs): gap, piece, parameter and the centreline's derivatives there (what the
        # gradient and hessian are made of) from the all-pairs pass equal, bit for bit, those
        # of the generic candidate search (_locate, then the curve at the chosen pieces)
        if which == "bend":
            v = Vessel.bend(bend_radius=0.02, angle=np.pi / 2, radius=R,
                            straight_before=0.01, straight_after=0.01)  # fmt: skip
        else:  # a tapered polyline with round ends (no extension half-lines)
            v = Vessel([[0, 0, 0], [0.01, 0, 0], [0.02, 0.005, 0.002]], [R, 0.8 * R, 1.2 * R],
                       ends="round")  # fmt: skip
        assert v._tree is None
        assert not v._needs_newton.any()
        s = rng.uniform(-0.01, v.length + 0.01, 400)
        p = v.position(np.clip(s, 0, v.length)) + rng.normal(size=(400, 3)) * 2e-3
        p[:3] = v.position(np.array([0.0, 0.5 * v.length, v.length]))  # on the centreline
        g, j, u = v._locate(p)
        x, xu, xuu = v._pieces.curve(j, u, 2)
        fast = v._locate_closed_form(p)
        for a, b in zip((g, j, u, x, xu, xuu), fast, strict=True):
            np.testing.assert_array_equal(b, a)


def _twin_cases():
    """Vessels whose search is the all-pairs closed form (a bend: lines, an arc and the two
    extension half-lines; a tapered polyline with round ends: round cones; a branch's two
    tubes, the side one with a round root), and points: random near the centreline, at the
    pieces' junctions (ties), on the axis at junctions and inside pieces, beyond the ends."""
    bend = Vessel.bend(bend_radius=0.02, angle=np.pi / 2, radius=R,
                       straight_before=0.01, straight_after=0.01)  # fmt: skip
    tapered = Vessel([[0, 0, 0], [0.01, 0, 0], [0.02, 0.005, 0.002]], [R, 0.8 * R, 1.2 * R],
                     ends="round")  # fmt: skip
    return [bend, tapered, *Vessel.branch(0.04, 2e-3, 0.02, 1.5e-3, math.pi / 3).vessels]


def test_compiled_search_is_the_numpy_search():
    """The compiled search and evaluation (run here as plain Python: ``py_func``, nothing is
    compiled) against its numpy twin (the all-pairs search, the generic derivatives): the
    same piece and parameter, gaps, gradients and hessians to rounding (of the points'
    coordinates, and for the normal over the distance to the centreline); on the axis
    (normal undefined), the gap, piece and parameter."""
    from coilrod.contact import _compiled_search as cs
    from coils._immutable import kernel_input

    rng = np.random.default_rng(7)
    for v in _twin_cases():
        assert v._all_pairs(64)
        m = v._m
        joints = np.concatenate([v._pieces.lo[:m], [v.length]])
        s = np.concatenate([joints, rng.uniform(-0.005, v.length + 0.005, 12)])
        on_axis = v.position(s)
        near = on_axis + rng.normal(size=on_axis.shape) * 0.7 * v.min_radius
        normal = np.cross(v.tangent(joints), rng.normal(size=3))  # at the junctions
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        p = np.concatenate([near, v.position(joints) + 0.5 * v.min_radius * normal, on_axis])
        j, kind, geom = v._search_inputs()
        n, searched = len(p), []
        for order in (0, 2):
            g, col, u = np.zeros(n), np.zeros(n, dtype=np.int64), np.zeros(n)
            grad, hess = np.zeros((n, 3)), np.zeros((n, 3, 3))
            cs.closed_form_search.py_func(
                kernel_input(p), order, kind, geom, v._rho_scale, vessel_module.ON_LINE,
                g, col, u, grad, hess,
            )  # fmt: skip
            assert (np.abs(grad).max() > 0) == (order > 0)
            searched.append((g, col, u))
        for a, b in zip(*searched, strict=True):  # the search is the same at every order
            np.testing.assert_array_equal(a, b)
        g0, j0, u0, x0 = v._locate_closed_form(p)[:4]
        _, grad0, hess0 = v._evaluate_numpy(p, 2)
        np.testing.assert_array_equal(j[col], j0)
        np.testing.assert_allclose(u, u0, rtol=0, atol=1e-15 * v.length)
        np.testing.assert_allclose(g, g0, rtol=0, atol=16 * np.finfo(float).eps * np.abs(p).max())
        off = slice(0, len(p) - len(on_axis))  # the normal is defined: to the rounding of
        # the centreline point (coordinates up to |p|) over the distance d to it
        tol = 16 * np.finfo(float).eps * np.abs(p).max() / np.linalg.norm(p - x0, axis=1)[off]
        assert np.all(np.abs(grad - grad0)[off].max(axis=1) <= tol)
        size = np.abs(hess0[off]).max(axis=(1, 2))
        assert np.all(np.abs(hess - hess0)[off].max(axis=(1, 2)) <= tol * size)
        np.testing.assert_allclose(np.linalg.norm(grad, axis=1), 1.0, rtol=0, atol=1e-15)
        exact = np.all(p == x0, axis=1)  # on the axis exactly: the same unit normal
        np.testing.assert_array_equal(grad[exact], grad0[exact])


def test_vessel_takes_the_compiled_search_when_it_pays(monkeypatch):
    """Once compiling has paid, a vessel evaluates by the compiled search (here its plain
    Python ``py_func``) and remembers it: the numbers of the numpy path to rounding, the
    same pieces; a vessel needing Newton (a spline) keeps the numpy search."""
    eps = np.finfo(float).eps
    from coilrod.contact import _compiled_search as cs

    calls, plain = [], cs.closed_form_search.py_func

    def kernel(*args):
        calls.append(len(args[0]))
        return plain(*args)

    monkeypatch.setattr(cs._rental, "ready", True)
    monkeypatch.setattr(cs, "closed_form_search", kernel)
    v, twin = _twin_cases()[0], _twin_cases()[0]
    p = v.position(np.linspace(-0.002, v.length + 0.002, 9)) + 4e-4  # 0.69 mm off the axis
    tol = 16 * eps * np.abs(p).max() / 6.9e-4  # the normal's rounding (see above)
    for order in (2, 0, 1, 2):  # one search, then remembered
        got, want = v.evaluate(p, order), twin._evaluate_numpy(p, order)
        np.testing.assert_allclose(got.gap, want[0], rtol=0, atol=16 * eps * np.abs(p).max())
        for a, b in zip(got[1:], want[1:], strict=True):
            assert (a is None and b is None) or np.allclose(a, b, 0, tol * np.abs(b).max())
    assert calls == [9]
    obstacles()["spline"].evaluate(p, 2)
    assert calls == [9]
    # a gaps-only search (order 0: no derivatives kept), then one with them, remembered
    v._memo().clear()
    for order in (0, 2, 0, 1):
        got, want = v.evaluate(p, order), twin._evaluate_numpy(p, order)
        np.testing.assert_allclose(got.gap, want[0], rtol=0, atol=16 * eps * np.abs(p).max())
        for a, b in zip(got[1:], want[1:], strict=True):
            assert (a is None and b is None) or np.allclose(a, b, 0, tol * np.abs(b).max())
    assert calls == [9, 9, 9]


def test_compiled_search_is_rented_until_compiling_pays(monkeypatch):
    """Ski rental: numpy searches are charged their estimated cost until the next would
    pass the price (here 2.5 searches of 65 points x 5 pieces), then the compiled search runs
    for good (numba's cache not looked at; nothing is compiled)."""
    from coilrod.contact import _compiled_search as cs
    from coils._numba_cache import Rental

    cost = cs._NUMPY_CALL_S + cs._NUMPY_PAIR_S * 65 * 5
    monkeypatch.setattr(cs, "COMPILE_AFTER", 2.5 * cost)
    monkeypatch.setattr(cs, "_rental", Rental(cs.__name__, cs._kernel))
    monkeypatch.setattr(cs._rental, "held", lambda: False)
    assert [cs.search_pays(65, 5) for _ in range(4)] == [False, False, True, True]
    assert cs._rental.spent == pytest.approx(2 * cost)


# -- continuity ---------------------------------------------------------------------------------
class TestContinuity:
    @pytest.mark.parametrize("name", list(obstacles()) + ["network", "wall"])
    def test_gap_is_one_lipschitz(self, rng, name):
        """A maximum of 1-Lipschitz functions: continuous everywhere (vertices, joints,
        junctions, ends), and never steeper than 1."""
        ob = {
            "network": Vessel.branch(0.04, 2e-3, 0.02, 1.5e-3, math.pi / 3),
            "wall": Wall((0, 0, 0), (1, 1, 0)),
        }.get(name) or obstacles()[name]
        lo, hi = ob.bounds if name != "wall" else (-0.01 * np.ones(3), 0.01 * np.ones(3))
        a = rng.uniform(lo, hi, (4000, 3))
        b = a + rng.normal(size=a.shape) * 1e-4
        slope = np.abs(ob.gap(a) - ob.gap(b)) / np.linalg.norm(a - b, axis=1)
        assert slope.max() <= 1 + 1e-9

    def test_gap_across_polyline_vertex(self):
        """Along lines crossing a corner's normal planes, on both sides of the turn."""
        pts = np.array([[0, 0, 0], [0.02, 0, 0], [0.03, 0.01, 0]])
        v = Vessel(pts, R)
        x = np.linspace(0.015, 0.025, 20001)
        for y in (-0.8e-3, -0.3e-3, 0.3e-3, 0.8e-3):
            g = v.gap(np.c_[x, np.full_like(x, y), 0 * x])
            assert np.abs(np.diff(g)).max() <= (x[1] - x[0]) * (1 + 1e-9)

    def test_convex_corner_is_the_vertex_sphere_and_concave_the_nearer_segment(self, rng):
        pts = np.array([[0, 0, 0], [0.02, 0, 0], [0.02, 0.02, 0]])  # left turn of 90 deg
        v = Vessel(pts, R)
        # outside of the turn (x > 20 mm, y < 0): the nearest point is the vertex
        p = np.c_[
            0.02 + rng.uniform(0, 1e-3, 200),
            -rng.uniform(0, 1e-3, 200),
            rng.normal(size=200) * 3e-4,
        ]
        np.testing.assert_allclose(v.gap(p), R - np.linalg.norm(p - pts[1], axis=1), atol=ATOL)
        grad = v.gap_gradient(p)
        np.testing.assert_allclose(
            grad, -(p - pts[1]) / np.linalg.norm(p - pts[1], axis=1)[:, None]
        )
        # inside of the turn (x < 20 mm, y > 0): the nearer of the two segments
        p = np.c_[0.02 - rng.uniform(0, 1.5e-3, 200), rng.uniform(0, 1.5e-3, 200), 0 * np.ones(200)]
        to_first, to_second = np.abs(p[:, 1]), np.abs(p[:, 0] - 0.02)
        np.testing.assert_allclose(v.gap(p), R - np.minimum(to_first, to_second), atol=ATOL)

    def test_bend_joint_gradient_continuous_hessian_from_each_side(self):
        """At the G1 joint of a line and an arc the gradient is continuous; the hessian on
        each side is the cylinder's or the torus's."""
        v = quarter_bend()
        rad, rho = 2e-3, 10e-3
        for y in (-1.2e-3, 0.7e-3):
            before = v.evaluate([0.01 - 1e-9, y, 0.0])
            after = v.evaluate([0.01 + 1e-9, y, 0.0])
            np.testing.assert_allclose(before.gradient, after.gradient, atol=1e-6)
            # cylinder: -1/|y| in z; torus: the z curvature and the along-axis term
            assert before.hessian[0, 2, 2] == pytest.approx(-1 / abs(y))
            assert before.hessian[0, 0, 0] == pytest.approx(0.0, abs=1e-6)
            # along the arc: 1/|y| (rho / (rho - y) - 1)
            assert after.hessian[0, 0, 0] == pytest.approx((rho / (rho - y) - 1) / abs(y), rel=1e-5)
            assert abs(before.gap[0] - after.gap[0]) < 1e-11
            assert before.gap[0] == pytest.approx(rad - abs(y))


# -- derivatives --------------------------------------------------------------------------------
class TestDerivatives:
    @pytest.mark.parametrize("name", list(obstacles()))
    def test_gradient_and_hessian_match_finite_differences(self, rng, name):
        v = obstacles()[name]
        p = smooth_points(name, v, rng)
        ev = v.evaluate(p)
        h = 1e-8
        grad, hess = central_differences(v, p, h)
        np.testing.assert_allclose(ev.gradient, grad, atol=1e-6)
        scale = np.abs(ev.hessian).max(axis=(1, 2))[:, None, None]
        assert np.all(np.abs(ev.hessian - hess) <= 1e-5 * scale)

    def test_network_and_wall_derivatives(self, rng):
        net = Vessel.branch(0.04, 2e-3, 0.02, 1.5e-3, math.pi / 3)
        main, side = net.vessels
        p = np.concatenate(
            [
                radial_points(main, rng.uniform(0.002, 0.012, 20), rng, 0.25, 0.9),
                radial_points(side, rng.uniform(0.008, 0.018, 20), rng, 0.25, 0.9),
            ]
        )
        for ob in (net, Wall((0.001, 0, 0), (0.3, 1, -0.2))):
            ev = ob.evaluate(p)
            grad, hess = central_differences(ob, p, 1e-8)
            np.testing.assert_allclose(ev.gradient, grad, atol=1e-6)
            np.testing.assert_allclose(
                ev.hessian, hess, atol=1e-5 * max(1.0, np.abs(ev.hessian).max())
            )

    @pytest.mark.parametrize("name", list(obstacles()))
    def test_distance_function_identities(self, rng, name):
        """|grad| = 1, H grad = 0 (the gap does not curve along the normal), H symmetric."""
        v = obstacles()[name]
        p = rng.uniform(v.bounds[0], v.bounds[1], (500, 3))
        ev = v.evaluate(p)
        np.testing.assert_allclose(np.linalg.norm(ev.gradient, axis=1), 1.0, atol=1e-14)
        scale = np.abs(ev.hessian).max(axis=(1, 2))
        np.testing.assert_allclose(ev.hessian, ev.hessian.transpose(0, 2, 1), atol=1e-12)
        hg = np.einsum("nij,nj->ni", ev.hessian, ev.gradient)
        assert np.all(np.abs(hg).max(axis=1) <= 1e-9 * scale)

    def test_evaluate_agrees_with_the_separate_methods(self, rng):
        v = obstacles()["spline"]
        p = rng.uniform(v.bounds[0], v.bounds[1], (300, 3))
        ev = v.evaluate(p)
        np.testing.assert_array_equal(ev.gap, v.gap(p))
        np.testing.assert_array_equal(ev.gradient, v.gap_gradient(p))
        np.testing.assert_array_equal(ev.hessian, v.gap_hessian(p))
        assert v.evaluate(p, 0).gradient is None
        assert v.evaluate(p, 1).hessian is None


# -- numerical stability ------------------------------------------------------------------------
class TestNumericalStability:
    @pytest.mark.parametrize("name", ["straight", "bend", "spline", "aneurysm"])
    def test_points_on_and_a_few_ulp_off_the_centerline(self, rng, name):
        v = obstacles()[name] if name != "bend" else quarter_bend()
        s = np.array([0.3, 0.6]) * v.length
        c = v.position(s)
        normal = np.cross(v.tangent(s), rng.normal(size=3))
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        p = np.concatenate([c, c + 3 * np.spacing(np.abs(c).max()) * normal])
        ev = v.evaluate(p)
        # the distance from the axis to the wall: the radius (less where it varies)
        np.testing.assert_allclose(ev.gap[2:], ev.gap[:2], atol=ATOL)
        assert np.all(ev.gap <= np.tile(v.radius_at(s), 2) * (1 + 1e-14))
        assert np.all(ev.gap >= 0.99 * np.tile(v.radius_at(s), 2))
        np.testing.assert_allclose(np.linalg.norm(ev.gradient, axis=1), 1.0, rtol=1e-12)
        assert np.isfinite(ev.hessian).all()

    def test_points_far_away(self, rng):
        v = Vessel.straight(0.04, R)
        off = rng.normal(size=(100, 3))
        off[:, 0] = 0.0
        off *= 1e8 / np.linalg.norm(off, axis=1, keepdims=True)
        p = off + [0.02, 0.0, 0.0]
        np.testing.assert_allclose(v.gap(p), R - 1e8, rtol=1e-15)
        b = quarter_bend()
        p = rng.normal(size=(100, 3)) * 1e8
        ev = b.evaluate(p)
        # reference: the distance to the two (half-)lines and to a dense sampling of the arc
        foot = np.c_[np.minimum(p[:, 0], 0.01), 0 * p[:, 0], 0 * p[:, 0]]
        d_before = np.linalg.norm(p - foot, axis=1)
        foot = np.c_[0.02 + 0 * p[:, 0], np.maximum(p[:, 1], 0.01), 0 * p[:, 0]]
        d_after = np.linalg.norm(p - foot, axis=1)
        phi = np.linspace(0, math.pi / 2, 10_001)
        arc = np.c_[0.01 + 0.01 * np.sin(phi), 0.01 - 0.01 * np.cos(phi), 0 * phi]
        d_arc = np.linalg.norm(p[:, None, :] - arc[None], axis=2).min(axis=1)
        ref = np.minimum(np.minimum(d_before, d_after), d_arc)
        np.testing.assert_allclose(ev.gap, 2e-3 - ref, rtol=1e-12)
        assert np.isfinite(ev.hessian).all()
        np.testing.assert_allclose(np.linalg.norm(ev.gradient, axis=1), 1.0)

    @pytest.mark.parametrize("scale", [1e-3, 1e3])
    @pytest.mark.parametrize("name", ["bend", "cones", "spline", "aneurysm"])
    def test_scale_invariance(self, rng, scale, name):
        """A tube of radius 1 um (and 1 m) is the millimetre tube scaled: gap * scale,
        gradient unchanged, hessian / scale."""
        t = np.linspace(0, 2.5, 12)
        make = {
            "bend": lambda k: Vessel.bend(10e-3 * k, 1.0, 2e-3 * k, 10e-3 * k, 10e-3 * k),
            "cones": lambda k: Vessel(
                np.array([[0, 0, 0], [0.02, 0, 0], [0.04, 0.006, 0]]) * k,
                np.array([1e-3, 2e-3, 1.5e-3]) * k,
            ),
            "spline": lambda k: Vessel(
                np.c_[0.02 * np.cos(t), 0.02 * np.sin(t), 0.002 * t] * k, R * k, smooth=True
            ),
            "aneurysm": lambda k: Vessel.aneurysm(0.04 * k, R * k, 2e-3 * k),
        }[name]
        ref, small = make(1.0), make(scale)
        p = rng.uniform(ref.bounds[0], ref.bounds[1], (500, 3))
        a, b = ref.evaluate(p), small.evaluate(p * scale)
        np.testing.assert_allclose(b.gap / scale, a.gap, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(b.gradient, a.gradient, atol=1e-8)
        np.testing.assert_allclose(
            b.hessian * scale, a.hessian, rtol=1e-6, atol=1e-6 * np.abs(a.hessian).max()
        )

    def test_kdtree_search_matches_brute_force(self, rng):
        """A random walk of 400 segments (KD-tree candidates) against numpy brute force."""
        steps = rng.normal(size=(400, 3))
        steps[:, 0] = np.abs(steps[:, 0]) + 1.0  # a meandering path that never folds back
        pts = np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)]) * 1e-3
        v = Vessel(pts, 0.1e-3, ends="round")
        assert v._tree is not None
        p = rng.uniform(v.bounds[0], v.bounds[1], (3000, 3))  # (far points widen the search)
        p[:1000] = pts[rng.integers(0, 401, 1000)] + rng.normal(size=(1000, 3)) * 2e-4
        np.testing.assert_allclose(v.gap(p), 0.1e-3 - polyline_distance(p, pts), atol=ATOL)

    def test_kdtree_search_on_a_long_spline(self, rng):
        t = np.linspace(0, 6 * math.pi, 80)
        pts = np.c_[0.02 * np.cos(t), 0.02 * np.sin(t), 0.004 * t]  # a helix, pitch 25 mm
        v = Vessel(pts, 2e-3, smooth=True)
        assert v._tree is not None
        p = rng.uniform(v.bounds[0], v.bounds[1], (3000, 3))
        tree = v.evaluate(p)
        brute = v._evolve(v._params, _tree=None).evaluate(p)  # every piece a candidate
        np.testing.assert_allclose(tree.gap, brute.gap, atol=ATOL)
        np.testing.assert_allclose(tree.gradient, brute.gradient, atol=1e-12)


# -- validation ---------------------------------------------------------------------------------
LINE = [[0, 0, 0], [0.04, 0, 0]]


class TestValidation:
    @pytest.mark.parametrize(
        ("make", "match"),
        [
            (lambda: Vessel([[0, 0, 0]], R), "centerline must have at least 2 points; got 1"),
            (lambda: Vessel([[0, 0, 0], [np.nan, 0, 0]], R), "centerline must be finite"),
            (lambda: Vessel([[0, 0, 0], [np.inf, 0, 0]], R), "centerline must be finite"),
            (lambda: Vessel([[0, 0], [1, 0]], R), r"centerline must have shape \(n, 3\)"),
            (
                lambda: Vessel([[0, 0, 0], [1, 0, 0], [1, 0, 0], [2, 0, 0]], R),
                "centerline points 1 and 2 coincide",
            ),
            (lambda: Vessel(LINE, 0.0), "radius must be positive; got 0.0"),
            (lambda: Vessel(LINE, -1e-3), "radius must be positive"),
            (lambda: Vessel(LINE, np.nan), "radius must be finite"),
            (lambda: Vessel(LINE, [R, R, R]), r"radius must .* have shape \(2,\)"),
            (lambda: Vessel(LINE, [R, 0.0]), r"radius\[1\] must be positive"),
            (lambda: Vessel(LINE, "1 mm"), "radius must be a positive number"),
            (lambda: Vessel(LINE, lambda s: R - s), r"radius\(s\) must be positive"),
            (lambda: Vessel(LINE, lambda s: s * np.nan), r"radius\(s\) must be finite"),
            (lambda: Vessel(LINE, lambda: R), "radius must be a callable mapping arc length"),
            (lambda: Vessel(LINE, R, smooth=1), "smooth must be True or False"),
            (lambda: Vessel(LINE, R, ends="open"), "ends must be 'extend' or 'round'"),
            (lambda: Vessel(LINE, R, ends=("round",)), "ends must be 'extend', 'round' or a pair"),
            # a U of three segments: the inner walls of the two corners overlap
            (
                lambda: Vessel([[0, 0, 0], [0.01, 0, 0], [0.01, 1.5e-3, 0], [0, 1.5e-3, 0]], R),
                "the inner wall folds between points 1 and 2",
            ),
            # a hairpin at one corner
            (
                lambda: Vessel([[0, 0, 0], [0.01, 0, 0], [0, 1e-3, 0]], R),
                "inner wall folds between points 0 and 1: the turn of 174.3 deg",
            ),
            # a closed square loop: the last segment runs back into the first
            (
                lambda: Vessel(
                    [[0, 0, 0], [0.01, 0, 0], [0.01, 0.01, 0], [0, 0.01, 0], [0, -0.01, 0]], R
                ),
                "the tube intersects itself",
            ),
            # legs of a long U 1.5 mm apart (the corners alone would be fine)
            (
                lambda: Vessel(
                    [[0, 0, 0], [0.02, 0, 0], [0.025, 0.005, 0], [0.02, 0.01, 0], [0.0, 0.0015, 0]],
                    R,
                ),
                "the tube intersects itself",
            ),
            # a spline tighter than the tube
            (
                lambda: Vessel(
                    np.c_[
                        1.5e-3 * np.cos(np.linspace(0, 2, 20)),
                        1.5e-3 * np.sin(np.linspace(0, 2, 20)),
                        np.zeros(20),
                    ],
                    2e-3,
                    smooth=True,
                ),
                "radius of curvature of 1.4\\d* mm .* not more than the tube radius 2 mm",
            ),
            # extensions of a 350 deg bend cross
            (lambda: Vessel.bend(10e-3, 6.1, 2e-3), "straight extension"),
            (lambda: Vessel.bend(1e-3, 1.0, 2e-3), "bend_radius must exceed radius"),
            (lambda: Vessel.bend(10e-3, 0.0, 2e-3), r"angle must be in \(0, 2 pi\)"),
            (lambda: Vessel.bend(10e-3, 7.0, 2e-3), r"angle must be in \(0, 2 pi\)"),
            (lambda: Vessel.bend(10e-3, 1.0, 2e-3, -1.0), "straight_before must be >= 0"),
            (
                lambda: Vessel.bend(10e-3, 1.0, 2e-3, direction=(0, 0, 1)),
                "plane_normal must not be parallel to direction",
            ),
            (lambda: Vessel.straight(0.0, R), "length must be positive"),
            (lambda: Vessel.straight(0.04, R, direction=(0, 0, 0)), "direction must be a non-zero"),
            (
                lambda: Vessel.aneurysm(0.04, R, 3e-3, bulge_width=2e-3),
                "bulge_width: the bulge at s = 20 mm is too sharp",
            ),
            (lambda: Vessel.aneurysm(0.04, R, -1.0), "bulge_radius must be positive"),
            (
                lambda: Vessel.branch(0.04, R, 0.02, branch_radius=2e-3),
                "branch_radius must not exceed radius",
            ),
            (lambda: Vessel.branch(0.04, R, 0.02, branch_angle=math.pi), "branch_angle must be"),
            (lambda: Vessel.branch(0.04, R, 0.02, branch_at=0.05), "branch_at must lie in"),
            (lambda: Vessel.branch(0.04, R, 0.5e-3), "branch_length must exceed radius"),
            (lambda: Wall((0, 0, 0), (0, 0, 0)), "normal must be a non-zero vector"),
            (lambda: Wall((0, 0, 0), (np.nan, 0, 1)), "normal must be finite"),
            (lambda: Wall((0, 0, 0), (1, 0)), r"normal must have shape \(3,\)"),
            (lambda: Wall((0, np.inf, 0), (1, 0, 0)), "point must be finite"),
            (lambda: VesselNetwork([]), "vessels must hold at least one obstacle"),
            (lambda: VesselNetwork([Vessel(LINE, R), "pipe"]), r"vessels\[1\] must be a Vessel"),
            (lambda: VesselNetwork(3), "vessels must be a sequence of obstacles"),
            (lambda: Vessel(LINE, R).gap([[0, 0]]), r"points must have shape \(n, 3\)"),
            (lambda: Vessel(LINE, R).gap([[0, np.nan, 0]]), "points must be finite"),
            (
                lambda: Vessel(LINE, R).evaluate([0, 0, 0], 3),
                "order must be an integer from 0 to 2",
            ),
        ],
    )
    def test_refused(self, make, match):
        with pytest.raises(ValueError, match=match):
            make()

    def test_check_start(self):
        v = Vessel.straight(0.04, R)
        v.check_start(np.c_[np.linspace(0, 0.04, 41), np.zeros((41, 2))], "rod nodes")
        with pytest.raises(
            ValueError, match=r"^clamp at \(10, 4.2, 0\) mm lies 3.2 mm outside the vessel$"
        ):
            v.check_start([0.01, 4.2e-3, 0.0], "clamp")
        nodes = np.c_[np.linspace(0, 0.04, 41), np.linspace(0, 4e-3, 41), np.zeros(41)]
        with pytest.raises(
            ValueError,
            match=r"rod nodes\[11\] at \(11, 1.1, 0\) mm lies 0.1 mm outside the vessel "
            r"\(30 of 41 rod nodes are; the deepest, rod nodes\[40\], by 3 mm\)",
        ):
            v.check_start(nodes, "rod nodes")
        wall = Wall((0, -1e-3, 0), "y")
        with pytest.raises(ValueError, match="clamp at .* lies 3.2 mm behind the wall"):
            wall.check_start([0.01, -4.2e-3, 0.0], "clamp")
        wall.check_start([0.0, -1e-3 - 1e-12, 0.0], tol=1e-9)
        with pytest.raises(ValueError, match="tol must be >= 0"):
            wall.check_start([0.0, 0.0, 0.0], tol=-1.0)
        with pytest.raises(ValueError, match="outside the vessels"):
            Vessel.branch(0.04, R, 0.02).check_start([0.01, 0.01, 0.0])


# -- API ----------------------------------------------------------------------------------------
class TestAPI:
    def test_exports(self):
        for name in ("Wall", "Vessel", "VesselNetwork"):
            assert name in coilrod.__all__
        assert coilrod.Vessel is Vessel
        assert coilrod.Wall is Wall
        assert issubclass(Vessel, Obstacle)
        assert issubclass(Wall, Obstacle)
        assert set(presets.__all__) == {"straight", "bend", "aneurysm", "branch"}

    def test_presets_equal_classmethods(self, rng):
        p = rng.uniform(-0.01, 0.03, (200, 3))
        pairs = [
            (presets.straight(0.04, R), Vessel.straight(0.04, R)),
            (presets.bend(0.01, 1.0, R, 0.01), Vessel.bend(0.01, 1.0, R, 0.01)),
            (presets.aneurysm(0.04, R, 2e-3), Vessel.aneurysm(0.04, R, 2e-3)),
            (presets.branch(0.04, R, 0.02), Vessel.branch(0.04, R, 0.02)),
        ]
        for a, b in pairs:
            np.testing.assert_array_equal(a.gap(p), b.gap(p))

    def test_shapes(self):
        v = Vessel.straight(0.04, R)
        assert v.gap([0.01, 0, 0]).shape == (1,)
        assert v.gap_gradient([0.01, 0, 0]).shape == (1, 3)
        assert v.gap_hessian([0.01, 0, 0]).shape == (1, 3, 3)
        empty = np.zeros((0, 3))
        assert v.gap(empty).shape == (0,)
        assert v.gap_hessian(empty).shape == (0, 3, 3)
        assert v.contains(empty).shape == (0,)
        assert v.closest(empty).shape == (0,)
        assert Wall((0, 0, 0), "x").gap_hessian(empty).shape == (0, 3, 3)

    def test_bounds(self, rng):
        b = quarter_bend()
        np.testing.assert_allclose(b.bounds, [[-2e-3, -2e-3, -2e-3], [22e-3, 22e-3, 2e-3]])
        assert np.all(np.isinf(Wall((0, 0, 0), "z").bounds))
        net = Vessel.branch(0.04, R, 0.02)
        np.testing.assert_allclose(net.bounds, [[-1e-3, -1e-3, -1e-3], [41e-3, 21e-3, 1e-3]])
        # every lumen point of the finite tube lies in the box
        for name, v in obstacles().items():
            s = rng.uniform(0, v.length, 500)
            p = radial_points(v, s, rng, 0.0, 1.0)
            assert np.all((p >= v.bounds[0]) & (p <= v.bounds[1])), name

    def test_centerline_queries(self):
        b = quarter_bend()
        arc_end = 0.01 + 0.005 * math.pi
        s = np.array([-0.01, 0.005, 0.01 + 0.0025 * math.pi, 0.03, 0.05])
        half = 0.01 * math.sqrt(0.5)
        np.testing.assert_allclose(
            b.position(s),
            [
                [-0.01, 0, 0],
                [0.005, 0, 0],
                [0.01 + half, 0.01 - half, 0],
                [0.02, 0.01 + 0.03 - arc_end, 0],
                [0.02, 0.01 + 0.05 - arc_end, 0],
            ],
            atol=1e-15,
        )
        np.testing.assert_allclose(b.tangent(s)[[0, -1]], [[1, 0, 0], [0, 1, 0]], atol=1e-15)
        np.testing.assert_allclose(b.closest(b.position(s) + [0, 0, 1e-3]), s, atol=1e-15)
        assert b.length == pytest.approx(0.02 + 0.005 * math.pi)
        assert "Vessel(length=35.71 mm, radius=2 mm" in repr(b)
        assert repr(Wall((0, 1e-3, 0), "-y")) == "Wall(point=(0, 1, 0) mm, normal=(0, -1, 0))"

    def test_plot(self):
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots()
        net = Vessel.branch(0.04, 2e-3, 0.02, 1.5e-3, math.pi / 3)
        assert net.plot(ax) is ax
        Wall((0, -3e-3, 0), (0.2, 1, 0)).plot(ax, color="r")
        assert len(ax.lines) > 3
        ax2 = quarter_bend().plot()
        x, y = (
            np.concatenate([line.get_xdata() for line in ax2.lines]),
            np.concatenate([line.get_ydata() for line in ax2.lines]),
        )
        assert x.min() == pytest.approx(-6e-3, abs=1e-5)  # open ends drawn 3 radii long
        assert y.max() == pytest.approx(0.026, abs=1e-5)
        plt.close("all")

    def test_module_presets_are_importable_from_the_subpackage(self):
        assert vessel_module.Vessel is Vessel


def test_vessel_remembered_search_is_the_search():
    """A vessel remembers its last few nearest-point searches (a contact solve asks for the
    same points again): a repeated query returns what a fresh vessel computes, bitwise,
    whatever the caller did to the previous answer, at every order; the memory stays bounded
    and a pickled copy starts without it."""
    import pickle

    def make():
        return Vessel.bend(bend_radius=0.02, angle=np.pi / 2, radius=0.002,
                           straight_before=0.02, straight_after=0.03)  # fmt: skip

    v = make()
    rng = np.random.default_rng(3)
    sets = [v.position(rng.uniform(-0.005, 0.07, 9)) + 5e-4 * rng.standard_normal((9, 3))
            for _ in range(vessel_module._LOCATED_KEPT + 2)]  # fmt: skip
    first = v.evaluate(sets[0], order=1)
    first.gap[:] = 7.0  # the caller's copy: the remembered search must not see this
    first.gradient[:] = 7.0
    fresh = make()

    def same(p):
        for order in (2, 0, 1):
            got, want = v.evaluate(p, order=order), fresh.evaluate(p, order=order)
            for a, b in zip(got, want, strict=True):
                assert (a is None and b is None) or np.array_equal(a, b)

    same(sets[0])  # remembered
    for p in sets[1:]:  # pushes sets[0] out of the memory
        v.evaluate(p, order=0)
    assert len(v.__dict__["_located_memo"]) == vessel_module._LOCATED_KEPT
    for p in sets[::-1]:
        same(p)
    assert pickle.loads(pickle.dumps(v)).__dict__["_located_memo"] is None
