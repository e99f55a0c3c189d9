"""The demo and shipped scenes end to end: each asserts a number against an independent reference.

- ideal-field rod runs against the closed-form elliptic-integral elastica;
- coil-field rod runs against an independent scipy solve_bvp solve in the same Biot-Savart field;
- the planner skips what the scene does not need (a rod-only run never imports scikit-fem).
"""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from rod_bvp_reference import bvp_tip_continued

from coilrod import elastica
from coilrod.scene import load_scene
from coilrod.scene.cli import main, shipped_scenes
from coilrod.scene.planner import plan_scene
from coilrod.scene.runner import field_strength, run_scene


@pytest.fixture(scope="module")
def demo_out(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    code = main(["demo", "--out", str(out), "--quiet"])
    return code, out


def test_demo_runs_and_writes_outputs(demo_out):
    code, out = demo_out
    assert code == 0
    for case in ("M1", "M2a"):
        for name in ("tip_path.csv", "summary.json", "tip_vs_field.png", "shapes.png"):
            assert (out / case / name).stat().st_size > 0


def test_demo_ideal_run_matches_closed_form_elastica(demo_out):
    _, out = demo_out
    summary = json.loads((out / "M1" / "summary.json").read_text())
    lam = summary["reference"]["number"]
    shift = summary["shift"][0]
    L = 0.04
    ref = elastica.elastica(lam, math.pi / 2, length=L)
    tip = np.array(shift["ideal_tip_mm"]) * 1e-3  # (x, y, z): a planar run stays at z = 0
    np.testing.assert_allclose(tip, [*ref.tip, 0.0], atol=1e-6 * L)


def test_demo_coil_run_matches_independent_bvp(demo_out):
    _, out = demo_out
    summary = json.loads((out / "M1" / "summary.json").read_text())
    from coilrod.scene import parse_scene
    from coilrod.scene.cli import DEMO_SCENES, _demo_scene

    scene = parse_scene(_demo_scene("M1", DEMO_SCENES["M1"]))
    tip = bvp_tip_continued(scene.rod, scene.fields["coils"], np.linspace(0.1, 1.0, 10))
    np.testing.assert_allclose(
        np.array(summary["shift"][0]["coil_tip_mm"]) * 1e-3,
        [*tip[:2], 0.0],
        atol=1e-6 * scene.rod.length,
    )
    # and the real coils move the tip measurably (more than 1% of L for R = 2 L)
    assert summary["shift"][0]["tip_shift_percent_L"] > 1.0


def test_planner_skips_what_is_not_needed():
    scene = load_scene(shipped_scenes()["config_a_m1"])
    text = "\n".join(plan_scene(scene).decisions)
    assert "no Biot-Savart" in text
    assert "force (gradient) path skipped" in text
    scene = load_scene(shipped_scenes()["helmholtz_vs_ideal"])
    plan = plan_scene(scene)
    text = "\n".join(plan.decisions)
    assert "scikit-fem is not imported" in text
    assert "Biot-Savart of 2 filaments" in text
    assert plan.cache_box is None
    assert plan_scene(scene, cache=True).cache_box is not None


def test_rod_only_scene_never_imports_scikit_fem(tmp_path):
    code = (
        "import sys\n"
        "from coilrod.scene.cli import main\n"
        f"rc = main(['run', 'helmholtz_vs_ideal', '--out', r'{tmp_path}', '--quiet',"
        " '--no-progress'])\n"
        "assert rc == 0, rc\n"
        "print('skfem' in sys.modules)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "False"


def test_cached_coil_field_gives_same_tip_as_direct():
    # the grid cache is an approximation: its tip must agree with the direct evaluation to far
    # below the real-vs-ideal shift it is used to measure
    scene = load_scene(shipped_scenes()["helmholtz_vs_ideal"])
    scene.scales = scene.scales[::3]
    direct = run_scene(scene, plan=plan_scene(scene, cache=False), progress=False)
    cached = run_scene(scene, plan=plan_scene(scene, cache=True), progress=False)
    a, b = direct.run("rod", "coils"), cached.run("rod", "coils")
    np.testing.assert_allclose(a.tip, b.tip, atol=1e-7 * scene.rod.length)
    assert direct.shift()[0]["tip_shift_mm"] > 100 * 1e3 * 1e-7 * scene.rod.length


@pytest.mark.parametrize("name", ["config_a_m41", "config_a_m42"])
def test_segment_scenes_run(name):
    scene = load_scene(shipped_scenes()[name])
    result = run_scene(scene, progress=False)
    assert result.ok
    # |M| A L^2 / EI lambda at the top load agrees with the formula computed by hand
    rod = scene.rod
    B = np.linalg.norm(scene.fields["ideal"].B0)
    lam = 0.2 * 640e3 * B * rod.area * rod.length**2 / rod.bending_stiffness
    assert result.table()[-1]["lambda"] == pytest.approx(lam, rel=1e-12)


def test_seed_fig5_m42_deflects_more_at_high_field():
    # the seed's Fig. 5 claim: turning one segment's magnetization increases the deflection,
    # "especially in the range with a bigger strength of magnetic field" (example layout here)
    deflection = {}
    for name in ("config_a_m41", "config_a_m42"):
        scene = load_scene(shipped_scenes()[name])
        tip = run_scene(scene, progress=False).run("rod", "ideal").tip
        deflection[name] = np.hypot(tip[:, 0] - scene.rod.length, tip[:, 1])
    ratio = deflection["config_a_m42"] / deflection["config_a_m41"]
    assert ratio[-1] > 1.05
    assert ratio[-1] > ratio[0]


def test_demo_rod_and_fem_agree_on_the_shift(demo_out):
    # two independent models (Kirchhoff rod, neo-Hookean continuum) see the same coil effect
    _, out = demo_out
    for case in ("M1", "M2a"):
        shift = {
            s["model"]: s for s in json.loads((out / case / "summary.json").read_text())["shift"]
        }
        assert set(shift) == {"rod", "fem2d"}
        assert shift["fem2d"]["tip_shift_percent_L"] == pytest.approx(
            shift["rod"]["tip_shift_percent_L"], abs=0.1
        )
        assert shift["fem2d"]["tip_angle_shift_deg"] == pytest.approx(
            shift["rod"]["tip_angle_shift_deg"], abs=0.1
        )


def test_fem_scene_matches_closed_form_elastica():
    scene = load_scene(shipped_scenes()["config_a_m1"])
    scene.scales = scene.scales[1::3]
    result = run_scene(scene, progress=False)
    assert result.ok
    _, _, lam = field_strength(scene)
    L = scene.rod.length
    fem = result.run("fem2d", "ideal")
    for k, s in enumerate(fem.scales):
        ref = elastica.elastica(s * lam, math.pi / 2, length=L)
        np.testing.assert_allclose(fem.tip[k, :2], ref.tip, atol=0.01 * L)
        assert fem.tip_angle[k] == pytest.approx(ref.tip_angle, abs=0.02)


@pytest.mark.slow
def test_maxwell_scene_rod_fem_and_bvp_agree():
    # Config (B) with real coils: the rod's coil-field tip against an independent solve_bvp, and
    # the rod and FEM shifts against each other
    scene = load_scene(shipped_scenes()["maxwell_vs_ideal"])
    result = run_scene(scene, progress=False)
    assert result.ok
    L = scene.rod.length
    tip = bvp_tip_continued(scene.rod, scene.fields["coils"], scene.scales)
    np.testing.assert_allclose(result.run("rod", "coils").tip[-1, :2], tip, atol=1e-6 * L)
    shift = {s["model"]: s for s in result.shift()}
    assert shift["rod"]["tip_shift_percent_L"] > 0.5
    assert shift["fem2d"]["tip_shift_percent_L"] == pytest.approx(
        shift["rod"]["tip_shift_percent_L"], abs=0.1
    )
    # its figures: the rod's curves visible next to the FEM's (they agree to ~1 % of L), the
    # title clear of the colour bar
    import matplotlib.pyplot as plt
    from _figure_checks import assert_readable

    from coilrod.scene.figures import plot_scene_shapes, plot_tip_vs_field

    for plot in (plot_tip_vs_field, plot_scene_shapes):
        fig = plot(result).figure
        assert_readable(fig)
        plt.close(fig)


def test_runner_reports_buckling_in_both_models():
    # M(1) in a field antiparallel to it: rod and FEM stay straight and both report the loss of
    # stability past the Euler load lambda = pi^2/4 (about 2.47) in the table and the summary
    import warnings

    from coilrod.scene import parse_scene

    scene = parse_scene(
        {
            "robot": {
                "length": "40 mm",
                "width": "3 mm",
                "thickness": "2 mm",
                "youngs_modulus": "1 MPa",
                "magnetization": {"preset": "M1"},
            },
            "field": {"type": "uniform", "B": "5 mT", "direction": "-x"},
            "load": {"scales": [0.5, 1.0]},
            "models": {"run": ["rod", "fem2d"]},
        }
    )
    lam = field_strength(scene)[2]
    assert 0.5 * lam < math.pi**2 / 4 < lam
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = run_scene(scene, progress=False)
    for model in ("rod", "fem2d"):
        rows = [r for r in result.table() if r["model"] == model]
        assert [r["stable"] for r in rows] == [True, False]
    assert result.summary().count("UNSTABLE") == 2


@pytest.mark.slow
def test_unreachable_load_exit_1_keeps_reached_path(tmp_path, capsys):
    # a Helmholtz pair smaller than the robot: beyond the coils the field turns back and the rod
    # meets a fold near 0.41 of the load; the run says so, keeps the path up to there, exits 1
    scene = tmp_path / "small_pair.toml"
    scene.write_text(
        '[robot]\nlength = "40 mm"\ndiameter = "2 mm"\nyoungs_modulus = "1 MPa"\n'
        'magnetization = { preset = "M1" }\n[field]\ntype = "coils"\n'
        'coil = [ { type = "helmholtz", radius = "30 mm", turns = 200, B = "15 mT", '
        'axis = "y" } ]\n[load]\nsteps = 5\n[models]\nrun = ["rod"]\n'
    )
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "--quiet"]) == 1
    out = capsys.readouterr().out
    assert "FAILED" in out
    assert "limit point" in out
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    run = next(r for r in summary["runs"] if r["field"] == "coils")
    assert run["scales_reached"] == 2  # 0.2 and 0.4 of the load, before the fold
