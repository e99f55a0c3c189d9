"""Input validation (coils._validate): what each kind of argument accepts and refuses.

Every refusal is a ValueError whose message names the argument.  Checked here:

* leniencies found while hardening the scene parser, now refused by the library itself: axes
  with more than one sign ("--z"), numbers given as strings or bytes ("1"), booleans as numbers
  (``turns=True``), fractional turns in the turn-by-turn model;
* what stays accepted: numpy scalars, 0-d arrays, integral floats as counts, signed axes,
  fractional turns where only the ampere-turns N I matter (the field scales with N I);
* the same helpers at the public entry points of coils and of the robot description.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

import coils
from coilrod import Circle, Magnetization, Rectangle, Rod
from coils._validate import (
    as_array,
    as_axis,
    as_bool,
    as_choice,
    as_count,
    as_counts,
    as_points,
    as_triple,
    as_vector,
    finite_scalar,
    nonnegative,
    positive,
)
from coils.clearance import Box, winding_contacts
from coils.design import wire_length
from coils.ideal import linearize, maxwell_gradient
from coils.plot import plane_grid, plot_field_map

R = 0.1


# -- axes -----------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "axis",
    ["--z", "++x", "+-y", "-+y", "- -x", "z-", "-", "", "zz", "w", "x y", b"z", True, False],
)
def test_axis_strings_with_more_than_one_sign_or_not_an_axis_are_refused(axis):
    with pytest.raises(ValueError, match=r"^axis must be 'x', 'y' or 'z' with at most one sign"):
        as_axis(axis)
    with pytest.raises(ValueError, match="axis must be"):
        coils.Coil(R, 10, 1.0, axis=axis)


@pytest.mark.parametrize(
    ("axis", "expected"),
    [
        ("z", (0, 0, 1)),
        ("-z", (0, 0, -1)),
        ("+y", (0, 1, 0)),
        (" -X ", (-1, 0, 0)),
        ("- y", (0, -1, 0)),
        ((0, 0, -2.5), (0, 0, -1)),
        ((1e308, 1e308, 0.0), (2**-0.5, 2**-0.5, 0)),  # the norm would overflow
        ((0.0, 1e-320, 0.0), (0, 1, 0)),  # subnormal: the norm would underflow
    ],
)
def test_axis_accepted_forms(axis, expected):
    np.testing.assert_allclose(as_axis(axis), expected, rtol=0, atol=1e-15)


def test_signed_axis_reverses_the_field_of_a_coil():
    up = coils.Coil(R, 10, 1.0, axis="z")
    down = coils.Coil(R, 10, 1.0, axis="-z")
    p = [[0.01, 0.02, 0.03]]
    np.testing.assert_allclose(down.B(p), -up.B(p), rtol=1e-14, atol=0)


@pytest.mark.parametrize(
    ("axis", "match"),
    [
        ((0, 0, 0), r"axis must be a non-zero vector; got \[0.0, 0.0, 0.0\]"),
        ((0, np.nan, 1), "axis must be finite"),
        ((np.inf, 0, 0), "axis must be finite"),
        ((1, 0), r"axis must have shape \(3,\)"),
        ((True, False, False), "axis must be real numbers"),
        (("0", "0", "1"), "axis must be real numbers"),
    ],
)
def test_axis_vectors_refused(axis, match):
    with pytest.raises(ValueError, match=match):
        as_axis(axis)
    with pytest.raises(ValueError, match=match):
        coils.HelmholtzPair(R, 10, 1.0, axis=axis)


def test_uniformity_axis_is_validated_too():
    pair = coils.HelmholtzPair(R, 10, 1.0, axis="y")
    with pytest.raises(ValueError, match="axis must be"):
        coils.uniformity(pair, axis="--y")


# -- real numbers: strings, bytes and booleans are not numbers -----------------------------------
@pytest.mark.parametrize("value", ["1", "2.5", b"1", bytearray(b"1"), np.str_("1"), np.array("1")])
def test_finite_scalar_refuses_text(value):
    with pytest.raises(ValueError, match=r"^current must be a real number; got "):
        finite_scalar(value, "current")


@pytest.mark.parametrize("value", [True, False, np.True_, np.array(True)])
def test_finite_scalar_refuses_booleans(value):
    with pytest.raises(ValueError, match=r"^current must be a real number; got .*True|False"):
        finite_scalar(value, "current")


@pytest.mark.parametrize(
    ("value", "match"),
    [
        (1j, "must be a real number"),
        (np.complex128(1.0), "must be a real number"),
        (None, "must be a real number"),
        ([1.0], "must be a real number"),
        (np.array([1.0]), r"must be a scalar; got shape \(1,\)"),
        (np.nan, "must be finite; got nan"),
        (10**400, "must be finite"),
    ],
)
def test_finite_scalar_refuses_other_non_reals(value, match):
    with pytest.raises(ValueError, match="^x " + match):
        finite_scalar(value, "x")


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        (2, 2.0),
        (2.5, 2.5),
        (np.float32(2.5), 2.5),
        (np.int64(3), 3.0),
        (np.array(2.5), 2.5),
        (np.array(3, dtype=np.int8), 3.0),
        (Fraction(1, 4), 0.25),
    ],
)
def test_finite_scalar_accepts_numbers(value, expected):
    out = finite_scalar(value, "x")
    assert out == expected
    assert type(out) is float


def test_positive_and_nonnegative():
    assert positive(np.float64(2.0), "r") == 2.0
    assert nonnegative(0, "m") == 0.0
    with pytest.raises(ValueError, match="r must be positive; got 0.0"):
        positive(0, "r")
    with pytest.raises(ValueError, match=r"m must be >= 0; got -1.0"):
        nonnegative(-1, "m")
    with pytest.raises(ValueError, match="r must be a real number; got '2'"):
        positive("2", "r")


@pytest.mark.parametrize(
    "value",
    ["abc", "000", ("0", "0", "0"), (b"0", 0, 0), (True, 0, 0), (0, np.False_, 0), (0, None, 0)],
)
def test_as_vector_refuses_text_and_booleans(value):
    with pytest.raises(ValueError, match=r"^center must be real numbers with shape \(3,\); got "):
        as_vector(value, "center")
    with pytest.raises(ValueError, match="center must be real numbers"):
        coils.HelmholtzPair(R, 10, 1.0, center=value)


@pytest.mark.parametrize(
    ("value", "match"),
    [
        ((1j, 0, 0), "must be real numbers"),
        (np.array([1 + 0j, 0, 0]), "must be real numbers"),
        (np.array(["1", "0", "0"]), "must be real numbers"),
        (np.array([True, False, False]), "must be real numbers"),
        ([[0, 1], [2]], "must be real numbers"),
        ((0, 0), r"must have shape \(3,\); got \(2,\)"),
        ((0, 0, np.inf), r"must be finite; got \[0.0, 0.0, inf\]"),
        ((0, 0, 10**400), "must be finite"),
    ],
)
def test_as_vector_refuses_other_non_reals(value, match):
    with pytest.raises(ValueError, match="^v " + match):
        as_vector(value, "v")


def test_as_vector_accepts_numeric_sequences():
    np.testing.assert_array_equal(
        as_vector((0, np.float32(1.5), Fraction(1, 2)), "v"), [0, 1.5, 0.5]
    )
    np.testing.assert_array_equal(as_vector(np.arange(3), "v"), [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(
        as_vector(np.array([0, 10**30, 0], dtype=object), "v"), [0.0, 1e30, 0.0]
    )


@pytest.mark.parametrize(
    "points",
    ["abc", [["0", "0", "0"]], [[0.0, True, 0.0]], np.array([["0", "0", "0"]]), [[0, 0, 1j]]],
)
def test_points_as_text_or_booleans_are_refused(points):
    pair = coils.HelmholtzPair(R, 10, 1.0)
    with pytest.raises(ValueError, match=r"^points must be real numbers with shape \(n, 3\)"):
        pair.B(points)


def test_points_accepted_forms():
    pts = as_points([0, 0, 1])
    assert pts.shape == (1, 3)
    assert pts.dtype == np.float64
    arr = np.zeros((4, 3))
    assert as_points(arr) is arr  # the solvers' arrays pass without a copy
    assert as_points(np.zeros((4, 3), dtype=np.float32)).dtype == np.float64


def test_as_array_shapes_and_names():
    assert as_array([[1, 2, 3]], "filaments", ("f", 3)).shape == (1, 3)
    with pytest.raises(ValueError, match=r"filaments must have shape \(f, 3\); got \(2,\)"):
        as_array([1, 2], "filaments", ("f", 3))
    with pytest.raises(ValueError, match=r"gradient must be finite; row 1 is \[0.0, nan, 0.0\]"):
        as_array([[0, 0, 0], [0, np.nan, 0], [0, 0, 0]], "gradient", (3, 3))


# -- counts -------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("value", "match"),
    [
        (True, "got True"),
        (np.True_, "got np.True_"),
        ("3", "got '3'"),
        (2.5, "got 2.5"),
        (np.nan, "got nan"),
        (np.inf, "got inf"),
        (0, "got 0"),
        ([3], r"got \[3\]"),
    ],
)
def test_as_count_refusals(value, match):
    with pytest.raises(ValueError, match=f"^n must be a positive integer; {match}"):
        as_count(value, "n")


def test_as_count_range():
    assert as_count(np.array(2), "axis", 0, 2) == 2
    with pytest.raises(ValueError, match="axis must be an integer from 0 to 2; got 3"):
        as_count(3, "axis", 0, 2)


def test_as_counts():
    assert as_counts(np.array([3, 2]), "filaments", ("n_axial", "n_radial")) == (3, 2)
    with pytest.raises(ValueError, match=r"filaments must be \(n_axial, n_radial\), 2 positive"):
        as_counts(3, "filaments", ("n_axial", "n_radial"))
    with pytest.raises(ValueError, match=r"filaments must be \(n_axial, n_radial\)"):
        as_counts("33", "filaments", ("n_axial", "n_radial"))
    with pytest.raises(ValueError, match="filaments n_radial must be a positive integer; got 2.5"):
        as_counts((3, 2.5), "filaments", ("n_axial", "n_radial"))


def test_as_triple():
    np.testing.assert_array_equal(as_triple(4, "shape", integer=True), [4.0, 4.0, 4.0])
    with pytest.raises(ValueError, match=r"shape must be a scalar or have shape \(3,\); got '4'"):
        as_triple("4", "shape", integer=True)
    with pytest.raises(ValueError, match=r"spacing must be a scalar or have shape \(3,\)"):
        as_triple(True, "spacing")
    with pytest.raises(ValueError, match="spacing must be positive; got -1.0"):
        as_triple((1.0, -1.0, 1.0), "spacing")


# -- turns ---------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("turns", "match"),
    [
        (True, "turns must be a real number; got True"),
        (np.True_, "turns must be a real number; got np.True_"),
        ("200", "turns must be a real number; got '200'"),
        (0, "turns must be positive"),
        (-3, "turns must be positive"),
        (np.nan, "turns must be finite"),
    ],
)
def test_bad_turns(turns, match):
    for make in (coils.Coil, coils.HelmholtzPair, coils.MaxwellPair):
        with pytest.raises(ValueError, match=match):
            make(R, turns, 1.0)


def test_fractional_turns_in_the_filament_models_count_as_ampere_turns():
    # the filament and Gauss models depend on N I only: 200.5 turns at 2 A is 401 A-turns
    p = np.array([[0.01, 0.02, -0.03], [0.0, 0.0, 0.0]])
    for winding in (None, (0.01, 0.02)):
        half = coils.HelmholtzPair(R, 200.5, 2.0, winding=winding)
        whole = coils.HelmholtzPair(R, 401, 1.0, winding=winding)
        assert half.ampere_turns == whole.ampere_turns == 401.0
        np.testing.assert_allclose(half.B(p), whole.B(p), rtol=1e-14, atol=0)


def test_turn_by_turn_model_needs_a_whole_number_of_turns():
    with pytest.raises(
        ValueError, match=r"turns must be a whole number for turn_layout .*got 200.5"
    ):
        coils.Coil(R, 200.5, 1.0, winding=(0.01, 0.01), turn_layout=(10, 20))
    coil = coils.Coil(R, 200.0, 1.0, winding=(0.01, 0.01), turn_layout=(10, 20))
    assert coil.filaments.shape == (200, 3)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"filaments": (2, 2)}, r"filaments=\(2, 2\) model a finite winding .*give winding"),
        ({"turn_layout": (5, 2)}, "needs a winding"),
        (
            {"winding": (0.01, 0.01), "filaments": (2, 2), "turn_layout": (5, 2)},
            "not both",
        ),
        ({"winding": (0.01, 0.01), "filaments": (3,)}, r"filaments must be \(n_axial, n_radial\)"),
        ({"winding": (0.01, 0.01), "filaments": (2.5, 2)}, "filaments n_axial must be a positive"),
        ({"winding": (0.01, 0.01), "filaments": (2, True)}, "filaments n_radial must be a pos"),
        ({"winding": (0.01, 0.01), "turn_layout": (5, "2")}, "turn_layout layers must be a pos"),
        ({"winding": 0.01}, r"winding \(width, height\) must have shape \(2,\); got \(\)"),
        ({"winding": ("1 cm", "1 cm")}, r"winding \(width, height\) must be real numbers"),
        ({"winding": (0.01, 0.01, 0.01)}, r"winding \(width, height\) must have shape \(2,\)"),
    ],
)
def test_bad_winding_models(kwargs, match):
    with pytest.raises(ValueError, match=match):
        coils.Coil(R, 10, 1.0, **kwargs)


def test_winding_is_stored_validated():
    pair = coils.HelmholtzPair(R, 10, 1.0, winding=np.array([0.01, 0.02]))
    assert pair.winding == (0.01, 0.02)
    assert all(type(w) is float for w in pair.winding)


# -- public entry points -------------------------------------------------------------------------
def _pair():
    return coils.HelmholtzPair(R, 10, 1.0, axis="y")


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: coils.HelmholtzPair("0.1", 10, 1.0), "radius must be a real number; got '0.1'"),
        (lambda: coils.HelmholtzPair(R, 10, b"1"), "current must be a real number; got b'1'"),
        (lambda: coils.HelmholtzPair(R, 10, 1.0, spacing="0.1"), "spacing must be a real number"),
        (lambda: coils.UniformField(B="0.005"), "B must be real numbers"),
        (lambda: coils.LinearField(gradient=[["1"] * 3] * 3), "gradient must be real numbers"),
        (lambda: _pair() * "2", "factor must be a real number; got '2'"),
        (lambda: _pair() * True, "factor must be a real number; got True"),
        (lambda: coils.FieldSum(_pair()), "parts must be a sequence of coils Fields"),
        (lambda: maxwell_gradient("1"), "g must be a real number"),
        (lambda: maxwell_gradient(1.0, axis=3), "axis must be an integer from 0 to 2; got 3"),
        (lambda: maxwell_gradient(1.0, axis=True), "axis must be an integer from 0 to 2; got True"),
        (lambda: linearize(_pair(), (0, 0, 0), zero_tol=-1), "zero_tol must be >= 0"),
        (lambda: linearize("pair", (0, 0, 0)), "field must be a coils Field; got str"),
        (lambda: coils.deviation(_pair(), [[0, 0, 0]], quantity="b"), "quantity must be 'B'"),
        (lambda: coils.deviation(coils.FieldSum([_pair()]), [[0, 0, 0]]), "has no ideal()"),
        (lambda: coils.deviation(_pair(), [[0, 0, 0]], ideal=_pair()), "ideal must be a coils"),
        (lambda: coils.uniformity(_pair(), tol="0.01"), "tol must be a real number"),
        (lambda: coils.uniformity(_pair(), directions="8"), "directions must be a positive int"),
        (lambda: coils.uniformity(_pair(), center="000"), "center must be real numbers"),
        (lambda: plane_grid(["xy"], (0, 0, 0), 1.0), "plane must be one of 'xy'"),
        (lambda: plane_grid("xy", (0, 0, 0), "1"), "half_width must be a real number"),
        (lambda: plot_field_map(_pair(), streamlines="no"), "streamlines must be True or False"),
        (lambda: plot_field_map(_pair(), show=None), "show must be 'deviation' or 'magnitude'"),
        (
            lambda: coils.GriddedField(_pair(), (-0.01,) * 3, (0.01,) * 3, shape="4"),
            r"shape must be a scalar or have shape \(3,\); got '4'",
        ),
        (
            lambda: coils.GriddedField(_pair(), (-0.01,) * 3, (0.01,) * 3, spacing=True),
            r"spacing must be a scalar or have shape \(3,\); got True",
        ),
        (
            lambda: coils.GriddedField(_pair(), (-0.01,) * 3, (0.01,) * 3, outside=["raise"]),
            "outside must be 'raise' or 'direct'",
        ),
        (
            lambda: winding_contacts(_pair(), Box((0,) * 3, (0.01,) * 3), margin="0"),
            "margin must be a real number",
        ),
        (lambda: winding_contacts(_pair(), "box"), "shape must be a Box or a Segment; got str"),
        (lambda: Box(("0", 0, 0), (1, 1, 1)), "lower must be real numbers"),
        (lambda: wire_length("coil"), "coil must be a Coil, HelmholtzPair or MaxwellPair"),
        (
            lambda: coils.CoaxialCoils([[0.0, R, 1.0]], windings=[[0.0, R, 0.0, 0.01]]),
            "positive radius, width and height",
        ),
        (lambda: coils.CoaxialCoils(np.zeros((0, 3))), "f >= 1"),
    ],
)
def test_public_entry_points_name_the_bad_argument(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_choices_and_flags():
    assert as_choice("xy", "plane", ("xy", "xz")) == "xy"
    assert as_bool(np.True_, "streamlines") is True
    with pytest.raises(ValueError, match="streamlines must be True or False; got 0"):
        as_bool(0, "streamlines")
    with pytest.raises(ValueError, match="cross must be 'grid' or 'hessian'; got 'fd'"):
        as_choice("fd", "cross", ("grid", "hessian"))


def test_sum_still_starts_from_zero_but_not_from_false():
    a, b = _pair(), coils.UniformField((0, 1e-3, 0))
    total = sum([a, b])
    np.testing.assert_allclose(total.B([[0, 0, 0]]), a.B([[0, 0, 0]]) + b.B([[0, 0, 0]]))
    with pytest.raises(TypeError):
        False + a  # noqa: B018


# -- the robot description uses the same helpers -------------------------------------------------
@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: Circle("2e-3"), "diameter must be a real number; got '2e-3'"),
        (lambda: Circle(True), "diameter must be a real number; got True"),
        (lambda: Rectangle(1e-3, b"1"), "thickness must be a real number"),
        (lambda: Magnetization("128e3"), "magnitude must be a real number; got '128e3'"),
        (lambda: Magnetization(1e5, angle=True), "angle must be a real number; got True"),
        (lambda: Magnetization(1e5, breakpoints=0.02), r"breakpoints must have shape \(n,\)"),
        (lambda: Magnetization(1e5, breakpoints=["0.02"]), "breakpoints must be real numbers"),
        (lambda: Magnetization(1e5, breakpoints=[np.nan]), "breakpoints must be finite"),
        (lambda: Magnetization.segments(0.04, [1e5]), r"segment lengths must have shape \(n,\)"),
        (lambda: Magnetization.segments([], []), "at least one segment"),
        (lambda: Magnetization.segments([0.04], ["1e5"]), "segment magnitudes must be real"),
        (lambda: Magnetization.segments([0.04], [1e5], "0"), "segment angle must be a real"),
        (lambda: Magnetization.segments([0.04], [1e5], [True]), "segment angles must be real"),
        (lambda: Magnetization(1e5).magnitude("0.01"), "s must be real numbers"),
        (lambda: Magnetization(1e5).max_magnitude(0.04, samples=1), "samples must be an integer"),
        (lambda: Rod("0.04", 1e6, Circle(1e-3), Magnetization(1e5)), "length must be a real"),
        (lambda: Rod(0.04, True, Circle(1e-3), Magnetization(1e5)), "youngs_modulus must be a"),
    ],
)
def test_robot_description_refuses_text_and_booleans(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_robot_description_keeps_numpy_numbers():
    rod = Rod(np.float32(0.04), np.array(1e6), Circle(np.float64(2e-3)), Magnetization(np.int64(5)))
    assert rod.length == pytest.approx(0.04)
    assert rod.youngs_modulus == 1e6
    m = Magnetization.segments(np.array([0.02, 0.02]), np.array([1e5, 2e5]))
    mags = np.array([1e5, 2e5])
    m2 = Magnetization.segments([0.02, 0.02], mags)
    mags[0] = 0.0  # the profile keeps its own copy
    assert m.magnitude(np.array([0.01, 0.03])).tolist() == [1e5, 2e5]
    assert m2.magnitude(np.array([0.01])).tolist() == [1e5]


# -- awkward floats (h-brk3) ----------------------------------------------------------------------
def test_tiny_current_limits_give_the_largest_fraction_not_a_solver_error():
    # with 1e-12 A limits and a 1e-12 T target the limits' linear program ran in amperes and
    # tesla: HiGHS's absolute tolerances (~1e-7) called the target feasible, and the
    # least-distance step then raised RuntimeError; in units of the limits it is a ValueError
    # with the fraction the limits allow: B = (4/5)^1.5 mu0 N I / R at a Helmholtz pair's centre
    from scipy.constants import mu_0

    system = coils.presets.three_axis_helmholtz().with_limits(1e-12)
    pair = system.channels[0]  # along x
    per_ampere = 0.8**1.5 * mu_0 * pair.turns / pair.radius
    with pytest.raises(ValueError, match=rf"at most {100 * per_ampere:.4g} % .*limit 1e-12 A"):
        system.currents_for(B=(1e-12, 0.0, 0.0))
    I = system.currents_for(B=(1e-20, 0.0, 0.0))  # within the limits: 5.6e-18 A
    np.testing.assert_allclose(I, [1e-20 / per_ampere, 0.0, 0.0], rtol=1e-9, atol=1e-30)
    with pytest.raises(ValueError, match="exceeds the current limits") as err:
        system.with_limits(10.0).currents_for(B=(1e-3, 0.0, 0.0), at=(1e7, 0.0, 0.0))
    assert "-0 %" not in str(err.value)  # (10000 km away: none of it, printed as "-0 %")
