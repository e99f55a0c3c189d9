"""Scenes with the spatial rod: the rod table's model and clamp rotation, 3D figures and VTK
output."""

from __future__ import annotations

import numpy as np
import pytest
from _scenes import scene_with
from scipy.spatial.transform import Rotation

from coilrod.scene import SceneError, parse_scene
from coilrod.scene.parse import load_scene
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
