"""Control scenes ([control] with a coil system, ``field.type = "system"``), grouped by property:

- the scene's currents are those of ``coilrod.solve_currents`` called directly on the same
  robot, system and target built through the library (not through the scene parser), and an
  independent forward solve (``solve_rod`` at tolerance 1e-11) with the real controller's
  currents lands within 1e-6 L of the target; the ideal controller's reported miss is that
  solve's distance;
- the coil system a scene describes (a preset with its arguments, a coil list, both) is the
  one the library builds from the same numbers;
- validation: every problem is one line naming its key, all reported at once; a corrupted value
  anywhere in the system or the control table is a SceneError naming that key, never another
  exception;
- the CLI: ``check`` prints the controllers and the target, ``run`` prints the currents and
  writes the files; an unreachable target gives the solver's message with the closest tip found
  and exit code 1, without a traceback; control scenes are not swept (exit code 2).
"""

import contextlib
import copy
import datetime
import io
import json
import re
import types
import warnings

import numpy as np
import pytest
from _scenes import BASE

import coils
from coilrod import Circle, Magnetization, Rod, solve_currents, solve_rod
from coilrod.scene import SceneError, load_scene, parse_scene
from coilrod.scene.cli import main, shipped_scenes
from coilrod.scene.planner import plan_scene

# the seed's robot with M(1), built through the library (|M| = 0.2 x 640 kA/m)
ROD = Rod(0.04, 1e6, Circle(2e-3), Magnetization(128e3, 0.0))
L = ROD.length
TARGET = (0.02, 0.03)
SCALES = np.linspace(0.1, 1.0, 10)

CONTROL = {
    "name": "control test",
    "robot": copy.deepcopy(BASE["robot"]),
    "field": {"type": "system", "preset": "three_axis_helmholtz"},
    "control": {"target": ["20 mm", "30 mm"]},
}


def control_with(field=None, control=None, **top):
    """CONTROL with the field and control tables updated (a None value removes the key) and
    top-level tables replaced."""
    data = copy.deepcopy(CONTROL)
    for table, changes in (("field", field), ("control", control)):
        for k, v in (changes or {}).items():
            if v is None:
                data[table].pop(k, None)
            else:
                data[table][k] = v
    data.update(top)
    return data


def problems_of(data) -> list[str]:
    with pytest.raises(SceneError) as info:
        parse_scene(data)
    assert str(info.value) == "\n".join(info.value.problems)
    assert all("\n" not in line for line in info.value.problems)
    return info.value.problems


def forward_tip(system, currents):
    """Tip (x, y) of an independent forward solve with these currents (tight tolerance)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return solve_rod(ROD, system.with_currents(currents), SCALES, tol=1e-11).tip[-1, :2]


def run_cli(*args) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(args))
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    """The shipped control scene run by the CLI: (exit code, stdout, control.json, folder)."""
    folder = tmp_path_factory.mktemp("control")
    code, out, err = run_cli("run", "control_three_axis", "--out", str(folder), "--no-progress")
    assert err == ""
    return code, out, json.loads((folder / "control.json").read_text()), folder


# -- the scene's currents are the library's ---------------------------------------------------
class TestAgainstTheLibrary:
    SYSTEM = coils.presets.three_axis_helmholtz(radii=(0.100, 0.140, 0.180), turns=200)

    def test_real_controller_currents_and_an_independent_tip(self, example):
        code, _, summary, _ = example
        assert code == 0
        run = next(r for r in summary["runs"] if r["model"] == "real")
        direct = solve_currents(ROD, self.SYSTEM, TARGET, max_current=10.0, model="real")
        np.testing.assert_allclose(run["currents_A"], direct.currents, rtol=0, atol=1e-9)
        assert run["ok"]
        # an independent forward solve with the scene's currents lands on the target
        tip = forward_tip(self.SYSTEM, np.array(run["currents_A"]))
        assert np.linalg.norm(tip - TARGET) <= 1e-6 * L
        assert run["miss_mm"] <= 1e3 * 1e-6 * L
        assert run["power_W"] == pytest.approx(self.SYSTEM.power(run["currents_A"]), rel=1e-12)
        np.testing.assert_allclose([run["tip_x_mm"], run["tip_y_mm"]], 1e3 * tip, atol=1e-6)

    def test_ideal_controller_currents_and_its_real_miss(self, example):
        _, _, summary, _ = example
        run = next(r for r in summary["runs"] if r["model"] == "ideal")
        direct = solve_currents(ROD, self.SYSTEM, TARGET, max_current=10.0, model="ideal")
        np.testing.assert_allclose(run["currents_A"], direct.currents, rtol=0, atol=1e-9)
        # the miss it reports is where its currents really put the tip (independent solve)
        tip = forward_tip(self.SYSTEM, np.array(run["currents_A"]))
        assert run["miss_mm"] == pytest.approx(1e3 * np.linalg.norm(tip - TARGET), rel=1e-6)
        # pairs of radius 2.5 L and more: the ideal controller is off by 0.1 % to 5 % of L
        assert 0.1 < run["miss_percent_L"] < 5

    def test_coil_list_system(self):
        # two listed Helmholtz pairs (each one channel) with their copper, limits from the scene
        data = control_with(
            field={
                "preset": None,
                "coil": [
                    {"type": "helmholtz", "radius": "90 mm", "turns": 150, "axis": "x",
                     "wire_diameter": "1.5 mm"},
                    {"type": "helmholtz", "radius": "120 mm", "turns": 250, "axis": "y",
                     "wire_diameter": "1.5 mm"},
                ],
            },
            control={"max_current": ["8 A", "6 A"], "model": "real"},
        )  # fmt: skip
        scene = parse_scene(data)
        result = plan_and_run(scene)
        assert result.ok
        system = coils.CoilSystem(
            [
                coils.HelmholtzPair(0.09, 150, 0.0, axis="x", wire_diameter=1.5e-3),
                coils.HelmholtzPair(0.12, 250, 0.0, axis="y", wire_diameter=1.5e-3),
            ]
        )
        direct = solve_currents(ROD, system, TARGET, max_current=[8.0, 6.0])
        out = result.run("real").result
        np.testing.assert_allclose(out.currents, direct.currents, rtol=0, atol=1e-9)
        assert np.linalg.norm(forward_tip(system, out.currents) - TARGET) <= 1e-6 * L
        assert out.power == pytest.approx(float(system.power(out.currents)), rel=1e-12)
        assert result.channels == ("coil[0] helmholtz +x", "coil[1] helmholtz +y")


def test_coils_without_copper_have_no_power(tmp_path):
    # listed coils without wire_diameter have no resistance: the power is "n/a" (null in the
    # JSON, never NaN), and the minimum-power weighting falls back to sum I^2
    coil = {"type": "helmholtz", "radius": "90 mm", "turns": 150}
    data = control_with(
        field={"preset": None, "coil": [{**coil, "axis": "x"}, {**coil, "axis": "y"}]},
        control={"max_current": "8 A", "model": "ideal"},
    )
    result = plan_and_run(parse_scene(data))
    assert result.ok
    power = next(ln for ln in result.summary().splitlines() if "power (W)" in ln)
    assert power.split() == ["power", "(W)", "n/a"]
    result.write(tmp_path)
    run = json.loads((tmp_path / "control.json").read_text())["runs"][0]
    assert run["power_W"] is None
    assert len(run["currents_A"]) == 2


def plan_and_run(scene):
    from coilrod.scene.runner import run_scene

    return run_scene(scene, plan=plan_scene(scene), progress=False)


# -- the system a scene describes is the library's -----------------------------------------------
PROBES = np.array([[0.01, 0.004, 0.001], [0.03, -0.01, 0.002], [-0.02, 0.015, -0.003]])


def same_system(a, b):
    Ba, Ga = a.unit_fields(PROBES)
    Bb, Gb = b.unit_fields(PROBES)
    np.testing.assert_allclose(Ba, Bb, rtol=1e-13, atol=0)
    np.testing.assert_allclose(Ga, Gb, rtol=1e-13, atol=0)
    np.testing.assert_array_equal(a.max_current, b.max_current)
    assert a.names == b.names
    np.testing.assert_allclose(a.resistance, b.resistance, rtol=1e-13)


@pytest.mark.parametrize(
    ("preset", "arguments", "library"),
    [
        (
            "three_axis_helmholtz",
            {"radii": "120 mm", "turns": [100, 200, 300], "max_current": ["5 A", "6 A", "7 A"],
             "wire_diameter": "1 mm", "center": ["0 mm", "5 mm", "0 mm"]},
            {"radii": 0.12, "turns": (100, 200, 300), "max_current": (5.0, 6.0, 7.0),
             "wire_diameter": 1e-3, "center": (0.0, 0.005, 0.0)},
        ),
        (
            "helmholtz_maxwell",
            {"maxwell_radius": "300 mm", "maxwell_turns": 400, "maxwell_max_current": "12 A",
             "maxwell_axis": "x", "winding": ["30 mm", "30 mm"], "wire_diameter": "1 mm"},
            {"maxwell_radius": 0.3, "maxwell_turns": 400, "maxwell_max_current": 12.0,
             "maxwell_axis": "x", "winding": (0.03, 0.03), "wire_diameter": 1e-3},
        ),
        (
            "eight_coil_hemisphere",
            {"distance": "250 mm", "radius": "70 mm", "turns": 500, "max_current": "15 A"},
            {"distance": 0.25, "radius": 0.07, "turns": 500, "max_current": 15.0},
        ),
    ],
)  # fmt: skip
def test_preset_arguments_build_the_library_preset(preset, arguments, library):
    scene = parse_scene(control_with(field={"preset": preset, **arguments}))
    same_system(scene.fields["coils"], getattr(coils.presets, preset)(**library))
    np.testing.assert_array_equal(scene.control.max_current, scene.fields["coils"].max_current)


def test_a_preset_and_a_coil_list_make_one_system():
    coil = {"type": "coil", "radius": "50 mm", "turns": 300, "axis": "x", "wire_diameter": "1 mm",
            "center": ["-120 mm", "0 mm", "0 mm"]}  # fmt: skip
    data = control_with(field={"coil": [coil]}, control={"max_current": "4 A"})
    scene = parse_scene(data)
    preset = coils.presets.three_axis_helmholtz()
    extra = coils.Coil(0.05, 300, 0.0, axis="x", center=(-0.12, 0, 0), wire_diameter=1e-3)
    library = coils.CoilSystem(
        [preset, extra], center=preset.center, names=(*preset.names, "coil[0] coil +x")
    )
    same_system(scene.fields["coils"], library)
    # the system keeps its ratings (the listed coil has none); the scene's limits are apart
    np.testing.assert_array_equal(scene.fields["coils"].max_current, [10.0, 10.0, 10.0, np.inf])
    np.testing.assert_array_equal(scene.control.max_current, [4.0] * 4)
    # the ideal controller's centre is the preset's, not the mean of the parts
    np.testing.assert_array_equal(scene.fields["coils"].center, preset.center)


def test_control_defaults():
    scene = parse_scene(CONTROL)
    spec = scene.control
    np.testing.assert_allclose(spec.target, TARGET, rtol=1e-15)
    assert spec.angle is None
    assert spec.models == ("real", "ideal")
    np.testing.assert_array_equal(spec.max_current, [10.0, 10.0, 10.0])  # the preset's rating
    assert spec.steps == 10
    assert scene.models == ("rod",)
    scene = parse_scene(
        control_with(
            control={"angle": "60 deg", "model": "ideal", "max_current": ["1 A", "2 A", "3 A"]},
            load={"steps": 4},
            rod={"nodes": 16},
        )
    )
    assert scene.control.angle == pytest.approx(np.pi / 3)
    assert scene.control.models == ("ideal",)
    np.testing.assert_array_equal(scene.control.max_current, [1.0, 2.0, 3.0])
    assert scene.control.steps == 4
    assert scene.rod_options == {"nodes": 16}


# -- validation: one line per problem, naming the key -------------------------------------------
Z_ONLY = [{"type": "helmholtz", "radius": "80 mm", "turns": 200, "axis": "z"}]
ON_CLAMP = [{"type": "coil", "radius": "20 mm", "turns": 100, "axis": "z",
             "winding": ["10 mm", "10 mm"], "center": ["-20 mm", "0 mm", "0 mm"]}]  # fmt: skip
CENTRE_ON_WIRE = [
    {"type": "coil", "radius": "20 mm", "turns": 10, "axis": "z", "center": [x, "0 mm", "5 mm"]}
    for x in ("-20 mm", "20 mm")
] + [
    {"type": "helmholtz", "radius": "150 mm", "turns": 10, "axis": a,
     "center": ["0 mm", "0 mm", "5 mm"]}
    for a in "xy"
]  # fmt: skip


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (control_with(control={"target": ["50 mm", "0 mm"]}),
         "control.target: (50 mm, 0 mm) is 50 mm from the clamp, beyond the robot's length"),
        (control_with(control={"target": ["-30 mm", "30 mm"]}),
         "control.target: (-30 mm, 30 mm) is 42.4264068712 mm from the clamp, beyond"),
        (control_with(control={"target": ["20 mm"]}),
         "control.target: expected a list of 2 lengths"),
        (control_with(control={"target": "20 mm"}), "control.target: expected a list of 2"),
        (control_with(control={"target": None}), "control.target: missing required key"),
        (control_with(control={"target": ["20 mm", "nan mm"]}), "control.target[1]: cannot read"),
        (control_with(control={"target": [float("nan"), "30 mm"]}),
         "control.target[0]: missing unit in nan"),
        (control_with(control={"target": ["20 mT", "30 mm"]}),
         "control.target[0]: unknown unit 'mT' for a length"),
        (control_with(control={"target": ["1e400 mm", "30 mm"]}),
         "control.target[0]: '1e400 mm' is not finite"),
        (control_with(control={"angle": "30"}), "control.angle: missing unit in '30'"),
        (control_with(control={"angle": "1000 deg"}), "control.angle: must be between -360 deg"),
        (control_with(control={"model": "linear"}),
         "control.model: expected 'real', 'ideal' or 'both'; got 'linear'"),
        (control_with(control={"max_current": "0 A"}), "control.max_current: must be positive"),
        (control_with(control={"max_current": "-2 A"}), "control.max_current: must be positive"),
        (control_with(control={"max_current": "5 mT"}),
         "control.max_current: unknown unit 'mT' for a current"),
        (control_with(control={"max_current": ["1 A", "nan A", "1 A"]}),
         "control.max_current[1]: cannot read 'nan A'"),
        (control_with(control={"max_current": ["1 A", "1 A"]}),
         "control.max_current: expected one current or a list of 3"),
        (control_with(control={"max_current": "20 A"}),
         "control.max_current: 20 A is above the rating of the channels x Helmholtz, y "
         "Helmholtz, z Helmholtz (10, 10, 10 A; the preset's max_current)"),
        (control_with(control={"max_current": ["1 A", "11 A", "1 A"]}),
         "control.max_current[1]: 11 A is above the rating of the channel y Helmholtz (10 A;"),
        (control_with(control={"speed": "fast"}), "control.speed: unknown key"),
        (control_with(field={"preset": "five_axis"}),
         "field.preset: unknown coil-system preset 'five_axis'"),
        (control_with(field={"preset": None}), "field.preset: missing required key"),
        (control_with(field={"radii": ["100 mm", "140 mm"]}),
         "field.radii: expected one value or a list of 3"),
        (control_with(field={"radii": "-100 mm"}), "field.radii: must be positive"),
        (control_with(field={"radii": ["100 mm", "140", "180 mm"]}),
         "field.radii[1]: missing unit in '140'"),
        (control_with(field={"turns": 0}), "field.turns: must be positive"),
        (control_with(field={"turns": 1.5}), "field.turns: expected an integer"),
        (control_with(field={"max_current": "0 A"}), "field.max_current: must be positive"),
        (control_with(field={"wire_diameter": 2}), "field.wire_diameter: missing unit"),
        (control_with(field={"maxwell_radius": "300 mm"}),
         "field.maxwell_radius: not a parameter of preset three_axis_helmholtz"),
        (control_with(field={"preset": "helmholtz_maxwell", "maxwell_radius": "150 mm"}),
         "field.maxwell_radius: must exceed the largest Helmholtz radius (180 mm)"),
        (control_with(field={"preset": "eight_coil_hemisphere", "radius": "250 mm"}),
         "field.radius: the coil radius (250 mm) must be below the distance"),
        (control_with(field={"compare_ideal": True}), "field.compare_ideal: unknown key"),
        (control_with(field={"preset": None, "coil": Z_ONLY}, control={"max_current": "5 A"}),
         "field.coil: the channels cannot make every in-plane field (B_x, B_y)"),
        (control_with(field={"preset": None, "coil": Z_ONLY[:1] * 2}),
         "control.max_current: missing required key: the channels coil[0] helmholtz +z, "
         "coil[1] helmholtz +z have no current limit"),
        (control_with(field={"coil": [{**Z_ONLY[0], "B": "5 mT"}]}, control={"max_current": "1 A"}),
         "field.coil[0].B: not used in a coil system under control ([control] finds"),
        (control_with(field={"coil": ON_CLAMP}, control={"max_current": "1 A"}),
         "field.coil[0]: the clamp (the robot's base, at the origin) touches the winding of this"),
        (control_with(field={"radii": "30 mm", "center": ["0 mm", "0 mm", "15 mm"]}),
         "field.preset: the undeformed robot, at s = 30 mm from the clamp, touches the winding "
         "of channel 'z Helmholtz' of the preset"),
        (control_with(field={"preset": None, "coil": CENTRE_ON_WIRE},
                      control={"max_current": "1 A"}),
         "field.coil: the system's centre (0 mm, 0 mm, 5 mm), where the ideal controller"),
        (control_with(models={"run": ["rod", "fem2d"]}),
         "models.run[1]: 'fem2d' is not used for control (the currents are found with the rod"),
        (control_with(load={"scales": [0.5, 1.0]}), "load.scales: not used in a control scene"),
        (control_with(load={"steps": 5, "max_scale": 2.0}),
         "load.max_scale: not used in a control scene"),
        (control_with(field={"type": "coils", "preset": None,
                             "coil": [{**Z_ONLY[0], "axis": "y", "B": "5 mT"}]}),
         "field.type: a control scene drives a coil system: give type = 'system'"),
        (control_with(field={"type": "uniform", "preset": None, "B": "5 mT"}),
         "field.type: a control scene drives a coil system"),
        ({k: v for k, v in CONTROL.items() if k != "control"},
         "control: missing required table (e.g. target = ['20 mm', '30 mm'])"),
    ],
)  # fmt: skip
def test_each_problem_names_its_key(data, message):
    lines = problems_of(data)
    assert len(lines) == 1, lines
    assert lines[0].startswith(message), lines[0]


def test_target_on_the_rod_length_is_accepted():
    # the straight robot's tip is exactly L from the clamp: not beyond it
    scene = parse_scene(control_with(control={"target": ["40 mm", "0 mm"]}))
    np.testing.assert_allclose(scene.control.target, [0.04, 0.0])


def test_every_problem_at_once_in_scene_order():
    data = control_with(
        field={"radii": "-1 mm", "turns": 0, "colour": "red"},
        control={"target": ["20 mm", 30], "angle": "5 T", "model": 3, "max_current": "0 A"},
        models={"run": ["fem3d"]},
        load={"scales": [1.0]},
    )
    keys = [line.split(":")[0] for line in problems_of(data)]
    assert keys == [
        "field.colour",
        "field.radii",
        "field.turns",
        "load.scales",
        "models.run[0]",
        "control.target[1]",
        "control.angle",
        "control.model",
    ]  # control.max_current is checked against the channels, which field.radii spoils


# a scene with every key of a control system and table (a preset with arguments and a listed
# coil), corrupted one key at a time by the fuzz test below
FULL = control_with(
    field={
        "radii": ["100 mm", "140 mm", "180 mm"],
        "turns": 200,
        "max_current": "10 A",
        "wire_diameter": "2 mm",
        "center": ["0 mm", "0 mm", "0 mm"],
        "coil": [
            {"type": "coil", "radius": "50 mm", "turns": 300, "axis": "x",
             "wire_diameter": "1 mm", "center": ["-120 mm", "0 mm", "0 mm"]},
        ],
    },
    control={"angle": "60 deg", "model": "both", "max_current": ["8 A", "8 A", "8 A", "5 A"]},
)  # fmt: skip


def _paths(node, prefix=()):
    items = node.items() if isinstance(node, dict) else enumerate(node)
    for k, v in items:
        yield (*prefix, k)
        if isinstance(v, dict | list):
            yield from _paths(v, (*prefix, k))


_PATHS = [p for p in _paths(FULL) if p[0] in ("field", "control")]
_JUNK = [None, 10**400, datetime.date(2024, 1, 1), 0, -1, 1.5, float("nan"), "", "abc", "5",
         "5 mm", "-5 mm", "5 A", "-5 A", "1e9 A", [], ["1 mm"], {}, True, "nan mm", "-x",
         "three_axis_helmholtz", "real"]  # fmt: skip


def _spell(path) -> str:
    out = ""
    for k in path:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else k)
    return out


def _names(line: str, key: str) -> bool:
    return any(line.startswith(key + end) for end in (":", ".", "["))


#: Keys that may be left out (a default applies).
_OPTIONAL = {
    "field.radii", "field.turns", "field.max_current", "field.wire_diameter", "field.center",
    "field.coil[0].axis", "field.coil[0].wire_diameter", "field.coil[0].center",
    "control.angle", "control.model",
}  # fmt: skip


def _still_valid(key: str, value) -> bool:
    """Whether a "corruption" is a valid value of the key (of the right kind, unit and sign):
    the only ones the parser may accept."""
    if value is None:
        return key in _OPTIONAL
    positive_length = re.fullmatch(r"field\.(radii(\[\d\])?|wire_diameter)", key) or re.fullmatch(
        r"field\.coil\[0\]\.(radius|wire_diameter)", key
    )
    position = re.fullmatch(r"(field\.(coil\[0\]\.)?center|control\.target)\[\d\]", key)
    return bool(
        (positive_length and value == "5 mm")
        or (position and value in ("5 mm", "-5 mm"))
        or (re.fullmatch(r"control\.max_current(\[\d\])?", key) and value == "5 A")
        or any(
            (key, value) == pair
            for pair in (
                ("field.preset", "three_axis_helmholtz"),
                ("field.coil[0].axis", "-x"),
                ("control.angle", 0),
                ("control.model", "real"),
            )
        )
    )


def test_any_corrupted_value_is_a_scene_error_naming_its_key():
    """Every key of FULL set to every junk value (or removed): a SceneError whose every line
    names that key, unless the value is a valid one (then it parses)."""
    wrong = []
    for path in _PATHS:
        for value in _JUNK:
            data = copy.deepcopy(FULL)
            node = data
            for k in path[:-1]:
                node = node[k]
            removed = value is None and isinstance(node, dict)
            if removed:
                node.pop(path[-1])
            else:
                node[path[-1]] = value
            key = _spell(path)
            allowed = [key] + ([_spell(path[:-1])] if removed else [])
            if path[:2] in (("field", "max_current"), ("field", "coil")):
                allowed.append("control.max_current")  # checked against the changed channels
            try:
                parse_scene(data)
            except SceneError as exc:
                problems = exc.problems or ["<a SceneError without problems>"]
                if _still_valid(key, value):
                    wrong.append(f"{key} = {value!r} is valid but refused: {problems}")
                wrong += [
                    f"{key} = {value!r}: {line!r}"
                    for line in problems
                    if not any(_names(line, k) for k in allowed)
                ]
            else:
                if not _still_valid(key, value):
                    wrong.append(f"{key} = {value!r}: accepted silently")
    assert not wrong, "\n".join(wrong)


def test_full_control_scene_is_valid():
    scene = parse_scene(FULL)
    assert len(scene.fields["coils"].names) == 4
    assert scene.control.angle == pytest.approx(np.pi / 3)


# -- the CLI -----------------------------------------------------------------------------------
def test_shipped_example_is_listed_and_valid():
    code, out, _ = run_cli("scenes")
    assert code == 0
    assert "control_three_axis" in out
    scene = load_scene(shipped_scenes()["control_three_axis"])
    assert scene.control is not None
    assert scene.fields["coils"].names == ("x Helmholtz", "y Helmholtz", "z Helmholtz")


def test_check_prints_the_controllers_and_the_target():
    code, out, err = run_cli("check", "control_three_axis")
    assert (code, err) == (0, "")
    assert "run   rod    currents by the real controller" in out
    assert "run   rod    currents by the ideal controller" in out
    assert (
        "coil system: preset three_axis_helmholtz, 3 current channels (x Helmholtz, y Helmholtz, "
        "z Helmholtz), limits 10, 10, 10 A"
    ) in out
    assert "target: tip at (20, 30) mm in the plane" in out
    assert "each rod solve ramps the currents from zero in 10 load steps" in out
    assert "scikit-fem is not imported" in out


def test_run_prints_the_currents_and_writes_the_files(example):
    code, out, summary, folder = example
    assert code == 0
    assert "Traceback" not in out
    lines = out.splitlines()
    header = next(line for line in lines if line.strip().startswith("real"))
    assert header.split() == ["real", "ideal", "limit", "(A)"]
    for j, name in enumerate(summary["channels"]):
        row = next(line for line in lines if line.strip().startswith(f"{name} (A)"))
        currents = [f"{r['currents_A'][j]:.4f}" for r in summary["runs"]]
        assert row.split()[-3:] == [*currents, "10"]
    assert any(line.strip().startswith("power (W)") for line in lines)
    assert "real: ok" in out
    assert "ideal: ok" in out
    for name in ("control.csv", "control.json", "control.png"):
        assert (folder / name).stat().st_size > 0
    csv_lines = (folder / "control.csv").read_text().splitlines()
    assert csv_lines[0].startswith("model,ok,closest,current_x_Helmholtz_A,current_y_Helmholtz_A")
    assert [line.split(",")[0] for line in csv_lines[1:]] == ["real", "ideal"]


def test_unreachable_target_gives_the_closest_tip_and_exit_1(tmp_path):
    # 0.5 A in each pair makes at most ~0.9 mT: the target (20, 30) mm is out of reach
    scene = tmp_path / "far.toml"
    text = shipped_scenes()["control_three_axis"].read_text()
    scene.write_text(text.replace('model = "both"', 'model = "both"\nmax_current = "0.5 A"'))
    code, out, err = run_cli("run", str(scene), "--out", str(tmp_path / "out"), "--quiet")
    assert code == 1
    assert "Traceback" not in out + err
    assert err == ""
    lines = {line.split(":")[0].strip(): line.strip() for line in out.splitlines()}
    assert lines["real"].startswith(
        "real: FAILED (* the closest found): solve_currents: the target"
    )
    assert "is beyond the current limits: not reachable within them (channels " in lines["real"]
    assert " at their limit); the closest stable tip found is" in lines["real"]
    # the ideal controller is stopped by the limits in its own model too: also a failure
    assert lines["ideal"].startswith(
        "ideal: FAILED (* the closest found): the ideal controller cannot put the tip on the "
        "target even in its own model (the centre field) within the current limits"
    )
    runs = json.loads((tmp_path / "out" / "control.json").read_text())["runs"]
    system = coils.presets.three_axis_helmholtz()
    for run in runs:
        assert (run["ok"], run["closest"]) == (False, True)
        assert np.all(np.abs(run["currents_A"]) <= 0.5 + 1e-12)
        # the closest tip it reports is where those currents really put the tip
        tip = forward_tip(system, np.array(run["currents_A"]))
        np.testing.assert_allclose([run["tip_x_mm"], run["tip_y_mm"]], 1e3 * tip, atol=1e-6)
        assert run["miss_percent_L"] > 50


def test_a_pose_the_channels_cannot_make_is_not_met():
    # three Helmholtz pairs make uniform fields only: two in-plane controls for three
    # conditions (x, y, angle); the least-squares compromise misses and the run says so
    scene = parse_scene(control_with(control={"angle": "80 deg", "model": "real"}))
    result = plan_and_run(scene)
    assert not result.ok
    run = result.run("real")
    assert run.error.startswith("the target pose is not reachable: the closest the currents make")
    assert run.error.endswith("(the least-squares compromise within the current limits)")
    assert run.result.miss > 1e-3 * L
    assert "real*" in result.summary()


def test_control_scenes_are_not_swept(tmp_path):
    code, _, err = run_cli(
        "sweep", "control_three_axis", "--param", "robot.length=30mm:40mm:2", "--out",
        str(tmp_path / "sweep"),
    )  # fmt: skip
    assert code == 2
    assert err.strip() == (
        "coilrod: error: control: a control scene ([control]) cannot be swept yet (a sweep row "
        "holds tips under a given field); run it with 'coilrod run'"
    )
    from coilrod import sweep

    with pytest.raises(SceneError, match="cannot be swept yet"):
        sweep(shipped_scenes()["control_three_axis"], {"robot.length": "30 mm:40 mm:2"})


# -- the README's control scene --------------------------------------------------------------
def test_readme_control_scene_is_the_example_and_its_output(example):
    import re
    import tomllib
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    block = next(b for b in re.findall(r"```toml\n(.*?)```", text, re.S) if "[control]" in b)
    shipped = load_scene(shipped_scenes()["control_three_axis"])
    data = {"robot": shipped.data["robot"], **tomllib.loads(block)}
    scene = parse_scene(data)
    same_system(scene.fields["coils"], shipped.fields["coils"])
    np.testing.assert_array_equal(scene.control.target, shipped.control.target)
    assert scene.control.models == shipped.control.models
    # every line of the printed table it shows (but "...") is in the example's output
    _, out, summary, _ = example
    ideal = next(r for r in summary["runs"] if r["model"] == "ideal")
    mm, percent = re.search(r"\(here ([\d.]+) mm, ([\d.]+) % of L\)", text).groups()
    assert f"{ideal['miss_mm']:.2f}" == mm
    assert f"{ideal['miss_percent_L']:.1f}" == percent
    printed = {" ".join(line.split()) for line in out.splitlines()}
    shown = re.search(r"prints one column per controller:\n```\n(.*?)```", text, re.S).group(1)
    for line in shown.splitlines():
        if "..." not in line:
            assert " ".join(line.split()) in printed, line


@pytest.mark.parametrize(
    ("status", "said", "not_said"),
    [
        ("max_solves", "search stopped (max_solves, after 40 solves)", "the current limits"),
        ("branch_edge", "search stopped (branch_edge, after 40 solves)", "the current limits"),
        ("optimal", "within the current limits", "search stopped"),
    ],
)
def test_an_ideal_controller_stopped_by_its_budget_is_not_blamed_on_the_limits(
    status, said, not_said
):
    """The ideal controller's reason names what stopped it: a search that ran out of solves
    (Navion at (20, 30) mm creeps there on a nearly singular Jacobian) or stopped at an edge
    of the rod's branch (what it now does there) is not 'within the current limits' (the old
    message said so whatever stopped it)."""
    from coilrod.control.currents import ControlResult
    from coilrod.scene.control_runner import _unmet

    L = 0.04
    rod = types.SimpleNamespace(length=L)
    spec = types.SimpleNamespace(target=np.array([0.02, 0.03]))
    out = ControlResult(
        currents=np.zeros(3), tip=np.array([0.02, 0.03001, 0.0]), tip_angle=0.0, miss=1e-5,
        angle_miss=None, power=0.0, result=None, model="ideal", target=spec.target, solves=40,
        start_solves=0, history=[1e-3, 1.36e-5], status=status,
    )  # fmt: skip
    text = _unmet(out, spec, rod)
    assert said in text
    assert not_said not in text
    assert "0.0136 mm away" in text
