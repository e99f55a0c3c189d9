"""Bad input to the rod model and solvers: ValueError naming the argument; unreachable loads:
ConvergenceError saying which scale was reached."""

import numpy as np
import pytest

import coils
from coilrod import (
    Circle,
    ConvergenceError,
    Magnetization,
    Rectangle,
    Rod,
    presets,
    solve_rod,
    trace_rod,
)

ROD = presets.seed_rod()
FIELD = coils.UniformField(B=(0.0, 5e-3, 0.0))


@pytest.mark.parametrize(
    ("make", "name"),
    [
        (lambda: Rod(0.0, 1e6, Circle(1e-3), Magnetization(1e5)), "length"),
        (lambda: Rod(-0.04, 1e6, Circle(1e-3), Magnetization(1e5)), "length"),
        (lambda: Rod(0.04, 0.0, Circle(1e-3), Magnetization(1e5)), "youngs_modulus"),
        (lambda: Rod(0.04, float("nan"), Circle(1e-3), Magnetization(1e5)), "youngs_modulus"),
        (lambda: Circle(0.0), "diameter"),
        (lambda: Circle(-1e-3), "diameter"),
        (lambda: Rectangle(1e-3, 0.0), "thickness"),
        (lambda: Rectangle(-1e-3, 1e-3), "width"),
        (lambda: Magnetization(float("nan")), "magnitude"),
        (lambda: Magnetization(1e5, float("inf")), "angle"),
        (lambda: Rod(0.04, 1e6, "round", Magnetization(1e5)), "section"),
    ],
)
def test_bad_rod_description(make, name):
    with pytest.raises(ValueError, match=name):
        make()


def test_nan_from_a_magnetization_profile_names_it():
    rod = Rod(0.04, 1e6, Circle(2e-3), Magnetization(lambda s: np.where(s > 0.02, np.nan, 1e5)))
    with pytest.raises(ValueError, match="magnetization magnitude"):
        solve_rod(rod, FIELD, [1.0])


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"scales": [1.0, float("nan")]}, "scales"),
        ({"scales": [float("inf")]}, "scales"),
        ({"scales": []}, "scales"),
        ({"scales": [[1.0, 2.0]]}, "scales"),
        ({"scales": "1.0"}, "scales"),
        ({"nodes": 2}, "nodes"),
        ({"nodes": 10.5}, "nodes"),
        ({"clamp_position": (0.0, 0.0)}, "clamp_position"),
        ({"clamp_position": (0.0, float("nan"), 0.0)}, "clamp_position"),
        ({"clamp_angle": float("nan")}, "clamp_angle"),
        ({"field": np.zeros(3)}, "field"),
        ({"rod": "rod"}, "rod"),
        ({"tol": float("nan")}, "tol"),
    ],
)
def test_bad_solver_input(kwargs, name):
    args = {"rod": ROD, "field": FIELD, "scales": [1.0]} | kwargs
    with pytest.raises(ValueError, match=name):
        solve_rod(args.pop("rod"), args.pop("field"), args.pop("scales"), **args)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"scale_range": (0.0, float("nan"))}, "scale_range"),
        ({"scale_start": 5.0}, "scale_start"),
        ({"direction": 0}, "direction"),
        ({"initial": np.full(65, np.nan)}, "initial"),
    ],
)
def test_bad_trace_input(kwargs, name):
    args = {"scale_start": 0.0, "scale_range": (0.0, 1.0)} | kwargs
    with pytest.raises(ValueError, match=name):
        trace_rod(ROD, FIELD, args.pop("scale_start"), args.pop("scale_range"), **args)


class _Unreachable(coils.Field):
    """A field that cannot be evaluated beyond a line (like the inside of a coil winding)."""

    linear = True

    def _B(self, pts):
        if np.any(pts[:, 1] > 0.5 * ROD.length):
            raise ValueError("point lies inside a coil winding")
        return np.tile([0.0, 0.02, 0.0], (pts.shape[0], 1))

    def _gradient(self, pts):
        self._B(pts)
        return np.zeros((pts.shape[0], 3, 3))


def test_unreachable_scale_raises_convergence_error_with_reached_scale():
    with pytest.raises(
        ConvergenceError,
        match=r"could not reach scale 1 \(index 2\); it "
        r"reached scale 0\.\d+",
    ) as info:
        solve_rod(ROD, _Unreachable(), [0.05, 0.1, 1.0], nodes=16)
    err = info.value
    assert err.target == 1.0
    assert 0.1 <= err.reached < 1.0
    assert err.residual > 0  # inf: the field raised at every trial state beyond the line
    assert "field could not be evaluated" in str(err)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"step": 0.0}, "step"),
        ({"step": -0.1}, "step"),
        ({"step": float("nan")}, "step"),
        ({"max_steps": 0}, "max_steps"),
        ({"max_steps": -3}, "max_steps"),
        ({"max_steps": 2.5}, "max_steps"),
        ({"tol": 0.0}, "tol"),
        ({"direction": 0}, "direction"),
        ({"direction": True}, "direction"),
    ],
)
def test_trace_rod_numerical_parameters(kwargs, name):
    """Parameters that would give meaningless output (a zero or negative step, no steps) are
    a ValueError naming them."""
    with pytest.raises(ValueError, match=name):
        trace_rod(ROD, FIELD, 0.5, (0.0, 1.0), **kwargs)
