"""3D steering with calibrated eMNS models (coils.MPEM): the tip direction target and its
exact sensitivities, and the report of a stalled search.

References: derivatives against Richardson-extrapolated central differences of full forward
solves; every answer against an independent forward solve (solve_rod, tolerance 1e-11) with
the returned currents; the straight rod's tip in closed form.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

import coils
from coilrod import ConvergenceError, presets, solve_currents, solve_rod
from coilrod.control import currents
from coilrod.design.sensitivity import tip_derivatives

ROD = presets.seed_rod(presets.M1())
L = ROD.length
SCALES = np.linspace(0.1, 1.0, 10)
CARDIOMAG = coils.presets.cardiomag()
NODES = 8
#: currents of CardioMag that make a field and a gradient at the centre: a bent 3D rod
MADE = CARDIOMAG.currents_for(B=(0.003, 0.004, -0.003), gradient=np.diag([0.05, -0.02, -0.03]))


def _solve(system, I, scales=SCALES):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return solve_rod(ROD, system.with_currents(I), scales, tol=1e-11, nodes=NODES)


def _tip_and_tangent(system, I, scales=SCALES):
    res = _solve(system, I, scales)
    assert res.model == "spatial"
    return res.tip[-1], res.frames(len(res) - 1)[-1, :, 0]


def test_tip_tangent_sensitivities_against_finite_differences():
    """d(tip tangent)/d(currents) of a Richardson-extrapolated spatial state (the frames
    extrapolated on SO(3)) against central differences of full solves, extrapolated in h
    (error O(h^4)): 1e-9 of the largest rate.  The linear combination (4 a_f - a_c) / 3 of
    the meshes' rotations, the leading order, is off by about 1e-7 here.  The controller's
    Jacobian of the direction's misses (the stereographic projection, chain rule) against the
    same differences of its misses."""
    res = _solve(CARDIOMAG, MADE, [1.0])
    _, _, _, D = tip_derivatives(res, [len(res) - 1], ["currents"], tangent=True)
    dt = D[0, 4:7]
    t = res.frames(len(res) - 1)[-1, :, 0]
    assert np.abs(t @ dt).max() <= 1e-14  # a unit vector's rate is normal to it
    # a target direction 0.2 rad off the tangent: the misses' Jacobian is not the tangent's
    off = np.cross(t, [0.0, 0.0, 1.0])
    d = np.cos(0.2) * t + np.sin(0.2) * off / np.linalg.norm(off)
    p = currents._problem(
        ROD, CARDIOMAG, res.tip[-1], None, "real", None, 1, (0.0, 0.0, 0.0), 0.0, NODES, None, d
    )
    J = p.jacobian(res)[3:]  # the direction's two rows
    for j in (5,):
        e = np.eye(8)[j]
        fd_t, fd_r = [], []
        for h in (2e-4, 1e-4):
            plus, minus = (
                _solve(CARDIOMAG, MADE + h * e, [1.0]),
                _solve(CARDIOMAG, MADE - h * e, [1.0]),
            )
            tangent = [r.frames(0)[-1, :, 0] for r in (plus, minus)]
            fd_t.append((tangent[0] - tangent[1]) / (2 * h))
            fd_r.append((p.residual(plus)[3:] - p.residual(minus)[3:]) / (2 * h))
        ref = (4 * fd_t[1] - fd_t[0]) / 3
        assert np.abs(dt[:, j] - ref).max() <= 1e-9 * np.abs(dt).max()
        ref = (4 * fd_r[1] - fd_r[0]) / 3
        assert np.abs(J[:, j] - ref).max() <= 1e-9 * np.abs(J).max()
    # the position rows are unchanged by asking for the tangent
    _, _, _, D4 = tip_derivatives(res, [len(res) - 1], ["currents"])
    np.testing.assert_array_equal(D4[0], D[0, :4])


def test_position_and_direction_on_cardiomag():
    """Five conditions, eight coils: the tip position and tangent of a state made by known
    currents met again (independent forward solve), with less sum I^2 than those currents
    (CardioMag has no resistances: equal weights)."""
    target, direction = _tip_and_tangent(CARDIOMAG, MADE)
    out = solve_currents(ROD, CARDIOMAG, target, direction=direction, nodes=NODES, steps=4)
    assert out.status == "converged"
    tip, tangent = _tip_and_tangent(CARDIOMAG, out.currents)
    assert np.linalg.norm(tip - target) <= 1e-6 * L
    angle = np.arctan2(np.linalg.norm(np.cross(tangent, direction)), tangent @ direction)
    assert angle <= 1e-6
    assert out.direction_miss == pytest.approx(angle, abs=1e-9)
    np.testing.assert_allclose(out.tip_direction, tangent, atol=1e-9)
    assert np.sum(out.currents**2) < np.sum(MADE**2)
    assert np.isnan(out.power)  # no copper resistances in a calibrated model


def test_stalled_search_says_where_and_how_far():
    """A stalled search near the straight rod (the state of zero currents of air coils
    here): the error names the status, the closest tip -- the straight rod's (L, 0, 0), in
    closed form -- and its distance from the target, and says the rod is nearly straight
    there.  (CardioMag stalls so at this target after some 50 solves.)"""
    target = np.array([0.98 * L, 0.0, 0.0])
    system = coils.presets.three_axis_helmholtz()
    p = currents._problem(
        ROD, system, target, None, "real", None, 10, (0.0, 0.0, 0.0), 0.0, NODES, None
    )
    zero = np.zeros(3)
    res = _solve(system, zero)
    miss = np.linalg.norm(res.tip[-1] - target)
    assert miss == pytest.approx(0.02 * L, rel=1e-9)
    with pytest.raises(ConvergenceError, match="stalled") as info:
        currents._finish(p, zero, res, 5, 0, [miss], "stalled")
    text = str(info.value)
    assert "nearly straight" in text
    assert "outside the robot's reachable set" in text
    assert f"{miss:.4g} m (0.02 L) away" in text
    assert info.value.result.status == "stalled"
    # a search stopped at a branch edge says so, with the edge's direction and the solves
    edge = currents._BranchEdge(np.array([0.6, 0.0, 0.8]), 2, 1.05, 2e-4)
    with pytest.raises(ConvergenceError, match="edge of the rod's branch") as info:
        currents._finish(p, zero, res, 5, 0, [miss], "branch_edge", edge)
    text = str(info.value)
    assert "branch_edge after 5 solves" in text
    assert "along [0.6, 0.0, 0.8]" in text
    assert f"{miss:.4g} m (0.02 L) from the target" in text
    assert "outside the robot's reachable set" not in text
    assert info.value.result.message in text


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"target": (0.03, 0.02), "direction": (1.0, 0.0, 0.0)}, "direction"),
        ({"direction": (1.0, 0.1, 0.0)}, "direction must be a unit vector"),
        ({"direction": (1.0, 0.0)}, "direction"),
    ],
)
def test_bad_direction(kwargs, match):
    with pytest.raises(ValueError, match=match):
        solve_currents(ROD, CARDIOMAG, **({"target": (0.03, 0.02, 0.01)} | kwargs))


# -- scenes: an eMNS preset as the system ----------------------------------------------------
def _scene(field, control=None):
    import copy

    from _scenes import BASE

    return {
        "name": "eMNS control",
        "robot": copy.deepcopy(BASE["robot"]),
        "field": {"type": "system", **field},
        "control": {"target": ["20 mm", "25 mm"], **(control or {})},
        "rod": {"nodes": NODES},
        "load": {"steps": 4},
    }


PROBES = np.array([[0.01, 0.004, 0.001], [0.03, -0.01, 0.002], [-0.02, 0.015, -0.003]])


@pytest.mark.parametrize(
    ("field", "library"),
    [
        ({"preset": "navion", "max_current": "20 A"}, coils.presets.navion(max_current=20.0)),
        ({"preset": "cardiomag"}, CARDIOMAG),
        ({"preset": "octomag", "max_current": "15 A"}, coils.presets.octomag(max_current=15.0)),
    ],
)
def test_a_scene_names_an_emns_preset(field, library):
    """The scene's system is the library's preset built directly (fields per ampere at probe
    points, limits, names), and its limits are the scene's."""
    from coilrod.scene import parse_scene

    scene = parse_scene(_scene(field))
    system = scene.fields["coils"]
    for a, b in zip(system.unit_fields(PROBES), library.unit_fields(PROBES), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(system.max_current, library.max_current)
    assert system.names == library.names
    np.testing.assert_array_equal(scene.control.max_current, library.max_current)


@pytest.mark.parametrize(
    ("field", "message"),
    [
        ({"preset": "octomag"}, "field.max_current: missing required key"),
        (
            {"preset": "cardiomag", "coil": [{"type": "coil", "radius": "50 mm", "turns": 30}]},
            "field.coil: the preset cardiomag is a calibrated eMNS model",
        ),
        ({"preset": "navion", "max_current": ["1 A", "2 A"]}, "a list of 3 (one per coil"),
        ({"preset": "navion", "radii": "100 mm"}, "field.radii: not a parameter of preset navion"),
    ],
)
def test_emns_scene_problems_name_their_key(field, message):
    from coilrod.scene import SceneError, parse_scene

    with pytest.raises(SceneError, match=re.escape(message)):
        parse_scene(_scene(field))


def test_an_emns_scene_drives_the_model(monkeypatch):
    """A control scene with an eMNS preset hands the calibrated model itself (a coils.MPEM,
    the library's preset) to solve_currents, with the scene's target, limits and mesh (the
    solve on an MPEM is checked above; here the call is recorded, not run)."""
    from coilrod import ConvergenceError
    from coilrod.scene import control_runner, parse_scene

    calls = []

    def record(rod, system, target, **kwargs):
        calls.append((system, np.asarray(target), kwargs))
        raise ConvergenceError("recorded", reached=0.0, target=1.0)

    monkeypatch.setattr(control_runner, "solve_currents", record)
    scene = parse_scene(_scene({"preset": "navion", "max_current": "20 A"}, {"model": "ideal"}))
    result = control_runner.run_control(scene)
    assert result.run("ideal").error == "recorded"
    ((system, target, kwargs),) = calls
    assert isinstance(system, coils.MPEM)
    navion = coils.presets.navion(max_current=20.0)
    for a, b in zip(system.unit_fields(PROBES), navion.unit_fields(PROBES), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(target, [0.02, 0.025])
    np.testing.assert_array_equal(kwargs["max_current"], [20.0] * 3)
    assert (kwargs["model"], kwargs["nodes"], kwargs["steps"]) == ("ideal", NODES, 4)


def test_the_3d_start_makes_its_field_over_the_offset(monkeypatch):
    """CardioMag's calibration has a current-free (offset) field, 1.5 mT at the centre: the
    start currents (:func:`coilrod.control.currents._start_3d`) make the turned uniform-field
    answer -- here a given in-plane field b (the uniform-field search replaced) turned into
    the target's plane about the clamp tangent, in closed form -- with the offset: the field
    of the currents and the offset together (evaluated by the model) is that field."""
    b = np.array([0.004, 0.003])
    monkeypatch.setattr(currents, "_uniform_start", lambda *args: (b, 0))
    target = np.array([0.7 * L, 0.4 * L, 0.3 * L])
    p = currents._problem(
        ROD, CARDIOMAG, target, None, "real", None, 4, (0.0, 0.0, 0.0), 0.0, NODES, None
    )
    assert np.linalg.norm(p.B_fixed) > 1e-3  # the offset is there
    I, _ = currents._start_3d(p)
    B = CARDIOMAG.with_currents(I).B(np.zeros((1, 3)))[0]
    phi = np.arctan2(target[2], target[1])  # the target's plane about x
    expected = np.array([b[0], b[1] * np.cos(phi), b[1] * np.sin(phi)])
    np.testing.assert_allclose(B, expected, atol=1e-12)


@pytest.mark.parametrize(
    ("direction", "angle"),
    [
        ((np.cos(1.2), 0.0, np.sin(1.2)), 1.2),  # in the target's plane (x-z): its angle
        ((np.cos(2.5), 0.0, -np.sin(2.5)), -2.5 + 2 * np.pi),  # the branch near the chord's
        ((0.0, 1.0, 0.0), None),  # across the plane: no angle to fit
    ],
)
def test_the_3d_start_fits_the_direction(monkeypatch, direction, angle):
    """The target direction enters the start: the planar uniform-field fit gets the tip angle
    of its projection on the target's plane (here the x-z plane, a target with y = 0: the
    angle from x towards +z, by hand), on the branch nearest twice the chord's angle (the
    tip angle of a uniformly bent rod), unless the direction lies across that plane."""
    seen = {}

    def fit(rod, goal, with_angle, *args):
        seen.update(goal=goal, with_angle=with_angle)
        return np.array([0.004, 0.003]), 0

    monkeypatch.setattr(currents, "_uniform_start", fit)
    target = np.array([0.6 * L, 0.0, 0.5 * L])
    p = currents._problem(
        ROD, CARDIOMAG, target, None, "real", None, 4, (0.0, 0.0, 0.0), 0.0, NODES, None,
        np.array(direction),
    )  # fmt: skip
    currents._start_3d(p)
    np.testing.assert_allclose(seen["goal"][:2], [0.6 * L, 0.5 * L], atol=1e-15)
    assert seen["with_angle"] == (angle is not None)
    if angle is not None:
        assert seen["goal"][2] == pytest.approx(angle, abs=1e-12)
    else:
        assert seen["goal"].size == 2


def test_steps_ignore_round_off_singular_values():
    """A 5 x 8 Jacobian of rank 3 plus round-off (1e-10): the restoring and minimum-power
    steps are those of the rank-3 part (independent: numpy's pinv with a cut at 1e-6), not
    steps of ~1e8 A that the limits cut to nothing."""
    rng = np.random.default_rng(1)
    A = rng.normal(size=(5, 3)) @ rng.normal(size=(3, 8))
    J = A + 1e-10 * rng.normal(size=(5, 8))
    r = 1e-2 * rng.normal(size=5)
    p = type("P", (), {"resistance": np.ones(8), "limits": np.full(8, 20.0)})()
    I = np.zeros(8)
    step = currents._restoring_step(J, r, I, p)
    np.testing.assert_allclose(step, np.linalg.pinv(A, rcond=1e-6) @ -r, rtol=1e-6, atol=1e-12)
    lp = currents._least_power_step(J, r, I, p)
    np.testing.assert_allclose(lp, step, rtol=1e-6, atol=1e-12)  # from I = 0: the same
    assert np.linalg.norm(step) < 1.0


def test_direction_target_on_cardiomag_in_few_solves():
    """Position + direction of a made state on CardioMag: met in at most 8 solves of the
    search (the old steps needed 19-23, 21 at these 16 nodes; not timed, a count)."""
    I0 = CARDIOMAG.currents_for(B=(-0.002, -0.006, 0.003))
    res = solve_rod(ROD, CARDIOMAG.with_currents(I0), np.arange(1, 11) / 10, tol=1e-12, nodes=16)
    target, direction = res.tip[-1], res.frames(len(res) - 1)[-1, :, 0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = solve_currents(ROD, CARDIOMAG, target, direction=direction, nodes=16)
    assert out.status == "converged"
    assert out.solves <= 8
    assert np.sum(out.currents**2) <= np.sum(I0**2)
    # independently: a forward solve with the currents found puts the tip and its tangent there
    check = solve_rod(ROD, CARDIOMAG.with_currents(out.currents), np.arange(1, 11) / 10,
                      tol=1e-12, nodes=16)  # fmt: skip
    np.testing.assert_allclose(check.tip[-1], target, atol=1e-8 * L)
    np.testing.assert_allclose(check.frames(len(check) - 1)[-1, :, 0], direction, atol=1e-7)
