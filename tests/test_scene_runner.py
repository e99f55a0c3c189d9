"""The runner: partial results of a failed solve, and the module structure of the scene package."""

import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

import coilrod.fem
import coilrod.rod
from coilrod.errors import ConvergenceError
from coilrod.scene import parse_scene
from coilrod.scene.runner import run_scene

SCENE = {
    "robot": {
        "length": "40 mm",
        "diameter": "2 mm",
        "youngs_modulus": "1 MPa",
        "magnetization": {"preset": "M1"},
    },
    "field": {"type": "uniform", "B": "5 mT"},
    "load": {"steps": 4},
    "models": {"run": ["rod"]},
}


@pytest.fixture
def scene():
    return parse_scene(SCENE)


@pytest.fixture
def reached(scene):
    """A real rod result for the first two of the scene's four scales."""
    return coilrod.rod.solve_rod(scene.rod, scene.fields["ideal"], scene.scales[:2])


def failing_solver(calls, partial, reached_scale=0.5):
    """A solver that fails on the full path (with ``partial`` attached if not None) and
    passes the call through to the real rod solver for the reachable part."""
    real = coilrod.rod.solve_rod

    def solve(rod, field, scales, **kwargs):
        calls.append(np.asarray(scales).tolist())
        if len(calls) == 1:
            exc = ConvergenceError("limit point near scale 0.6", reached=reached_scale, target=0.75)
            if partial is not None:
                exc.result = partial
            raise exc
        return real(rod, field, scales, **kwargs)

    return solve


def test_runner_takes_the_partial_result_from_the_error(monkeypatch, scene, reached):
    calls = []
    monkeypatch.setattr(coilrod.rod, "solve_rod", failing_solver(calls, reached))
    result = run_scene(scene, progress=False)
    run = result.run("rod", "ideal")
    assert len(calls) == 1  # no second solve
    assert run.result is reached
    np.testing.assert_array_equal(run.scales, [0.25, 0.5])
    np.testing.assert_array_equal(run.tip, reached.tip)
    assert run.error == "limit point near scale 0.6"
    assert not result.ok
    assert [row["scale"] for row in result.table()] == [0.25, 0.5]


@pytest.mark.parametrize("partial", [None, "empty"])
def test_runner_falls_back_to_solving_the_reachable_scales(monkeypatch, scene, reached, partial):
    if partial == "empty":
        partial = SimpleNamespace(scales=np.zeros(0), tip=np.zeros((0, 3)), tip_angle=np.zeros(0))
    calls = []
    monkeypatch.setattr(coilrod.rod, "solve_rod", failing_solver(calls, partial))
    run = run_scene(scene, progress=False).run("rod", "ideal")
    assert calls == [[0.25, 0.5, 0.75, 1.0], [0.25, 0.5]]
    np.testing.assert_allclose(run.tip, reached.tip, rtol=0, atol=1e-12)


def test_fem_partial_result_is_kept(monkeypatch):
    # the FEM had no fallback: a partial result attached to its error is now kept
    data = dict(SCENE, models={"run": ["fem2d"]})
    scene = parse_scene(data)
    partial = SimpleNamespace(
        scales=np.array([0.25]),
        tip=np.array([[0.039, 0.004, 0.0]]),
        tip_angle=np.array([0.2]),
        stable=np.array([True]),
    )

    def solve_fem(*args, **kwargs):
        exc = ConvergenceError("no convergence at scale 0.5", reached=0.25)
        exc.result = partial
        raise exc

    monkeypatch.setattr(coilrod.fem, "solve_fem", solve_fem)
    run = run_scene(scene, progress=False).run("fem2d", "ideal")
    assert run.result is partial
    np.testing.assert_array_equal(run.tip, partial.tip)
    assert run.error == "no convergence at scale 0.5"


def test_figures_do_not_import_the_runner():
    # the field strength lives in its own module: figures and runner no longer import each other
    code = (
        "import sys\n"
        "import coilrod.scene.figures\n"
        "print('coilrod.scene.runner' in sys.modules)\n"
        "from coilrod.scene import runner, strength\n"
        "print(runner.field_strength is strength.field_strength)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["False", "True"]
