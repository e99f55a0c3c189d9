"""Damaged, ambiguous and absurd input files and unwritable outputs: one clear error naming the
file (never a traceback from inside a library, never a silently wrong number), and outputs
written whole or not at all."""

import json
import os

import numpy as np
import pytest

from coilrod.contact import MeshVessel, read_centerline
from coils import MPEM
from coils._files import MissingFileError, NotAFileError
from coils.presets import NAVION_FILE, _data_file

GOOD_CSV = "x,y,z,radius\n0,0,0,1\n10,0,0,1\n20,0,0,1\n"
VTP = """<?xml version="1.0"?><VTKFile type="PolyData"><PolyData><Piece NumberOfPoints="3">
<Points><DataArray NumberOfComponents="3" format="ascii">0 0 0 10 0 0 20 0 0</DataArray></Points>
<PointData><DataArray Name="radius" format="ascii">1 1 1</DataArray></PointData>
<Lines><DataArray Name="connectivity" format="ascii">CONN</DataArray>
<DataArray Name="offsets" format="ascii">OFFS</DataArray></Lines></Piece></PolyData></VTKFile>"""


def _vtp(conn="0 1 2", offs="3"):
    return VTP.replace("CONN", conn).replace("OFFS", offs)


# each case failed on the old code: a traceback (IndexError, a bare UnicodeDecodeError or
# reshape error not naming the file), or a vessel built from the wrong column or points
@pytest.mark.parametrize(
    ("name", "content", "match"),
    [
        ("h.csv", "x,y,z,radius\n", "header but no points"),  # IndexError
        ("b.csv", b"x,y,z,radius\n0,0,0,1\n1\xe9,0,0,1\n", "not UTF-8 text.*line 3"),
        ("x.csv", "x,y,z,x,radius\n0,0,0,5,1\n10,0,0,6,1\n", r"\['x'\] appear more than once"),
        ("r.csv", "x,y,z,radius,r\n0,0,0,1,2\n10,0,0,1,2\n", "2 radius columns"),
        ("l.csv", "x,y,z,radius\n0,0,0,1,99\n10,0,0,1\n", "line 2 has 5 cells"),
        ("s.csv", "x,y,z,radius\n0,0,0,1\n10,0\n", "line 3 has 2 cells"),
        ("p.vtp", _vtp().replace("20 0 0<", "20 0<"), "8 numbers, not 3 per point"),
        ("f.vtp", _vtp(conn="0 1.7 2"), "whole numbers"),  # 1.7 was read as point 1
        ("o.vtp", _vtp(offs="9"), "offset is 9"),  # past the 3 entries: ignored
        ("z.vtp", _vtp(offs="0"), "offset is 0"),  # a numpy reduction error
    ],
)
def test_centerline_file_damage_is_one_error_naming_it(tmp_path, name, content, match):
    path = tmp_path / name
    if isinstance(content, str):
        content = content.encode()
    path.write_bytes(content)
    with pytest.raises(ValueError, match=f"{name}.*{match}"):
        read_centerline(path)


def test_centerline_file_paths_and_a_bom(tmp_path):
    # a folder was reported as "does not exist"; a missing file is also a FileNotFoundError
    with pytest.raises(NotAFileError, match="is a folder"):
        read_centerline(tmp_path)
    with pytest.raises(MissingFileError, match="none.csv.*does not exist"):
        read_centerline(tmp_path / "none.csv")
    with pytest.raises(FileNotFoundError):
        read_centerline(tmp_path / "none.csv")
    # a spreadsheet's byte-order mark: the same vessel as without (gap closed form r - |y|)
    path = tmp_path / "bom.csv"
    path.write_bytes(b"\xef\xbb\xbf" + GOOD_CSV.encode())
    v = read_centerline(path, units="mm")
    np.testing.assert_allclose(v.gap([[0.005, 0.0004, 0.0]]), [0.6e-3], atol=1e-15)


# -- meshes -------------------------------------------------------------------------------------
trimesh = pytest.importorskip("trimesh")


def _cube_stl():
    return trimesh.creation.box(extents=(2e-3,) * 3).export(file_type="stl")


@pytest.mark.parametrize(
    ("name", "content", "match"),
    [
        # a damaged binary STL ended in trimesh's text fallback: "No module named
        # 'charset_normalizer'"
        ("t.stl", lambda: _cube_stl()[:300], r"cannot be read as \.stl: not a valid file"),
        ("g.obj", lambda: bytes(range(256)) * 2, r"cannot be read as \.obj: not a valid file"),
        ("noext", _cube_stl, "has no extension"),  # "file_type '/tmp/.../noext'"
        ("c.foo", _cube_stl, r"\.foo is not a mesh format"),
    ],
)
def test_mesh_file_damage_is_one_error_naming_it(tmp_path, name, content, match):
    path = tmp_path / name
    path.write_bytes(content())
    with pytest.raises(ValueError, match=f"{name}.*{match}") as err:
        MeshVessel.from_file(path)
    assert "charset" not in str(err.value)
    with pytest.raises(NotAFileError, match="is a folder"):  # was "does not exist"
        MeshVessel.from_file(tmp_path)


# -- MPEM calibrations --------------------------------------------------------------------------
SRC0_B = "      - -0.0007771057508049871\n"


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        # YAML keeps the last of two keys: the source's coefficient silently became 1.0
        ("    A_Coeff: ~\n", "    A_Coeff: ~\n    B_Coeff: [1.0]\n", "'B_Coeff' is given twice"),
        # numpy reads true as 1 and '-1e-3' as -1e-3
        (SRC0_B, "      - true\n", r"B_Coeff must be 1 numbers; got \[True\]"),
        (SRC0_B, "      - '-1e-3'\n", "B_Coeff must be 1 numbers"),
        # the same coil twice: two channels driving one coil
        ("  - Coil_1\n", "  - Coil_0\n", r"Coil_List names coil\(s\) \['Coil_0'\] more than once"),
        # the same source twice: its moment counted twice
        ("    - Src_1\n", "    - Src_0\n", r"Source_List names source\(s\) \['Src_0'\] more"),
    ],
)
def test_mpem_file_mistakes_are_errors_not_other_fields(tmp_path, old, new, match):
    text = _data_file(NAVION_FILE).read_text()
    assert old in text
    path = tmp_path / "cal.yaml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(ValueError, match=f"cal.yaml.*{match}"):
        MPEM.from_yaml(path)


def test_mpem_file_paths_and_bytes(tmp_path):
    with pytest.raises(ValueError, match="path must be a file name"):  # was a TypeError
        MPEM.from_yaml(None)
    with pytest.raises(FileNotFoundError, match="none.yaml.*does not exist"):
        MPEM.from_yaml(tmp_path / "none.yaml")
    path = tmp_path / "bin.yaml"
    path.write_bytes(b"Coil_List: [a]\n\xff\xfe")  # a bare UnicodeDecodeError, no file named
    with pytest.raises(ValueError, match=r"bin.yaml.*not UTF-8 text \(byte 0xff on line 2\)"):
        MPEM.from_yaml(path)


def test_scene_files_and_data_files_share_one_utf8_reader(tmp_path, monkeypatch):
    # load_scene had its own copy of read_text's reading and UTF-8 check; now both call
    # read_utf8 with their own wording (a path with braces is not taken for template fields).
    # After a byte-order mark both copies named the wrong byte and line (0x78 on line 1: the
    # decoder's offset counts from after the mark)
    import coilrod.scene.parse as parse
    from coils._files import read_text, read_utf8

    path = tmp_path / "{odd} name.toml"
    path.write_bytes(b'\xef\xbb\xbfname = "x"\n\xff\n')
    calls = []
    monkeypatch.setattr(parse, "read_utf8", lambda p, **kw: calls.append(p) or read_utf8(p, **kw))
    with pytest.raises(SceneError) as err:
        parse.load_scene(path)
    assert calls == [path]
    assert err.value.problems == [
        f"{path}: not UTF-8 text (byte 0xff on line 2); save the scene file as UTF-8"
    ]
    with pytest.raises(ValueError, match=r"data file '.*\{odd\} name.toml' is not UTF-8 text"):
        read_text(path, "data file")


def test_a_damaged_numba_cache_index_is_removed_before_the_kernel_runs(tmp_path, monkeypatch):
    # numba's loader catches only a missing index: a damaged one raised from inside the
    # kernel's first call (the ski rental counted it as cached, so it bought at once).  Now
    # the rental removes it with a warning when it buys, and numba compiles anew.  Nothing is
    # compiled here: numba's own loader reads the index, before and after
    import pickle
    import sys
    from pathlib import Path

    import numba
    from numba.core import config

    import coils._numba_cache as nc

    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path))  # what NUMBA_CACHE_DIR sets

    def twice(x):
        return 2.0 * x

    kernel = numba.njit(cache=True)(twice)
    index = Path(kernel._cache._cache_file._index_path)
    assert tmp_path in index.parents
    index.parent.mkdir(parents=True, exist_ok=True)
    index.write_bytes(b"not a pickle")
    with pytest.raises(pickle.UnpicklingError):  # what the kernel's first call raised
        kernel._cache._cache_file._load_index()
    monkeypatch.setattr(sys.modules[__name__], "_PRICE", 0.0, raising=False)
    rental = nc.Rental(__name__, lambda: kernel, "_PRICE")
    with pytest.warns(RuntimeWarning, match=r"index of twice '.*' is damaged.*removed it"):
        assert rental.pays()
    assert not index.exists()
    assert kernel._cache._cache_file._load_index() == {}  # numba: an empty cache, compile
    assert not kernel.overloads  # nothing compiled


# -- outputs ------------------------------------------------------------------------------------
from _scenes import scene_with  # noqa: E402

from coilrod.design.sweep_file import SweepFile  # noqa: E402
from coilrod.scene import parse_scene  # noqa: E402
from coilrod.scene.outputs import write_rows  # noqa: E402
from coilrod.scene.parse import SceneError  # noqa: E402
from coilrod.scene.planner import plan_scene  # noqa: E402
from coilrod.scene.runner import ModelRun, SceneResult  # noqa: E402
from coilrod.scene.units import parse_quantity  # noqa: E402


def _mode(path):
    return os.stat(path).st_mode & 0o777


def _umask():
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def test_a_failed_table_write_leaves_the_old_file(tmp_path):
    # csv.DictWriter fails on the second row (an extra key): the old code left the header and
    # the first row in place of the earlier table
    path = tmp_path / "tip_path.csv"
    path.write_text("old table\n")
    with pytest.raises(ValueError, match="fields not in fieldnames"):
        write_rows(path, [{"a": 1.0}, {"a": 2.0, "b": 3.0}])
    assert path.read_text() == "old table\n"
    assert os.listdir(tmp_path) == ["tip_path.csv"]  # no temporary file left
    write_rows(path, [{"a": 1.0}, {"a": 2.0}])  # an existing file is replaced
    assert path.read_text().splitlines() == ["a", "1.0", "2.0"]
    assert _mode(path) == 0o666 & ~_umask()  # as open() would give, not mkstemp's 0600


class _TwoStates:
    """The least a ``write_vtk`` result has: two states of a straight 3-node rod."""

    s = np.linspace(0.0, 0.04, 3)
    scales = [0.5, 1.0]

    def __len__(self):
        return 2

    def centerline(self, k):
        return np.column_stack([self.s, 0 * self.s, k * self.s])

    def frames(self, k):
        return np.broadcast_to(np.eye(3), (3, 3, 3))


@pytest.mark.parametrize("old", [False, True])
def test_vtk_states_are_written_all_or_none(tmp_path, old):
    # the second state's file cannot be written (a folder in its place): the old code had
    # written the first state's file (new, or over an earlier run's) before it failed
    from coilrod.rod.export import write_vtk

    (tmp_path / "rod_001.vtu").mkdir()
    if old:
        (tmp_path / "rod_000.vtu").write_text("an earlier run")
    with pytest.raises(IsADirectoryError, match="cannot write '.*rod_001.vtu'"):
        write_vtk(_TwoStates(), tmp_path / "rod.vtu")
    assert sorted(os.listdir(tmp_path)) == ["rod_000.vtu", "rod_001.vtu"][1 - old :]
    if old:
        assert (tmp_path / "rod_000.vtu").read_text() == "an earlier run"
    (tmp_path / "rod_001.vtu").rmdir()
    files = write_vtk(_TwoStates(), tmp_path / "rod.vtu")
    assert [f.name for f in files] == ["rod_000.vtu", "rod_001.vtu", "rod.pvd"]
    assert sorted(os.listdir(tmp_path)) == ["rod.pvd", "rod_000.vtu", "rod_001.vtu"]


def test_files_written_together_are_removed_when_a_rename_fails(tmp_path, monkeypatch):
    # the publishing step of write_vtk's all-or-none: the first file renamed is taken back
    import coils._files as files

    rename, calls = os.replace, []

    def replace(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            raise PermissionError(13, "Permission denied")
        rename(src, dst)

    def write_both():
        with files.replacing_together() as replacing:
            for name in ("a.txt", "b.txt"):
                with replacing(tmp_path / name) as tmp:
                    tmp.write_text(name)

    monkeypatch.setattr(files.os, "replace", replace)
    with pytest.raises(PermissionError, match=r"cannot write '.*b.txt' \(Permission denied\)"):
        write_both()
    assert os.listdir(tmp_path) == []


def test_a_symlinked_output_is_written_through(tmp_path):
    # the link was replaced by a regular file and the file it points to left as it was
    (tmp_path / "data").mkdir()
    real = tmp_path / "data" / "tip_path.csv"
    real.write_text("old table\n")
    link = tmp_path / "tip_path.csv"
    link.symlink_to(os.path.join("data", "tip_path.csv"))  # relative, as ln -s makes it
    write_rows(link, [{"a": 1.0}])
    assert link.is_symlink()
    assert real.read_text().splitlines() == ["a", "1.0"]
    assert sorted(os.listdir(tmp_path / "data")) == ["tip_path.csv"]  # no temporary left


def _scene_result():
    """Two rod runs (coil and ideal field) whose tip angle is not defined (NaN)."""
    scene = parse_scene(scene_with(load__steps=1, output={"figures": False}))
    tip = np.array([[0.03, 0.02, 0.0]])
    runs = [
        ModelRun("rod", label, np.ones(1), tip, np.array([np.nan]), 0.1)
        for label in ("coils", "ideal")
    ]
    return SceneResult(scene, plan_scene(scene), runs)


def test_scene_outputs_are_strict_json_and_unwritable_files_are_named(tmp_path):
    result = _scene_result()
    result.write(tmp_path / "a")

    def refuse(name):
        raise ValueError(f"{name} in summary.json (not JSON)")

    summary = json.loads((tmp_path / "a" / "summary.json").read_text(), parse_constant=refuse)
    assert summary["shift"][0]["tip_angle_shift_deg"] is None  # was a bare NaN
    assert summary["shift"][0]["tip_shift_mm"] == 0.0
    # a folder where the table goes (enforceable as root, unlike a read-only mode): one line
    # naming the file, not an IsADirectoryError from inside the writer
    (tmp_path / "b" / "tip_path.csv").mkdir(parents=True)
    with pytest.raises(SceneError, match=r"cannot write '.*tip_path.csv'"):
        result.write(tmp_path / "b")
    assert os.listdir(tmp_path / "b") == ["tip_path.csv"]


def test_sweep_table_and_fingerprint_modes(tmp_path):
    # the table rewritten in grid order was mkstemp's 0600: unreadable to the group
    table = SweepFile(tmp_path / "sweep.csv", ["point", "x"], {"point": "int", "x": "number"})
    table.rewrite([{"point": 0, "x": 0.5}])
    assert (tmp_path / "sweep.csv").read_text() == "point,x\n0,0.5\n"
    assert _mode(tmp_path / "sweep.csv") == 0o666 & ~_umask()


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_scene_non_finite_number_is_not_offered_a_unit(value):
    # TOML's nan and inf were answered with "write it as a string with a unit, e.g. 'nan T'"
    with pytest.raises(
        ValueError, match=f"field.B: missing unit in {value}, and the number must be finite.*'5 mT'"
    ):
        parse_quantity(value, "flux density", "field.B")


@pytest.mark.parametrize(
    ("content", "rows"),
    [
        (b"point,x,rod_converged,er", set()),  # killed while writing the header: start again
        (b"\xef\xbb\xbfpoint,x,rod_converged,error\n0,0.5,True,\n", {0}),  # a spreadsheet's BOM
        (b"my notes, not a sweep", None),  # was taken for a cut header and overwritten
    ],
)
def test_sweep_resume_reads_only_its_own_table(tmp_path, content, rows):
    path = tmp_path / "sweep.csv"
    path.write_bytes(content)
    kinds = {"point": "int", "x": "number", "rod_converged": "bool", "error": "text"}
    table = SweepFile(path, list(kinds), kinds)
    if rows is None:
        with pytest.raises(SceneError, match="sweep.csv: not a sweep's table"):
            table.check(resume=True, overwrite=False)
    else:
        assert set(table.check(resume=True, overwrite=False)) == rows


def test_coils_demo_output_folder_that_is_a_file(tmp_path, capsys):
    # was a FileExistsError traceback from mkdir
    from coils.demo import main

    blocker = tmp_path / "maps"
    blocker.write_text("")
    assert main([str(blocker)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("coils.demo: error: cannot create the folder")
    assert "maps" in err


def test_files_in_the_wrong_unit_are_doubted(tmp_path):
    # a centreline in mm read as m (a 1 m radius) and a mesh in m read as mm (2 um across):
    # valid files, absurd vessels; the numbers are kept as given, with a UnitsWarning
    from coilrod import UnitsWarning

    path = tmp_path / "cl.csv"
    path.write_text(GOOD_CSV)
    with pytest.warns(UnitsWarning, match=r"cl.csv.*1 m.*units='mm'"):
        v = read_centerline(path)
    assert v.gap([[5.0, 0.0, 0.0]])[0] == pytest.approx(1.0)
    cube = tmp_path / "cube.stl"
    cube.write_bytes(_cube_stl())
    with pytest.warns(UnitsWarning, match=r"cube.stl.*2e-06 m across.*units='m'"):
        MeshVessel.from_file(cube, units="mm")


@pytest.mark.parametrize("text", ["", "# only a comment\n\n"])
def test_empty_scene_file_is_named(tmp_path, text):
    # was "robot: missing required table ...", not naming the file
    from coilrod.scene.parse import load_scene

    path = tmp_path / "blank.toml"
    path.write_text(text)
    with pytest.raises(SceneError, match="blank.toml: the scene file is empty") as err:
        load_scene(path)
    assert len(err.value.problems) == 1


def test_cli_write_failure_after_the_checks_is_one_line(monkeypatch, capfd):
    # an OSError while writing results (a full disk, the folder removed) was a traceback; a
    # closed pipe (``coilrod scenes | head -1``) was "BrokenPipeError"
    import coilrod.scene.cli as cli

    def fail(exc):
        def command(*args):
            raise exc

        return command

    monkeypatch.setattr(cli, "_command", fail(PermissionError("cannot write 'out/a.csv'")))
    assert cli.main(["scenes"]) == 2
    assert capfd.readouterr().err == "coilrod: error: cannot write 'out/a.csv'\n"
    monkeypatch.setattr(cli, "_command", fail(BrokenPipeError()))
    assert cli.main(["scenes"]) == 1
    assert capfd.readouterr().err == ""
