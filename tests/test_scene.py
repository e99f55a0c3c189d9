"""Scene files: validation names the key and the reason; the CLI exits 2 without a traceback."""

import copy
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import coils
from coilrod.scene import SceneError, load_scene, parse_scene
from coilrod.scene.cli import main, shipped_scenes
from coilrod.scene.units import parse_quantity

BASE = {
    "name": "test",
    "robot": {
        "length": "40 mm",
        "diameter": "2 mm",
        "youngs_modulus": "1 MPa",
        "magnetization": {"preset": "M1"},
    },
    "field": {"type": "uniform", "B": "5 mT", "direction": "y"},
    "load": {"steps": 4},
    "models": {"run": ["rod"]},
}


def with_change(path: str, value):
    data = copy.deepcopy(BASE)
    *parents, last = path.split(".")
    node = data
    for p in parents:
        node = node[p]
    if value is None:
        del node[last]
    else:
        node[last] = value
    return data


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
        ("field.type", "rotating", "field.type: expected 'uniform', 'gradient' or 'coils'"),
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
    assert main(["run", str(bad), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "robot.length: must be positive" in err[0]
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


def test_cli_help_teaches():
    proc = subprocess.run(
        [sys.executable, "-m", "coilrod", "--help"], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0
    for word in ("demo", "run", "check", "scenes", "40 mm", "examples"):
        assert word in proc.stdout


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


@pytest.mark.stress
@settings(max_examples=400, deadline=None)
@given(path=st.sampled_from(_PATHS), value=st.sampled_from(_JUNK))
def test_any_corrupted_value_gives_a_scene_error(path, value):
    """Whatever a user writes in any key, the answer is a valid scene or a SceneError naming
    the problem -- never another exception (which the CLI would show as a traceback)."""
    data = copy.deepcopy(FULL)
    node = data
    for k in path[:-1]:
        node = node[k]
    if value is None and isinstance(node, dict):
        del node[path[-1]]
    else:
        node[path[-1]] = value
    try:
        parse_scene(data)
        message = "ok"
    except SceneError as exc:
        message = str(exc)
    assert message
