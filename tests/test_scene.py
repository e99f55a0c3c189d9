"""Scene files: validation names the key and the reason; the CLI exits 2 without a traceback."""

import copy
import datetime
import pickle
import subprocess
import sys

import numpy as np
import pytest
from _scenes import BASE, scene_with
from hypothesis import given, settings
from hypothesis import strategies as st

import coils
from coilrod.scene import SceneError, load_scene, parse_scene
from coilrod.scene.cli import main, shipped_scenes
from coilrod.scene.units import parse_quantity


def with_change(path: str, value):
    """BASE with the dotted key ``path`` set to ``value`` (None removes it)."""
    return scene_with(**{path.replace(".", "__"): value})


def test_units_convert_to_si():
    assert parse_quantity("40 mm", "length") == pytest.approx(0.04)
    assert parse_quantity("15 mT", "flux density") == pytest.approx(0.015)
    assert parse_quantity("640 kA/m", "magnetization") == pytest.approx(640e3)
    assert parse_quantity("1 MPa", "pressure") == pytest.approx(1e6)
    assert parse_quantity("90 deg", "angle") == pytest.approx(np.pi / 2)
    assert parse_quantity("10 G/cm", "gradient") == pytest.approx(0.1)


def test_valid_scene_builds_objects():
    scene = parse_scene(BASE)
    assert scene.rod.length == pytest.approx(0.04)
    assert scene.rod.section.diameter == pytest.approx(2e-3)
    np.testing.assert_allclose(scene.fields["ideal"].B0, [0, 5e-3, 0])
    np.testing.assert_allclose(scene.scales, [0.25, 0.5, 0.75, 1.0])


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        ("robot.length", "-40 mm", "robot.length: must be positive"),
        ("robot.length", 40, "robot.length: missing unit"),
        ("robot.length", "40", "robot.length: missing unit"),
        ("robot.length", "40 mT", "unknown unit 'mT' for a length"),
        ("robot.length", None, "robot.length: missing required key"),
        ("robot.colour", "red", "robot.colour: unknown key"),
        ("robot.youngs_modulus", "0 Pa", "robot.youngs_modulus: must be positive"),
        ("robot.magnetization", {"preset": "M9"}, "unknown preset 'M9'"),
        (
            "field.type",
            "rotating",
            "field.type: expected 'uniform', 'gradient', 'coils' or 'system'",
        ),
        ("field.B", "5 T/m", "unknown unit 'T/m' for a flux density"),
        ("load.steps", 0, "load.steps: must be positive"),
        ("load.steps", 2.5, "load.steps: expected an integer"),
        ("models.run", ["rod", "fem4d"], "unknown model 'fem4d'"),
        ("bogus", 1, "bogus: unknown key"),
    ],
)
def test_invalid_scene_names_key_and_reason(path, value, message):
    with pytest.raises(SceneError, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_scene(with_change(path, value))


def test_invalid_coil_reports_index():
    data = with_change(
        "field",
        {
            "type": "coils",
            "coil": [
                {"type": "helmholtz", "radius": "80 mm", "turns": 100, "B": "5 mT"},
                {"type": "maxwell", "radius": "-1 mm", "turns": 100, "current": "1 A"},
            ],
        },
    )
    with pytest.raises(SceneError, match=r"field.coil\[1\].radius: must be positive"):
        parse_scene(data)
    data["field"]["coil"][1] = {"type": "maxwell", "radius": "80 mm", "turns": 10}
    with pytest.raises(SceneError, match="exactly one of current, B"):
        parse_scene(data)


def test_coil_scene_meets_target_field_and_builds_ideal():
    data = with_change(
        "field",
        {
            "type": "coils",
            "coil": [
                {"type": "helmholtz", "radius": "80 mm", "turns": 200, "B": "15 mT", "axis": "y"}
            ],
        },
    )
    scene = parse_scene(data)
    real, ideal = scene.fields["coils"], scene.fields["ideal"]
    assert isinstance(real, coils.HelmholtzPair)
    # the target centre field, checked against the closed form (4/5)^1.5 mu0 N I / R
    assert real.center_field == pytest.approx(0.015, rel=1e-12)
    assert ideal.uniform


def test_segments_must_add_up():
    mag = {
        "segments": [
            {"length": "10 mm", "magnitude": "64 kA/m"},
            {"length": "20 mm", "magnitude": "128 kA/m", "angle": "90 deg"},
        ]
    }
    with pytest.raises(SceneError, match="add up to 30 mm; the robot is 40 mm long"):
        parse_scene(with_change("robot.magnetization", mag))
    mag["segments"][1]["length"] = "30 mm"
    scene = parse_scene(with_change("robot.magnetization", mag))
    assert scene.rod.magnetization.angle(np.array([0.035]))[0] == pytest.approx(np.pi / 2)


def test_every_shipped_scene_is_valid():
    shipped = shipped_scenes()
    assert len(shipped) >= 5
    for path in shipped.values():
        scene = load_scene(path)
        assert scene.models


def test_cli_invalid_scene_exit_2_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(
        '[robot]\nlength = "-40 mm"\ndiameter = "2 mm"\nyoungs_modulus = "1 MPa"\n'
        'magnetization = { preset = "M1" }\n[field]\ntype = "uniform"\nB = "5 mT"\n'
    )
    # the problem keeps its key first; the error names the file (it did not), also pickled
    # (a sweep's workers send errors back)
    with pytest.raises(SceneError) as exc:
        load_scene(bad)
    assert exc.value.problems == ["robot.length: must be positive; got -40 mm"]
    assert exc.value.source == str(bad)
    assert str(exc.value).splitlines()[-1] == f"{bad}: the scene file with the problem above"
    assert pickle.loads(pickle.dumps(exc.value)).lines == exc.value.lines
    assert main(["run", str(bad), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "coilrod: error: robot.length: must be positive; got -40 mm",
        f"coilrod: error: {bad}: the scene file with the problem above",
    ]
    assert main(["check", str(tmp_path / "missing.toml")]) == 2
    bad.write_text("[robot\n")
    assert main(["check", str(bad)]) == 2
    assert "not valid TOML" in capsys.readouterr().err


def test_cli_console_script_no_traceback(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(
        '[robot]\nlength = 40\ndiameter = "2 mm"\nyoungs_modulus = "1 MPa"\n'
        'magnetization = { preset = "M1" }\n[field]\ntype = "uniform"\nB = "5 mT"\n'
    )
    proc = subprocess.run(
        [sys.executable, "-m", "coilrod", "run", str(bad)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert "robot.length: missing unit" in proc.stderr


def test_cli_help_teaches(capsys):
    # in this process: ``python -m coilrod`` itself is run by the test above
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for word in ("demo", "run", "check", "scenes", "40 mm", "examples"):
        assert word in out


FULL = {
    "name": "every key",
    "robot": {
        "length": "40 mm",
        "diameter": "2 mm",
        "youngs_modulus": "1 MPa",
        "poisson_ratio": 0.45,
        "magnetization": {
            "preset": "M4.2",
            "M0": "640 kA/m",
            "segment": 1,
            "segment_angle": "10 deg",
        },
    },
    "field": {
        "type": "coils",
        "compare_ideal": True,
        "coil": [
            {
                "type": "helmholtz",
                "radius": "80 mm",
                "turns": 200,
                "B": "15 mT",
                "axis": "y",
                "center": ["0 mm", "0 mm", "0 mm"],
                "winding": ["5 mm", "5 mm"],
                "filaments": [2, 2],
                "spacing": "80 mm",
            }
        ],
    },
    "load": {"steps": 4, "max_scale": 1.0},
    "models": {"run": ["rod"]},
    "rod": {"nodes": 32},
    "fem": {"order": 2, "elements2d": [10, 1], "elements3d": [10, 1, 1]},
    "output": {"figures": True, "tables": False},
}


def _key_paths(node, prefix=()):
    if isinstance(node, dict):
        items = node.items()
    elif isinstance(node, list):
        items = enumerate(node)
    else:
        return
    for k, v in items:
        yield (*prefix, k)
        yield from _key_paths(v, (*prefix, k))


_PATHS = list(_key_paths(FULL))
_JUNK = [
    None,
    10**400,
    datetime.date(2024, 1, 1),
    0,
    -1,
    1.5,
    float("nan"),
    float("inf"),
    "",
    "abc",
    "5",
    "5 mm",
    "-5 mm",
    "5 T",
    [],
    [1],
    ["1 mm"],
    {},
    {"a": 1},
    True,
    "nan mm",
    "1e400 mm",
    [0, 0],
    [-1, 2],
    "-x",
]


def test_full_scene_is_valid():
    scene = parse_scene(FULL)
    assert scene.fields["coils"].winding == (5e-3, 5e-3)


def _key(path) -> str:
    """('field', 'coil', 0, 'radius') -> 'field.coil[0].radius' (the scene's own spelling)."""
    out = ""
    for k in path:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else k)
    return out


def _same(a, b) -> bool:
    """Equality that tells True from 1 and 0.0 from False."""
    return type(a) is type(b) and a == b


# The oracle, written from the scene format's rules and independent of the parser: for each key
# of FULL, the junk values that are in fact valid there (everything else must be rejected).
# Contextual cases are spelled out: "5 mm" is a valid coil radius (winding height 5 mm < 2 R),
# but not a valid spacing (it must exceed the 5 mm winding width); "5 T" keeps lambda = 4096
# below the 1e4 limit; turns must be whole; "-x" turns the pair's axis along the robot, which
# stays clear of the windings.
_STRINGS = [v for v in _JUNK if isinstance(v, str)]
VALID_JUNK = {
    "name": _STRINGS,
    "robot.length": ["5 mm"],
    "robot.diameter": ["5 mm"],
    "robot.poisson_ratio": [0],
    "robot.magnetization.segment": [0, -1],
    "robot.magnetization.segment_angle": [0],
    "field.compare_ideal": [True],
    "field.coil[0].radius": ["5 mm"],
    "field.coil[0].B": ["5 T"],
    "field.coil[0].axis": ["-x"],
    "field.coil[0].center[0]": ["5 mm", "-5 mm"],
    "field.coil[0].center[1]": ["5 mm", "-5 mm"],
    "field.coil[0].center[2]": ["5 mm", "-5 mm"],
    "field.coil[0].winding[0]": ["5 mm"],
    "field.coil[0].winding[1]": ["5 mm"],
    "load": [{}],
    "load.max_scale": [1.5],
    "rod": [{}],
    "fem": [{}],
    "output": [{}],
    "output.figures": [True],
    "output.tables": [True],
}
# Keys that may be left out, and whether leaving them out changes the scene (False: the default
# is FULL's value).
OPTIONAL = {
    "name": True,
    "robot.poisson_ratio": True,
    "robot.magnetization.M0": False,
    "robot.magnetization.segment": True,
    "robot.magnetization.segment_angle": True,
    "field.compare_ideal": False,
    "field.coil[0].axis": False,
    "field.coil[0].center": False,
    "field.coil[0].filaments": True,
    "field.coil[0].spacing": False,
    "load": True,
    "load.steps": True,
    "load.max_scale": False,
    "models": False,
    "rod": True,
    "rod.nodes": True,
    "fem": True,
    "fem.order": True,
    "fem.elements2d": True,
    "fem.elements3d": True,
    "output": True,
    "output.figures": False,
    "output.tables": True,
}
_PROBES = np.array([[0.01, 0.004, 0.001], [0.03, -0.01, 0.002]])


def _fingerprint(scene) -> tuple:
    """Everything a run depends on, as plain numbers and strings."""
    s = np.linspace(0.0, scene.rod.length, 41)
    mag = scene.rod.magnetization
    parts = [
        scene.name,
        scene.rod.length,
        scene.rod.youngs_modulus,
        repr(scene.rod.section),
        tuple(mag.magnitude(s)),
        tuple(mag.angle(s)),
        tuple(mag.elevation(s)),
        scene.poisson_ratio,
        scene.rod.poisson_ratio,
        tuple(scene.scales),
        scene.models,
        tuple(sorted(scene.rod_options.items())),
        tuple(sorted(scene.fem_options.items())),
        tuple(sorted(scene.outputs.items())),
    ]
    for label, fld in sorted(scene.fields.items()):
        parts += [label, repr(fld), tuple(fld.B(_PROBES).ravel())]
        parts.append(tuple(np.ravel(getattr(fld, "filaments", ()))))
    return tuple(parts)


_FULL_FINGERPRINT = _fingerprint(parse_scene(FULL))


def _names(line: str, key: str) -> bool:
    return any(line.startswith(key + end) for end in (":", ".", "["))


def check_corruption(path, value):
    """Corrupt one key of FULL: a valid value must be accepted (and, unless it is FULL's own
    value, change the scene); any other must give a SceneError whose every line names the
    corrupted key (or, for a removed key, its table)."""
    data = copy.deepcopy(FULL)
    node = data
    for k in path[:-1]:
        node = node[k]
    key = _key(path)
    removed = value is None and isinstance(node, dict)
    if removed:
        original = node.pop(path[-1])
        valid, changes = key in OPTIONAL, OPTIONAL.get(key, True)
    else:
        original = node[path[-1]]
        node[path[-1]] = value
        valid = any(_same(value, v) for v in VALID_JUNK.get(key, []))
        changes = not _same(value, original)
    try:
        scene, problems = parse_scene(data), None
    except SceneError as exc:
        scene, problems = None, exc.problems
    if problems is not None:
        assert not valid, f"{key} = {value!r} is valid but was rejected: {problems}"
        assert problems, "a SceneError without problems"
        allowed = [key] + ([_key(path[:-1])] if removed and len(path) > 1 else [])
        for line in problems:
            assert any(_names(line, k) for k in allowed), f"{key} = {value!r}: {line!r}"
        return
    assert valid, f"{key} = {value!r} was silently accepted"
    if changes:
        assert _fingerprint(scene) != _FULL_FINGERPRINT, f"{key} = {value!r} changed nothing"


@pytest.mark.stress
@settings(max_examples=300, deadline=None, derandomize=True)
@given(path=st.sampled_from(_PATHS), value=st.sampled_from(_JUNK))
def test_any_corrupted_value_gives_a_scene_error(path, value):
    """Whatever a user writes in any key, the answer is the scene they meant or a SceneError
    naming that key -- never another exception (a traceback in the CLI), never a wrong value
    taken silently."""
    check_corruption(path, value)


@pytest.mark.parametrize(
    ("path", "value"),
    [
        (("output", "figures"), "no"),
        (("output", "tables"), 0),
        (("field", "compare_ideal"), "false"),
        (("field", "coil", 0, "turns"), True),
        (("field", "coil", 0, "turns"), 1.5),
        (("field", "coil", 0, "axis"), "--z"),
        (("field", "coil", 0, "spacing"), "5 mm"),
        (("load", "steps"), 1e20),
        (("robot", "length"), "1e300 m"),
        (("rod", "nodes"), 10**9),
        (("robot", "magnetization", "segment"), 4),
        (("name",), 5),
    ],
)
def test_known_silent_misreads_are_errors(path, value):
    # values the scene once read silently (or crashed on): each is now an error naming its key
    check_corruption(path, value)


def test_the_oracle_accepts_what_it_should():
    # the fuzz test's oracle against itself: every listed valid value parses and changes the
    # scene (a typo in VALID_JUNK would make the fuzz test reject good values)
    for key, values in VALID_JUNK.items():
        path = next(p for p in _PATHS if _key(p) == key)
        for value in values:
            check_corruption(path, value)
    for key in OPTIONAL:
        path = next(p for p in _PATHS if _key(p) == key)
        check_corruption(path, None)
