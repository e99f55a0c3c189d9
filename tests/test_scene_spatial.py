"""Scenes with the spatial rod: the rod table's model and clamp rotation, 3D figures and VTK
output."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from _scenes import scene_with
from scipy.spatial.transform import Rotation

from coilrod.scene import SceneError, parse_scene
from coilrod.scene.cli import main
from coilrod.scene.parse import load_scene
from coilrod.scene.planner import plan_scene
from coilrod.scene.runner import run_scene

EXAMPLE = "coilrod/scene/examples/tilted_clamp_3d.toml"


def test_rod_table_keys():
    scene = parse_scene(
        scene_with(
            rod={"model": "spatial", "clamp_rotation": {"axis": [1, 0, 0], "angle": "30 deg"}}
        )
    )
    assert scene.rod_options["model"] == "spatial"
    expected = Rotation.from_rotvec([np.pi / 6, 0, 0]).as_matrix()
    assert np.abs(scene.rod_options["clamp_rotation"] - expected).max() < 1e-15


@pytest.mark.parametrize(
    ("rod", "match"),
    [
        ({"model": "3d"}, "rod.model"),
        ({"clamp_rotation": {"axis": [0, 0, 0], "angle": "1 deg"}}, "non-zero"),
        ({"clamp_rotation": {"axis": [1, 0], "angle": "1 deg"}}, "3 numbers"),
        ({"clamp_rotation": {"axis": [1, 0, 0]}}, "expected a table"),
        ({"clamp_rotation": {"axis": [1, 0, 0], "angle": "1 m"}}, "angle"),
    ],
)
def test_bad_rod_table(rod, match):
    with pytest.raises(SceneError, match=match):
        parse_scene(scene_with(rod=rod))


def test_clamp_rotation_with_fem_is_refused():
    data = scene_with(rod={"clamp_rotation": {"axis": [1, 0, 0], "angle": "10 deg"}})
    data["models"] = {"run": ["rod", "fem2d"]}
    with pytest.raises(SceneError, match="rod runs only"):
        parse_scene(data)


def test_example_runs_spatial_and_writes_3d_outputs(tmp_path):
    scene = load_scene(EXAMPLE)
    result = run_scene(scene, progress=False)
    run = result.run("rod", "coils")
    assert run.result.model == "spatial"
    assert np.abs(run.result.tip[-1, 2]) > 1e-4  # out of the plane, m
    files = {p.name for p in result.write(tmp_path)}
    assert "shapes_3d.png" in files
    assert any(name.endswith(".pvd") for name in files)
    assert any(name.endswith(".vtu") for name in files)
    # the figures show what they claim: every labelled curve visible, no text over another,
    # the suptitle says "leaves its plane" once, the x-z view is no strip and has a legend
    import matplotlib.pyplot as plt
    from _figure_checks import assert_readable

    from coilrod.scene.figures import plot_scene_shapes, plot_scene_shapes_3d, plot_tip_vs_field

    for plot in (plot_tip_vs_field, plot_scene_shapes, plot_scene_shapes_3d):
        fig = plot(result).figure
        assert_readable(fig)
        plt.close(fig)
    # the tables keep the tip's z (issue 23: tip_path.csv had no z, summary.json two components)
    with (tmp_path / "tip_path.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    for label in ("coils", "ideal"):
        tip = result.run("rod", label).result.tip  # the solve_rod call's own result
        got = np.array(
            [[float(r[f"tip_{c}_mm"]) for c in "xyz"] for r in rows if r["field"] == label]
        )
        np.testing.assert_allclose(got, 1e3 * tip, rtol=1e-12, atol=1e-12)
    summary = json.loads((tmp_path / "summary.json").read_text())
    (shift,) = summary["shift"]
    np.testing.assert_allclose(shift["coil_tip_mm"], 1e3 * run.result.tip[-1], rtol=1e-12)
    tips = {r["field"]: r["tip_mm"] for r in summary["runs"]}
    np.testing.assert_allclose(tips["coils"], 1e3 * run.result.tip[-1], rtol=1e-12)
    assert abs(tips["coils"][2]) > 0.1  # mm, out of the plane


def test_planar_tables_have_z_at_the_clamp(tmp_path):
    scene = parse_scene(scene_with(load__steps=2, output={"figures": False}))
    result = run_scene(scene, progress=False)
    result.write(tmp_path)
    with (tmp_path / "tip_path.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    tip = result.run("rod", "ideal").result.tip
    np.testing.assert_allclose([float(r["tip_z_mm"]) for r in rows], 1e3 * tip[:, 2], atol=0)
    assert np.all(tip[:, 2] == 0.0)


# -- scene checks and the cache of a robot that can leave its plane (issue 23) --------------------
FEM2D_OUT_OF_PLANE = """\
name = "fem2d in an out-of-plane field"
[robot]
length = "40 mm"
thickness = "2 mm"
width = "2 mm"
youngs_modulus = "1 MPa"
magnetization = { preset = "M1" }
[field]
type = "uniform"
B = "5 mT"
direction = [0, 2, 3]
[load]
steps = 2
[models]
run = ["MODELS"]
"""


def test_check_refuses_fem2d_in_an_out_of_plane_field(tmp_path, capsys):
    """The 2D FEM would keep (B_x, B_y) and drop B_z: check reports it, by the planar rod's
    criterion; fem3d alone is fine."""
    path = tmp_path / "scene.toml"
    path.write_text(FEM2D_OUT_OF_PLANE.replace("MODELS", "fem2d"))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "field.direction: the field has an out-of-plane component B_z" in err
    assert "planar fem2d model would drop" in err
    path.write_text(FEM2D_OUT_OF_PLANE.replace("MODELS", "fem3d"))
    assert main(["check", str(path)]) == 0
    capsys.readouterr()


def _small_coil(**rod):
    """A 5 mm coil around the +y axis at y = 20 mm: clear of a robot along +x, on the path of
    one whose clamp is turned 90 deg about z."""
    coil = {
        "type": "coil",
        "radius": "5 mm",
        "turns": 10,
        "current": "1 A",
        "axis": "x",
        "center": ["0 mm", "20 mm", "0 mm"],
    }
    return scene_with(field={"type": "coils", "coil": [coil]}, **rod)


def test_check_clearance_follows_the_rotated_clamp():
    parse_scene(_small_coil())  # along +x: clear of the coil
    rotated = {"clamp_rotation": {"axis": [0, 0, 1], "angle": "90 deg"}}
    with pytest.raises(SceneError, match=r"s = 15 mm .* along the rotated clamp's tangent"):
        parse_scene(_small_coil(rod=rotated))
    tilted = {"model": "spatial", "clamp_rotation": {"axis": [0, 1, 0], "angle": "90 deg"}}
    parse_scene(_small_coil(rod=tilted))  # along -z (t = R e_x): clear again


def test_cache_covers_a_robot_that_leaves_its_plane():
    """An elevated magnetization takes the robot out of the plane z = 0: the cached field's box
    was the plane's (+- the section) and the solve failed at scale ~0.2 ("outside the grid
    box").  The cache now covers the ball of radius L, and agrees with direct evaluation."""
    data = scene_with(
        robot__magnetization={"magnitude": "128 kA/m", "angle": "0 deg", "elevation": "30 deg"},
        field={
            "type": "coils",
            "coil": [
                {"type": "helmholtz", "radius": "150 mm", "turns": 200, "B": "10 mT", "axis": "y"}
            ],
        },
        load__steps=3,
    )
    scene = parse_scene(data)
    plan = plan_scene(scene, cache=True)
    L = scene.rod.length
    assert plan.cache_box is not None
    assert plan.cache_box[1][2] > L
    cached = run_scene(scene, plan=plan, progress=False).run("rod", "coils")
    direct = run_scene(scene, plan=plan_scene(scene, cache=False), progress=False)
    direct = direct.run("rod", "coils")
    assert not cached.error
    assert not direct.error
    assert direct.tip[-1, 2] < -0.1 * L  # well out of the plane
    np.testing.assert_allclose(cached.tip, direct.tip, atol=1e-9 * L)
    # a planar robot keeps the thin box
    flat = parse_scene({**data, "robot": {**data["robot"], "magnetization": {"preset": "M1"}}})
    assert plan_scene(flat, cache=True).cache_box[1][2] < 0.1 * L
