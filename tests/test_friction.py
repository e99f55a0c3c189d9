"""Coulomb friction at the contact points of the spatial rod (quasi-static, incremental):
frictionless limit to round-off, exact stick, slip on the cone (push force = mu times the
normal reaction, closed form for a tip sliding on a flat wall), hysteresis of insertion and
withdrawal, the Jacobian of the friction rows, and bad input."""

from __future__ import annotations

import numpy as np
import pytest

import coilrod
import coils
from coilrod import Circle, Magnetization, Rod, Vessel, Wall, solve_rod
from coilrod.path.stepping import PathOptions, follow_load
from coilrod.rod.solve import build_spatial_problem, make_mesh
from coilrod.rod.spatial import SpatialRod

L = 0.04


def _rod():
    return Rod(L, 1e6, Circle(2e-3), Magnetization(128e3, 0.0))


def _tip_on_wall(mu, friction_rows=None, nodes=16):
    """A cantilever along x bent up by a field along +y onto the wall y = 0.2 L (its tip
    touches): the problem and the field."""
    rod = _rod()
    field = coils.UniformField(B=(0, rod.field_for_lambda(1.0), 0))
    wall = Wall((0, 0.2 * L, 0), (0, -1, 0), friction=mu)
    P = build_spatial_problem(
        rod, field, make_mesh(rod, nodes), np.zeros(3), np.eye(3), 1e-10, obstacles=[wall]
    )
    if friction_rows is not None:
        args = (P.mesh, P.mu, P.K, P.field, P.L, P.clamp, P.R0, P.tol)
        P = SpatialRod(*args, obstacles=[wall], section=rod.section, friction_rows=friction_rows)
    return P


def _follow(P, scales):
    opts = PathOptions(relative_correction=1.0)
    run = follow_load(P, P.straight(), scales, opts)
    return np.array([p.u for p in run.points])


def test_zero_friction_is_frictionless_to_round_off():
    scales = [3.0]  # (one contact state: the rows are per state)
    plain = _tip_on_wall(0.0)
    rows = _tip_on_wall(0.0, friction_rows=True)  # friction unknowns with mu = 0
    assert plain.nt == 0
    assert rows.nt == 3
    a, b = _follow(plain, scales), _follow(rows, scales)
    Va, Vb = a.reshape(1, plain.n, plain.nv), b.reshape(1, rows.n, rows.nv)
    np.testing.assert_allclose(Vb[:, :, : plain.nv], Va, rtol=0, atol=1e-9 * np.abs(Va).max())
    assert np.abs(Vb[:, :, plain.nv :]).max() == 0.0  # no tangential force at all


def test_stick_within_the_cone_and_a_tip_that_touches_within_a_step_sticks_where_it_touched():
    # after the tip touches, the frictionless shape no longer changes with the load, so the
    # tip sticks as the load triples with an unchanged friction force (the wall's extra
    # reaction is normal): the contact point does not move at all
    P = _tip_on_wall(0.3)
    U = _follow(P, [1.5, 3.0, 4.5])
    tip = P.contact_points(U)[:, -1]
    V = U.reshape(3, P.n, P.nv)
    lam, tau = V[:, -1, 9], V[:, -1, 10:13]
    assert np.all(lam > 0)
    assert np.all(np.linalg.norm(tau, axis=1) < 0.3 * lam)  # strictly inside: stick
    assert np.abs(tau[:, 1:]).max() == 0.0  # tangential: along the wall
    assert np.abs(tau - tau[0]).max() < 1e-9 * lam.min()  # (round-off of the normal force)
    assert np.abs(tip - tip[0]).max() < 1e-13
    # The tip touches within the first step.  Its slip was measured from where it was before
    # the accepted sub-step in which it touched, so its approach counted as slip: it landed
    # on the cone (|tau| = mu lam at landing, set by the sub-steps) and stuck there, 1e-8 to
    # 1e-7 L from the frictionless tip, by an amount that moved with the mesh and the step
    # count (with a Richardson solve: tau / lam = -0.014, -0.014, +0.004, -0.001 at 8..64
    # segments; tau = 2 EI / L^3 at 8 segments in 3 steps).  Reference: the frictionless
    # solution -- its tip does not move after touching, so it is the frictional one too,
    # with tau = 0.  Now: the frictionless tip to 1e-9 L at every mesh, in one step or
    # three, tau ~ 0; the one-step tips converge monotonically, at second order
    assert np.abs(tau).max() < 1e-4  # EI / L^3 (0.18 before: mu lam at landing)
    tips = []
    for nodes in (4, 8, 16):  # (8, 16, 32 as well; 32 costs 3x)
        free = _tip_on_wall(0.0, nodes=nodes)
        ref = free.contact_points(_follow(free, [4.5]))[0, -1]
        P = _tip_on_wall(0.3, nodes=nodes)
        u = _follow(P, [4.5])[-1]
        np.testing.assert_allclose(P.contact_points(u[None])[0, -1], ref, rtol=0, atol=1e-9)
        assert np.abs(u.reshape(P.n, P.nv)[-1, 10:13]).max() < 1e-4
        if nodes == 16:
            np.testing.assert_allclose(tip, np.tile(ref, (3, 1)), rtol=0, atol=1e-9)
        tips.append(ref[0])
    d = np.diff(tips)
    assert np.all(d > 0)  # monotone
    assert d[1] < 0.5 * d[0]  # second order (ratio ~ 1/4)


def test_slip_on_the_cone_push_force_and_hysteresis():
    # a tip bent onto a flat wall parallel to the introducer's axis slides along it as the
    # rod is pushed in or pulled back: in a uniform field (no magnetic force) the clamp's
    # axial force balances the friction alone, push = mu N (closed form, Coulomb), with the
    # sign of the motion; frictionless, the push force is zero both ways
    mag = Magnetization.segments([0.04, 0.01], [0.0, 128e3], [0.0, 0.0])
    rod = Rod(0.05, 1e6, Circle(1e-3), mag)
    field = coils.UniformField(B=(0, 0.01, 0))
    lengths = [0.02, 0.03, 0.035, 0.03, 0.03]  # in, in, in, back, held
    kw = dict(clamp_position=(0, 0, 0), clamp_rotation=np.eye(3), nodes=16)
    runs = {}
    for mu in (0.0, 0.3):
        wall = Wall((0, 0.004, 0), (0, -1, 0), friction=mu)
        runs[mu] = ins = coilrod.insert(rod, wall, lengths, field, **kw)
        N = ins.wall_force[:, 1]  # the normal force on the wall (the tip's)
        assert np.all(N > 0)
        ratio = ins.push_force / N
        if mu == 0:
            assert np.abs(ins.push_force).max() < 1e-12 * N.max()
        else:  # the first step bends the tip in from the straight rod (it slides back)
            np.testing.assert_allclose(ratio[:4], [-mu, mu, mu, -mu], rtol=1e-6)
            # a held step: the previous state is the solution (no creep; its friction stays)
            assert np.abs(ins.tip[4] - ins.tip[3]).max() < 1e-14
            assert abs(ratio[4] / ratio[3] - 1) < 1e-9
    # hysteresis: at 30 mm on the way in and on the way back the tips differ; frictionless
    # they are the same state
    free, rough = runs[0.0], runs[0.3]
    assert abs(free.tip[1, 0] - free.tip[3, 0]) < 1e-12
    assert rough.tip[3, 0] - rough.tip[1, 0] > 1e-4


def test_friction_jacobian_against_finite_differences():
    # a curved wall (the gap hessian enters) and a flat one, random multipliers, slipping
    # and sticking points
    rod = Rod(L, 1e6, Circle(1e-3), Magnetization(128e3, 0.0))
    vessel = Vessel([[0, 0, 0], [0.02, 0, 0], [0.03, 0.01, 0.003]], 3e-3, smooth=True,
                    friction=0.3)  # fmt: skip
    G = 0.4 * np.diag([-0.5, 1.0, -0.5])
    field = coils.LinearField(B0=(0.0, rod.field_for_lambda(1.0), 0.0), gradient=G)
    obstacles = [vessel, Wall((0, -0.002, 0), (0, 1, 0.2), friction=0.5)]
    P = build_spatial_problem(rod, field, make_mesh(rod, 5), np.zeros(3), np.eye(3), 1e-9,
                              obstacles=obstacles)  # fmt: skip
    rng = np.random.default_rng(1)
    phi = 0.2 * rng.standard_normal((P.n, 3))
    phi[0] = 0
    u = P.from_rotations(phi, 0.5).reshape(P.n, P.nv)
    u[:, 9:11] = rng.uniform(-0.5, 2, (P.n, 2))
    u[:, 11:] = 0.5 * rng.standard_normal((P.n, 6))
    u[:, 0:3] += 1e-3 * rng.standard_normal((P.n, 3))
    u = u.ravel()
    ref = P.contact_points(u[None])[0] + 3e-3 * rng.standard_normal((P.n, 3))
    P.set_reference(ref, rng.standard_normal((P.n, 2, 3)))
    P.stick_slack = 0.0  # the exact derivative (the Newton step's proximal term off)
    J = P.dense_jacobian(u, 0.5)
    eps = 1e-7
    E = np.eye(P.size) * eps
    stack = np.concatenate([u + E, u - E])  # all perturbed states in one batched call
    R = P.linearize(stack, np.full(2 * P.size, 0.5), tangent=False).residual
    Jf = (R[: P.size] - R[P.size :]).T / (2 * eps)
    assert np.abs(J - Jf).max() < 1e-7 * np.abs(J).max()


def test_bad_friction():
    for bad in (-0.1, np.nan, np.inf, "x"):
        with pytest.raises(ValueError, match="friction"):
            Wall((0, 0, 0), "y", friction=bad)
        with pytest.raises(ValueError, match="friction"):
            Vessel.straight(0.1, 0.002).with_friction(bad)
    with pytest.raises(ValueError, match="friction"):
        Vessel([[0, 0, 0], [1, 0, 0]], 0.1, friction=-1)
    bend = Vessel.bend(bend_radius=0.02, angle=1.0, radius=0.002).with_friction(0.2)
    assert bend.friction == 0.2
    assert Wall((0, 0, 0), "y", friction=0.2).replace(point=(0, 1, 0)).friction == 0.2

    class Rough:  # the bare gap interface with a negative coefficient
        friction = -0.5

        def gap(self, x):
            return np.asarray(x)[:, 1] + 1.0

        def gap_gradient(self, x):
            return np.tile([0.0, 1.0, 0.0], (len(x), 1))

        def gap_hessian(self, x):
            return np.zeros((len(x), 3, 3))

    with pytest.raises(ValueError, match=r"obstacles\[0\].friction"):
        solve_rod(_rod(), coils.UniformField(B=(0, 1e-3, 0)), [1.0], obstacles=[Rough()])


@pytest.mark.parametrize(("mu", "steps"), [(0.2, 7), (0.2, 12), (0.0, 10)])
def test_capstan_round_a_bend(mu, steps):
    # a floppy rod (E = 1 kPa) drawn round a 90 degree bend by a magnet ahead of it wraps
    # the bend's inner wall like a rope round a post; sliding, its tension grows by the
    # capstan factor exp(mu theta) across the wrap (theta: the turn of the rod's tangent
    # between two points on its free straight spans), against the motion: toward the tip
    # while inserted (the tip pulls), toward the clamp while withdrawn (the clamp pulls).
    # The limit of vanishing bending stiffness; here EI / (T rho^2) ~ 4e-3 and 1e-4
    # (benchmarks/bench_friction.py shows the approach).  Then in again at the high
    # tension (the ratio toward the tip again): a reversal there diverged at every step size
    # (every carried point, moved the new way, stuck; the rod taut between its contacts
    # cannot take that up) until the start's friction was turned round with the motion,
    # and at this tension (3x the pull that passed) until the stick rows' proximal weight
    # was raised (1e-6 -> 1e-3: the Newton steps gave stuck points 1e3 times the cone).
    # The way in in 7 or 12 steps (10 passed before): the rod, pushed against friction,
    # folded in the straight part at one coarse step (a node turned 1.6-2.1 rad from the
    # carried start; at 0.5 mm steps it does not), and that step (12) or the withdrawal
    # (7) failed; a step that turns a node more than 1 rad is now halved.  Frictionless,
    # the tension is the same on both sides of the wrap (exp(0) = 1, to the rod's bending:
    # 5e-3 here), and the frictionless way in at 10 steps folded and failed the same way
    vessel = Vessel.bend(bend_radius=0.02, angle=np.pi / 2, radius=0.002, straight_before=0.02,
                         straight_after=0.06).with_friction(mu)  # fmt: skip
    mag = Magnetization.segments([0.09, 0.01], [0.0, 128e3], [0.0, 0.0])
    rod = Rod(0.1, 1e3, Circle(1e-3), mag)
    # in, back 2 mm, in again (the reversals once, at 7 steps: at 12 and frictionless they
    # repeated those states and checks; the way in is what failed there)
    back = [0.079, 0.078, 0.08] if steps == 7 else []
    lengths = [*np.linspace(0.015, 0.08, steps), *back]
    moments = [5.0] * steps + [150.0] * len(back)  # the magnet's pull (T) raised for the withdrawal
    fields = [coils.Dipole(moment=(0, m, 0), center=(0.04, 0.14, 0)) for m in moments]
    ins = coilrod.insert(rod, vessel, lengths, fields, nodes=16)
    states = ((steps - 1, 1.0), (steps + 1, -1.0), (steps + 2, 1.0))[: 1 + 2 * bool(back)]
    for k, sign in states:
        s, axial = ins.s(k)[:-1], ins.axial_force(k)
        chord = np.diff(ins.centerline(k), axis=0)
        angle = np.arctan2(chord[:, 1], chord[:, 0])
        (t_in, t_out), theta = (
            np.interp([0.01, 0.055], s, axial),
            np.ptp(np.interp([0.01, 0.055], s, angle)),
        )
        assert theta > 1.3  # wrapped (the straight spans are not quite along the walls)
        assert abs((t_out / t_in) ** sign / np.exp(mu * theta) - 1) < (5e-3 if mu else 8e-3)
        assert (t_out / t_in) ** sign > (1.3 if mu else 0.99)  # frictionless, it is 1
    assert np.abs(np.diff(angle)).max() < 0.5  # not folded (a chord turns 0.1-0.3 rad)
    chord = np.diff(ins.centerline(steps - 1), axis=0)  # (and at the end of the way in)
    assert np.abs(np.diff(np.arctan2(chord[:, 1], chord[:, 0]))).max() < 0.5


def test_stick_is_exact_at_several_sticking_points():
    # a cantilever pressed by a uniform load q (N/m, EI/L^3 units: 10) onto a frictionless
    # floor 0.05 L below its surface lies on it from node 11 to the tip; then, with friction
    # and at the same normal load, a uniform tangential load 0.1 q along the rod (toward the
    # tip) is added.  The lying points stick: the friction between them is statically
    # indeterminate (an inextensible straight span), yet each stuck point must not move at
    # all (before: a stick slack r u = 1e-6 (tau_ref - tau) moved them 1.5e-10 L).
    # Equilibrium: the load per length A M t_x (G_xx, G_xy, 0) of the gradient's field (a
    # dead force on the axial moment) integrates to A M (G_xx, G_xy, 0) (x_tip - x_clamp)
    # (trapezoid weights, like the centreline's): the rod's forces on the clamp and on the
    # wall add up to it
    rod = _rod()
    q, AM, mu = 10 * rod.bending_stiffness / L**3, rod.area * 128e3, 0.5
    G = np.zeros((3, 3))
    G[0, 1] = -q / AM
    floor = Wall((0, -0.05 * L - 1e-3, 0), (0, 1, 0))
    args = (rod, coils.LinearField(B0=(0, 0, 0), gradient=G), make_mesh(rod, 16), np.zeros(3),
            np.eye(3), 1e-10)  # fmt: skip
    P0 = build_spatial_problem(*args, obstacles=[floor])
    u0 = follow_load(P0, P0.straight(), [1.0]).points[-1].u
    G[0, 0] = 0.1 * q / AM
    args = (*args[:1], coils.LinearField(B0=(0, 0, 0), gradient=G), *args[2:])
    P = build_spatial_problem(*args, obstacles=[floor.with_friction(mu)])
    ref = P0.contact_points(u0[None])[0]
    P.set_reference(ref)
    start = np.zeros((P.n, P.nv))
    start[:, : P0.nv] = u0.reshape(P0.n, P0.nv)
    run = follow_load(P, start.ravel(), [1.0], PathOptions(relative_correction=1.0),
                      start_scale=1.0)  # fmt: skip
    u = run.points[-1].u
    V = u.reshape(P.n, P.nv)
    lam, tau = V[:, 9], V[:, 10:13]
    force, _, active = P.contact_state(u[None])
    touching = np.flatnonzero(active[0, :, 0])
    np.testing.assert_array_equal(touching, np.arange(11, 17))
    t = np.linalg.norm(tau[touching], axis=1)
    assert np.all(t <= mu * lam[touching] * (1 + 1e-12))  # within the cone
    stuck = touching[t < mu * lam[touching] * (1 - 1e-6)]  # strictly inside: stick
    np.testing.assert_array_equal(stuck, np.arange(12, 17))  # (11 lifts off: on the cone)
    assert np.all(t > 0)
    assert np.abs(P.contact_points(u[None])[0][stuck] - ref[stuck]).max() <= 1e-12  # units of L
    # the frames at hand (an insertion's record) give the same contact state and points
    frames = P.frames(u[None])
    np.testing.assert_array_equal(P.contact_state(u[None], frames)[0], force)
    np.testing.assert_array_equal(P.contact_points(u[None], frames), P.contact_points(u[None]))
    f = AM * G[0, :] * L**3 / rod.bending_stiffness  # per length along x, EI / L^3
    wall = P.contact_totals(force)[0, 0]  # the rod's force on the wall, EI / L^2
    clamp = V[0, 6:9] + P.mesh.w[0] * f  # on the clamp (its node's share of the load)
    np.testing.assert_allclose(clamp + wall, f * (V[-1, 0] - V[0, 0]), rtol=0, atol=1e-9)
    assert wall[0] > 0.5  # the friction carries much of the tangential load (1)


def test_a_tip_that_touches_within_an_insertion_step_sticks_where_it_touched():
    # insert() at a held length in a rising field (the rod and wall of _tip_on_wall): the
    # tip touches the rough wall within the step lambda 0.3 -> 1.5 (at lambda ~0.55).  After
    # it touches, the frictionless shape no longer changes with the field (the wall's extra
    # reaction is normal), so the frictionless state is the frictional one too, with no
    # friction force and no push force (a uniform field pulls the rod with no net force: the
    # clamp's axial force balances the wall's tangential one) -- in any number of steps.
    # Before, the insertion step measured the tip's slip from where it was before the step,
    # so its approach counted as slip and froze a full-slip force in: f_t / f_n = -0.016 in
    # 1 or 3 steps, the tip 2.7e-6 L from the frictionless one (8 segments; at 16 and 32
    # segments most such runs failed at the landing, ConvergenceError).
    rod = _rod()
    kw = dict(clamp_position=(0, 0, 0), clamp_rotation=np.eye(3), nodes=8)
    tips = {}
    for mu, steps in ((0.0, 1), (0.3, 1), (0.3, 3)):
        lam = np.linspace(0.3, 1.5, steps + 1)
        fields = [coils.UniformField(B=(0, rod.field_for_lambda(v), 0)) for v in lam]
        wall = Wall((0, 0.2 * L, 0), (0, -1, 0), friction=mu)
        ins = coilrod.insert(rod, wall, [L] * lam.size, fields, **kw)
        f_t, f_n = ins.wall_force[-1, 0], ins.wall_force[-1, 1]
        assert f_n > 0
        assert abs(f_t) < 1e-6 * f_n  # (-0.016 before)
        assert abs(ins.push_force[-1]) < 1e-6 * f_n
        tips[mu, steps] = ins.tip[[0, -1]]
    # the frictionless tip, in 1 or 3 steps to the touch (2.7e-6 L before)
    np.testing.assert_allclose(tips[0.3, 1], tips[0.0, 1], rtol=0, atol=1e-9 * L)
    np.testing.assert_allclose(tips[0.3, 3], tips[0.0, 1], rtol=0, atol=1e-9 * L)


def test_an_insertion_that_lands_on_a_rough_bend_does_not_depend_on_its_steps():
    # h-brk5's reproducer: a 4 mm catheter fed into a rough bend (mu 0.2) lands on the outer
    # wall between 15.7 and 18.8 mm of free length; at 48 segments the landing step failed
    # (ConvergenceError after 12 halvings at 15.6953 mm, as at 56-128 segments).  The
    # quasi-static answer of a feed that keeps every point sliding one way does not depend on
    # the number of insertion steps: 9 and 17 steps agree at the common lengths.
    rod = Rod(0.04, 1e6, Circle(2e-3), Magnetization(128e3, 0))
    bend = Vessel.bend(0.02, np.pi / 2, 0.003, 0.005, 0.03, start=(-1e-3, 0, 0))
    field = coils.UniformField(B=(0, 8e-3, 0))
    runs = [
        coilrod.insert(rod, bend.with_friction(0.2), np.linspace(0.006, 0.04, k), field, nodes=48)
        for k in (9, 17)
    ]
    coarse, fine = runs
    assert np.abs(coarse.push_force).max() > 1e-3  # N: the wall is reached and pushed on
    np.testing.assert_allclose(coarse.tip, fine.tip[::2], rtol=0, atol=1e-9 * 0.04)
    np.testing.assert_allclose(
        coarse.push_force, fine.push_force[::2], rtol=0, atol=1e-9 * np.abs(coarse.push_force).max()
    )
