"""Sweeps (``coilrod.sweep``, ``coilrod sweep``): a scene over a grid of parameter values.

Cross-checks, by property:

- values: each row equals the scene solved directly at that point, built independently of the
  scene parser (``solve_rod`` on a hand-built rod and field; the Helmholtz current from its
  closed-form centre field; the closed-form elastica); parameters are read in SI;
- executors: serial, local processes and a real Dask cluster (a ``dask scheduler`` and two
  ``dask worker`` processes on 127.0.0.1) write the same file, byte for byte, in grid order;
- resume: a sweep killed mid-way (and a file cut mid-line) is completed by solving only the
  missing points, into the file an uninterrupted sweep writes; a file of another sweep is
  refused;
- failures: a point whose value makes the scene invalid, a solver that cannot reach the load
  and an unexpected exception each give a row with the error, and the other rows are kept;
- bad input: unknown keys, malformed or empty ranges, wrong units, an unreachable or foreign
  scheduler, an unusable folder: one line each, exit code 2, nothing solved;
- imports: a rod-only sweep imports neither dask nor scikit-fem.
"""

import json
import math
import multiprocessing
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from _scenes import scene_with
from scipy.constants import mu_0

import coilrod
import coilrod.design.sweep as sweep_module
import coils
from coilrod import Circle, ConvergenceError, Rod, presets, solve_rod
from coilrod.rod.elastica import elastica
from coilrod.scene import SceneError, load_scene, parse_scene
from coilrod.scene.cli import main

REPO = Path(coilrod.__file__).resolve().parents[1]
L, D, B, M = 0.04, 2e-3, 5e-3, 0.2 * 640e3  # the base scene: 40 mm, 2 mm, 5 mT, M(1) phi 0.2

#: The base scene with a Helmholtz pair (and its ideal field), rod model only, 2 load steps.
COIL_TOML = """\
name = "sweep test"
[robot]
length = "40 mm"
diameter = "2 mm"
youngs_modulus = "1 MPa"
magnetization = { preset = "M1" }
[field]
type = "coils"
coil = [ { type = "helmholtz", radius = "80 mm", turns = 200, B = "5 mT", axis = "y" } ]
[load]
steps = 2
[rod]
nodes = 16
"""


def coil_scene() -> dict:
    import tomllib

    return tomllib.loads(COIL_TOML)


@pytest.fixture
def coil_file(tmp_path) -> Path:
    path = tmp_path / "coil.toml"
    path.write_text(COIL_TOML, encoding="utf-8")
    return path


@pytest.fixture
def count_solves(monkeypatch):
    """Counts the points solved in this process (serial sweeps)."""
    calls = []
    real = sweep_module.solve_point

    def counting(data, source="<embedded>"):
        calls.append(data)
        return real(data, source)

    monkeypatch.setattr(sweep_module, "solve_point", counting)
    return calls


@pytest.fixture
def no_solving(monkeypatch):
    """Any solve fails the test: bad input must stop the sweep before."""

    def refuse(*args, **kwargs):
        raise AssertionError("a point was solved although the sweep should have stopped")

    monkeypatch.setattr(sweep_module, "solve_point", refuse)
    monkeypatch.setattr(sweep_module, "_run_processes", refuse)


def errors(capsys) -> list[str]:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert all(line.startswith("coilrod: error: ") for line in lines), lines
    return [line.removeprefix("coilrod: error: ") for line in lines]


def magneto_elastic(E: float) -> float:
    """lambda = |M| |B| A L^2 / (E I) of the base scene's robot (circle of diameter D)."""
    A, I = math.pi * D**2 / 4, math.pi * D**4 / 64
    return M * B * A * L**2 / (E * I)


# -- values: each row is the scene solved at that point ---------------------------------------
def test_rows_equal_direct_solves_and_the_closed_form_elastica():
    result = sweep(scene_with(load__steps=3), {"robot.youngs_modulus": "0.5 MPa:2 MPa:4"})
    assert [r["robot.youngs_modulus_Pa"] for r in result.rows] == [5e5, 1e6, 1.5e6, 2e6]
    for row in result.rows:
        E = row["robot.youngs_modulus_Pa"]
        rod = Rod(L, E, Circle(D), presets.M1(M0=640e3, phi=0.2))
        direct = solve_rod(rod, coils.UniformField((0, B, 0)), [1 / 3, 2 / 3, 1.0])
        tip = [row[f"rod_ideal_tip_{c}_m"] for c in "xyz"]
        np.testing.assert_allclose(tip, direct.tip[-1], rtol=0, atol=1e-12 * L)
        ref = elastica(magneto_elastic(E), math.pi / 2, length=L)
        np.testing.assert_allclose(tip[:2], ref.tip, rtol=0, atol=1e-6 * L)
        assert row["rod_ideal_converged"]
        assert row["rod_ideal_stable"]
        assert row["error"] == ""
    # a uniform field has nothing to compare: no coils columns, no shift
    assert not any("coils" in c or "shift" in c for c in result.columns)


def test_coil_rows_equal_a_hand_built_pair_and_its_ideal_field():
    result = sweep(coil_scene(), {"field.coil[0].radius": ["60 mm", 0.12]})
    assert [r["field.coil.0.radius_m"] for r in result.rows] == [0.06, 0.12]
    scales = [0.5, 1.0]
    for row in result.rows:
        R = row["field.coil.0.radius_m"]
        current = B * R / ((4 / 5) ** 1.5 * mu_0 * 200)  # centre field of a Helmholtz pair
        pair = coils.HelmholtzPair(R, 200, current, axis="y")
        rod = Rod(L, 1e6, Circle(D), presets.M1(M0=640e3, phi=0.2))
        real = solve_rod(rod, pair, scales, nodes=16)
        ideal = solve_rod(rod, coils.UniformField((0, B, 0)), scales, nodes=16)
        for label, res in (("coils", real), ("ideal", ideal)):
            tip = [row[f"rod_{label}_tip_{c}_m"] for c in "xyz"]
            np.testing.assert_allclose(tip, res.tip[-1], rtol=0, atol=1e-10 * L)
        shift = np.linalg.norm(real.tip[-1] - ideal.tip[-1])
        np.testing.assert_allclose(row["rod_shift_m"], shift, rtol=1e-6)
    # the smaller pair moves the tip more (the shift decays with the coil radius)
    assert result.rows[0]["rod_shift_m"] > 3 * result.rows[1]["rod_shift_m"] > 0


def test_grid_order_first_parameter_slowest_and_plain_integers_stay_integers():
    result = sweep(
        scene_with(load__steps=1),
        {"rod.nodes": "8:16:2", "robot.magnetization.phi": [0.1, 0.2, 0.3]},
    )
    got = [(r["point"], r["rod.nodes"], r["robot.magnetization.phi"]) for r in result.rows]
    assert got == [
        (0, 8, 0.1),
        (1, 8, 0.2),
        (2, 8, 0.3),
        (3, 16, 0.1),
        (4, 16, 0.2),
        (5, 16, 0.3),
    ]
    assert all(isinstance(r["rod.nodes"], int) for r in result.rows)
    # a key the scene did not set (rod.nodes is absent from it) is honoured
    rod = Rod(L, 1e6, Circle(D), presets.M1(M0=640e3, phi=0.3))
    direct = solve_rod(rod, coils.UniformField((0, B, 0)), [1.0], nodes=8)
    np.testing.assert_allclose(
        [result.rows[2][f"rod_ideal_tip_{c}_m"] for c in "xyz"], direct.tip[-1], atol=1e-12 * L
    )


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        ("500 kPa:2 MPa:4", [5e5, 1e6, 1.5e6, 2e6]),
        ("1MPa:1MPa:1", [1e6]),
        ("2 MPa:1 MPa:2", [2e6, 1e6]),  # decreasing is fine
        (["0.5 MPa", 2e6], [5e5, 2e6]),  # numbers in a sequence are SI
        (np.array([1e6, 3e6]), [1e6, 3e6]),
    ],
)
def test_values_are_read_in_si(spec, expected):
    scene = parse_scene(scene_with())
    (param,) = sweep_module.sweep_parameters({"robot.youngs_modulus": spec}, scene)
    assert list(param.values) == expected
    assert param.column == "robot.youngs_modulus_Pa"
    assert param.scene_value(param.values[0]) == f"{expected[0]!r} Pa"


def test_a_scene_file_a_dict_and_a_parsed_scene_sweep_alike(coil_file):
    params = {"robot.youngs_modulus": "1 MPa:2 MPa:2"}
    rows = [sweep(src, params).rows for src in (coil_file, str(coil_file), load_scene(coil_file))]
    assert rows[0] == rows[1] == rows[2]
    assert rows[0] == sweep(coil_scene(), params).rows


def test_the_file_holds_the_rows_exactly(tmp_path):
    pd = pytest.importorskip("pandas")
    result = sweep(coil_scene(), {"field.coil.0.radius": "60 mm:90 mm:3"}, out=tmp_path)
    assert result.path == tmp_path / "sweep.csv"
    frame = pd.read_csv(result.path)
    assert list(frame.columns) == result.columns
    for col in ("field.coil.0.radius_m", "rod_coils_tip_y_m", "rod_shift_m"):
        assert frame[col].tolist() == [r[col] for r in result.rows]  # repr: exact floats
    assert frame["rod_coils_converged"].tolist() == [True] * 3
    assert result.to_pandas()["rod_shift_m"].tolist() == frame["rod_shift_m"].tolist()


# -- executors: serial == local processes == a Dask cluster -----------------------------------
#: Four points, two of them invalid (phi > 1): the error rows must agree too.
GRID = {"field.coil.0.radius": "60 mm:120 mm:2", "robot.magnetization.phi": [0.2, 1.5]}


@pytest.fixture(scope="module")
def serial_file(tmp_path_factory) -> str:
    out = tmp_path_factory.mktemp("serial")
    result = sweep(coil_scene(), GRID, workers=1, out=out)
    assert result.executor == "serially"
    assert len(result.failed) == 2
    return (out / "sweep.csv").read_text()


def test_local_processes_write_the_serial_file(serial_file, tmp_path):
    result = sweep(coil_scene(), GRID, workers=2, out=tmp_path)
    assert result.executor == "in 2 local processes"
    assert (tmp_path / "sweep.csv").read_text() == serial_file


@pytest.fixture(scope="class")
def dask_cluster(tmp_path_factory):
    """A ``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1, torn down after
    the tests of :class:`TestDaskCluster` (an idle cluster left up to the module's end spun
    ~10 s of CPU in its three processes while the later tests ran)."""
    pytest.importorskip("distributed")
    root = tmp_path_factory.mktemp("dask")
    env = dict(
        os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    )
    info = root / "scheduler.json"
    log = (root / "dask.log").open("w")
    common = ["--no-dashboard", "--host", "127.0.0.1"]
    procs = []
    try:
        procs.append(
            subprocess.Popen(
                [sys.executable, "-m", "dask", "scheduler", "--port", "0", *common]
                + ["--scheduler-file", str(info)],
                cwd=root,
                env=env,
                stdout=log,
                stderr=log,
            )
        )
        deadline = time.monotonic() + 60
        while not (info.exists() and info.read_text().strip()):
            assert procs[0].poll() is None, (root / "dask.log").read_text()
            assert time.monotonic() < deadline, "the dask scheduler did not start"
            time.sleep(0.1)
        address = json.loads(info.read_text())["address"]
        for _ in range(2):
            procs.append(
                subprocess.Popen(
                    [sys.executable, "-m", "dask", "worker", address, *common]
                    + ["--nthreads", "1", "--no-nanny", "--local-directory", str(root)],
                    cwd=root,
                    env=env,
                    stdout=log,
                    stderr=log,
                )
            )
        from distributed import Client

        with Client(address, set_as_default=False) as client:
            client.wait_for_workers(2, timeout=60)
        yield address
    finally:  # the workers first: a worker whose scheduler is gone may wait for it
        for proc in [*procs[1:], *procs[:1]]:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        log.close()


@pytest.mark.cluster
class TestDaskCluster:
    def test_a_dask_cluster_writes_the_serial_file(self, serial_file, dask_cluster, tmp_path):
        result = sweep(coil_scene(), GRID, client=dask_cluster, out=tmp_path / "address")
        assert result.executor == f"on the Dask cluster at {dask_cluster}"
        assert (tmp_path / "address" / "sweep.csv").read_text() == serial_file
        from distributed import Client

        with Client(dask_cluster, set_as_default=False) as client:  # the caller's own client
            sweep(coil_scene(), GRID, client=client, out=tmp_path / "client")
            assert client.status == "running"  # not closed by the sweep
        assert (tmp_path / "client" / "sweep.csv").read_text() == serial_file

    def test_cli_on_a_dask_cluster(self, serial_file, dask_cluster, coil_file, tmp_path, capsys):
        args = ["sweep", str(coil_file), "--out", str(tmp_path), "--scheduler", dask_cluster]
        args += ["--param", "field.coil.0.radius=60mm:120mm:2"]
        args += ["--param", "robot.magnetization.phi=0.2:1.5:2", "--no-progress"]
        assert main(args) == 1  # two points failed
        out = capsys.readouterr().out
        assert f"4 solved on the Dask cluster at {dask_cluster}" in out
        assert "2 failed" in out
        # the scene file's source differs from the dict's, the rows do not
        assert (tmp_path / "sweep.csv").read_text() == serial_file


# -- resume -----------------------------------------------------------------------------------
E_GRID = {"robot.youngs_modulus": "1 MPa:2 MPa:6"}


@pytest.fixture(scope="module")
def full_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("full")
    sweep(scene_with(load__steps=2), E_GRID, workers=1, out=out)
    return out


@pytest.fixture(scope="module")
def full_file(full_dir) -> str:
    return (full_dir / "sweep.csv").read_text()


@pytest.fixture
def fingerprinted(full_dir, tmp_path) -> Path:
    """``tmp_path`` with the full sweep's scene fingerprint (sweep.json) and no table yet."""
    (tmp_path / "sweep.json").write_text((full_dir / "sweep.json").read_text())
    return tmp_path


def test_resume_solves_only_the_missing_points(full_file, tmp_path, fingerprinted, count_solves):
    lines = full_file.splitlines(keepends=True)
    # header, points 0 and 3 written (completion order), point 4 cut by a kill mid-line
    partial = lines[0] + lines[1] + lines[4] + lines[5][:30]
    (tmp_path / "sweep.csv").write_text(partial)
    result = sweep(scene_with(load__steps=2), E_GRID, workers=1, out=tmp_path, resume=True)
    assert (result.reused, result.solved, len(count_solves)) == (2, 4, 4)
    assert (tmp_path / "sweep.csv").read_text() == full_file
    # resuming a finished sweep solves nothing
    result = sweep(scene_with(load__steps=2), E_GRID, workers=1, out=tmp_path, resume=True)
    assert (result.reused, result.solved, len(count_solves)) == (6, 0, 4)
    assert (tmp_path / "sweep.csv").read_text() == full_file


@pytest.mark.parametrize("keep", [0, 8, 40])
def test_resume_of_a_file_cut_in_its_header_starts_again(full_file, tmp_path, keep):
    (tmp_path / "sweep.csv").write_text(full_file[:keep])
    result = sweep(scene_with(load__steps=2), E_GRID, workers=1, out=tmp_path, resume=True)
    assert (result.reused, result.solved) == (0, 6)
    assert (tmp_path / "sweep.csv").read_text() == full_file


def test_resume_without_a_file_runs_the_whole_sweep(full_file, tmp_path):
    result = sweep(scene_with(load__steps=2), E_GRID, workers=1, out=tmp_path, resume=True)
    assert result.solved == 6
    assert (tmp_path / "sweep.csv").read_text() == full_file


def test_a_killed_cli_sweep_resumes_to_the_uninterrupted_file(full_file, tmp_path, count_solves):
    scene = tmp_path / "scene.toml"
    scene.write_text(
        '[robot]\nlength = "40 mm"\ndiameter = "2 mm"\nyoungs_modulus = "1 MPa"\n'
        'magnetization = { preset = "M1" }\n[field]\ntype = "uniform"\nB = "5 mT"\n'
        'direction = "y"\n[load]\nsteps = 2\n',
        encoding="utf-8",
    )
    out = tmp_path / "out"
    args = ["sweep", str(scene), "--param", "robot.youngs_modulus=1MPa:2MPa:6"]
    args += ["--out", str(out), "--workers", "1", "--no-progress"]
    # each point takes a second longer, so that the sweep is killed between two points
    code = (
        "import sys, time\n"
        "import coilrod.design.sweep as sw\n"
        "real = sw.solve_point\n"
        "def slow(data, source):\n"
        "    row = real(data, source)\n"
        "    time.sleep(1.0)\n"
        "    return row\n"
        "sw.solve_point = slow\n"
        "from coilrod.scene.cli import main\n"
        f"sys.exit(main({args!r}))\n"
    )
    env = dict(
        os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    )
    proc = subprocess.Popen([sys.executable, "-c", code], env=env, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while not (
            (out / "sweep.csv").exists() and len((out / "sweep.csv").read_bytes().splitlines()) >= 3
        ):
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "the sweep wrote no rows"
            time.sleep(0.05)
    finally:
        proc.kill()
        proc.wait()
    written = (out / "sweep.csv").read_text().splitlines()
    assert 3 <= len(written) < 7  # killed before the end, every finished point kept
    assert written == full_file.splitlines()[: len(written)]
    assert main([*args, "--resume"]) == 0
    assert len(count_solves) == 7 - len(written)
    assert (out / "sweep.csv").read_text() == full_file


UNIFORM_TOML = """\
# a uniform-field scene
[robot]
length = "40 mm"
diameter = "2 mm"
youngs_modulus = "1 MPa"
magnetization = { preset = "M1" }
[field]
type = "uniform"
B = "5 mT"
direction = "y"
[load]
steps = 2
"""


def test_resume_refuses_the_rows_of_an_edited_scene_and_keeps_those_of_a_reformatted_one(
    tmp_path, capsys, count_solves
):
    """The fingerprint is the parsed scene: B 5 -> 10 mT is refused (exit 2, the key named,
    nothing solved), a changed comment and layout resume, and the resumed rows are a fresh
    sweep's."""
    scene, out = tmp_path / "scene.toml", tmp_path / "out"
    args = ["sweep", str(scene), "--param", "robot.youngs_modulus=1MPa:2MPa:3"]
    args += ["--out", str(out), "--workers", "1", "--no-progress", "--quiet"]
    scene.write_text(UNIFORM_TOML, encoding="utf-8")
    assert main(args) == 0
    lines = (out / "sweep.csv").read_text().splitlines(keepends=True)
    (out / "sweep.csv").write_text("".join(lines[:2]))  # stopped after point 0
    capsys.readouterr()
    del count_solves[:]

    scene.write_text(UNIFORM_TOML.replace('B = "5 mT"', 'B = "10 mT"'), encoding="utf-8")
    assert main([*args, "--resume"]) == 2
    (line,) = errors(capsys)
    assert "solved for another scene (scene content differs: field.B was " in line, line
    assert '"5 mT", now "10 mT"' in line, line
    assert count_solves == []
    assert (out / "sweep.csv").read_text() == "".join(lines[:2])  # untouched

    scene.write_text(
        UNIFORM_TOML.replace("# a uniform-field scene", "# another comment\n\n").replace(
            'B = "5 mT"', 'B   =   "5 mT"   # same field'
        ),
        encoding="utf-8",
    )
    assert main([*args, "--resume"]) == 0
    assert len(count_solves) == 2
    fresh = sweep(scene, {"robot.youngs_modulus": "1MPa:2MPa:3"}, workers=1, progress=False)
    resumed = sweep(scene, {"robot.youngs_modulus": "1MPa:2MPa:3"}, out=out, resume=True)
    assert resumed.reused == 3
    assert resumed.rows == fresh.rows


def test_resume_refuses_rows_of_another_coilrod_version_or_without_a_fingerprint(
    full_file, tmp_path, fingerprinted, no_solving
):
    (tmp_path / "sweep.csv").write_text(full_file)
    record = json.loads((tmp_path / "sweep.json").read_text())
    record["coilrod_version"] = "0.0.1"
    (tmp_path / "sweep.json").write_text(json.dumps(record))
    with pytest.raises(SceneError, match=r"solved by coilrod 0\.0\.1, this is coilrod "):
        sweep(scene_with(load__steps=2), E_GRID, out=tmp_path, resume=True)
    (tmp_path / "sweep.json").unlink()
    with pytest.raises(SceneError, match="sweep.json: missing, so the scene .* is unknown"):
        sweep(scene_with(load__steps=2), E_GRID, out=tmp_path, resume=True)
    assert (tmp_path / "sweep.csv").read_text() == full_file


def test_an_existing_file_needs_resume_or_overwrite(full_file, tmp_path, count_solves):
    (tmp_path / "sweep.csv").write_text("precious\n")
    with pytest.raises(SceneError, match="exists .* --resume .* --overwrite"):
        sweep(scene_with(load__steps=2), E_GRID, out=tmp_path)
    assert (tmp_path / "sweep.csv").read_text() == "precious\n"
    sweep(scene_with(load__steps=2), E_GRID, workers=1, out=tmp_path, overwrite=True)
    assert (tmp_path / "sweep.csv").read_text() == full_file


@pytest.mark.parametrize(
    ("params", "message"),
    [
        (
            {"robot.youngs_modulus": "1 MPa:2 MPa:7"},
            "has robot.youngs_modulus_Pa = 1200000.0 at point 1, this sweep 1166666.666",
        ),
        (
            {"robot.length": "30 mm:40 mm:6"},
            "it has robot.youngs_modulus_Pa; this sweep writes robot.length_m",
        ),
        ({"robot.youngs_modulus": "1 MPa:2 MPa:2"}, "has point 2, this sweep has points 0 to 1"),
    ],
)
def test_resume_refuses_the_file_of_another_sweep(
    full_file, tmp_path, fingerprinted, no_solving, params, message
):
    (tmp_path / "sweep.csv").write_text(full_file)
    with pytest.raises(SceneError, match=message) as info:
        sweep(scene_with(load__steps=2), params, out=tmp_path, resume=True)
    assert len(info.value.problems) == 1
    assert (tmp_path / "sweep.csv").read_text() == full_file


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda ls: ls[:2] + ["1,oops\n"] + ls[3:], "line 3 is damaged .*2 cells, the header has"),
        (lambda ls: ls[:3] + [ls[2]] + ls[4:], "line 4 repeats point 1"),
        (
            lambda ls: ls[:2] + [ls[2].replace("True", "yes", 1)] + ls[3:],
            "line 3 is damaged .*column rod_ideal_converged",
        ),
    ],
)
def test_a_damaged_file_is_named_not_overwritten(
    full_file, tmp_path, fingerprinted, no_solving, damage, message
):
    text = "".join(damage(full_file.splitlines(keepends=True)))
    (tmp_path / "sweep.csv").write_text(text)
    with pytest.raises(SceneError, match=message):
        sweep(scene_with(load__steps=2), E_GRID, out=tmp_path, resume=True)
    assert (tmp_path / "sweep.csv").read_text() == text


# -- failed points are rows with their error --------------------------------------------------
def test_an_invalid_point_is_a_row_with_the_scene_error(tmp_path):
    result = sweep(
        scene_with(load__steps=2), {"robot.magnetization.phi": [0.2, 1.5, 0.3]}, out=tmp_path
    )
    ok, bad, ok2 = result.rows
    assert bad["error"] == (
        "invalid scene at this point: robot.magnetization.phi: must be at most 1 "
        "(a particle volume fraction); got 1.5"
    )
    assert bad["rod_ideal_tip_y_m"] is None
    assert bad["rod_ideal_converged"] is None
    assert ok["error"] == ok2["error"] == ""
    assert ok2["rod_ideal_tip_y_m"] > ok["rod_ideal_tip_y_m"] > 0
    assert result.failed == [bad]
    line = (tmp_path / "sweep.csv").read_text().splitlines()[2]
    assert line.startswith("1,1.5,,,,,,")
    assert line.endswith("got 1.5")


def test_a_point_the_solver_cannot_reach_is_a_row_with_its_message(monkeypatch):
    real = solve_rod

    def failing(rod, field, scales, **kw):
        if rod.youngs_modulus == 2e6:
            raise ConvergenceError("cannot reach scale 0.5 (test)", reached=0.0, target=0.5)
        return real(rod, field, scales, **kw)

    monkeypatch.setattr("coilrod.rod.solve_rod", failing)
    result = sweep(coil_scene(), {"robot.youngs_modulus": "1 MPa:2 MPa:2"}, workers=1)
    good, bad = result.rows
    assert good["error"] == ""
    assert good["rod_coils_converged"]
    assert good["rod_shift_m"] > 0
    assert bad["rod_coils_converged"] is False
    assert bad["rod_ideal_converged"] is False
    assert bad["rod_coils_tip_x_m"] is None
    assert bad["rod_shift_m"] is None
    assert bad["error"] == (
        "rod in the coils field: cannot reach scale 0.5 (test); "
        "rod in the ideal field: cannot reach scale 0.5 (test)"
    )


def test_an_unexpected_exception_is_a_row_not_a_lost_sweep(monkeypatch):
    import coilrod.scene.runner

    real = coilrod.scene.runner.run_scene

    def broken(scene, **kw):
        if scene.rod.youngs_modulus == 1e6:
            raise RuntimeError("something\nbroke")
        return real(scene, **kw)

    monkeypatch.setattr(coilrod.scene.runner, "run_scene", broken)
    result = sweep(scene_with(), {"robot.youngs_modulus": "1 MPa:2 MPa:2"}, workers=1)
    assert [r["error"] for r in result.rows] == ["RuntimeError: something broke", ""]


_SOLVE_POINT = sweep_module.solve_point


def crashing_at_2_mpa(data, source="<embedded>"):
    """``solve_point``, but the process dies (out of memory, a segfault) at E = 2 MPa."""
    if data["robot"]["youngs_modulus"] == "2000000.0 Pa":
        os._exit(3)
    return _SOLVE_POINT(data, source)


@pytest.mark.skipif(
    multiprocessing.get_start_method() != "fork", reason="the crash is patched in by forking"
)
def test_a_worker_process_that_dies_gives_rows_with_the_error(monkeypatch, tmp_path):
    monkeypatch.setattr(sweep_module, "solve_point", crashing_at_2_mpa)
    grid = {"robot.youngs_modulus": "1 MPa:2 MPa:5"}
    result = sweep(scene_with(), grid, workers=2, out=tmp_path)
    assert [r["point"] for r in result.rows] == [0, 1, 2, 3, 4]
    assert result.rows[0]["error"] == ""  # solved before the pool started
    assert result.rows[4]["error"].startswith("worker process: BrokenProcessPool")
    good = [r for r in result.rows if not r["error"]]
    assert all(r["rod_ideal_converged"] for r in good)
    # resuming solves the points whose worker died again (and only those)
    monkeypatch.setattr(sweep_module, "solve_point", _SOLVE_POINT)
    resumed = sweep(scene_with(), grid, out=tmp_path, resume=True)
    assert resumed.solved == len(result.failed)
    assert resumed.rows == sweep(scene_with(), grid).rows


def test_cli_reports_failed_points_exit_1(coil_file, tmp_path, capsys):
    args = ["sweep", str(coil_file), "--param", "robot.magnetization.phi=0.5:1.5:3"]
    assert main([*args, "--out", str(tmp_path), "--workers", "1", "--no-progress"]) == 1
    out = capsys.readouterr().out
    assert "3 points (3 solved serially" in out
    assert "1 failed" in out
    assert "point 2 (robot.magnetization.phi = 1.5): invalid scene at this point" in out
    assert f"wrote {tmp_path / 'sweep.csv'}" in out


# -- bad input: one line each, exit 2, nothing solved -----------------------------------------
@pytest.mark.parametrize(
    ("param", "message"),
    [
        ("robot.foo=1:2:3", "sweep parameter robot.foo: unknown key (allowed here: diameter, "),
        ("foo.bar=1:2:3", "sweep parameter foo.bar: foo: unknown key (allowed here: "),
        (
            "field.coil.3.radius=60mm:90mm:2",
            "sweep parameter field.coil.3.radius: field.coil has 1 entry (indices 0 to 0)",
        ),
        (
            "robot.magnetization=1:2:2",
            "sweep parameter robot.magnetization: is a table; name one value in it",
        ),
        ("field.type=1:2:2", "sweep parameter field.type: is 'coils' in the scene, not a number"),
        ("robot..length=1:2:2", "sweep parameter robot..length: not a scene key"),
        ("robot.youngs_modulus=1MPa:2MPa:0", "N must be at least 1 (the number of values); got 0"),
        (
            "robot.youngs_modulus=1MPa:2MPa:-2",
            "N must be at least 1 (the number of values); got -2",
        ),
        ("robot.youngs_modulus=1MPa:2MPa:2.5", "N must be a whole number of values"),
        ("robot.youngs_modulus=1MPa:2MPa", "expected START:STOP:N"),
        ("robot.youngs_modulus=1MPa::3", "expected START:STOP:N"),
        ("robot.youngs_modulus=", "expected START:STOP:N"),
        ("robot.youngs_modulus=1MPa:2MPa:3:4", "expected START:STOP:N"),
        ("robot.youngs_modulus=a:b:3", "cannot read 'a' as a number with an optional unit"),
        ("robot.youngs_modulus=1 MPa:2 furlong:3", "unknown unit 'furlong'"),
        ("robot.youngs_modulus=1:2:3", "missing unit in '1:2:3'; it is a pressure"),
        (
            "robot.youngs_modulus=1MPa:2:3",
            "START '1MPa' is a pressure but STOP '2' is a plain number",
        ),
        ("robot.youngs_modulus=1mm:2mm:2", "is a pressure in the scene ('1 MPa'); got a length"),
        ("field.coil.0.turns=1mm:2mm:2", "is a plain number in the scene (200); got a length"),
        ("robot.youngs_modulus=1MPa:2MPa:2000000", "at most 1000000 values; got 2000000"),
        ("robot.youngs_modulus", "--param 'robot.youngs_modulus': expected KEY=START:STOP:N"),
    ],
)
def test_cli_bad_parameter(coil_file, tmp_path, capsys, no_solving, param, message):
    args = ["sweep", str(coil_file), "--param", param, "--out", str(tmp_path / "out")]
    assert main(args) == 2
    (line,) = errors(capsys)
    assert message in line, line
    assert not (tmp_path / "out").exists()  # nothing created


def test_cli_reports_every_problem_at_once(coil_file, tmp_path, capsys, no_solving):
    (tmp_path / "file").write_text("")
    args = ["sweep", str(coil_file), "--out", str(tmp_path / "file"), "--workers", "0"]
    args += ["--param", "robot.foo=1:2:2", "--param", "robot.youngs_modulus=1MPa:2MPa:0"]
    args += [
        "--param",
        "field.coil.0.radius=60mm:90mm:2",
        "--param",
        "field.coil[0].radius=1m:2m:2",
    ]
    assert main(args) == 2
    assert errors(capsys) == [
        "--workers: expected a whole number of at least 1; got 0",
        "sweep parameter robot.foo: unknown key (allowed here: diameter, length, magnetization, "
        "poisson_ratio, thickness, width, youngs_modulus)",
        "sweep parameter robot.youngs_modulus: N must be at least 1 (the number of values); got 0",
        "sweep parameter field.coil[0].radius: given twice (also as field.coil.0.radius)",
        f"--out: {tmp_path / 'file'} is an existing file, not a folder; give a folder (new or "
        "existing) for the results",
    ]


def test_cli_bad_scene_and_workers_with_scheduler(tmp_path, capsys, no_solving):
    bad = tmp_path / "bad.toml"
    bad.write_text('[robot]\nlength = "-40 mm"\n')
    args = ["sweep", str(bad), "--param", "robot.length=1mm:2mm:2", "--out", str(tmp_path)]
    assert main(args) == 2
    assert errors(capsys)[0] == "robot.length: must be positive; got -40 mm"
    args = ["sweep", "config_a_m1", "--param", "robot.length=30mm:40mm:2", "--out", str(tmp_path)]
    assert main([*args, "--workers", "2", "--scheduler", "tcp://127.0.0.1:8786"]) == 2
    assert errors(capsys) == [
        "--workers: give either --workers (local processes) or --scheduler, not both"
    ]


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def foreign_server():
    """A TCP server on 127.0.0.1 that answers like a web server, not like dask."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            with conn:
                try:
                    conn.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n")
                except OSError:
                    pass

    threading.Thread(target=serve, daemon=True).start()
    yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    server.close()


@pytest.mark.parametrize(
    ("address", "message"),
    [
        ("closed", "cannot connect (Connection refused); is a Dask scheduler running there"),
        ("foreign", "not a Dask scheduler (no dask handshake"),
        ("nonsense", "scheduler nonsense: not an address, e.g. tcp://10.0.0.5:8786"),
        ("foo://host:1", "unknown scheme 'foo'"),
        ("tcp://no-such-host.invalid:8786", "unknown host 'no-such-host.invalid'"),
        ("", "scheduler: expected the address of a Dask scheduler"),
    ],
)
def test_cli_unreachable_scheduler(
    coil_file, tmp_path, capsys, no_solving, foreign_server, address, message
):
    pytest.importorskip("distributed")
    address = {"closed": f"tcp://127.0.0.1:{_closed_port()}", "foreign": foreign_server}.get(
        address, address
    )
    args = ["sweep", str(coil_file), "--param", "robot.youngs_modulus=1MPa:2MPa:2"]
    assert main([*args, "--out", str(tmp_path / "out"), "--scheduler", address]) == 2
    (line,) = errors(capsys)
    assert message in line, line
    assert not (tmp_path / "out").exists()


def test_cli_unwritable_out_before_any_solve(coil_file, tmp_path, capsys, no_solving, denied):
    locked = tmp_path / "locked"
    locked.mkdir()
    denied(locked)  # as chmod 0o500 would, for root too
    args = ["sweep", str(coil_file), "--param", "robot.youngs_modulus=1MPa:2MPa:2"]
    assert main([*args, "--out", str(locked / "out")]) == 2
    (line,) = errors(capsys)
    assert line == f"--out: cannot create folders in {locked} (permission denied)"


def test_cli_out_below_a_file_before_any_solve(coil_file, tmp_path, capsys, no_solving):
    (tmp_path / "file").write_text("")
    args = ["sweep", str(coil_file), "--param", "robot.youngs_modulus=1MPa:2MPa:2"]
    assert main([*args, "--out", str(tmp_path / "file" / "out")]) == 2
    (line,) = errors(capsys)
    assert line == f"--out: cannot create the folder {tmp_path / 'file' / 'out'}: " + (
        f"{tmp_path / 'file'} is a file"
    )


def test_out_is_a_folder_named_like_the_table(tmp_path, no_solving):
    (tmp_path / "sweep.csv").mkdir()
    with pytest.raises(SceneError, match="sweep.csv: is a folder"):
        sweep(scene_with(), E_GRID, out=tmp_path)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"params": {}}, "sweep parameters: expected at least one scene key and its values"),
        ({"params": {"robot.youngs_modulus": []}}, r"no values \(an empty sequence\)"),
        ({"params": {"robot.youngs_modulus": 3e6}}, "expected 'START:STOP:N' .* or a sequence"),
        ({"params": {"robot.youngs_modulus": [1e6, math.nan]}}, r"\[1\]: must be finite"),
        ({"params": {"robot.youngs_modulus": [True]}}, r"\[0\]: expected a number"),
        ({"params": {"robot.youngs_modulus": ["1 MPa", "1 mm"]}}, "values of different kinds"),
        ({"workers": 0}, "workers: expected a whole number of at least 1; got 0"),
        ({"workers": 2.0}, "workers: expected a whole number"),
        ({"workers": 2, "client": "tcp://127.0.0.1:1"}, "give either workers .* or a client"),
        ({"client": 42}, "client: expected a dask Client or a scheduler address; got 42"),
        ({"resume": True}, "resume: needs the folder of the sweep to resume"),
        (
            {"params": {"robot.youngs_modulus": "1 MPa:2 MPa:1000", "rod.nodes": "8:64:1001"}},
            "sweep parameters: 1001000 points, more than the 1000000 allowed",
        ),
    ],
)
def test_library_bad_input(no_solving, kwargs, message):
    kwargs = {"params": {"robot.youngs_modulus": "1 MPa:2 MPa:2"}, **kwargs}
    with pytest.raises(SceneError, match=message) as info:
        sweep(scene_with(), **kwargs)
    assert len(info.value.problems) == 1
    assert isinstance(info.value, ValueError)


def test_a_scene_without_its_data_cannot_be_swept(no_solving):
    import dataclasses

    scene = dataclasses.replace(parse_scene(scene_with()), data=None)
    with pytest.raises(SceneError, match="built without its TOML data"):
        sweep(scene, E_GRID)


def test_zero_angle_without_unit_takes_angle_values():
    data = scene_with(robot__magnetization={"magnitude": "128 kA/m", "angle": 0})
    (param,) = sweep_module.sweep_parameters(
        {"robot.magnetization.angle": "0 deg:90 deg:3"}, parse_scene(data)
    )
    np.testing.assert_allclose(param.values, [0, math.pi / 4, math.pi / 2], rtol=1e-15)


# -- progress and imports ---------------------------------------------------------------------
def test_progress_bar_can_be_shown_and_hidden(capsys):
    sweep(scene_with(load__steps=1), {"robot.youngs_modulus": "1 MPa:2 MPa:2"}, progress=True)
    assert "sweep: 100%" in capsys.readouterr().err
    sweep(scene_with(load__steps=1), {"robot.youngs_modulus": "1 MPa:2 MPa:2"}, progress=False)
    assert capsys.readouterr().err == ""


def test_rod_only_sweeps_import_neither_dask_nor_scikit_fem(tmp_path):
    code = (
        "import sys\n"
        "import coilrod\n"
        "scene = {'robot': {'length': '40 mm', 'diameter': '2 mm', 'youngs_modulus': '1 MPa',\n"
        "         'magnetization': {'preset': 'M1'}}, 'field': {'type': 'uniform', 'B': '5 mT'},\n"
        "         'load': {'steps': 1}}\n"
        "for workers in (1, 2):\n"
        "    r = coilrod.sweep(scene, {'robot.youngs_modulus': '1 MPa:2 MPa:3'}, workers=workers)\n"
        "    assert not r.failed, r.failed\n"
        "heavy = ('dask', 'distributed', 'skfem')\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in heavy))\n"
    )
    env = dict(
        os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    )
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "[]"


def sweep(scene, params, **kwargs):
    """``coilrod.sweep``, serial and quiet unless told otherwise."""
    if "client" not in kwargs:
        kwargs.setdefault("workers", 1)
    kwargs.setdefault("progress", False)
    return coilrod.sweep(scene, params, **kwargs)


ELEVATION_SCENE = """\
name = "uniform magnetization, no elevation set"
[robot]
length = "40 mm"
diameter = "2 mm"
youngs_modulus = "1 MPa"
magnetization = { magnitude = "128 kA/m", angle = "0 deg" }
[field]
type = "uniform"
B = "5 mT"
[load]
steps = 2
"""


@pytest.mark.parametrize(
    ("param", "message"),
    [
        # a plain 0 passes for an angle: the first grid point alone did not show it (issue 23)
        ("robot.magnetization.elevation=0:0.5:2", "missing unit in 0.5"),
        ("robot.magnetization.elevation=0.1:0.5:2", "missing unit in 0.1"),
        ("robot.magnetization.elevation=0mm:5mm:2", "unknown unit 'm'"),
    ],
)
def test_cli_plain_number_for_a_key_the_scene_does_not_set(
    tmp_path, capsys, no_solving, param, message
):
    scene = tmp_path / "scene.toml"
    scene.write_text(ELEVATION_SCENE)
    args = ["sweep", str(scene), "--param", param, "--out", str(tmp_path / "out")]
    assert main(args) == 2
    (line,) = errors(capsys)
    assert line.startswith("sweep parameter robot.magnetization.elevation: "), line
    assert message in line, line
    assert "rad, deg" in line, line  # the unit expected
    assert not (tmp_path / "out").exists()  # nothing created
