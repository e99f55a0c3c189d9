"""Bad input to the field layer: a ValueError that names the problem, never a silent NaN."""

import numpy as np
import pytest

import coils


@pytest.fixture
def pair():
    return coils.HelmholtzPair(0.1, 100, 2.0, axis="y")


@pytest.mark.parametrize(
    ("points", "match"),
    [
        ([[0.0, np.nan, 0.0]], "finite"),
        ([[0.0, 0.0, np.inf]], "finite"),
        (np.zeros((4, 2)), r"shape \(n, 3\)"),
        (np.zeros((2, 3, 1)), r"shape \(n, 3\)"),
        ([1.0, 2.0], r"shape \(n, 3\)"),
        ("abc", "could not convert|shape"),
    ],
)
def test_bad_points(pair, points, match):
    with pytest.raises(ValueError, match=match):
        pair.B(points)
    with pytest.raises(ValueError, match=match):
        pair.gradient(points)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"radius": 0.0}, "radius must be positive"),
        ({"radius": -1.0}, "radius must be positive"),
        ({"radius": np.nan}, "radius must be finite"),
        ({"turns": 0}, "turns must be positive"),
        ({"current": np.inf}, "current must be finite"),
        ({"spacing": -0.1}, "spacing must be positive"),
        ({"axis": "w"}, "axis must be"),
        ({"axis": (0, 0, 0)}, "non-zero"),
        ({"center": (0, 0)}, r"center must have shape \(3,\)"),
        ({"winding": (0.0, 0.01)}, "winding width must be positive"),
        ({"winding": (0.01, 0.3)}, "below twice the radius"),
        ({"winding": (0.2, 0.01)}, "spacing .* must exceed the winding width"),
        ({"winding": (0.01, 0.01), "filaments": (0, 2)}, "n_axial must be a positive integer"),
        ({"winding": (0.01, 0.01), "turn_layout": (10, 3)}, "places 30 turns"),
        ({"turn_layout": (10, 10)}, "needs a winding"),
    ],
)
def test_bad_coil_parameters(kwargs, match):
    args = {"radius": 0.1, "turns": 100, "current": 2.0}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        coils.HelmholtzPair(**args)


def test_point_on_winding(pair):
    with pytest.raises(ValueError, match="lies on a coil winding"):
        pair.B([[0.0, 0.05, 0.0], [0.1, 0.05, 0.0]])


def test_point_inside_finite_winding():
    pair = coils.MaxwellPair(0.1, 100, 2.0, axis="z", winding=(0.02, 0.02))
    h = pair.spacing / 2
    with pytest.raises(ValueError, match="inside a coil winding"):
        pair.gradient([[0.105, 0.0, h + 0.005]])


def test_ideal_field_validation():
    with pytest.raises(ValueError, match=r"B must have shape \(3,\)"):
        coils.UniformField((0, 1))
    with pytest.raises(ValueError, match=r"gradient must have shape \(3, 3\)"):
        coils.LinearField(gradient=np.eye(2))
    with pytest.raises(ValueError, match="gradient must be finite"):
        coils.LinearField(gradient=np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match="every part must be a coils Field"):
        coils.CoilSystem([coils.UniformField(), "coil"])
    with pytest.raises(ValueError, match="factor must be finite"):
        coils.UniformField() * np.nan
