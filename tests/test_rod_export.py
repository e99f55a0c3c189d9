"""VTK export of rod centrelines (meshio round trip, ParaView collection, errors)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

import coils
from coilrod import Circle, Magnetization, Rod, solve_rod
from coilrod.rod.export import write_vtk


@pytest.fixture(scope="module")
def result():
    rod = Rod(0.04, 1e6, Circle(2e-3), Magnetization(128e3, 0.3))
    return solve_rod(rod, coils.UniformField(B=(1e-3, 5e-3, 3e-3)), [0.5, 1.0], nodes=16)


def test_round_trip(result, tmp_path):
    files = write_vtk(result, tmp_path / "rod.vtu")
    assert [f.name for f in files] == ["rod_000.vtu", "rod_001.vtu", "rod.pvd"]
    mesh = meshio.read(files[1])
    assert np.abs(mesh.points - result.centerline(1)).max() == 0.0
    lines = mesh.cells_dict["line"]
    assert lines.shape == (len(result.s) - 1, 2)
    assert np.array_equal(lines[:, 1] - lines[:, 0], np.ones(len(lines), int))
    assert np.abs(mesh.point_data["tangent"] - result.frames(1)[:, :, 0]).max() == 0.0
    assert np.abs(mesh.point_data["s"] - result.s).max() == 0.0


def test_collection_lists_the_states_with_their_scales(result, tmp_path):
    files = write_vtk(result, tmp_path / "path.vtk")
    root = ET.parse(files[-1]).getroot()
    sets = root.find("Collection").findall("DataSet")
    assert [d.get("file") for d in sets] == ["path_000.vtk", "path_001.vtk"]
    assert [float(d.get("timestep")) for d in sets] == [0.5, 1.0]


def test_result_method(result, tmp_path):
    files = result.write_vtk(tmp_path / "m.vtu", states=[1])
    assert [f.name for f in files] == ["m_001.vtu", "m.pvd"]


def test_one_state(result, tmp_path):
    files = write_vtk(result, tmp_path / "one.vtu", states=-1, frames=False)
    assert files == [tmp_path / "one.vtu"]
    assert "tangent" not in meshio.read(files[0]).point_data


@pytest.mark.parametrize(("states", "match"), [(5, "out of range"), ([0.5], "integers")])
def test_bad_states(result, tmp_path, states, match):
    with pytest.raises(ValueError, match=match):
        write_vtk(result, tmp_path / "x.vtu", states=states)


def test_bad_extension_and_unwritable_directory(result, tmp_path):
    with pytest.raises(ValueError, match=r"\.vtu or \.vtk"):
        write_vtk(result, tmp_path / "x.csv")
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(OSError, match="not a directory"):
        write_vtk(result, blocker / "x.vtu")
