"""Scene validation: nothing is read loosely, every problem is reported at once, and a scene
that passes can be solved (the checks ``coilrod check`` shares with ``coilrod run``)."""

import math

import numpy as np
import pytest
from _scenes import scene_with

import coils
from coilrod.scene import SceneError, limits, parse_scene
from coilrod.scene.planner import plan_scene


def problems_of(data) -> list[str]:
    with pytest.raises(SceneError) as info:
        parse_scene(data)
    assert str(info.value) == "\n".join(info.value.problems)
    return info.value.problems


def coil_scene(*coil_tables, models=("rod",), **robot):
    data = scene_with(field={"type": "coils", "coil": list(coil_tables)})
    data["models"] = {"run": list(models)}
    data["robot"].update(robot)
    return data


HELMHOLTZ = {"type": "helmholtz", "radius": "80 mm", "turns": 200, "B": "15 mT", "axis": "y"}


# -- magnetization: one way to give it -------------------------------------------------------
@pytest.mark.parametrize(
    ("extra", "key"),
    [
        ({"magnitude": "64 kA/m"}, "robot.magnetization.magnitude"),
        ({"angle": "90 deg"}, "robot.magnetization.angle"),
        (
            {"segments": [{"length": "40 mm", "magnitude": "1 kA/m"}]},
            "robot.magnetization.segments",
        ),
    ],
)
def test_preset_with_explicit_magnetization_is_an_error(extra, key):
    # formerly the preset won silently
    lines = problems_of(scene_with(robot__magnetization={"preset": "M1", **extra}))
    assert len(lines) == 1
    assert lines[0].startswith(f"{key}: not used with a preset")


def test_preset_parameters_belong_to_their_preset():
    lines = problems_of(scene_with(robot__magnetization={"preset": "M1", "slope": 0.3}))
    assert lines == [
        "robot.magnetization.slope: not a parameter of preset M1 (its parameters: M0, phi)"
    ]
    lines = problems_of(scene_with(robot__magnetization={"magnitude": "64 kA/m", "phi": 0.3}))
    assert lines[0].startswith("robot.magnetization.phi: only used with a preset")
    lines = problems_of(
        scene_with(
            robot__magnetization={
                "segments": [{"length": "40 mm", "magnitude": "64 kA/m"}],
                "angle": "10 deg",
            }
        )
    )
    assert lines[0].startswith("robot.magnetization.angle: not used with segments")


def test_each_preset_parameter_changes_the_magnetization():
    # the parameters that are accepted are also used (none is read and dropped)
    s = np.linspace(0, 0.04, 9)

    def profile(mag):
        m = parse_scene(scene_with(robot__magnetization=mag)).rod.magnetization
        return np.concatenate([m.magnitude(s), m.angle(s)])

    for preset, params in {
        "M1": {"M0": "100 kA/m", "phi": 0.5},
        "M2a": {"M0": "100 kA/m", "phi": 0.5},
        "M3": {"M0": "100 kA/m", "slope": 0.5},
        "M4.1": {"M0": "100 kA/m"},
        "M4.2": {"M0": "100 kA/m", "segment": 0, "segment_angle": "30 deg"},
    }.items():
        plain = profile({"preset": preset})
        for name, value in params.items():
            changed = profile({"preset": preset, name: value})
            assert not np.allclose(changed, plain), (preset, name)


# -- booleans, integers, axes: no loose reading -------------------------------------------------
@pytest.mark.parametrize("value", ["no", "false", 0, 1, "yes"])
@pytest.mark.parametrize("key", ["figures", "tables"])
def test_output_booleans_must_be_toml_booleans(key, value):
    lines = problems_of(scene_with(**{f"output__{key}": value}))
    assert len(lines) == 1
    assert lines[0].startswith(f"output.{key}: expected true or false")


def test_false_is_honoured():
    scene = parse_scene(scene_with(output={"figures": False, "tables": False}))
    assert scene.outputs == {"figures": False, "tables": False, "vtk": False}


@pytest.mark.parametrize(
    ("entry", "value", "message"),
    [
        ("turns", True, "field.coil[0].turns: expected an integer; got true"),
        ("turns", 12.5, "field.coil[0].turns: expected an integer; got 12.5"),
        ("current", "2", "field.coil[0].current: missing unit in '2'"),
        ("axis", "--z", "field.coil[0].axis: expected 'x', 'y', 'z'"),
        ("axis", "+-y", "field.coil[0].axis: expected 'x', 'y', 'z'"),
        ("axis", "xy", "field.coil[0].axis: expected 'x', 'y', 'z'"),
        ("axis", [1, "0", 0], "field.coil[0].axis: expected 'x', 'y', 'z'"),
        ("axis", [True, 0, 0], "field.coil[0].axis: expected 'x', 'y', 'z'"),
        ("axis", [0, 0, 0], "field.coil[0].axis: a direction cannot be the zero vector"),
    ],
)
def test_coil_values_name_their_key(entry, value, message):
    coil = {"type": "helmholtz", "radius": "80 mm", "turns": 200, "current": "2 A"}
    coil[entry] = value
    lines = problems_of(coil_scene(coil))
    assert len(lines) == 1
    assert lines[0].startswith(message)


@pytest.mark.parametrize(("value", "expected"), [("-x", (-1, 0, 0)), ("+Y", (0, 1, 0))])
def test_signed_axes_read_as_written(value, expected):
    scene = parse_scene(scene_with(field__direction=value))
    np.testing.assert_allclose(scene.fields["ideal"].B0, 5e-3 * np.array(expected))


def test_target_field_or_gradient_must_exist_at_the_centre():
    lines = problems_of(coil_scene({**HELMHOLTZ, "type": "maxwell"}))
    assert lines == [
        "field.coil[0].B: a Maxwell pair has no field at its centre; give its gradient"
    ]
    coil = {k: v for k, v in HELMHOLTZ.items() if k != "B"}
    lines = problems_of(coil_scene({**coil, "gradient": "0.1 T/m"}))
    assert lines[0].startswith("field.coil[0].gradient: a Helmholtz pair has no gradient")


# -- segments span the robot, exactly -----------------------------------------------------------
def segments(*lengths):
    return {"segments": [{"length": x, "magnitude": "64 kA/m"} for x in lengths]}


def test_segments_must_add_up_exactly():
    lines = problems_of(scene_with(robot__magnetization=segments("10 mm", "30.0000001 mm")))
    assert lines == [
        "robot.magnetization.segments: lengths add up to 40.0000001 mm; the robot is 40 mm long "
        "(robot.length)"
    ]
    lines = problems_of(scene_with(robot__magnetization=segments("10 mm", "29.9999999 mm")))
    assert lines[0].startswith("robot.magnetization.segments: lengths add up to 39.9999999 mm")


def test_segments_that_add_up_to_rounding_are_accepted_and_span_the_robot():
    third = "13.333333333333333 mm"
    scene = parse_scene(
        scene_with(robot__magnetization=segments(third, third, "13.333333333333334 mm"))
    )
    edges = scene.rod.magnetization.segment_edges
    assert edges[-1] == pytest.approx(0.04, rel=1e-15)
    scene = parse_scene(scene_with(robot__magnetization=segments("1 cm", "30 mm")))
    assert scene.rod.magnetization.segment_edges[-1] == pytest.approx(0.04, rel=1e-15)


def test_segments_are_checked_against_a_valid_length_only():
    # with the length itself wrong there is one problem, not a second one about the segments
    data = scene_with(robot__magnetization=segments("10 mm", "30 mm"), robot__length="-40 mm")
    assert problems_of(data) == ["robot.length: must be positive; got -40 mm"]


# -- limits -------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"load__steps": 1e20}, "load.steps: must be from 1 to 1000"),
        ({"load__steps": 1001}, "load.steps: must be from 1 to 1000"),
        ({"load": {"scales": [0.5] * 1001}}, "load.scales: at most 1000 load steps"),
        ({"load": {"scales": [0.5, 1e6]}}, "load.scales[1]: must be from -1000 to 1000"),
        ({"load__max_scale": 1e9}, "load.max_scale: must be from 0 to 1000"),
        ({"robot__length": "1e300 m"}, "robot.length: must be between 1 um and 10 m"),
        ({"robot__length": "0.1 um"}, "robot.length: must be between 1 um and 10 m"),
        ({"robot__youngs_modulus": "1e20 Pa"}, "robot.youngs_modulus: must be between 1 Pa"),
        ({"robot__diameter": "40 mm"}, "robot.diameter: must be smaller than robot.length"),
        ({"field__B": "1e9 T"}, "field.B: must be at most 100 T in size"),
        ({"rod": {"nodes": 10**9}}, "rod.nodes: must be from 4 to 4096"),
        ({"rod": {"nodes": 3}}, "rod.nodes: must be from 4 to 4096"),
        (
            {"robot__magnetization": {"magnitude": "1e12 A/m"}},
            "robot.magnetization.magnitude: must be at most 10 MA/m in size",
        ),
        (
            {"robot__magnetization": {"magnitude": "64 kA/m", "angle": "1e30 deg"}},
            "robot.magnetization.angle: must be between -360 deg and 360 deg",
        ),
        (
            {"models": {"run": ["fem2d"]}, "fem": {"elements2d": [10**6, 2]}},
            "fem.elements2d[0]: must be at most 20000",
        ),
        (
            {"models": {"run": ["fem2d"]}, "fem": {"elements2d": [10000, 10]}},
            "fem.elements2d: [10000, 10] makes 100000 elements; at most 20000 in 2D",
        ),
        (
            {"models": {"run": ["fem3d"]}, "fem": {"elements3d": [100, 10, 10]}},
            "fem.elements3d: [100, 10, 10] makes 50000 elements; at most 2000 in 3D",
        ),
        (
            {"models": {"run": ["fem3d"]}, "load": {"steps": 500}},
            "fem.elements3d: the default [20, 2, 1] of fem3d makes 240 elements, times 500 load",
        ),
        ({"field__B": "90 T"}, "field.B: at the top load the magneto-elastic number lambda"),
    ],
)
def test_absurd_sizes_name_the_key_and_the_range(change, message):
    lines = problems_of(scene_with(**change))
    assert len(lines) == 1
    assert lines[0].startswith(message), lines[0]


def test_limits_are_what_the_messages_say():
    # the messages quote the limits module; the numbers there are the documented ones
    assert limits.MAX_STEPS == 1000
    assert (limits.MIN_NODES, limits.MAX_NODES) == (4, 4096)
    assert limits.MAX_FEM_ELEMENTS == {2: 20_000, 3: 2_000}
    assert limits.RANGES["robot length"].low == 1e-6
    assert limits.RANGES["robot length"].high == 10.0
    # at the limit itself a scene is accepted
    scene = parse_scene(scene_with(load__steps=limits.MAX_STEPS, rod={"nodes": limits.MAX_NODES}))
    assert len(scene.scales) == limits.MAX_STEPS


def test_coil_current_from_a_target_stays_in_range():
    coil = {"type": "helmholtz", "radius": "80 m", "turns": 1, "B": "50 T"}
    lines = problems_of(coil_scene(coil))
    assert lines[0].startswith("field.coil[0].B: needs 4.45e+09 A per turn in this coil")


# -- every mistake at once ----------------------------------------------------------------------
def test_all_mistakes_are_reported_one_line_each_in_scene_order():
    data = {
        "name": 5,
        "robot": {
            "length": "-40 mm",
            "diameter": "2",
            "youngs_modulus": "1 MPa",
            "magnetization": {"preset": "M1", "slope": 0.3},
            "colour": "red",
        },
        "field": {"type": "uniform", "B": "5 mT", "direction": "--z"},
        "load": {"steps": 0},
        "models": {"run": ["rod", "fem4d"]},
        "output": {"figures": "no"},
    }
    lines = problems_of(data)
    keys = [line.split(":")[0] for line in lines]
    assert keys == [
        "name",
        "robot.colour",
        "robot.length",
        "robot.diameter",
        "robot.magnetization.slope",
        "field.direction",
        "load.steps",
        "models.run[1]",
        "output.figures",
    ]
    # the single-mistake messages are unchanged by being collected
    assert "robot.length: must be positive; got -40 mm" in lines
    assert "load.steps: must be positive; got 0" in lines
    assert any(line.startswith("robot.diameter: missing unit in '2'") for line in lines)
    assert all("\n" not in line for line in lines)


def test_problems_in_several_coils_name_each_coil():
    bad0 = {**HELMHOLTZ, "radius": "-1 mm"}
    bad2 = {**HELMHOLTZ, "turns": 0}
    lines = problems_of(coil_scene(bad0, HELMHOLTZ, bad2))
    assert [line.split(":")[0] for line in lines] == [
        "field.coil[0].radius",
        "field.coil[2].turns",
    ]


def test_scene_error_is_a_value_error_and_pickles():
    import pickle

    err = SceneError(["a: one", "b: two\nsplit"])
    assert isinstance(err, ValueError)
    assert err.problems == ["a: one", "b: two split"]
    again = pickle.loads(pickle.dumps(err))
    assert again.problems == err.problems


# -- the scene can be solved: what check shares with run ----------------------------------------
def test_clamp_on_a_winding_names_the_coil_and_the_field_agrees():
    # a single coil whose finite winding (10 mm x 10 mm at radius 20 mm) holds the origin
    coil = {
        "type": "coil",
        "radius": "20 mm",
        "turns": 100,
        "current": "1 A",
        "axis": "z",
        "winding": ["10 mm", "10 mm"],
        "center": ["-20 mm", "0 mm", "0 mm"],
    }
    lines = problems_of(coil_scene(HELMHOLTZ, coil))
    assert len(lines) == 1
    assert lines[0].startswith("field.coil[1]: the clamp (the robot's base, at the origin)")
    # independent confirmation: the coil library refuses to evaluate the field at the clamp
    real = coils.Coil(0.02, 100, 1.0, axis="z", center=(-0.02, 0, 0), winding=(0.01, 0.01))
    with pytest.raises(ValueError, match="lies (on|inside) a coil winding"):
        real.B([[0.0, 0.0, 0.0]])


def test_robot_through_a_winding_names_the_coil_and_where():
    # a coil of radius 15 mm centred at x = 35 mm, its axis along z: the filament crosses the
    # robot's centreline at s = 20 mm (and again beyond the tip)
    coil = {
        "type": "coil",
        "radius": "15 mm",
        "turns": 10,
        "current": "1 A",
        "axis": "z",
        "center": ["35 mm", "0 mm", "0 mm"],
    }
    lines = problems_of(coil_scene(HELMHOLTZ, coil))
    assert len(lines) == 1
    assert lines[0].startswith("field.coil[1]: the undeformed robot, at s = 20 mm from the clamp")
    # moved 2 mm off the robot's axis (the body reaches 1 mm from it), the coil is fine
    coil["center"] = ["35 mm", "0 mm", "2 mm"]
    parse_scene(coil_scene(HELMHOLTZ, coil))


def test_robot_just_touching_a_winding_is_caught_between_samples():
    # the winding section comes to 2 nm inside the body (which reaches 1 mm from the
    # centreline) between two samples of the centreline, where sampling alone would see it
    # 0.5 nm clear: the closest approach is refined
    coil = {
        "type": "coil",
        "radius": "10 mm",
        "turns": 10,
        "current": "1 A",
        "axis": "y",
        "winding": ["2 mm", "2 mm"],
        "center": ["20.0123 mm", "0 mm", "11.999998 mm"],
    }
    lines = problems_of(coil_scene(HELMHOLTZ, coil))
    assert lines[0].startswith("field.coil[1]: the undeformed robot, at s = 20.01 mm")
    coil["center"] = ["20.0123 mm", "0 mm", "12.000002 mm"]  # 2 nm clear
    parse_scene(coil_scene(HELMHOLTZ, coil))


@pytest.mark.parametrize(
    ("field", "key"),
    [
        ({"type": "uniform", "B": "0 mT"}, "field.B: the field is zero"),
        ({"type": "gradient", "gradient": "0 T/m"}, "field.gradient: the gradient is zero"),
        (
            {"type": "coils", "coil": [{**HELMHOLTZ, "B": "0 mT"}]},
            "field.coil[0].B: the coil carries no current",
        ),
        (
            {
                "type": "coils",
                "coil": [
                    {"type": "helmholtz", "radius": "80 mm", "turns": 9, "current": "0 A"},
                    {"type": "maxwell", "radius": "80 mm", "turns": 9, "current": "0 A"},
                ],
            },
            "field.coil: every coil carries no current",
        ),
    ],
)
def test_zero_field_is_nothing_to_solve(field, key):
    lines = problems_of(scene_with(field=field))
    assert len(lines) == 1
    assert lines[0].startswith(key)


def test_zero_magnetization_is_nothing_to_solve():
    lines = problems_of(scene_with(robot__magnetization={"magnitude": "0 A/m"}))
    assert lines[0].startswith("robot.magnetization.magnitude: is zero")
    lines = problems_of(
        scene_with(robot__magnetization={"segments": [{"length": "40 mm", "magnitude": "0 A/m"}]})
    )
    assert lines[0].startswith("robot.magnetization.segments: every segment has zero magnitude")
    lines = problems_of(scene_with(load={"scales": [0, 0.0]}))
    assert lines[0].startswith("load.scales: every scale is 0")


def test_field_out_of_the_bending_plane_is_an_error_for_planar_models():
    planar = {"model": "planar"}
    lines = problems_of(scene_with(field__direction="z", rod=planar))
    assert lines[0].startswith("field.direction: the field has no component in the bending")
    lines = problems_of(scene_with(field__direction="z", models={"run": ["fem2d"]}))
    assert lines[0].startswith("field.direction: the field has no component in the bending")
    scene = parse_scene(scene_with(field__direction="z", models={"run": ["fem3d"]}))
    assert scene.models == ("fem3d",)
    # the rod's default model takes the spatial rod for it
    assert parse_scene(scene_with(field__direction="z")).models == ("rod",)
    # a coil with its axis along z: in its own plane its field is along z only
    coil = {"type": "coil", "radius": "60 mm", "turns": 100, "current": "5 A", "axis": "z"}
    coil["center"] = ["20 mm", "0 mm", "0 mm"]
    lines = problems_of({**coil_scene(coil), "rod": planar})
    assert lines[0].startswith("field.coil[0].current: the field has no component in the bending")
    # 10 mm out of its plane the real field has a radial part that bends the rod (its ideal
    # field, taken at the centre, is still along z): the comparison is meaningful, so accepted
    coil["center"] = ["20 mm", "0 mm", "10 mm"]
    scene = parse_scene(coil_scene(coil))
    B = scene.fields["coils"].B([[0.035, 0.0, 0.0]])[0]
    assert abs(B[0]) > 1e-3 * abs(B[2])
    np.testing.assert_allclose(scene.fields["ideal"].B0[:2], 0, atol=1e-15)


def test_fem_must_resolve_the_magnetization_segments():
    mag = segments("1.5 mm", "38.5 mm")
    lines = problems_of(scene_with(robot__magnetization=mag, models={"run": ["fem2d"]}))
    assert lines == [
        "fem.elements2d[0]: the default [20, 1] of fem2d: 20 elements along the robot are 2 mm "
        "long, longer than its shortest magnetization segment (1.5 mm), which the mesh cannot "
        "resolve; give fem.elements2d = [27, 1]"
    ]
    data = scene_with(
        robot__magnetization=mag, models={"run": ["fem2d"]}, fem={"elements2d": [26, 1]}
    )
    assert problems_of(data)[0].startswith("fem.elements2d[0]: [26, 1]: 26 elements")
    data["fem"]["elements2d"] = [27, 1]
    parse_scene(data)
    # the rod places nodes at the breakpoints itself: no such limit
    parse_scene(scene_with(robot__magnetization=mag))


def test_unused_options_are_noted_in_the_plan():
    scene = parse_scene(scene_with(rod={"nodes": 32}, fem={"elements3d": [10, 1, 1]}))
    text = "\n".join(plan_scene(scene).decisions)
    assert "fem.elements3d is set but fem3d is not run" in text
    scene = parse_scene(scene_with(rod={"nodes": 32}, models={"run": ["fem2d"]}))
    assert "rod.nodes is set but the rod model is not run" in "\n".join(plan_scene(scene).decisions)


def test_gradient_scene_lambda_limit_uses_gamma():
    lines = problems_of(scene_with(field={"type": "gradient", "gradient": "9000 T/m"}))
    assert lines[0].startswith("field.gradient: at the top load the magneto-elastic number gamma")
    ok = parse_scene(scene_with(field={"type": "gradient", "gradient": "1 T/m"}))
    assert ok.field_kind == "gradient"
    assert math.isfinite(ok.scales[-1])


def test_coils_centre_on_a_winding_is_an_error_not_a_crash():
    # two coils whose mean centre (where the ideal field and the reference strength are taken)
    # lies on both of their filaments
    a = {"type": "coil", "radius": "20 mm", "turns": 10, "current": "1 A", "axis": "z"}
    left = {**a, "center": ["-20 mm", "0 mm", "5 mm"]}
    right = {**a, "center": ["20 mm", "0 mm", "5 mm"]}
    for compare in (True, False):
        data = coil_scene(left, right)
        data["field"]["compare_ideal"] = compare
        lines = problems_of(data)
        assert len(lines) == 1
        assert lines[0].startswith("field.coil: the coils' centre (0 mm, 0 mm, 5 mm), where their")


def test_huge_values_give_short_lines():
    lines = problems_of(scene_with(load__steps=10**400))
    assert lines == [
        "load.steps: must be from 1 to 1000 (load steps; more would take hours); got an integer "
        "of about 401 digits"
    ]
    lines = problems_of(scene_with(robot__length="1" * 100_000 + " mm"))
    assert len(lines) == 1
    assert lines[0].startswith("robot.length: ")
    assert len(lines[0]) <= 400
    lines = problems_of(scene_with(robot__length=10**400))
    assert lines == [
        "robot.length: missing unit in an integer of about 401 digits; write it as a string with "
        "a unit, e.g. '40 mm'"
    ]


# -- out-of-plane magnetization and the Poisson ratio ------------------------------------------
UNIFORM = {"magnitude": "128 kA/m", "angle": "10 deg"}


def test_elevation_is_read_with_its_unit():
    s = np.linspace(0.0, 0.04, 5)
    m = parse_scene(
        scene_with(robot__magnetization={**UNIFORM, "elevation": "30 deg"})
    ).rod.magnetization
    np.testing.assert_allclose(m.elevation(s), math.pi / 6, rtol=1e-15)
    np.testing.assert_allclose(m.angle(s), math.pi / 18, rtol=1e-15)
    assert not m.is_planar
    # absent, or written as a plain 0 like an angle: planar
    assert parse_scene(scene_with(robot__magnetization=UNIFORM)).rod.magnetization.is_planar
    m = parse_scene(scene_with(robot__magnetization={**UNIFORM, "elevation": 0})).rod.magnetization
    assert m.is_planar


def test_segment_elevations_are_read_per_segment():
    segs = [
        {"length": "10 mm", "magnitude": "64 kA/m", "angle": "0 deg", "elevation": "-45 deg"},
        {"length": "30 mm", "magnitude": "128 kA/m", "elevation": "0.5 rad"},
    ]
    m = parse_scene(scene_with(robot__magnetization={"segments": segs})).rod.magnetization
    np.testing.assert_allclose(m.segment_elevations, [-math.pi / 4, 0.5], rtol=1e-15)
    np.testing.assert_allclose(m.elevation(np.array([0.005, 0.03])), [-math.pi / 4, 0.5])


@pytest.mark.parametrize(
    ("magnetization", "message"),
    [
        ({**UNIFORM, "elevation": "30"}, "robot.magnetization.elevation: missing unit"),
        ({**UNIFORM, "elevation": "nan deg"}, "robot.magnetization.elevation: "),
        ({**UNIFORM, "elevation": "30 mm"}, "robot.magnetization.elevation: "),
        ({**UNIFORM, "elevation": True}, "robot.magnetization.elevation: "),
        ({**UNIFORM, "elevation": "720 deg"}, "robot.magnetization.elevation: "),
        (
            {"preset": "M1", "elevation": "10 deg"},
            "robot.magnetization.elevation: not used with a preset",
        ),
        (
            {"segments": [{"length": "40 mm", "magnitude": "1 kA/m"}], "elevation": "10 deg"},
            "robot.magnetization.elevation: not used with segments",
        ),
        (
            {"segments": [{"length": "40 mm", "magnitude": "1 kA/m", "elevation": "x"}]},
            "robot.magnetization.segments[0].elevation: ",
        ),
    ],
)
def test_bad_elevation_names_its_key(magnetization, message):
    lines = problems_of(scene_with(robot__magnetization=magnetization))
    assert len(lines) == 1
    assert lines[0].startswith(message)


def test_planar_models_refuse_an_out_of_plane_magnetization():
    lifted = {**UNIFORM, "elevation": "30 deg"}
    lines = problems_of(scene_with(robot__magnetization=lifted, models={"run": ["fem2d"]}))
    assert lines == [
        "robot.magnetization: has an out-of-plane elevation; the planar fem2d supports only "
        "planar magnetizations (elevation 0)"
    ]
    assert parse_scene(scene_with(robot__magnetization=lifted, models={"run": ["fem3d"]}))


def test_poisson_ratio_reaches_the_rod_and_the_fem():
    scene = parse_scene(scene_with(robot__poisson_ratio=0.3))
    assert scene.rod.poisson_ratio == 0.3
    assert scene.poisson_ratio == 0.3  # the FEM's (runner: solve_fem(poisson_ratio=...))
    assert scene.rod.shear_modulus == pytest.approx(1e6 / 2.6, rel=1e-15)
    scene = parse_scene(scene_with())
    assert scene.rod.poisson_ratio == 0.5  # the Rod's default; the FEM keeps its own
    assert scene.poisson_ratio is None
    # incompressible: fine for the rod, not for the FEM's bulk modulus
    assert parse_scene(scene_with(robot__poisson_ratio=0.5)).rod.poisson_ratio == 0.5
    lines = problems_of(scene_with(robot__poisson_ratio=0.5, models={"run": ["rod", "fem3d"]}))
    assert lines == [
        "robot.poisson_ratio: 0.5 is incompressible, which the FEM (fem3d) cannot take "
        "(infinite bulk modulus); give e.g. 0.4995"
    ]
    # within the FEM's gap of 0.5: refused at check, not at run time (coilrod.fem.solve.NU_GAP)
    from coilrod.fem.solve import NU_GAP
    from coilrod.scene.checks import FEM_NU_GAP

    assert FEM_NU_GAP == NU_GAP
    lines = problems_of(scene_with(robot__poisson_ratio=0.5 - 1e-11, models={"run": ["fem2d"]}))
    assert lines == [
        "robot.poisson_ratio: 0.49999999999 is within 1e-10 of 0.5, beyond what the FEM (fem2d) "
        "solves in float64; 0.4999999 gives the same tips to 1e-8"
    ]
    assert parse_scene(scene_with(robot__poisson_ratio=0.5 - 1e-11))  # the rod takes it
    for bad in (0.51, -1.0, "0.3", True):
        assert problems_of(scene_with(robot__poisson_ratio=bad))[0].startswith(
            "robot.poisson_ratio: "
        )
