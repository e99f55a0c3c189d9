"""The workspace as a property of the robot (issue 18): exact symmetries, monotonicity in the
field bound, refinement up to the antiparallel cut and an honest error estimate.

Independent references: exact symmetries (turning the clamp turns every tip; a uniform
magnetization turned by a is the field turned by -a), tips of separate solve_rod runs along
radial ramps arbitrarily close to the cut, a run refined further.  Cheap settings (12 nodes, no
Richardson step, small initial grids): every property holds at any resolution.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
import shapely

import coils
from coilrod import Magnetization, presets, solve_rod, workspace
from coilrod.design.workspace import reference_direction

ROD = presets.seed_rod(presets.M1())
CHEAP = dict(directions=24, magnitudes=6, nodes=12, richardson=False)
B = 0.006  # T: twice the antiparallel buckling field of M(1)


@pytest.fixture(scope="module")
def base():
    return workspace(ROD, B, **CHEAP)


def _rotate(xy, angle):
    c, s = math.cos(angle), math.sin(angle)
    return xy @ np.array([[c, s], [-s, c]])


class TestSymmetries:
    @pytest.mark.parametrize("angle", [math.radians(2.5), 2.2])
    def test_turning_the_clamp_turns_the_workspace(self, base, angle):
        """Issue 18: 194.1 against 217.2 mm^2 with the clamp turned by 2.5 deg."""
        ws = workspace(ROD, B, clamp_angle=angle, **CHEAP)
        assert ws.area == pytest.approx(base.area, rel=1e-9)
        assert ws.area_error == pytest.approx(base.area_error, rel=1e-6, abs=1e-12)
        assert ws.reference == pytest.approx(angle, abs=1e-15)
        np.testing.assert_allclose(
            ws.tips[..., :2], _rotate(base.tips[..., :2], angle), atol=1e-9 * ROD.length
        )

    def test_a_uniform_magnetization_at_any_angle_has_the_same_equilibria(self, base):
        """Issue 18: Magnetization(128e3, 1.0) against M(1): 747 against 660 mm^2 at 16 x 4.
        The planar equilibria are the same (the grid turns with the moment: identical tips);
        their 3D stability is not -- a twist turns the normal component of a tilted
        magnetization out of the plane, which an axial one does not have -- so the areas of
        the 3D-stable sets may differ (tests/test_rod_stability3d.py checks that stability
        against an independent Hessian)."""
        m = ROD.magnetization.max_magnitude(ROD.length)
        turned = dataclasses.replace(ROD, magnetization=Magnetization(m, 1.0))
        assert reference_direction(turned) == pytest.approx(1.0, abs=1e-12)
        grid = {**CHEAP, "refine": 0}  # refinement follows the (different) 3D stability
        ws = workspace(turned, B, **grid)
        axial = workspace(ROD, B, **grid)
        np.testing.assert_allclose(ws.tips, axial.tips, atol=1e-8 * ROD.length)


class TestMonotonicity:
    def test_area_grows_with_the_field_bound_across_buckling(self):
        """Issue 18 (36 x 8): 23.66 mm^2 at 2.9 mT, 20.42 at 3.0 mT; buckling at 3.01 mT.
        The issue's two bounds and one past buckling."""
        areas = [workspace(ROD, b, **CHEAP).area for b in (0.0029, 0.003, 0.0031)]
        assert np.all(np.diff(areas) > 0), areas


class TestConvergence:
    def test_stable_tips_next_to_the_cut_are_in_the_workspace(self, base):
        """Tips of solve_rod runs along radial ramps 1e-2 ... 1e-6 rad from the antiparallel
        direction (either side) and elsewhere: every stable one lies in the workspace (to
        0.2 % of L): the wedge at the cut is not lost, wherever the grid falls."""
        eps = np.array([1e-2, 1e-4, 1e-6])
        alpha = np.r_[np.pi - eps, -np.pi + eps, 0.3, 2.0, -2.9]
        region = base.polygon.buffer(2e-3 * ROD.length)
        scales = np.linspace(0.05, 1.0, 20)
        inside = []
        for a in alpha:
            phi = base.reference + a
            field = coils.UniformField(B=B * np.array([math.cos(phi), math.sin(phi), 0.0]))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = solve_rod(ROD, field, scales, nodes=12, richardson=False)
            pts = shapely.points(res.tip[res.stable, :2])
            inside.append(shapely.contains(region, pts).all())
        assert all(inside), dict(zip(np.round(alpha, 7).tolist(), inside, strict=True))

    def test_area_error_bounds_the_distance_to_a_refined_run(self, base):
        """A run with twice the initial grid, two more levels and a 4 x smaller tolerance: the
        default's area within its area_error of it, and within 6 % (this cheap case: thin
        crescent, sharp knee past buckling)."""
        fine = workspace(
            ROD,
            B,
            directions=48,
            magnitudes=12,
            nodes=12,
            richardson=False,
            refine=8,
            tolerance=2.5e-4,
        )
        assert abs(base.area - fine.area) <= base.area_error
        assert base.area == pytest.approx(fine.area, rel=0.06)
        assert fine.area_error < base.area_error
        # 12 x 3: the two estimates together cover the distance (5.2 mm^2); undoing the
        # directions' and the magnitudes' bisections at once let them cancel (0.55 mm^2)
        coarse = workspace(ROD, B, directions=12, magnitudes=3, nodes=12, richardson=False)
        assert abs(coarse.area - fine.area) <= coarse.area_error + fine.area_error


class TestBadInput:
    @pytest.mark.parametrize(
        ("kwargs", "match"),
        [
            ({"refine": -1}, "refine"),
            ({"refine": 1.5}, "refine"),
            ({"refine": 100}, "refine"),
            ({"tolerance": 0.0}, "tolerance"),
            ({"tolerance": float("nan")}, "tolerance"),
            ({"reference": float("inf")}, "reference"),
        ],
    )
    def test_workspace(self, kwargs, match):
        with pytest.raises(ValueError, match=match):
            workspace(ROD, 0.01, **(dict(directions=8, magnitudes=2) | kwargs))
