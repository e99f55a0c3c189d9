"""Navigation scenes: the [insertion] table, `coilrod run` of an insertion (navigation.py)."""

import numpy as np
import pytest

from coilrod.scene import parse
from coilrod.scene.parse import SceneError, load_scene, parse_scene

ROBOT = {
    "length": "40 mm",
    "diameter": "2 mm",
    "youngs_modulus": "1 MPa",
    "magnetization": {"preset": "M1"},
}
BEND = {
    "preset": "bend",
    "bend_radius": "20 mm",
    "angle": "90 deg",
    "radius": "3 mm",
    "straight_before": "5 mm",
    "start": ["-1 mm", "0 mm", "0 mm"],
}


def _scene(insertion, obstacles=None, models=("rod",), **extra):
    data = {
        "robot": ROBOT,
        "field": {"type": "uniform", "B": "8 mT", "direction": "y"},
        "models": {"run": list(models)},
        "insertion": insertion,
        **extra,
    }
    if obstacles is not None:
        data["obstacles"] = obstacles
    return data


@pytest.mark.parametrize(
    ("insertion", "obstacles", "models", "match"),
    [
        ({"lengths": ["6 mm", "40 mm"]}, None, ["rod"], r"insertion: needs the lumen"),
        ({"lengths": ["6 mm"]}, {"vessel": [BEND]}, ["rod"], r"insertion.lengths: expected"),
        ({"lengths": ["9 mm", "6 mm"]}, {"vessel": [BEND]}, ["rod"], r"0 < first < last"),
        ({"lengths": ["6 mm", "50 mm"]}, {"vessel": [BEND]}, ["rod"], r"exceeds the robot"),
        ({"lengths": ["6 mm", "40 mm"], "steps": 1}, {"vessel": [BEND]}, ["rod"], r"steps"),
        ({"lengths": ["6 mm", "40 mm"], "withdraw": "y"}, {"vessel": [BEND]}, ["rod"], "withdr"),
        ({"lengths": ["6 mm", "40 mm"], "speed": 1}, {"vessel": [BEND]}, ["rod"], "unknown key"),
        (
            {"lengths": ["6 mm", "40 mm"]},
            {"vessel": [BEND, BEND]},
            ["rod"],
            r"exactly one obstacle \(the lumen\); got 2",
        ),
        (
            {"lengths": ["6 mm", "40 mm"]},
            {"wall": [{"point": ["0 mm", "8 mm", "0 mm"], "normal": "-y"}]},
            ["rod"],
            r"must be a lumen",
        ),
        ({"lengths": ["6 mm", "40 mm"]}, {"vessel": [BEND]}, ["rod", "fem2d"], "rod alone"),
    ],
)
def test_bad_insertion_tables_are_named(insertion, obstacles, models, match):
    with pytest.raises(SceneError, match=match):
        parse_scene(_scene(insertion, obstacles, models))


def test_the_straight_start_is_the_first_free_length():
    # a 5 mm straight part holds the 6 mm robot an insertion starts with, not the 40 mm one
    scene = parse_scene(_scene({"lengths": ["6 mm", "40 mm"]}, {"vessel": [BEND]}))
    assert scene.rod_options["insertion"]["lengths"][0] == pytest.approx(6e-3)
    data = _scene({"lengths": ["6 mm", "40 mm"]}, {"vessel": [BEND]})
    del data["insertion"]
    with pytest.raises(SceneError, match="straight robot leaves it"):
        parse_scene(data)


def test_navigation_scene_is_the_insertion_it_describes(tmp_path):
    # the scene's run equals coilrod.insert called with the scene's robot, lumen, clamp
    # (origin, +x), field and lengths (insertion and withdrawal by the same steps); its table,
    # summary and figure are written
    import matplotlib

    matplotlib.use("Agg")
    import coilrod
    import coils
    from coilrod.scene.navigation import push_force
    from coilrod.scene.runner import run_scene

    data = _scene(
        {"lengths": ["10 mm", "30 mm"], "steps": 2, "withdraw": True, "nodes": 12},
        {"vessel": [BEND]},
    )
    scene = parse_scene(data)
    result = run_scene(scene)
    assert result.ok
    (run,) = result.runs
    lengths = [0.01, 0.03, 0.01]
    np.testing.assert_allclose(run.result.lengths, lengths, rtol=1e-12)
    (vessel,) = scene.rod_options["obstacles"]
    ref = coilrod.insert(
        scene.rod,
        vessel,
        lengths,
        coils.UniformField(B=(0.0, 8e-3, 0.0)),
        clamp_position=(0.0, 0.0, 0.0),
        clamp_rotation=np.eye(3),
        nodes=12,
    )
    np.testing.assert_allclose(run.result.tip, ref.tip, atol=1e-12)
    assert ref.wall_force_magnitude.max() > 1e-3  # it presses on the wall
    # frictionless: insertion and withdrawal pass through the same states
    np.testing.assert_allclose(ref.tip[0], ref.tip[2], atol=1e-9)
    rows = result.table()
    assert len(rows) == 3
    assert rows[1]["push_force_mN"] == pytest.approx(1e3 * push_force(ref)[1])
    assert rows[1]["wall_force_mN"] == pytest.approx(1e3 * ref.wall_force_magnitude[1])
    # the push force: the clamp balances the wall alone (no friction, a uniform field); where
    # the insertion reports the clamp's axial force from the rod's internal force (friction
    # models), the two agree
    np.testing.assert_allclose(push_force(ref), ref.wall_force[:, 0], atol=0)
    assert abs(push_force(ref)[1]) > 1e-4  # the bend's wall has an axial component
    if len(getattr(ref, "push_force", ())):
        np.testing.assert_allclose(
            ref.push_force, ref.wall_force[:, 0], atol=1e-6 * np.abs(ref.wall_force).max()
        )
    assert "push force" in result.summary()
    names = sorted(p.name for p in result.write(tmp_path / "out"))
    assert names == ["insertion.csv", "navigation.png", "summary.json"]


def test_example_navigation_scenes_load():
    folder = parse.__file__.replace("parse.py", "examples/")
    for name in ("navigation_bend", "navigation_phantom"):
        scene = load_scene(folder + name + ".toml")
        assert "insertion" in scene.rod_options
        (lumen,) = scene.rod_options["obstacles"]
        assert lumen.gap([0.0, 0.0, 0.0])[0] > 1e-3  # the introducer is inside


def test_navigation_scenes_are_not_swept(tmp_path, capsys):
    """A sweep row holds a load path's tips, not an insertion: the CLI and the library refuse
    a navigation scene with one clear line (they wrote a row of AttributeErrors before)."""
    from coilrod import sweep
    from coilrod.scene.cli import main, shipped_scenes

    args = ["sweep", "navigation_bend", "--param", "robot.youngs_modulus=1MPa:2MPa:2"]
    assert main([*args, "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "insertion: a navigation scene ([insertion]) cannot be swept yet" in err
    assert not (tmp_path / "out").exists()
    with pytest.raises(SceneError, match=r"navigation scene \(\[insertion\]\) cannot be swept"):
        sweep(shipped_scenes()["navigation_bend"], {"robot.youngs_modulus": "1 MPa:2 MPa:2"})
