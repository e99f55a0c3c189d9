"""Control scenes with a 3D target (x, y, z) and a tip direction.

References: the shipped example run by the CLI (on a coarse rod: 8 nodes, 3 load steps) is
checked by an independent forward solve (``solve_rod`` at tolerance 1e-11) in the system the
library builds from the same preset; the runner's direction miss against the angle between the
target direction and the tip tangent of that independent solve; validation by the key each
problem names.
"""

import copy
import json
import tomllib
import warnings

import numpy as np
import pytest
from test_scene_control import control_with, problems_of, run_cli

import coils
from coilrod import solve_rod
from coilrod.control import ControlResult
from coilrod.scene import control_runner as runner
from coilrod.scene import parse_scene
from coilrod.scene.cli import shipped_scenes

L = 0.04
NODES = 8


def _forward(system, currents):
    """Last state of an independent forward solve (the spatial rod), tolerance 1e-11."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return solve_rod(
            parse_scene(control_with()).rod,
            system.with_currents(currents),
            np.linspace(0.1, 1.0, 10),
            tol=1e-11,
            nodes=NODES,
        )


def test_the_shipped_3d_example_runs(tmp_path):
    """control_cardiomag_3d through ``coilrod run`` (coarse): exit 0, the real controller's
    currents put the tip on (x, y, z) in an independent solve in the library's CardioMag, the
    ideal one's reported miss is that solve's distance, and the outputs carry z."""
    data = tomllib.loads(shipped_scenes()["control_cardiomag_3d"].read_text())
    data["rod"] = {"nodes": NODES}
    data["load"]["steps"] = 3
    path = tmp_path / "scene.toml"
    path.write_text(_toml(data))
    code, out, err = run_cli("run", str(path), "--out", str(tmp_path / "out"), "--no-progress")
    assert (code, err) == (0, "")
    summary = json.loads((tmp_path / "out" / "control.json").read_text())
    target = 1e-3 * np.array(summary["target_mm"])
    assert target.shape == (3,)
    # the plan the run prints names the 3D target, not an (x, y) in the plane
    shown = ", ".join(f"{1e3 * v:.6g}" for v in target)
    assert f"target: tip at ({shown}) mm (3D" in out
    assert "in the plane" not in out
    assert abs(target[2]) > 0.4 * L  # well out of the plane
    system = coils.presets.cardiomag()
    for run in summary["runs"]:
        res = _forward(system, np.array(run["currents_A"]))
        assert res.model == "spatial"
        tip = res.tip[-1]
        np.testing.assert_allclose(
            [run["tip_x_mm"], run["tip_y_mm"], run["tip_z_mm"]], 1e3 * tip, atol=1e-6
        )
        if run["model"] == "real":
            assert np.linalg.norm(tip - target) <= 1e-6 * L
        else:
            assert run["miss_mm"] == pytest.approx(1e3 * np.linalg.norm(tip - target), rel=1e-6)
    assert "real-field tip z (mm)" in out
    header = (tmp_path / "out" / "control.csv").read_text().splitlines()[0].split(",")
    assert "tip_z_mm" in header
    assert "direction_miss_deg" not in header
    assert (tmp_path / "out" / "control.png").stat().st_size > 0


def _toml(data) -> str:
    """A small TOML writer for the scene dicts used here (tables of scalars, lists, inline
    tables one level deep)."""

    def value(v):
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        return repr(v)

    top = [f"{k} = {value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    tables = [
        f"[{k}]\n" + "\n".join(f"{kk} = {value(vv)}" for kk, vv in v.items())
        for k, v in data.items()
        if isinstance(v, dict)
    ]
    return "\n".join(top) + "\n\n" + "\n\n".join(tables) + "\n"


def test_a_direction_reaches_the_solver_and_its_miss_the_outputs(monkeypatch, tmp_path):
    """The direction, normalised, is passed to solve_currents; the table, summary and JSON
    carry the direction miss it reports, here that of a forward solve at fixed currents
    against the angle computed independently from the solve's tip tangent."""
    system = coils.presets.three_axis_helmholtz()
    currents = system.currents_for(B=(0.0, 0.005, -0.004))
    res = _forward(system, currents)
    tangent = res.frames(len(res) - 1)[-1, :, 0]
    direction = np.array([0.0, 3.0, -4.0])
    seen = {}

    def fake(rod, system, target, **kwargs):
        seen.update(kwargs)
        d = kwargs["direction"]
        return ControlResult(
            currents=currents,
            tip=res.tip[-1].copy(),
            tip_angle=float(res.tip_angle[-1]),
            miss=float(np.linalg.norm(res.tip[-1] - target)),
            angle_miss=None,
            power=float("nan"),
            result=res,
            model=kwargs["model"],
            target=np.asarray(target),
            solves=1,
            start_solves=0,
            history=[0.0],
            tip_direction=tangent,
            direction_miss=float(np.arccos(np.clip(tangent @ d, -1, 1))),
        )

    monkeypatch.setattr(runner, "solve_currents", fake)
    tip_mm = [f"{1e3 * v} mm" for v in res.tip[-1]]
    scene = parse_scene(
        control_with(control={"target": tip_mm, "direction": direction.tolist(), "model": "real"})
    )
    result = runner.run_control(scene)
    np.testing.assert_allclose(seen["direction"], direction / 5.0, rtol=0, atol=1e-15)
    want = np.degrees(np.arccos(tangent @ (direction / 5.0)))
    assert want > 1.0  # the fixed currents miss the direction
    row = result.table()[0]
    assert row["direction_miss_deg"] == pytest.approx(want, rel=1e-12)
    assert row["tip_z_mm"] == pytest.approx(1e3 * res.tip[-1, 2], rel=1e-12)
    assert "from the target direction" in row["error"]  # the direction missed: not ok
    assert "direction miss (deg)" in result.summary()
    assert "tip direction (0, 0.6, -0.8)" in result.summary()
    result.write(tmp_path)
    saved = json.loads((tmp_path / "control.json").read_text())
    assert saved["target_direction"] == pytest.approx([0.0, 0.6, -0.8])
    assert saved["runs"][0]["direction_miss_deg"] == pytest.approx(want, rel=1e-12)


#: x and y Helmholtz pairs: no B_z at the centre (a planar-only system)
PLANAR = [
    {"type": "helmholtz", "radius": "90 mm", "turns": 150, "axis": "x"},
    {"type": "helmholtz", "radius": "120 mm", "turns": 250, "axis": "y"},
]
BAD = [
    (
        {"preset": None, "coil": PLANAR},
        {"target": ["10 mm", "20 mm", "5 mm"], "max_current": "5 A"},
        "control.target: a 3D target (x, y, z) needs a system whose channels make every field "
        "direction at its centre; the centre field per ampere of 2 listed coils has rank 2",
    ),
    ({}, {"target": ["10 mm", "20 mm", "5 mm"], "direction": [0, float("nan"), 1]},
     "control.direction[1]: must be finite"),
    ({}, {"target": ["10 mm", "20 mm", "5 mm"], "direction": [0, 0, 0]},
     "control.direction: must have a non-zero length"),
    ({}, {"target": ["10 mm", "20 mm", "5 mm"], "direction": [0, 1]},
     "control.direction: expected a list of 3 numbers"),
    ({}, {"target": ["10 mm", "20 mm", "5 mm"], "direction": ["0", 1, 0]},
     "control.direction[0]: expected a number"),
    ({}, {"direction": [0, 1, 0]}, "control.direction: a tip direction is for a target (x, y, z)"),
    ({}, {"target": ["10 mm", "20 mm", "5 mm"], "angle": "30 deg"},
     "control.angle: a tip angle is for a target (x, y) in the bending plane"),
    ({}, {"target": ["10 mm", "20 mm", "5 mm", "1 mm"]}, "control.target: expected a list of 2"),
    ({}, {"target": ["10 mm", "30 mm", "30 mm"]}, "control.target: (10 mm, 30 mm, 30 mm) is"),
]  # fmt: skip


@pytest.mark.parametrize(("field", "control", "message"), BAD, ids=range(len(BAD)))
def test_bad_3d_targets_name_their_key(field, control, message):
    problems = problems_of(control_with(field=field, control=control))
    assert any(line.startswith(message) for line in problems), problems


def test_a_3d_target_and_direction_parse():
    data = copy.deepcopy(control_with(control={"target": ["10 mm", "20 mm", "-5 mm"]}))
    data["control"]["direction"] = [1, 1, 0]
    spec = parse_scene(data).control
    assert spec.spatial
    np.testing.assert_allclose(spec.target, (0.010, 0.020, -0.005))
    np.testing.assert_allclose(spec.direction, np.array([1.0, 1.0, 0.0]) / np.sqrt(2))
