"""Awkward input to the FEM and the current controller, found by trying to break them
(tests/test_files_robust.py covers files, tests/test_extremes.py far and ulp-close numbers).

Each test failed on the code before its fix.  References: the element count times the
per-element memory (arithmetic), a direct ``solve_rod`` at the returned currents (an
independent forward solve), the unloaded straight rod (tip at (L, 0)).
"""

from __future__ import annotations

import numpy as np
import pytest

import coilrod
import coilrod.control.currents as control
import coilrod.fem.mesh as fem_mesh
import coils
from coilrod import ConvergenceError, presets, solve_currents, solve_rod

L = 0.04
ROD = coilrod.Rod(L, 1e6, coilrod.Rectangle(2e-3, 2e-3), presets.M1())
FIELD = coils.UniformField((0.0, 5e-3, 0.0))


def test_fem_elements_beyond_the_machines_memory_raise_before_meshing(monkeypatch):
    """(20000, 1) quadratic 2D elements need about 20000 x 70 kB = 1.4 GB: on a machine of
    1 GB that is a ValueError naming ``elements`` (was: meshed and solved until the operating
    system killed the process, e.g. for elements=(10**9, 1))."""
    monkeypatch.setattr(fem_mesh, "physical_memory", lambda: 1e9)
    with pytest.raises(ValueError, match=r"elements \(20000, 1\): 20,000 elements .* 1\.4 GB"):
        coilrod.solve_fem(ROD, FIELD, [1.0], dim=2, elements=(20000, 1))
    assert fem_mesh.element_count(coilrod.Circle(2e-3), 3, (5, 2, 3)) == 5 * (4 + 24)


@pytest.mark.parametrize("scales", ["1", b"1", ["a"]])
def test_fem_scales_that_are_not_numbers_name_scales(scales):
    """A string was read as the number it spells ("1" -> scale 1) or failed inside numpy
    without naming the argument."""
    with pytest.raises(ValueError, match="scales must be a sequence of numbers"):
        coilrod.solve_fem(ROD, FIELD, scales, dim=2, elements=(2, 1))


def test_control_limits_too_small_for_any_field_say_so():
    """Limits of 1e-12 A make a centre field that rounds to zero in some direction: the
    uniform start then asked the workspace for a field bound of -0.0 T and raised "b_max must
    be positive" (an argument the caller never gave).  Now the search starts at zero current
    and reports the limits, with the closest tip: the straight rod (lambda ~ 1e-12).  (No
    channel is at its limit there -- no step within them gains -- and the error first said
    "outside the robot's reachable set": with 10 A limits it is met at [0.31, 3.57, 0] A.)"""
    rod = presets.seed_rod(presets.M1())
    system = coils.presets.three_axis_helmholtz()
    with pytest.raises(ConvergenceError, match="beyond the current limits") as err:
        solve_currents(
            rod, system, (0.029, 0.025), max_current=1e-12, steps=1, nodes=8, max_solves=2
        )
    tip = err.value.result.tip
    np.testing.assert_allclose(tip[:2], [rod.length, 0.0], rtol=0, atol=1e-9 * rod.length)


def test_control_target_in_millimetres_is_called_so():
    """A target given in mm (1000 times too far) is unreachable, and the message says that
    the target is read in metres."""
    rod = presets.seed_rod(presets.M1())
    system = coils.presets.three_axis_helmholtz()
    with pytest.raises(ConvergenceError, match=r"unreachable \(target is in m: .* mm\?\)"):
        solve_currents(rod, system, (29.0, 25.0))
    with pytest.raises(ConvergenceError, match=r"unreachable$"):  # just beyond: no hint
        solve_currents(rod, system, (rod.length * 1.01, 0.0))


def test_control_start_whose_path_cannot_be_followed_backs_off(monkeypatch):
    """Where the forward solve at the start currents fails (a fold on its load path: the
    seed rod at a start of [-10, -4.5e-5, 0] A in a three-axis Helmholtz system with 10 load
    steps, for the target (-20, 0) mm), the whole solve_currents raised that solve's error
    and said nothing of the target; now the start is moved towards zero current and the
    search goes on from there.  Stand-in for the fold: forward solves beyond 6 A fail."""
    rod = presets.seed_rod(presets.M1())
    system = coils.presets.three_axis_helmholtz()
    forward = control._forward
    fold = [6.0]

    def folding(rod, field, steps, opts):
        if np.abs(field.currents).max() > fold[0]:
            raise ConvergenceError("fold", reached=0.5, target=1.0)
        return forward(rod, field, steps, opts)

    monkeypatch.setattr(control, "_forward", folding)
    p = control._problem(rod, system, (-0.02, 0.0), None, "real", None, 2, (0, 0, 0), 0.0, 8, None)
    start = np.array([-10.0, -4.5e-5, 0.0])
    search, I, res, status, _ = control._search(p, start, max_iter=15, max_solves=2)
    assert search.solves == 2
    assert status == "max_solves"
    # the first state is half the start; the reported one is a solved state, checked against
    # a direct forward solve at its currents
    assert np.abs(I).max() <= 6.0
    direct = solve_rod(rod, system.with_currents(I), [0.5, 1.0], nodes=8)
    np.testing.assert_allclose(res.tip[-1], direct.tip[-1], rtol=0, atol=1e-12 * L)
    fold[0] = 1.0  # no state at all: the first error
    with pytest.raises(ConvergenceError, match="fold"):
        control._search(p, start, max_iter=15, max_solves=5)


def test_calibration_data_beyond_the_rods_reach_name_measured():
    """Tip data in mm (1000 times too far): no state of the rod puts its tip beyond its
    length from the clamp, and the fit drove E to 1 Pa (with warnings only) and reported it.
    Now a ValueError naming ``measured``; data within reach still fit (the truth, E = 0.9 MPa,
    from solve_rod itself)."""
    rod = coilrod.Rod(
        0.0172, 9e5, coilrod.Rectangle(5e-3, 0.84e-3), coilrod.Magnetization(114e3, 0)
    )
    fields = np.array([[0.0, b, 0.0] for b in (5e-3, 10e-3)])
    truth = solve_rod(rod, coils.UniformField(B=(0, 10e-3, 0)), [0.5, 1.0]).tip[:, 1]
    start = coilrod.Rod(0.0172, 2e6, rod.section, rod.magnetization)
    with pytest.raises(ValueError, match=r"measured\[1\] = .* beyond the rod's length"):
        coilrod.calibrate(start, fields, 1e3 * truth)
    cal = coilrod.calibrate(start, fields, truth)
    assert cal.values["youngs_modulus"] == pytest.approx(9e5, rel=1e-8)


@pytest.mark.parametrize(
    "magnet",
    [
        coils.Dipole((0.0, 0.0, 0.0), center=(0.0, -0.06, 0.0)),
        coils.CylinderMagnet(20e-3, 20e-3, 0.0, center=(0.0, -0.06, 0.0), axis="y"),
        coils.CuboidMagnet((2e-2, 2e-2, 2e-2), (0.0, 0.0, 0.0), center=(0.0, -0.06, 0.0)),
    ],
    ids=["dipole", "cylinder", "cuboid"],
)
def test_magnet_pose_of_a_magnet_without_magnetization_is_refused(magnet):
    """A magnet of zero magnetization has no field (its B is zero everywhere, e.g. at the
    tip): the search spent its budget and reported an "optimal" pose; now a ValueError before
    any solve."""
    assert not np.any(magnet.B([[0.04, 0.0, 0.0]]))
    rod = presets.seed_rod(presets.M1())
    with pytest.raises(ValueError, match="magnetization .* is zero"):
        coilrod.solve_magnet_pose(rod, magnet, (0.03, 0.02), nodes=8, max_solves=2)


def test_fem_result_states_out_of_range_and_a_quiet_2d_export(tmp_path, capfd):
    """``displacement``, ``deformed_nodes`` and ``plot`` of a state that does not exist raised
    IndexError "list index out of range" (``export`` named ``k``); a 2D state written to VTU
    printed meshio's "VTU requires 3D points" warning.  The file's points are the mesh's
    nodes with z = 0 (the reference: the mesh itself), its displacement the state's."""
    import meshio

    res = coilrod.solve_fem(ROD, FIELD, [1.0], dim=2, elements=(2, 1))
    for call in (res.displacement, res.deformed_nodes, res.plot):
        with pytest.raises(ValueError, match="k must be a state index from -1 to 0; got 1"):
            call(1)
    capfd.readouterr()
    back = meshio.read(res.export(tmp_path / "state.vtu"))
    out, err = capfd.readouterr()
    assert out == err == ""
    nv = res.mesh.p.shape[1]
    np.testing.assert_array_equal(back.points, np.c_[res.mesh.p.T, np.zeros(nv)])
    np.testing.assert_array_equal(
        back.point_data["displacement"][:, :2], res.displacement(0)[:, :nv].T
    )


def test_control_a_channel_a_few_nanoamperes_short_of_its_limit_is_at_it():
    """The search for the target (-20, 0) mm (the seed rod, three-axis Helmholtz, 10 A)
    stalls at -9.999999996 A on channel 0: the error said "no current limit is active" next
    to currents [-10.0, 0.2176, 0.0] A.  A channel within LIMIT_RTOL of its limit is active
    (the reference: the limit itself)."""
    rod = presets.seed_rod(presets.M1())
    system = coils.presets.three_axis_helmholtz()
    p = control._problem(rod, system, (-0.02, 0.0), None, "real", None, 2, (0, 0, 0), 0.0, 8, None)
    I = np.array([-10.0 + 4e-9, 0.2176, 0.0])
    res = control._forward(p.rod, p.field_of(I), p.steps, p.opts)
    with pytest.raises(ConvergenceError, match=r"beyond the current limits.*channels 0 at") as err:
        control._finish(p, I, res, 1, 0, [1.0], "stalled")
    assert err.value.result.active == [0]


def test_fem_given_mesh_with_a_degenerate_element_or_a_nan_node_is_named():
    """A given mesh with an element of zero length raised scikit-fem's bare
    Exception("Zero Jacobian determinant"); one with a NaN node was reported as a mesh
    "height nan, nan % of the section's".  Both are ValueErrors saying what is wrong."""
    from skfem import MeshQuad1

    mesh = MeshQuad1.init_tensor(np.linspace(0, L, 5), np.linspace(-1e-3, 1e-3, 2))
    p = mesh.p.copy()
    p[0, np.isclose(p[0], L / 4)] = L / 2  # the second element collapses to zero length
    with pytest.raises(ValueError, match="mesh has a degenerate element"):
        coilrod.solve_fem(ROD, FIELD, [1.0], dim=2, order=1, mesh=MeshQuad1(p, mesh.t))
    p = mesh.p.copy()
    p[1, 3] = np.nan
    with pytest.raises(ValueError, match=r"mesh nodes must be finite; node 3 is \[.*nan\]"):
        coilrod.solve_fem(ROD, FIELD, [1.0], dim=2, order=1, mesh=MeshQuad1(p, mesh.t))


def test_fem_poisson_ratios_at_the_ends_of_the_range():
    """nu = 0.5 - 1e-11 (K/G = 5e10) stalled at scale 0 with a ConvergenceError; it is a
    ValueError now (the tips are the same to 1e-8 from 0.5 - 1e-7 to 0.5 - 1e-10).  nu < -0.5
    warns: the elements lock as G >> K.  The reference: in plane stress the bending stiffness
    is E I whatever nu, so nu = -0.9 must give nu = 0's tip -- it is 10 % short on this mesh."""
    with pytest.raises(ValueError, match="poisson_ratio = 0.49999999999 is within 1e-10 of 0.5"):
        coilrod.solve_fem(ROD, FIELD, [1.0], dim=2, elements=(2, 1), poisson_ratio=0.5 - 1e-11)
    weak = coils.UniformField((0.0, ROD.field_for_lambda(0.01), 0.0))
    zero = coilrod.solve_fem(ROD, weak, [1.0], dim=2, elements=(8, 1), poisson_ratio=0.0)
    with pytest.warns(UserWarning, match="poisson_ratio = -0.9 < -0.5: the elements lock"):
        auxetic = coilrod.solve_fem(ROD, weak, [1.0], dim=2, elements=(8, 1), poisson_ratio=-0.9)
    assert auxetic.tip[0, 1] < 0.95 * zero.tip[0, 1]
    assert zero.tip[0, 1] == pytest.approx(0.01 / 3 * L, rel=1e-3)


def test_point_dipole_sums_at_no_points_and_mpem_channel_names():
    """A Dipole's or an MPEM's field at no points (shape (0, 3)) raised numpy's "cannot
    reshape array of size 0" (a magnet's and a coil pair's give empty arrays, the reference);
    two MPEM channels of one name were accepted (``names`` name the channels in messages and
    results)."""
    none = np.zeros((0, 3))
    mpem = coils.MPEM([([[0.0, 0.0, -0.1]], [[0.0, 0.0, 1e-7]])], currents=[1.0])
    for source in (coils.Dipole((0.0, 0.0, 1.0)), mpem, coils.CylinderMagnet(1e-2, 1e-2, 1e6)):
        B, G, H = source.B_gradient_hessian(none)
        assert (B.shape, G.shape, H.shape) == ((0, 3), (0, 3, 3), (0, 3, 3, 3))
    assert [a.shape for a in mpem.unit_fields(none)] == [(0, 3, 1), (0, 3, 3, 1)]
    pair = [([[0.0, 0.0, -0.1]], [[0.0, 0.0, 1e-7]]), ([[0.0, 0.0, 0.1]], [[0.0, 0.0, 1e-7]])]
    with pytest.raises(ValueError, match=r"names must be distinct .* \['x'\] repeat"):
        coils.MPEM(pair, names=["x", "x"])


def test_cli_version(capsys):
    """``coilrod --version`` was an unrecognised argument (exit 2); it prints the installed
    package's version (the reference: importlib.metadata) and exits 0."""
    from importlib.metadata import version

    from coilrod.scene.cli import main

    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"coilrod {version('coilrod')}\n"


def test_a_scene_whose_fem_refuses_an_input_reports_that_model_failed():
    """An input solve_fem refuses (a Poisson ratio within 1e-10 of 0.5, in a scene built in
    code past `coilrod check`, which now refuses it too) was a traceback out of the runner
    (before, a ConvergenceError at scale 0); it is that model's error, the other models still
    run."""
    import dataclasses

    from _scenes import scene_with

    from coilrod.scene import parse_scene
    from coilrod.scene.runner import run_scene

    data = scene_with(
        robot__poisson_ratio=0.45,
        models__run=["rod", "fem2d"],
        fem={"elements2d": [2, 1]},
        load__steps=1,
        rod={"nodes": 8},
    )
    scene = dataclasses.replace(parse_scene(data), poisson_ratio=0.5 - 1e-11)
    rod_run, fem_run = run_scene(scene, progress=False).runs
    assert rod_run.error == ""
    assert fem_run.error.startswith("fem2d: poisson_ratio = 0.49999999999 is within 1e-10")
    assert fem_run.scales.size == 0
