"""Bad numerical parameters to coils' public functions: a ValueError naming the parameter, never
a silently wrong result (e.g. ``uniformity(samples=1)`` used to report the whole search radius as
uniform, having looked only at the centre)."""

from __future__ import annotations

import numpy as np
import pytest

import coils
from coils import GriddedField, uniformity
from coils._validate import as_count
from coils.design import winding_power
from coils.plot import plane_grid, plot_field_map


@pytest.fixture(scope="module")
def pair():
    return coils.HelmholtzPair(0.1, 100, 2.0, axis="y", winding=(0.02, 0.02))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"samples": 1}, "samples must be an integer >= 2; got 1"),
        ({"samples": 0}, "samples must be an integer >= 2"),
        ({"samples": 2.5}, "samples must be an integer >= 2; got 2.5"),
        ({"samples": True}, "samples must be an integer >= 2; got True"),
        ({"samples": "400"}, "samples must be an integer >= 2"),
        ({"samples": np.nan}, "samples must be an integer >= 2"),
        ({"directions": 0}, "directions must be a positive integer; got 0"),
        ({"directions": 7.5}, "directions must be a positive integer"),
        ({"tol": 0.0}, "tol must be positive"),
        ({"tol": -0.01}, "tol must be positive"),
        ({"tol": np.inf}, "tol must be finite"),
        ({"max_radius": 0.0}, "max_radius must be positive"),
        ({"max_radius": np.nan}, "max_radius must be finite"),
    ],
)
def test_uniformity_bad_parameters(pair, kwargs, match):
    with pytest.raises(ValueError, match=match):
        uniformity(pair, **kwargs)


def test_uniformity_smallest_sampling_still_brackets_the_crossing():
    # with 2 samples per ray (centre and max_radius) Brent's method still finds the crossing:
    # the 1% mid-plane extent of a filament Helmholtz pair, 0.378 R (the closed-form series)
    filament_pair = coils.HelmholtzPair(0.1, 100, 2.0, axis="y")
    coarse = uniformity(filament_pair, 0.01, samples=2, directions=4)
    assert coarse.radial == pytest.approx(0.0378, rel=2e-3)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n": 1}, "n must be an integer >= 2; got 1"),
        ({"n": 60.5}, "n must be an integer >= 2"),
        ({"tol": 0.0}, "tol must be positive"),
        ({"tol": -1.0}, "tol must be positive"),
        ({"show": "phase"}, "show must be 'deviation' or 'magnitude'"),
        ({"half_width": 0.0}, "half_width must be positive"),
    ],
)
def test_field_map_bad_parameters(pair, kwargs, match):
    with pytest.raises(ValueError, match=match):
        plot_field_map(pair, "xy", **kwargs)


def test_plane_grid_counts():
    with pytest.raises(ValueError, match="n must be an integer >= 2"):
        plane_grid("xy", (0, 0, 0), 1.0, n=1)
    pts, U, V, ij = plane_grid("xz", (0, 0, 0), 1.0, n=3)
    assert pts.shape == (9, 3)
    assert ij == (0, 2)
    np.testing.assert_array_equal(np.unique(U), [-1.0, 0.0, 1.0])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"packing": 0.0}, "packing must be positive"),
        ({"packing": 1.2}, r"packing is a fill factor and must be in \(0, 1\]"),
        ({"packing": np.nan}, "packing must be finite"),
        ({"temperature": -300.0}, r"temperature must be above absolute zero \(-273.15 degC\)"),
        ({"temperature": np.inf}, "temperature must be finite"),
        ({"resistivity": 0.0}, "resistivity must be positive"),
    ],
)
def test_winding_power_bad_parameters(kwargs, match):
    bare = coils.HelmholtzPair(0.1, 100, 1.0)  # no winding: packing is still checked
    for coil in (bare, coils.HelmholtzPair(0.1, 100, 1.0, winding=(0.02, 0.02))):
        with pytest.raises(ValueError, match=match):
            winding_power(coil, 1e-3, **kwargs)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"max_cells": 1.5}, "max_cells must be a positive integer; got 1.5"),
        ({"max_cells": True}, "max_cells must be a positive integer; got True"),
        ({"max_cells": "many"}, "max_cells must be a positive integer"),
        ({"max_cells": np.inf}, "max_cells must be a positive integer"),
        ({"shape": "abc"}, r"shape must be a scalar or have shape \(3,\)"),
        ({"shape": (3, np.nan, 3)}, "shape must be integers"),
        ({"spacing": "abc"}, r"spacing must be a scalar or have shape \(3,\)"),
    ],
)
def test_grid_bad_parameters(pair, kwargs, match):
    with pytest.raises(ValueError, match=match):
        GriddedField(pair, (-0.01,) * 3, (0.01,) * 3, **kwargs)


def test_grid_error_estimate_seed(pair):
    grid = GriddedField(pair, (-0.01,) * 3, (0.01,) * 3, shape=3)
    with pytest.raises(ValueError, match="seed must be an integer >= 0; got 0.5"):
        grid.error_estimate(seed=0.5)
    with pytest.raises(ValueError, match="seed must be an integer >= 0; got -1"):
        grid.error_estimate(seed=-1)


@pytest.mark.parametrize(
    ("value", "minimum", "expected"),
    [(3, 1, 3), (4.0, 2, 4), (np.int64(7), 2, 7), (np.array(5), 1, 5), (0, 0, 0)],
)
def test_as_count_accepts_integral_values(value, minimum, expected):
    count = as_count(value, "k", minimum)
    assert count == expected
    assert type(count) is int
