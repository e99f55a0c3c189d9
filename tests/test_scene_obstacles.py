"""The [obstacles] table of TOML scenes (coilrod/scene/obstacles.py)."""

import math

import numpy as np
import pytest

from coilrod.contact import MeshVessel, Vessel, Wall, tessellate
from coilrod.scene import parse
from coilrod.scene.parse import SceneError, load_scene, parse_scene

trimesh = pytest.importorskip("trimesh")

ROBOT = {
    "length": "40 mm",
    "diameter": "2 mm",
    "youngs_modulus": "1 MPa",
    "magnetization": {"preset": "M1"},
}


def _scene(obstacles, models=("rod",)):
    return {
        "robot": ROBOT,
        "field": {"type": "uniform", "B": "5 mT", "direction": "y"},
        "load": {"steps": 2},
        "models": {"run": list(models)},
        "obstacles": obstacles,
    }


def test_example_scene_builds_the_bend_preset():
    scene = load_scene(parse.__file__.replace("parse.py", "examples/navigation_bend.toml"))
    (vessel,) = scene.rod_options["obstacles"]
    ref = Vessel.bend(0.02, math.pi / 2, 3e-3, 0.005, 0.03, start=(-1e-3, 0, 0))
    p = np.random.default_rng(0).uniform(-0.01, 0.06, (50, 3))
    np.testing.assert_allclose(vessel.gap(p), ref.gap(p), atol=1e-15)


def test_wall_mesh_and_friction(tmp_path):
    # a straight lumen (the shipped bend turns 10 mm from the clamp: the straight robot leaves it)
    verts, faces = tessellate(Vessel.straight(0.05, 3e-3, start=(-1e-3, 0, 0)), 12, 2e-3)
    trimesh.Trimesh(verts, faces).export(tmp_path / "lumen.stl")
    scene_file = tmp_path / "s.toml"
    scene_file.write_text("")
    scene = parse_scene(
        _scene(
            {
                "friction": 0.3,
                "wall": [{"point": ["0 mm", "8 mm", "0 mm"], "normal": [0, -1, 0]}],
                "mesh": [{"file": "lumen.stl"}],
            }
        ),
        source=str(scene_file),
    )
    wall, mesh = scene.rod_options["obstacles"]
    assert isinstance(wall, Wall)
    assert isinstance(mesh, MeshVessel)
    assert wall.gap([0.0, 0.0, 0.0])[0] == pytest.approx(8e-3)
    assert mesh.gap([0.02, 0.0, 0.0])[0] == pytest.approx(3e-3 * math.cos(math.pi / 12))
    assert mesh.friction == 0.3  # obstacles.friction reaches the obstacles
    if hasattr(wall, "with_friction"):
        assert wall.friction == 0.3


def test_inward_mesh_names_the_key_and_fix_normals_turns_it(tmp_path):
    # the mesh file's faces wound inward: an error naming the table and the way out, and
    # fix_normals = true gives the outward mesh's gaps (the straight lumen's, closed form)
    verts, faces = tessellate(Vessel.straight(0.05, 3e-3, start=(-1e-3, 0, 0)), 12, 2e-3)
    trimesh.Trimesh(verts, faces[:, ::-1], process=False).export(tmp_path / "inward.stl")
    scene_file = tmp_path / "s.toml"
    scene_file.write_text("")

    def build(**extra):
        return parse_scene(
            _scene({"mesh": [{"file": "inward.stl", **extra}]}), source=str(scene_file)
        )

    with pytest.raises(SceneError, match=r"obstacles.mesh\[0\].file: .*inward.stl.*fix_normals"):
        build()
    with pytest.raises(SceneError, match=r"obstacles.mesh\[0\].fix_normals: expected true or"):
        build(fix_normals="yes")
    (mesh,) = build(fix_normals=True).rod_options["obstacles"]
    assert mesh.gap([0.02, 0.0, 0.0])[0] == pytest.approx(3e-3 * math.cos(math.pi / 12))


@pytest.mark.parametrize(
    ("obstacles", "models", "match"),
    [
        (
            {"friction": -0.1, "wall": [{"point": ["0 mm"] * 3, "normal": "y"}]},
            ["rod"],
            r"obstacles.friction: must be at least 0",
        ),
        ({"tube": []}, ["rod"], r"obstacles.tube: unknown key"),
        ({}, ["rod"], r"obstacles: no obstacle"),
        (
            {"wall": [{"point": ["0 mm", "1 mm", "0 mm"], "normal": "y"}]},
            ["rod"],
            r"obstacles.wall\[0\]: the clamp lies 1 mm outside",
        ),
        (
            {
                "vessel": [
                    {"preset": "bend", "bend_radius": "20 mm", "angle": "90 deg", "radius": "3 mm"}
                ]
            },
            ["rod"],
            r"straight robot leaves it",
        ),
        ({"vessel": [{"preset": "loop"}]}, ["rod"], r"obstacles.vessel\[0\].preset"),
        (
            {"vessel": [{"preset": "straight", "length": "50 mm", "radius": "-3 mm"}]},
            ["rod"],
            r"obstacles.vessel\[0\]",
        ),
        (
            {
                "vessel": [
                    {
                        "preset": "straight",
                        "length": "50 mm",
                        "radius": "0.9 mm",
                        "start": ["-1 mm", "0 mm", "0 mm"],
                    }
                ]
            },
            ["rod"],
            r"obstacles.vessel\[0\]: the robot \(1 mm from its axis.*thicker than the lumen "
            r"\(radius 0.9 mm",
        ),
        ({"mesh": [{"file": "missing.stl"}]}, ["rod"], r"obstacles.mesh\[0\].file: .*missing.stl"),
        (
            {"wall": [{"point": ["0 mm", "8 mm", "0 mm"], "normal": "-y"}]},
            ["rod", "fem2d"],
            r"contact is modelled by the rod only",
        ),
    ],
)
def test_bad_obstacles_are_named(obstacles, models, match):
    with pytest.raises(SceneError, match=match):
        parse_scene(_scene(obstacles, models))


def test_navigation_scene_runs_against_the_wall(tmp_path):
    # the tip's surface is stopped by the lumen's wall 3 mm from the axis; the
    # shapes figure draws the vessel and the contact forces
    import matplotlib

    matplotlib.use("Agg")
    from coilrod.scene.figures import plot_scene_shapes
    from coilrod.scene.runner import run_scene

    data = _scene(
        {
            "vessel": [
                {
                    "preset": "straight",
                    "length": "50 mm",
                    "radius": "3 mm",
                    "start": ["-1 mm", "0 mm", "0 mm"],
                }
            ]
        }
    )
    data["field"]["B"] = "12 mT"
    data["rod"] = {"nodes": 24}
    result = run_scene(parse_scene(data))
    (run,) = result.runs
    tip = run.result.centerline(-1)[-1]
    # the 2 mm rod's surface stops at the wall: its axis 3 mm - 1 mm from the vessel's axis
    assert tip[1] == pytest.approx(3e-3 - 1e-3, abs=1e-8)
    assert np.linalg.norm(run.result.contact_force(len(run.scales) - 1), axis=1).max() > 0
    ax = plot_scene_shapes(result)
    assert any("contact force" in t.get_text() for t in ax.get_legend().get_texts())
