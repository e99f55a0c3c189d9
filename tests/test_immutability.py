"""Field sources and obstacles are immutable, grouped by property:

* **assignment refused**: setting or deleting any attribute of every source kind and obstacle
  raises AttributeError saying how to change it, and the object's numbers do not change;
* **read-only arrays**: every array attribute refuses in-place writes, and no source keeps a
  view of the caller's array;
* **copies equal new objects**: ``with_current``, ``with_currents`` and ``replace`` give an
  object whose B and gradient (gap for obstacles) equal those of an independent construction
  with the same parameters, a Helmholtz pair's ``ideal()`` the closed-form centre field
  (4/5)^{3/2} mu0 N I / R, exact plane and tube distances for obstacles; the original is
  unchanged;
* **pickling** keeps the numbers and the immutability (Dask sweeps pickle sources);
* **opt-in**: a user's own ``Field`` subclass may keep mutable state.
"""

from __future__ import annotations

import copy
import math
import pickle

import numpy as np
import pytest
from scipy.constants import mu_0

import coils
from coilrod.contact import Vessel, VesselNetwork, Wall, presets

RNG = np.random.default_rng(18)
#: Points (m) well inside every coil below (radii >= 60 mm), off every symmetry plane.
POINTS = RNG.uniform(-0.02, 0.02, (7, 3))


def _sources():
    """One of every source kind of coils (name, object)."""
    pair = coils.HelmholtzPair(0.08, 200, 6.7, axis="y", wire_diameter=1e-3)
    return {
        "UniformField": coils.UniformField((0.0, 5e-3, 1e-3)),
        "LinearField": coils.LinearField(
            (0.0, 1e-3, 0.0), coils.maxwell_gradient(0.1), (0, 0.01, 0)
        ),
        "CoaxialCoils": coils.CoaxialCoils([[-0.01, 0.07, 50.0], [0.01, 0.07, 50.0]], axis="x"),
        "Coil": coils.Coil(0.06, 100, 2.0, axis=(0.3, -0.4, 0.9), center=(0.0, 0.0, -0.1)),
        "HelmholtzPair": pair,
        "MaxwellPair": coils.MaxwellPair(0.1, 300, 1.5, axis="z", winding=(0.01, 0.01)),
        "CoilSystem": coils.presets.three_axis_helmholtz().with_currents([1.0, -2.0, 3.0]),
        "FieldSum": pair + coils.UniformField((1e-3, 0.0, 0.0)),
        "ScaledField": 2.5 * pair,
        "GriddedField": coils.GriddedField(pair, (-0.02,) * 3, (0.02,) * 3, shape=3),
    }


def _obstacles():
    """One of every obstacle kind of coilrod.contact (name, object)."""
    return {
        "Wall": Wall(point=(0.0, -0.01, 0.0), normal=(0.0, 2.0, 0.0)),
        "Vessel": Vessel([[0, 0, 0], [0.02, 0.005, 0], [0.04, 0, 0.002]], 1.5e-3),
        "Vessel.bend": presets.bend(0.02, 1.2, 1e-3, straight_before=0.01),
        "VesselNetwork": presets.branch(0.04, 1e-3, 0.02),
    }


SOURCES = _sources()
OBSTACLES = _obstacles()
ALL = {**SOURCES, **OBSTACLES}


def _numbers(obj):
    """What the object computes at the test points (B and gradient, or the gap and its
    gradient)."""
    if isinstance(obj, coils.Field):
        return obj.B_and_gradient(POINTS)
    ev = obj.evaluate(POINTS, 1)
    return ev.gap, ev.gradient


def _attributes(obj) -> list[str]:
    """Every attribute name: public ones (data, properties, methods) and private ones."""
    return sorted(set(dir(obj)) - set(dir(object)) - {"__weakref__"})


# -- assignment refused ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", ALL)
def test_every_attribute_refuses_assignment_and_deletion(name):
    obj = ALL[name]
    before = _numbers(obj)
    names = _attributes(obj)
    assert len([n for n in names if not n.startswith("_")]) >= 5
    for attr in names:
        with pytest.raises(AttributeError, match=f"{type(obj).__name__} is immutable"):
            setattr(obj, attr, 1.0)
        with pytest.raises(AttributeError, match="is immutable"):
            delattr(obj, attr)
    with pytest.raises(AttributeError, match="is immutable"):
        obj.brand_new = 1.0
    for a, b in zip(_numbers(obj), before, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    ("name", "attr", "value", "hint"),
    [
        ("HelmholtzPair", "current", 3.35, r".with_current(3.35) or .replace(current=3.35)"),
        ("Coil", "current", -1.0, r".with_current(-1.0) or .replace(current=-1.0)"),
        ("HelmholtzPair", "radius", 0.1, r".replace(radius=0.1)"),
        ("HelmholtzPair", "center", (0.0, 0.01, 0.0), r".replace(center=(0.0, 0.01, 0.0))"),
        ("CoilSystem", "currents", [1.0, 0.0, 0.0], r".with_currents([1.0, 0.0, 0.0])"),
        ("CoilSystem", "max_current", 5.0, r".with_limits(5.0)"),
        ("UniformField", "B0", (0.0, 0.0, 1.0), "(its parameters: B)"),
        ("Wall", "point", (0.0, 0.0, 0.0), r".replace(point=(0.0, 0.0, 0.0))"),
        ("Vessel.bend", "radius", 2e-3, r".replace(radius=0.002)"),
    ],
)
def test_the_message_says_how_to_change_it(name, attr, value, hint):
    with pytest.raises(AttributeError) as info:
        setattr(ALL[name], attr, value)
    assert hint in str(info.value)


def test_the_reported_desync_is_gone():
    # issue 18 item 4: the assignment used to change repr and .current but not B or ideal()
    pair = coils.HelmholtzPair(radius=0.08, turns=200, current=6.7, axis="y")
    with pytest.raises(AttributeError, match=r"use .with_current\(3.35\)"):
        pair.current = 3.35
    assert pair.current == 6.7
    assert "current=6.7" in repr(pair)


# -- read-only arrays -------------------------------------------------------------------------
EXPECTED_ARRAYS = {
    "UniformField": {"B0", "G", "origin"},
    "LinearField": {"B0", "G", "origin"},
    "CoaxialCoils": {"filaments", "axis", "center", "rotation", "windings"},
    "Coil": {"filaments", "axis", "center", "rotation", "windings"},
    "HelmholtzPair": {"filaments", "axis", "center", "rotation", "windings"},
    "MaxwellPair": {"filaments", "axis", "center", "rotation", "windings"},
    "CoilSystem": {"center"},
    "FieldSum": set(),
    "ScaledField": set(),
    "GriddedField": {"lower", "upper", "shape", "cells", "spacing"},
    "Wall": {"point", "normal"},
    "Vessel": {"points"},
    "Vessel.bend": {"points"},
    "VesselNetwork": set(),
}


@pytest.mark.parametrize("name", ALL)
def test_array_attributes_are_read_only(name):
    obj = ALL[name]
    before = _numbers(obj)
    arrays = {k: v for k, v in vars(obj).items() if isinstance(v, np.ndarray)}
    public = {k for k in arrays if not k.startswith("_")}
    assert public == EXPECTED_ARRAYS[name]
    for arr in arrays.values():  # private ones too: the evaluation reads them
        with pytest.raises(ValueError, match="read-only"):
            arr[...] = 0.0
    for a, b in zip(_numbers(obj), before, strict=True):
        np.testing.assert_array_equal(a, b)


def test_tuples_replace_lists():
    assert isinstance(SOURCES["FieldSum"].parts, tuple)
    assert isinstance(SOURCES["CoilSystem"].parts, tuple)
    assert isinstance(OBSTACLES["VesselNetwork"].vessels, tuple)


@pytest.mark.parametrize(
    ("build", "arg"),
    [
        (lambda a: coils.UniformField(a), "B"),
        (lambda a: coils.LinearField(B0=(0, 1e-3, 0), origin=a), "origin"),
        (lambda a: coils.LinearField(B0=a), "B0"),
        (lambda a: coils.CoilSystem([coils.HelmholtzPair(0.1, 10, 1.0)], center=a), "center"),
        (lambda a: Wall(point=a, normal="y"), "point"),
    ],
)
def test_the_callers_array_is_copied(build, arg):
    """A source never keeps a view of the caller's array (writing to it later would change
    the source behind its back), and the caller's array stays writeable."""
    a = np.array([1e-3, 2e-3, 3e-3])
    obj = build(a)
    kept = {k: v.copy() for k, v in vars(obj).items() if isinstance(v, np.ndarray)}
    before = _numbers(obj)
    a[:] = 0.5  # the caller's array stays writeable
    for k, v in kept.items():
        np.testing.assert_array_equal(getattr(obj, k), v, err_msg=f"{arg} aliased")
    for x, y in zip(_numbers(obj), before, strict=True):
        np.testing.assert_array_equal(x, y)


def test_the_grid_box_is_copied():
    pair = coils.HelmholtzPair(0.1, 100, 1.0)
    lower, upper = np.full(3, -0.01), np.full(3, 0.01)
    grid = coils.GriddedField(pair, lower, upper, shape=3)
    lower[:] = -5.0
    upper[:] = 5.0  # would make the box check accept points far outside the grid
    with pytest.raises(ValueError, match="outside the grid box"):
        grid.B([0.02, 0.0, 0.0])


# -- copies equal new objects ---------------------------------------------------------------------
def _assert_same_field(a: coils.Field, b: coils.Field, rtol: float = 1e-15) -> None:
    (Ba, Ga), (Bb, Gb) = a.B_and_gradient(POINTS), b.B_and_gradient(POINTS)
    np.testing.assert_allclose(Ba, Bb, rtol=0, atol=rtol * np.abs(Bb).max())
    np.testing.assert_allclose(Ga, Gb, rtol=0, atol=rtol * np.abs(Gb).max())


PAIR_KINDS = [
    (coils.HelmholtzPair, {"axis": "y", "wire_diameter": 1e-3}),
    (coils.MaxwellPair, {"axis": "x", "winding": (0.01, 0.012)}),
    (coils.HelmholtzPair, {"axis": "z", "winding": (0.01, 0.01), "turn_layout": (4, 3)}),
    (coils.Coil, {"axis": (0.3, -0.4, 0.9), "center": (0.01, 0.0, -0.1)}),
]


@pytest.mark.parametrize(("kind", "extra"), PAIR_KINDS)
def test_with_current_and_replace_equal_a_new_coil(kind, extra):
    original = kind(0.08, 12, 6.7, **extra)
    B0, G0 = original.B_and_gradient(POINTS)  # builds its compiled data first
    fresh = kind(0.08, 12, 3.35, **extra)
    for copy_ in (original.with_current(3.35), original.replace(current=3.35)):
        assert copy_.current == 3.35
        assert type(copy_) is kind
        _assert_same_field(copy_, fresh)
        assert copy_.resistance == fresh.resistance
        np.testing.assert_array_equal(copy_.filaments, fresh.filaments)
    # the original is unchanged
    assert original.current == 6.7
    B1, G1 = original.B_and_gradient(POINTS)
    np.testing.assert_array_equal(B1, B0)
    np.testing.assert_array_equal(G1, G0)


@pytest.mark.parametrize(
    "changes",
    [
        {"radius": 0.1},
        {"turns": 24},
        {"center": (0.0, 0.005, -0.002)},
        {"axis": (1.0, 1.0, 0.0)},
        {"radius": 0.07, "current": -2.0, "spacing": 0.09},
    ],
)
def test_replace_geometry_equals_a_new_pair(changes):
    params = {"radius": 0.08, "turns": 12, "current": 6.7, "axis": "y", "wire_diameter": 1e-3}
    original = coils.HelmholtzPair(**params)
    original.B(POINTS)
    changed = original.replace(**changes)
    _assert_same_field(changed, coils.HelmholtzPair(**{**params, **changes}))
    _assert_same_field(original, coils.HelmholtzPair(**params), rtol=0.0)


@pytest.mark.parametrize("make", ["with_current", "replace"])
def test_helmholtz_ideal_is_the_closed_form(make):
    R, N = 0.08, 200
    pair = coils.HelmholtzPair(radius=R, turns=N, current=6.7, axis="y")
    pair.ideal()
    half = pair.with_current(3.35) if make == "with_current" else pair.replace(current=3.35)
    ideal = half.ideal()
    closed = (4 / 5) ** 1.5 * mu_0 * N * 3.35 / R  # T
    assert ideal.uniform
    np.testing.assert_allclose(ideal.B0, [0.0, closed, 0.0], rtol=0, atol=1e-14 * closed)
    # and the original keeps its own
    np.testing.assert_allclose(pair.ideal().B0, [0.0, 2 * closed, 0.0], rtol=0, atol=2e-14 * closed)


def test_system_copies_equal_new_systems():
    system = coils.presets.helmholtz_maxwell()
    I = np.array([1.0, -2.0, 3.0, 4.0])  # noqa: E741
    system.unit_fields(POINTS)  # builds the unit channels (a cache) first
    driven = system.with_currents(I)
    fresh = coils.CoilSystem(
        [ch.replace(current=i) for ch, i in zip(system.channels, I, strict=True)],
        center=system.center,
    )
    _assert_same_field(driven, fresh)
    Bu, Gu = driven.unit_fields(POINTS)  # the cache of the copy is its own, and consistent
    np.testing.assert_allclose(Bu @ I, fresh.B(POINTS), rtol=0, atol=1e-14 * 0.02)
    # replace(max_current=...) keeps the parts and checks the present currents
    np.testing.assert_array_equal(driven.replace(max_current=10.0).max_current, np.full(4, 10.0))
    with pytest.raises(ValueError, match="above its max_current"):
        driven.replace(max_current=3.5)
    np.testing.assert_array_equal(system.currents, np.zeros(4))  # the original is unchanged


def test_ideal_and_sum_copies_equal_new_ones():
    lin = SOURCES["LinearField"]
    moved = lin.replace(origin=(0.0, 0.0, 0.0), B0=(1e-3, 0.0, 0.0))
    ref = coils.LinearField((1e-3, 0.0, 0.0), coils.maxwell_gradient(0.1), (0.0, 0.0, 0.0))
    _assert_same_field(moved, ref, rtol=0.0)
    uni = SOURCES["UniformField"].replace(B=(0.0, 0.0, 2e-3))
    assert uni.uniform
    np.testing.assert_array_equal(uni.B(POINTS), np.tile([0.0, 0.0, 2e-3], (len(POINTS), 1)))
    scaled = SOURCES["ScaledField"].replace(factor=-1.0)
    pair = SOURCES["HelmholtzPair"]
    np.testing.assert_array_equal(scaled.B(POINTS), -pair.B(POINTS))
    summed = SOURCES["FieldSum"].replace(parts=[pair])
    np.testing.assert_array_equal(summed.B(POINTS), pair.B(POINTS))


def test_grid_replace_rebuilds_the_grid():
    grid = SOURCES["GriddedField"]
    half = grid.replace(field=SOURCES["HelmholtzPair"].with_current(3.35))
    ref = coils.GriddedField(
        coils.HelmholtzPair(0.08, 200, 3.35, axis="y", wire_diameter=1e-3),
        (-0.02,) * 3,
        (0.02,) * 3,
        shape=3,
    )
    _assert_same_field(half, ref)
    # linear in the current, to round-off (the coil pass's summation order may differ by an ulp)
    np.testing.assert_allclose(half.B(POINTS), 0.5 * grid.B(POINTS), rtol=1e-14, atol=0)


def test_wall_replace_is_the_exact_plane():
    wall = OBSTACLES["Wall"]
    moved = wall.replace(point=(0.0, 0.0, 0.003), normal=(0.0, -3.0, 4.0))
    n = np.array([0.0, -0.6, 0.8])
    np.testing.assert_allclose(moved.gap(POINTS), (POINTS - [0, 0, 0.003]) @ n, rtol=0, atol=1e-18)
    np.testing.assert_array_equal(wall.gap(POINTS), POINTS[:, 1] + 0.01)  # unchanged


def test_vessel_replace_is_the_exact_tube():
    tube = Vessel([[0.0, 0.0, 0.0], [0.04, 0.0, 0.0]], 1e-3)
    wider = tube.replace(radius=2e-3)
    p = np.column_stack([np.linspace(0.005, 0.035, 7), POINTS[:, 1:] * 0.1])
    np.testing.assert_allclose(wider.gap(p), 2e-3 - np.hypot(p[:, 1], p[:, 2]), atol=1e-18)
    np.testing.assert_allclose(tube.gap(p), 1e-3 - np.hypot(p[:, 1], p[:, 2]), atol=1e-18)


def test_preset_vessels_replace_through_their_preset():
    bend = OBSTACLES["Vessel.bend"]
    flatter = bend.replace(angle=0.6)
    assert isinstance(flatter, Vessel)
    assert flatter.length == pytest.approx(0.01 + 0.02 * 0.6, rel=1e-14)
    ref = presets.bend(0.02, 0.6, 1e-3, straight_before=0.01)
    np.testing.assert_array_equal(flatter.gap(POINTS), ref.gap(POINTS))
    net = OBSTACLES["VesselNetwork"].replace(branch_angle=math.pi / 3)
    assert isinstance(net, VesselNetwork)
    ref = presets.branch(0.04, 1e-3, 0.02, branch_angle=math.pi / 3)
    np.testing.assert_array_equal(net.gap(POINTS), ref.gap(POINTS))


@pytest.mark.parametrize("name", ALL)
def test_replace_refuses_unknown_names(name):
    with pytest.raises(ValueError, match=r"unknown parameter 'colour'; its parameters are"):
        ALL[name].replace(colour="red")


@pytest.mark.parametrize(
    ("obj", "changes", "match"),
    [
        (SOURCES["HelmholtzPair"], {"radius": -0.1}, "radius"),
        (SOURCES["Coil"], {"current": math.nan}, "current"),
        (SOURCES["CoilSystem"], {"names": ("a",)}, "names"),
        (OBSTACLES["Wall"], {"normal": (0, 0, 0)}, "normal"),
        (OBSTACLES["Vessel.bend"], {"radius": 0.05}, "radius"),
    ],
)
def test_replace_validates_like_a_constructor(obj, changes, match):
    with pytest.raises(ValueError, match=match):
        obj.replace(**changes)


def test_with_current_validates_the_current():
    with pytest.raises(ValueError, match="current must be a real number; got '3'"):
        SOURCES["HelmholtzPair"].with_current("3")


# -- pickling -----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ALL)
@pytest.mark.parametrize("how", ["pickle", "deepcopy", "copy"])
def test_copies_keep_the_numbers_and_the_immutability(name, how):
    obj = ALL[name]
    before = _numbers(obj)  # caches built before the copy
    clone = {
        "pickle": lambda o: pickle.loads(pickle.dumps(o)),
        "deepcopy": copy.deepcopy,
        "copy": copy.copy,
    }[how](obj)
    for a, b in zip(_numbers(clone), before, strict=True):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(AttributeError, match="is immutable"):
        clone.anything = 1
    for k, v in vars(clone).items():
        if isinstance(v, np.ndarray):
            assert not v.flags.writeable, k
    for k, v in (clone._params or {}).items():  # what replace() builds from
        if isinstance(v, np.ndarray):
            assert not v.flags.writeable, k
    if type(obj).__repr__ is not object.__repr__:
        assert repr(clone) == repr(obj)


def test_a_pickled_coil_still_makes_copies():
    pair = pickle.loads(pickle.dumps(SOURCES["HelmholtzPair"]))
    _assert_same_field(
        pair.with_current(1.0),
        coils.HelmholtzPair(0.08, 200, 1.0, axis="y", wire_diameter=1e-3),
    )
    system = pickle.loads(pickle.dumps(SOURCES["CoilSystem"]))
    Bu, _ = system.unit_fields(POINTS)
    np.testing.assert_allclose(Bu @ system.currents, system.B(POINTS), rtol=0, atol=1e-15 * 0.02)


# -- opt-in -------------------------------------------------------------------------------------
class Counting(coils.Field):
    """A user's field with mutable state (counts its evaluations)."""

    def __init__(self):
        self.calls = 0

    def _B(self, pts):
        self.calls += 1
        return np.zeros_like(pts)


def test_a_users_field_is_not_sealed_unless_it_opts_in():
    field = Counting()
    field.B(POINTS)
    assert field.calls == 1

    class Sealed(Counting):
        _immutable = True

    sealed = Sealed()
    with pytest.raises(AttributeError, match="Sealed is immutable"):
        sealed.B(POINTS)
    # the sums holding a user's field are sealed, the field itself is not
    total = Counting() + SOURCES["UniformField"]
    total.B(POINTS)
    assert total.parts[0].calls == 1


def test_a_subclass_with_extra_parameters_replaces_by_name():
    class Labelled(coils.HelmholtzPair):
        def __init__(self, radius, turns, current, *, label="", **options):
            super().__init__(radius, turns, current, **options)
            self.label = label

    pair = Labelled(0.08, 200, 6.7, label="main", axis="x")
    with pytest.raises(AttributeError, match="Labelled is immutable"):
        pair.label = "other"
    moved = pair.replace(center=(0.0, 0.0, 0.01), label="moved")
    assert moved.label == "moved"
    _assert_same_field(moved, coils.HelmholtzPair(0.08, 200, 6.7, axis="x", center=(0, 0, 0.01)))
    assert pair.with_current(1.0).replace(label="x").current == 1.0

    class Positional(coils.Coil):
        def __init__(self, *args):
            super().__init__(*args)

    coil = Positional(0.05, 10, 1.0)
    with pytest.raises(ValueError, match="records its parameters by name"):
        coil.replace(current=2.0)
    assert coil.with_current(2.0).current == 2.0
