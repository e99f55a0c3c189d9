"""Breaking the navigation code (issue 20) before a user does: contact, friction, vessels,
meshes, insertion and navigation scenes at awkward inputs.  Earlier rounds:
tests/test_files_robust.py, tests/test_extremes.py, tests/test_extremes_fem_sweep.py."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from coilrod.contact import MeshVessel, Wall


def _box(half=5e-3, at=(0.0, 0.0, 0.0)):
    m = trimesh.creation.box((2 * half,) * 3)
    m.apply_translation(at)
    return m


def _brute_box_gap(p, half, at=(0.0, 0.0, 0.0)):
    """Signed distance into an axis-aligned cube (> 0 inside), by hand."""
    q = np.abs(np.asarray(p) - at) - half
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    return np.where(q.max(axis=1) > 0, -outside, -q.max(axis=1))


def test_a_mesh_component_inside_out_beside_a_right_one_is_an_error():
    # the total volume of a right cube and an inverted one is ~0 (not < 0): the old check
    # took it, and the inverted cube's inside counted as wall-side (gap -5 mm at its centre,
    # a lumen there by its winding).  Now: the error naming its faces, or fixed per component
    # (then both cubes are lumens: gap = the brute-force box distance at each centre)
    right, wrong = _box(), _box(at=(0.05, 0, 0))
    wrong.invert()
    both = trimesh.util.concatenate([right, wrong])
    with pytest.raises(ValueError, match=r"point into the lumen \(faces 12-23 of 24\)"):
        MeshVessel(both.vertices, both.faces)
    fixed = MeshVessel(both.vertices, both.faces, fix_normals=True, smooth=False)
    p = np.array([[0.05, 0.0, 0.0], [0.0, 0.002, 0.0], [0.053, 0.0, -0.001]])
    ref = np.maximum(_brute_box_gap(p, 5e-3), _brute_box_gap(p, 5e-3, (0.05, 0, 0)))
    np.testing.assert_allclose(fixed.gap(p), ref, atol=1e-15)
    assert fixed.volume == pytest.approx(2 * 1e-6, rel=1e-12)


def test_a_cavity_is_kept_and_a_nested_lumen_is_an_error():
    # a solid cube (normals into it) inside a lumen cube: the gap is the brute-force distance
    # to the nearer wall, negative in the solid; a lumen cube nested with outward normals is
    # no lumen (winding number 2 inside it): an error
    outer, inner = _box(20e-3), _box()
    inner.invert()
    cav = trimesh.util.concatenate([outer, inner])
    mv = MeshVessel(cav.vertices, cav.faces, smooth=False)
    p = np.array([[0.0, 0.0, 0.0], [0.0075, 0.0, 0.0], [0.0, 0.018, 0.001]])
    ref = np.minimum(_brute_box_gap(p, 20e-3), -_brute_box_gap(p, 5e-3))
    np.testing.assert_allclose(mv.gap(p), ref, atol=1e-15)
    nested = trimesh.util.concatenate([outer, _box()])
    with pytest.raises(ValueError, match="lumen inside the lumen"):
        MeshVessel(nested.vertices, nested.faces)


def test_two_cubes_touching_at_a_corner_are_not_manifold():
    # the shared corner's faces form two fans: its pseudo-normal summed to zero and the
    # smoothed gap's ball search raised scipy's "'x' must be finite"
    pinch = trimesh.util.concatenate([_box(), _box(at=(0.01, 0.01, 0.01))])
    with pytest.raises(ValueError, match=r"pinch.stl' is not manifold: vertex \d+ at \(5, 5, 5\)"):
        MeshVessel(pinch.vertices, pinch.faces, source="pinch.stl")


def test_friction_must_be_a_number_not_a_bool_or_a_string():
    # Wall(friction=True) was mu = 1 and friction="0.3" was 0.3 (float() of them), while
    # MeshVessel refused both; one rule for every obstacle now
    v, f = _box().vertices, _box().faces
    for bad in (True, np.True_, "0.3"):
        with pytest.raises(ValueError, match="friction must be a number >= 0"):
            Wall((0, 0, 0), "y", friction=bad)
        with pytest.raises(ValueError, match="friction must be a number >= 0"):
            MeshVessel(v, f, friction=bad)
    with pytest.raises(ValueError, match="friction"):
        MeshVessel(v, f, friction=np.inf)
    assert Wall((0, 0, 0), "y", friction=np.float32(0.25)).friction == 0.25


# -- scenes ---------------------------------------------------------------------------------------
def _nav_scene(rotated: bool, vessel_along_y: bool):
    import tomllib
    from pathlib import Path

    import coilrod.scene

    path = Path(coilrod.scene.__file__).parent / "examples" / "navigation_bend.toml"
    data = tomllib.loads(path.read_text())
    data["insertion"].update(lengths=["6 mm", "20 mm"], steps=3, nodes=8, withdraw=False)
    if rotated:  # the clamp turned 90 deg about z: the robot along +y, its field along -x
        data["rod"] = {"clamp_rotation": {"axis": [0, 0, 1], "angle": "90 deg"}}
        data["field"]["direction"] = "-x"
    if vessel_along_y:  # the vessel turned by hand the same way
        data["obstacles"]["vessel"][0].update(
            direction=[0, 1, 0], start=["0 mm", "-1 mm", "0 mm"], plane_normal=[0, 0, 1]
        )
    return data, str(path)


def test_a_rotated_clamp_is_checked_along_its_own_direction():
    # the scene's start check took the straight robot along +x whatever rod.clamp_rotation
    # said: a clamp turned to +y in a vessel along +x passed (the robot leaves the 3 mm lumen
    # 3.2 mm from the clamp), and the same scene turned as a whole was refused.  The turned
    # scene now runs and its answer is the unturned one's turned (tips, wall forces; push
    # forces equal), to round-off
    from coilrod.scene.navigation import contact_patch_forces, run_navigation
    from coilrod.scene.parse import SceneError, parse_scene
    from coilrod.scene.runner import plan_scene

    with pytest.raises(SceneError, match=r"vessel\[0\]: the straight robot leaves it 3.188 mm"):
        parse_scene(*_nav_scene(rotated=True, vessel_along_y=False))
    runs = []
    for rotated in (False, True):
        scene = parse_scene(*_nav_scene(rotated, vessel_along_y=rotated))
        (run,) = run_navigation(scene, plan_scene(scene)).runs
        assert not run.error
        runs.append(run.result)
    a, b = runs
    Q = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z
    assert a.wall_force_magnitude[-1] > 1e-4  # the tip presses on the wall at the last step
    np.testing.assert_allclose(b.tip, a.tip @ Q.T, atol=1e-12 * 0.04)
    np.testing.assert_allclose(b.wall_force, a.wall_force @ Q.T, atol=1e-9 * 1e-3)
    np.testing.assert_allclose(b.push_force, a.push_force, atol=1e-9 * 1e-3)
    # the contact patches' forces (the figure's) are the wall's on the rod: minus wall_force
    patches = contact_patch_forces(a, len(a) - 1)
    np.testing.assert_allclose(patches.sum(axis=0), -a.wall_force[-1], rtol=0, atol=1e-15)


# -- insertion ------------------------------------------------------------------------------------
def _bend_insertion():
    import coils
    from coilrod import Circle, Magnetization, Rod, Vessel

    rod = Rod(0.04, 1e6, Circle(2e-3), Magnetization(640e3, 0.2))
    bend = Vessel.bend(
        bend_radius=0.02, angle=np.pi / 2, radius=0.003, straight_before=0.005,
        straight_after=0.03, start=(-0.001, 0, 0),
    )  # fmt: skip
    return rod, bend, coils.UniformField(B=(0, 8e-3, 0))


def test_a_first_length_that_leaves_the_vessel_straight_is_named():
    # the first step starts from the straight free part: where it left the bend, insert
    # raised solve_rod's "points[7] at (16.5, 0, 0) mm lies 0.585 mm outside the vessel"
    # (which points?).  By hand: the bend's wall is the torus about (4, 20) mm of major
    # radius 20 mm and lumen radius 3 mm, so the straight axis y = 0 from the clamp at
    # x = -1 mm leaves it at 1 + 4 + sqrt(23^2 - 20^2) = 16.358 mm and the 1 mm surface
    # reaches it at 5 + sqrt(22^2 - 20^2) = 14.165 mm
    from coilrod import insert

    rod, bend, field = _bend_insertion()
    with pytest.raises(ValueError, match=r"lengths\[0\] = 16.4 mm: .* leaves the vessel"):
        insert(rod, bend, [0.0164, 0.02], field, nodes=8)
    with pytest.raises(ValueError, match=r"lengths\[0\] = 14.2 mm: .* surface .* shorter first"):
        insert(rod, bend, [0.0142, 0.02], field, nodes=8)
    with pytest.raises(ValueError, match=r"mm from the clamp .* or turn clamp_rotation"):
        insert(rod, bend, [0.01], field, nodes=8, clamp_rotation=[[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    ins = insert(rod, bend, [0.0141], field, nodes=8)  # just short of it: solved
    assert ins.min_gap[0] >= -1e-9 * 0.0141


# -- vessels --------------------------------------------------------------------------------------
def test_a_sparse_smooth_centreline_with_a_hairpin_is_the_spline_through_its_points():
    # four points round a 180 deg turn: the arc-length knot iteration does not contract and
    # the spline is resampled; its cubic pieces were then taken per point interval from the
    # resampled spline's first coefficients -- another curve (reaching (246, -102) mm), which
    # the construction refused as "intersects itself at (3.302, -4.717, 0) mm".  Now: the gap
    # is R at the points and, off them, R minus the brute-force distance to the chord-length
    # spline through the points (scipy, densely sampled; ends="round": the end balls count)
    from scipy.interpolate import CubicSpline
    from scipy.spatial import cKDTree

    from coilrod.contact import Vessel

    P = np.array([[0, 0, 0], [0.02, 0, 0], [0.025, 0.005, 0], [0.02, 0.01, 0]])
    R = 5e-4
    v = Vessel(P, R, smooth=True, ends="round")
    np.testing.assert_allclose(v.gap(P), R, atol=1e-15)
    chords = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    curve = CubicSpline(chords, P)(np.linspace(0, chords[-1], 100_001))
    x = np.random.default_rng(0).uniform([0.0, -4e-3, -1e-3], [0.028, 0.012, 1e-3], (300, 3))
    dist = cKDTree(curve).query(x)[0]
    near = (dist > 2e-4) & (dist < 3e-3)  # (the samples are 0.4 um apart)
    np.testing.assert_allclose(v.gap(x[near]), R - dist[near], atol=1e-10)


def test_friction_with_a_unit_in_a_scene_says_it_has_none():
    # obstacles.friction = "0.1 mm" said only "expected a number" (every other length in a
    # scene is a quoted quantity with a unit); now it says the coefficient has no unit
    from coilrod.scene.parse import SceneError, parse_scene

    for bad in ("0.1 mm", "0.1"):
        data, path = _nav_scene(rotated=False, vessel_along_y=False)
        data["obstacles"]["friction"] = bad
        with pytest.raises(SceneError, match=r"obstacles.friction: .*Coulomb .*no unit"):
            parse_scene(data, path)


def test_a_single_precision_mesh_far_from_the_origin_is_reported(tmp_path):
    # a binary STL stores float32: a 10 mm cube 10 km from the origin is rounded by up to
    # 2^-11 m = 0.49 mm in the file (by hand: 2^13 <= 1e4 < 2^14, float32 steps of
    # 2^(13-23) m there, half a step), a twentieth of its
    # edge, and its gaps were silently a tenth of a millimetre off; a million metres off its
    # faces collapse (the "degenerate" error, now with the warning saying why).  The same
    # cube saved as OBJ (text, double) keeps its coordinates and has no warning
    import warnings

    for offset, ext, warns in ((1e4, "stl", True), (0.0, "stl", False), (1e4, "obj", False)):
        path = tmp_path / f"far{int(offset)}.{ext}"
        _box(at=(offset, 0, 0)).export(path)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            MeshVessel.from_file(path, smooth=False)
        hit = [w for w in caught if "single-precision" in str(w.message)]
        assert bool(hit) == warns, (offset, ext, [str(w.message) for w in caught])
        if warns:
            assert "rounded by up to 0.00049" in str(hit[0].message)


def test_insertion_plot_bad_steps_and_force_range():
    # steps=[5] of a 2-step insertion raised IndexError from inside the drawing, a reversed
    # or non-positive force_range drew an empty band on the log axis; one named error each,
    # before any figure is made
    ins = _point_contact(8, steps=2)  # (the checks come before any drawing: no solve)
    for kw, name in (
        ({"steps": [5]}, r"steps .* in \[0, 2\)"),
        ({"steps": [0.5]}, "steps must be step indices"),
        ({"force_range": (0.4, 0.1)}, "force_range"),
        ({"force_range": (0.0, 0.4)}, "force_range"),
        ({"force_range": "x"}, "force_range"),
    ):
        with pytest.raises(ValueError, match=name):
            ins.plot(**kw)


def test_a_network_of_rough_vessels_and_a_changed_preset_keep_their_friction():
    # the solver reads the obstacle's own coefficient: a VesselNetwork of vessels with
    # mu = 0.3 had the class's 0 (frictionless, silently), and a preset's replace() rebuilt
    # it from the preset's parameters without its friction.  Reference: the insertion into
    # the rough bend itself (a network of one member is the member); mu = 0 differs
    from coilrod import insert
    from coilrod.contact import VesselNetwork

    rod, bend, field = _bend_insertion()
    rough = bend.with_friction(0.3)
    lengths = [0.006, 0.03]  # (no contact at 6 mm: the first step is cheap)
    ref = insert(rod, rough, lengths, field, nodes=8)
    net = insert(rod, VesselNetwork([rough]), lengths, field, nodes=8)
    np.testing.assert_allclose(net.push_force, ref.push_force, rtol=1e-12, atol=1e-15)
    smooth = insert(rod, bend, lengths, field, nodes=8)
    assert abs(smooth.push_force[-1] - ref.push_force[-1]) > 1e-2 * abs(ref.push_force[-1])
    with pytest.raises(ValueError, match=r"friction coefficients differ \(0.3, 0\)"):
        VesselNetwork([rough, bend])
    assert VesselNetwork([rough, bend], friction=0.1).friction == 0.1
    # replace() of presets (their parameters have no friction) and of a network
    assert rough.replace(radius=0.0032).friction == 0.3
    assert rough.replace(friction=0.1).friction == 0.1
    assert VesselNetwork([rough]).replace(vessels=[rough, rough]).friction == 0.3


def test_a_scene_whose_straight_surface_reaches_the_wall_is_refused_before_the_run(monkeypatch):
    # the scene check took the centreline only: a first free length whose straight surface
    # reaches the bend's wall passed, and `coilrod run` ended in solve_rod's traceback.  By
    # hand: the scene's clamp is the origin, the bend's torus centre (4, 20) mm (5 mm straight
    # from x = -1 mm), so the 1 mm surface of the axis y = 0 meets the 3 mm lumen's wall
    # where (x - 4)^2 + 20^2 = 22^2: x = 4 + sqrt(84) = 13.165 mm.  Now 13.3 mm is a scene
    # error naming insertion.lengths[0] and 13.1 mm passes.  A ValueError in a run is
    # reported as that run's failure, not a traceback
    from coilrod.scene.navigation import run_navigation
    from coilrod.scene.parse import SceneError, parse_scene
    from coilrod.scene.runner import plan_scene

    data, path = _nav_scene(rotated=False, vessel_along_y=False)
    data["insertion"]["lengths"] = ["13.3 mm", "20 mm"]
    with pytest.raises(SceneError, match=r"insertion.lengths\[0\]: .* 13.3 mm, and its surface"):
        parse_scene(data, path)
    data["insertion"]["lengths"] = ["13.1 mm", "20 mm"]
    scene = parse_scene(data, path)

    def refuse(*args, **kwargs):
        raise ValueError("lengths[0]: refused")

    monkeypatch.setattr("coilrod.contact.insert", refuse)
    result = run_navigation(scene, plan_scene(scene))
    assert not result.ok
    assert "refused" in result.runs[0].error


def test_many_points_deep_in_a_fine_mesh_are_measured_in_blocks(monkeypatch):
    # a point deep in a lumen has every triangle and vertex of a few rings as candidates, and
    # the candidates of all points were measured at once (~1 kB of temporaries a pair at
    # order 2): 1000 points near the axis of a 1e5-face bend took 3.8 GB (now 0.24 GB).
    # Blocks of mesh_vessel.BLOCK pairs, here cut to 5000 on a coarse tube: the smoothed gap
    # on the axis (blended there into the polyhedral one: both kinds of block) peaks at 2.3 MB
    # instead of 10 MB, bitwise the one-block answers; the polyhedral gap on the axis is the
    # n-gon's apothem r cos(pi/n) (closed form)
    import tracemalloc

    from coilrod.contact import Vessel, tessellate
    from coilrod.contact import mesh_vessel as mvm

    n, r = 16, 2e-3
    v, f = tessellate(Vessel.straight(0.02, r), n, 0.5e-3)
    p = np.c_[np.linspace(0.005, 0.015, 64), np.zeros((64, 2))]
    smooth = MeshVessel(v, f)
    monkeypatch.setattr(mvm, "BLOCK", 10**9, raising=False)
    whole = smooth.evaluate(p, 2)
    monkeypatch.setattr(mvm, "BLOCK", 5000, raising=False)
    tracemalloc.start()
    try:
        ev = smooth.evaluate(p, 2)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 3e6, peak
    for a, b in zip((ev.gap, ev.gradient, ev.hessian), whole, strict=True):
        assert np.array_equal(a, b)
    exact = smooth._evaluate_exact(p, 0)[0]  # (smooth=False's gap, in blocks too)
    np.testing.assert_allclose(exact, r * np.cos(np.pi / n), rtol=0, atol=1e-15)
    np.testing.assert_allclose(smooth.closest(p)[:, 0], p[:, 0], atol=1e-15)


def test_a_short_tube_in_mm_read_as_metres_is_doubted(tmp_path):
    # a 2.5 mm piece of a 1 mm-radius tube saved in mm, read with the default units="m", is
    # 2.5 m across: under the 3 m size limit, so it passed silently as a lumen of 1 m radius
    # (a centreline file's radius over 50 mm is doubted).  Now its mean radius 2 V / A (a
    # capped tube's r L / (L + r), the lumen built as r = 1 mm, L = 2.5 mm: 0.7 of it) is:
    # over 50 mm with units="m" a UnitsWarning naming units='mm'; with units="mm" none
    import warnings

    from coilrod import UnitsWarning
    from coilrod.contact import Vessel, tessellate

    v, f = tessellate(Vessel.straight(2.5e-3, 1e-3), 12)
    path = tmp_path / "piece.obj"
    trimesh.Trimesh(1e3 * v, f).export(path)  # coordinates in mm
    with pytest.warns(UnitsWarning, match=r"piece.obj' encloses a lumen 0.6\d* m .*units='mm'"):
        MeshVessel.from_file(path, smooth=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mesh = MeshVessel.from_file(path, units="mm", smooth=False)
    assert 2 * mesh.volume / mesh._mesh.area == pytest.approx(1e-3 * 2.5 / 3.5, rel=0.05)


def test_a_lumen_with_no_room_at_the_clamp_is_a_scene_error():
    # the scene check left "no room for the robot's surface at the clamp" to the vessel's
    # narrowness check, which meshes do not have and which misses a clamp near a wide
    # vessel's wall: both passed `coilrod check` and failed in the run.  By hand: the bend's
    # axis 2.5 mm above the clamp leaves 3 - 2.5 = 0.5 mm to its wall, and the 1 mm robot
    # reaches 0.5 mm into it; the phantom's 12-gon (lumen radius 2 mm) has 2 cos(15 deg) =
    # 1.932 mm on its axis, 0.168 mm short of a 4.2 mm robot's surface
    import tomllib
    from pathlib import Path

    from coilrod.scene.parse import SceneError, parse_scene

    data, path = _nav_scene(rotated=False, vessel_along_y=False)
    data["obstacles"]["vessel"][0]["start"] = ["-1 mm", "2.5 mm", "0 mm"]
    with pytest.raises(SceneError, match=r"reaches the lumen's wall at the clamp .*by 0.5 mm"):
        parse_scene(data, path)
    phantom = path.replace("navigation_bend", "navigation_phantom")
    data = tomllib.loads(Path(phantom).read_text())
    data["robot"]["diameter"] = "4.2 mm"
    with pytest.raises(SceneError, match=r"2.1 mm from its axis.* clamp .*by 0.168 mm"):
        parse_scene(data, phantom)


def _point_contact(nodes, force=3.6e-3, length=0.02, steps=1, pushes=None):
    """An Insertion of ``steps`` equal straight steps along x whose wall pushes corner j
    with ``pushes[j]`` (N along +y; default the middle corner with -``force``): its force per
    length there is that over the corner's segment."""
    from coilrod.contact.insertion import Insertion

    pushes = {nodes // 2: -force} if pushes is None else pushes
    s = np.linspace(0.0, length, nodes + 1)
    x = np.c_[s, np.zeros((nodes + 1, 2))]
    f = np.zeros((nodes + 1, 3))
    on = np.zeros(nodes + 1, bool)
    for j, fy in pushes.items():
        f[j, 1], on[j] = fy / (length / nodes), True
    one, m = np.ones(steps), steps
    return Insertion(
        lengths=length * one, tip=np.tile(x[-1], (m, 1)),
        wall_force=np.tile([0.0, -sum(pushes.values()), 0.0], (m, 1)),
        max_contact_force=np.abs(f).max() * one, contact_nodes=[on] * m,
        min_gap=0 * one, stable=one > 0, substeps=one.astype(int), push_force=0 * one,
        _s=[s] * m, _shapes=[x] * m, _frames=[np.tile(np.eye(3), (nodes + 1, 1, 1))] * m,
        _forces=[f] * m, _points=[x] * m,
    )  # fmt: skip


def test_navigation_outputs_name_grid_free_contact_forces_and_no_empty_legends():
    # the figure labelled the contact forces with the largest force per length (N/m): for a
    # point contact its force over one segment, doubling with the nodes (the bend scene at
    # 40 mm: 1.0, 2.4, 5.8, 10.5 N/m at 16-128 segments); now the largest contact's force,
    # (3.58, 3.62, 3.63, 3.64 mN there): a 3.6 mN point force at 8 and 16 segments is 3.6 mN
    # in both labels.  A scene whose runs all failed printed matplotlib's "No artists with
    # labels found to put in legend" twice; it is drawn silently
    import warnings

    import matplotlib.pyplot as plt

    from coilrod.scene.navigation import NavigationRun, NavigationSceneResult, plot_navigation
    from coilrod.scene.parse import parse_scene
    from coilrod.scene.runner import plan_scene

    scene = parse_scene(*_nav_scene(rotated=False, vessel_along_y=False))
    plan = plan_scene(scene)
    runs = [
        NavigationRun(name, 0.1, _point_contact(n)) for name, n in (("ideal", 8), ("coils", 16))
    ]
    fig = plot_navigation(NavigationSceneResult(scene, plan, runs))
    labels = [x for x in fig.axes[0].get_legend_handles_labels()[1] if "largest" in x]
    assert len(labels) == 2, labels
    assert all("largest contact 3.6 mN" in x for x in labels), labels
    plt.close(fig)
    # the table and summary gave the total wall force alone, |sum of the contact forces|: with
    # the wall pushing at two places (3.6 mN down, 2 mN up) it is 1.6 mN, less than either
    run = NavigationRun("ideal", 0.1, _point_contact(8, pushes={2: -3.6e-3, 6: 2e-3}))
    two = NavigationSceneResult(scene, plan, [run])
    (row,) = two.table()
    assert row["wall_force_mN"] == pytest.approx(1.6, rel=1e-12)
    assert row["largest_contact_mN"] == pytest.approx(3.6, rel=1e-12)
    assert "total wall force max 1.6 mN (largest contact 3.6 mN)" in two.summary()
    result = NavigationSceneResult(scene, plan, [NavigationRun("ideal", 0.1)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fig = plot_navigation(result)
    assert fig.axes[0].get_legend() is None
    plt.close(fig)


def test_the_shipped_phantom_is_its_stated_recipe_bit_for_bit():
    # provenance (phantom_path, data/README.md): the project's bend preset tessellated with
    # 12 per ring, 1 mm spacing and fan caps, single precision; the file's triangles are those
    from coilrod.contact import Vessel, phantom_path, tessellate

    v, f = tessellate(Vessel.bend(0.02, np.pi / 2, 2e-3, 0.01, 0.01), 12, 1e-3, caps="fan")
    shipped = trimesh.load(phantom_path("bend"), process=False)
    assert np.array_equal(np.asarray(shipped.triangles), v[f].astype(np.float32).astype(float))


def test_tessellate_refuses_a_spacing_that_makes_another_vessel_or_no_memory():
    # spacing=1.0 (1 m, e.g. meant as 1 mm) on a 51 mm bend made two rings: a straight tube
    # along the chord, its gap on the bend's axis -10.7 mm (outside), silently; 1e-9 m asked
    # for 8e8 vertices (a MemoryError).  By hand: the bend from the origin along +x, 10 mm
    # straight, a 90 deg arc of radius 20 mm about (10, 20) mm, 10 mm straight along +y;
    # mid-length is mid-arc, (10 + 20 sin 45, 20 - 20 cos 45) mm, and the chord's middle
    # (15, 15) mm is sqrt(2) (20 sin 45 - 5) = 12.93 mm from it
    from coilrod.contact import Vessel, tessellate

    bend = Vessel.bend(0.02, np.pi / 2, 2e-3, 0.01, 0.01)
    with pytest.raises(ValueError, match=r"spacing = 1 m is too coarse .* is 12.93 mm from"):
        tessellate(bend, 16, 1.0)
    with pytest.raises(ValueError, match=r"\(8.23e\+08\) exceed 1e\+06 vertices"):
        tessellate(bend, 16, 1e-9)


def test_tessellated_caps_keep_the_smoothed_gap_near_their_rim():
    # tessellate capped each end with a fan from its centre: its edges are a lumen radius
    # long at any n_around, so the rim's vertices (a sharp edge) weighed tangent planes a
    # radius away, with curvatures of 1 / (ring edge): beside a tube near its cap the smoothed
    # gap was 0.66, 0.92, 1.6 mm off at 16, 32, 64 per ring (gradients of size 16-117), and a
    # branch network of meshes was 0.3 mm off outside its junction at 128 per ring (where the
    # branch's cap lies).  Now rings about one edge apart close the caps: the error is under
    # one ring edge and falls as the mesh is refined.  Reference: the same mesh's exact
    # polyhedral gap (smooth=False), at points 0.1-0.9 mm beside the 1.5 mm tube, within
    # 1.5 mm of its cap
    from coilrod.contact import Vessel, tessellate

    r, tube = 1.5e-3, Vessel.straight(0.006, 1.5e-3)
    rng = np.random.default_rng(0)
    ax, out, th = (rng.uniform(a, b, 150) for a, b in ((1e-4, 1.5e-3), (1e-4, 9e-4), (0, 7)))
    p = np.c_[ax, (r + out) * np.cos(th), (r + out) * np.sin(th)]
    errors = []
    for n in (16, 32):
        mesh = MeshVessel(*tessellate(tube, n))
        exact = mesh._evaluate_exact(p, 0)[0]  # (smooth=False's gap)
        errors.append(np.abs(mesh.gap(p) - exact).max())
        assert errors[-1] < 2 * np.pi * r / n  # one ring edge
    assert errors[1] < errors[0]
