"""Workspaces (coilrod.workspace) and magnetization optimisation, grouped by property.

Independent references: tips from separate solve_rod runs (one direction at a time), the
closed-form buckling field of the straight rod (lambda_c = pi^2 / 4), a rasterised area of the
cells (matplotlib paths, not shapely), central differences of shapely areas and of whole
workspace solves, the rod's mirror symmetry.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from matplotlib.path import Path

import coils
from coilrod import Magnetization, optimize_magnetization, presets, solve_rod, workspace
from coilrod.design.workspace import _triangles, _union, area_gradient, tip_derivatives

ROD = presets.seed_rod(presets.M1())
B_MAX = 0.02


@pytest.fixture(scope="module")
def m1():
    return workspace(ROD, B_MAX, directions=24, magnitudes=8, refine=0)


@pytest.fixture(scope="module")
def m42():
    return workspace(presets.seed_rod(presets.M42()), 0.015, directions=24, magnitudes=6, refine=0)


def _direction(rod, ws, d, **kw):
    phi = ws.directions[d]
    b = ws.magnitudes[-1] * np.array([math.cos(phi), math.sin(phi), 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return solve_rod(rod, coils.UniformField(B=b), ws.magnitudes[1:] / ws.magnitudes[-1], **kw)


class TestTips:
    @pytest.mark.parametrize("d", [0, 1, 5, 11, 12, 13, 20])
    def test_tips_are_those_of_single_direction_solves(self, m1, d):
        res = _direction(ROD, m1, d)
        assert np.max(np.abs(res.tip - m1.tips[d, 1:])) <= 1e-9 * ROD.length
        np.testing.assert_array_equal(res.stable, m1.stable[d, 1:])

    def test_unloaded_tip_and_inextensibility(self, m1):
        np.testing.assert_allclose(m1.tips[:, 0], [[ROD.length, 0.0, 0.0]] * 24)
        assert np.all(np.linalg.norm(m1.tips, axis=2) <= ROD.length * (1 + 1e-12))

    def test_mirror_symmetry_of_an_axial_magnetization(self, m1):
        """M(1) in the field at -phi is the mirror image (y -> -y) of M(1) at phi."""
        mirrored = m1.tips[::-1] * [1, -1, 1]  # directions symmetric about the reference
        np.testing.assert_allclose(mirrored, m1.tips, atol=1e-9 * ROD.length)


class TestStability:
    def test_antiparallel_straight_rod_buckles_at_the_closed_form_field(self):
        """Field along -x (the first refinement bisects the cut, the antiparallel direction):
        the straight rod is stable below lambda_c = pi^2 / 4 (continuous rod), unstable beyond
        (the workspace leaves those cells out)."""
        m1 = workspace(ROD, B_MAX, directions=24, magnitudes=8, refine=1)
        (d,) = np.flatnonzero(np.abs(np.cos(m1.directions) + 1) < 1e-12)  # 180 deg
        b_c = ROD.field_for_lambda(math.pi**2 / 4)
        below = m1.magnitudes < 0.98 * b_c
        above = m1.magnitudes > 1.02 * b_c
        assert below.any()
        assert above.any()
        assert np.all(m1.stable[d, below])
        assert not np.any(m1.stable[d, above])
        j = np.flatnonzero(above)[0]
        assert not m1.cells[d, j:].any()
        assert not m1.cells[d - 1, j:].any()
        assert any(e["direction"] == d and e["kind"] == "bifurcation" for e in m1.events)


class TestArea:
    def test_area_against_rasterised_cells(self, m42):
        """The shapely union against an independent count of grid points inside any cell
        triangle (matplotlib paths)."""
        tri, _ = _triangles(m42.tips[..., :2], m42.cells)
        lo, hi = tri.reshape(-1, 2).min(0), tri.reshape(-1, 2).max(0)
        n = 700
        x, y = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
        pts = np.column_stack([x.ravel(), y.ravel()])
        inside = np.zeros(len(pts), dtype=bool)
        for t in tri:
            u, v = t[1] - t[0], t[2] - t[0]
            if abs(u[0] * v[1] - u[1] * v[0]) > 0:
                inside |= Path(t).contains_points(pts)
        cell = (hi[0] - lo[0]) * (hi[1] - lo[1]) / (n - 1) ** 2
        assert inside.sum() * cell == pytest.approx(m42.area, rel=0.02)

    def test_area_gradient_against_central_differences(self, m42):
        g = area_gradient(m42)
        rng = np.random.default_rng(3)
        for _ in range(3):
            dt = rng.normal(size=g.shape) * ROD.length
            dt[:, 0] = 0.0  # the unloaded tip is shared by every direction
            h = 1e-7
            areas = [
                _union(m42.tips[..., :2] + s * h * dt, m42.cells, ROD.length)[1] for s in (1, -1)
            ]
            fd = (areas[0] - areas[1]) / (2 * h)
            assert np.sum(g * dt) == pytest.approx(fd, rel=1e-5)

    def test_real_coils_of_large_radius_approach_the_ideal_workspace(self):
        """A three-axis Helmholtz system 2.5 L in radius: the real workspace within 3 % of the
        ideal one; coils of about L in radius shrink it (the field falls off along the rod)."""
        kw = dict(directions=12, magnitudes=4, refine=0)
        ideal = workspace(ROD, 0.012, **kw)
        big = workspace(ROD, 0.012, system=coils.presets.three_axis_helmholtz(), **kw)
        small = workspace(
            ROD,
            0.012,
            system=coils.presets.three_axis_helmholtz(radii=(0.04, 0.05, 0.06), max_current=50),
            **kw,
        )
        assert big.area == pytest.approx(ideal.area, rel=0.03)
        assert small.area < 0.8 * ideal.area
        assert big.currents.shape == (12, 3)
        # each direction's currents make b_max along it at the centre
        for d in (0, 5):
            B = big.system.with_currents(big.currents[d]).B(np.zeros((1, 3)))[0]
            phi = big.directions[d]
            np.testing.assert_allclose(
                B, 0.012 * np.array([math.cos(phi), math.sin(phi), 0]), atol=1e-12
            )


class TestDerivatives:
    def test_tip_derivatives_against_workspace_differences(self, m42):
        rod = m42._solution.rod
        labels, dT = tip_derivatives(m42, ["magnitudes", "angles"])
        m = rod.magnetization
        lengths = np.diff(m.segment_edges)
        for j, h in [(1, 100.0), (3, 100.0), (6, 1e-5), (7, 1e-5)]:
            tips = []
            for s in (1, -1):
                mags, angs = m.segment_magnitudes.copy(), m.segment_angles.copy()
                if j < 4:
                    mags[j] += s * h
                else:
                    angs[j - 4] += s * h
                moved = dataclasses.replace(
                    rod, magnetization=Magnetization.segments(lengths, mags, angs)
                )
                ws = workspace(
                    moved, 0.015, directions=24, magnitudes=6, refine=0, reference=m42.reference
                )
                tips.append(ws.tips[..., :2])
            fd = (tips[0] - tips[1]) / (2 * h)
            assert np.max(np.abs(fd - dT[..., j])) <= 1e-5 * np.max(np.abs(fd)), labels[j]


class TestOptimisation:
    def test_gradient_of_the_refined_area_against_central_differences(self):
        """The objective's gradient (area_gradient x tip_derivatives, plus the turn of the
        directions with the net moment) against central differences of whole refined
        workspaces; turning both segments together is a symmetry: zero angle gradient sum."""
        from coilrod.design.optimize import _Objective

        obj = _Objective(ROD, 2, 0.006, 128e3, 12, 4, 2, 1e-3, 100)
        x = np.array([0.9, 0.7, 0.3, 1.2])
        _, g = obj.evaluate(x, True)
        for i, h in [(1, 1e-5), (2, 1e-6)]:
            up, down = x.copy(), x.copy()
            up[i] += h
            down[i] -= h
            fd = (obj.evaluate(up, False)[0] - obj.evaluate(down, False)[0]) / (2 * h)
            assert g[i] == pytest.approx(fd, rel=1e-5)
        assert abs(g[2] + g[3]) <= 1e-6 * abs(g[2])

    def test_one_segment_design_and_the_uniform_reference(self):
        """One segment at the magnitude bound: the design's area is its own workspace's, and
        the reference is the axial uniform magnetization's (in 3D a tilted one differs: its
        twist modes).  That reference is a layout of the search space, so the design is never
        worse than it, nor than any layout evaluated (the gradient start alone, a uniform
        magnetization tilted by pi/4, covers 0.71 of it here: its area's gradient is zero)."""
        kw = dict(directions=12, magnitudes=4, refine=2)
        best = optimize_magnetization(
            ROD, segments=1, b_max=0.008, max_magnitude=128e3, budget=6, starts=1, **kw
        )
        assert best.history.shape == (best.solves, 2)
        assert np.all(np.diff(best.history[:, 1]) >= 0)  # best so far never decreases
        assert best.area == best.history[:, 1].max()  # the best layout evaluated
        rod = dataclasses.replace(ROD, magnetization=Magnetization(128e3, 0.0))
        reference = workspace(rod, 0.008, **kw)
        uniform = reference.area
        assert uniform == pytest.approx(best.uniform_area, rel=1e-9)
        # the design's own workspace: where the design is the uniform layout itself (the same
        # magnetization vector everywhere, no breakpoints inside the rod: the same rod to
        # every solver, whose workspaces came out bitwise equal), that is the one just
        # computed; otherwise computed here
        s = np.linspace(0.0, ROD.length, 2001)
        same = np.array_equal(best.magnetization.vector3(s), rod.magnetization.vector3(s)) and set(
            best.magnetization.breakpoints
        ) <= {0.0, ROD.length}
        design = dataclasses.replace(ROD, magnetization=best.magnetization)
        again = reference if same else workspace(design, 0.008, **kw)
        assert again.area == pytest.approx(best.area, rel=1e-9)
        assert best.area >= uniform * (1 - 1e-9)
        assert best.ratio == pytest.approx(best.area / best.uniform_area, rel=1e-12)

    def test_evolution_respects_its_budget(self):
        best = optimize_magnetization(
            ROD,
            segments=1,
            b_max=B_MAX,
            method="evolution",
            budget=25,
            directions=8,
            magnitudes=3,
            refine=0,
        )
        assert best.solves <= 25
        assert best.area > 0


class TestBadInput:
    @pytest.mark.parametrize(
        ("kwargs", "match"),
        [
            ({"b_max": 0.0}, "b_max"),
            ({"b_max": -1.0}, "b_max"),
            ({"b_max": float("nan")}, "b_max"),
            ({"b_max": 10.0}, "magnetoelastic number"),
            ({"directions": 2}, "directions"),
            ({"magnitudes": 0}, "magnitudes"),
            ({"directions": 4.5}, "directions"),
            ({"directions": 10**6}, "directions"),
            ({"magnitudes": 10**5}, "magnitudes"),
            ({"nodes": 3}, "nodes"),
            ({"system": coils.UniformField(B=(0, 0, 0.01))}, "current control"),
        ],
    )
    def test_workspace(self, kwargs, match):
        args = {"b_max": 0.01, "directions": 8, "magnitudes": 2} | kwargs
        with pytest.raises(ValueError, match=match):
            workspace(ROD, **args)

    def test_not_a_rod(self):
        with pytest.raises(ValueError, match="coilrod.Rod"):
            workspace("rod", 0.01)

    def test_field_beyond_the_current_limits(self):
        with pytest.raises(ValueError, match="cannot make b_max = 0.2 T"):
            workspace(
                ROD, 0.2, directions=8, magnitudes=2, system=coils.presets.three_axis_helmholtz()
            )

    @pytest.mark.parametrize(
        ("kwargs", "match"),
        [
            ({"budget": 0}, "budget"),
            ({"b_max": 0.0}, "b_max"),
            ({"method": "newton"}, "method"),
            ({"max_magnitude": -1.0}, "max_magnitude"),
            ({"segments": 0}, "segments"),
            ({"segments": 1000}, "segments"),
            ({"budget": 10**9}, "budget"),
            ({"starts": 0}, "starts"),
        ],
    )
    def test_optimisation(self, kwargs, match):
        with pytest.raises(ValueError, match=match):
            optimize_magnetization(ROD, **({"b_max": 0.01} | kwargs))


class TestUnreachedDirections:
    def test_a_direction_that_stops_short_keeps_its_states_and_is_reported(self, monkeypatch):
        """A real-coil direction whose path cannot be followed to b_max (forced here: the
        solver gives up half-way) keeps the states it reached, its cells beyond are left out,
        and the event says so; the other directions are untouched."""
        import coilrod.design.workspace as W
        from coilrod import ConvergenceError

        system = coils.presets.three_axis_helmholtz()
        kw = dict(directions=8, magnitudes=4, system=system, refine=0, reference=np.pi / 8)
        full = workspace(ROD, 0.01, **kw)
        real = W._solve_direction

        def stops_half_way(rod, field, scales, *args):
            res = real(rod, field, scales, *args)
            if abs(field.currents[0]) < 1e-9 and field.currents[1] > 0:  # the +y direction
                part = real(rod, field, scales[:2], *args)
                err = ConvergenceError("gave up", reached=float(scales[1]), target=float(scales[2]))
                err.result = part
                raise err
            return res

        monkeypatch.setattr(W, "_solve_direction", stops_half_way)
        ws = workspace(ROD, 0.01, **kw)
        (d,) = np.flatnonzero(np.abs(np.sin(ws.directions) - 1) < 1e-12)  # 90 deg
        np.testing.assert_allclose(ws.tips[d, :3], full.tips[d, :3], atol=1e-12)
        assert np.isnan(ws.tips[d, 3:]).all()
        assert not ws.cells[d, 2:].any()
        assert not ws.cells[d - 1, 2:].any()
        assert [e["kind"] for e in ws.events if e["direction"] == d] == ["unreached"]
        others = [i for i in range(8) if i not in (d - 1, d)]
        np.testing.assert_array_equal(ws.cells[others], full.cells[others])
        assert ws.area < full.area
