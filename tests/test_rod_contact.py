"""Contact of the rod with rigid obstacles: a cantilever pushed by its field against a flat
wall (closed-form elastica with the tip reaction), global equilibrium, mesh independence of
the total force, no penetration, and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

import coilrod
import coils
from coilrod import Circle, Magnetization, Rod, Vessel, Wall, solve_rod
from coilrod.rod.elastica import elastica

L = 0.04


class _Wall:
    """A plane through ``point`` with unit ``normal`` (the admissible side); the minimal
    obstacle interface (gap, gradient, hessian of points in m)."""

    def __init__(self, point, normal):
        self.p = np.asarray(point, float)
        self.n = np.asarray(normal, float) / np.linalg.norm(normal)

    def gap(self, x):
        return (np.asarray(x) - self.p) @ self.n

    def gap_gradient(self, x):
        return np.broadcast_to(self.n, np.shape(x)).copy()

    def gap_hessian(self, x):
        return np.zeros(np.shape(x) + (3,))


def _rod():
    return Rod(L, 1e6, Circle(2e-3), Magnetization(128e3, 0.0))


def _tip_wall_reference(rod, lam, d):
    """M axial in a field along +y, a frictionless wall y = d touched at the tip: the bending
    moment is (M B A - F)(x_L - x(s)) with F the wall's (downward) tip force, the free
    elastica's moment with a smaller load -- so the shape is the free elastica at the
    lambda_eff whose tip height is d, and F = (lambda - lambda_eff) EI / L^2 (closed form,
    elliptic integrals)."""

    def height(le):
        return elastica(le, np.pi / 2, length=L).tip[1] - d

    lam_eff = brentq(height, 1e-9, lam, xtol=1e-15, rtol=1e-14)
    force = (lam - lam_eff) * rod.bending_stiffness / L**2
    return lam_eff, force


class TestTipContact:
    @pytest.mark.parametrize("kind", ["wall", "duck", "tube"])
    def test_force_and_shape_against_the_closed_form(self, kind):
        rod = _rod()
        d = 0.2 * L
        wall = {
            "wall": Wall((0, d, 0), (0, -1, 0)),
            "duck": _Wall((0, d, 0), (0, -1, 0)),  # the bare gap interface
            # a straight tube around the x axis: in the plane z = 0 its wall is y = +-d
            "tube": Vessel.straight(2 * L, d, start=(-0.5 * L, 0, 0)),
        }[kind]
        lams = np.array([1.5, 3.0, 6.0])
        b = rod.field_for_lambda(1.0)
        res = solve_rod(rod, coils.UniformField(B=(0, b, 0)), lams, obstacles=[wall])
        r = 0.5 * rod.section.diameter  # the rod's surface touches the wall: its axis at d - r
        for k, lam in enumerate(lams):
            lam_eff, force = _tip_wall_reference(rod, lam, d - r)
            ref = elastica(lam_eff, np.pi / 2, length=L)
            total = res.obstacle_forces(k)[0]
            assert abs(total[1] / force - 1) < 1e-6, (total, force)
            assert abs(total[0]) < 1e-12
            assert abs(total[2]) < 1e-12
            assert abs(res.tip[k, 0] - ref.tip[0]) < 1e-7 * L
            assert abs(res.tip[k, 1] - (d - r)) < 1e-9 * L
            active = res.contact_set(k)[:, 0]
            assert active[-1]
            assert not active[:-1].any()
            assert res.gaps(k).min() >= -1e-6 * L

    def test_small_deflection_by_hand(self):
        # linear beam: a uniform couple m (N m/m) and a tip force F (N) bend it alike,
        # w(L) = (m - F) L^3 / (3 EI); with the tip held at d: F = m - 3 EI d / L^3
        rod = _rod()
        lam = 1e-3
        d = 0.5 * lam * L / 3  # half the free deflection
        wall = _Wall((0, d + 0.5 * rod.section.diameter, 0), (0, -1, 0))  # the surface
        res = solve_rod(
            rod, coils.UniformField(B=(0, rod.field_for_lambda(lam), 0)), [1.0], obstacles=wall
        )
        m = lam * rod.bending_stiffness / L**2
        expected = m - 3 * rod.bending_stiffness * d / L**3
        assert abs(res.obstacle_forces(0)[0][1] / expected - 1) < 2e-3

    def test_total_force_is_mesh_independent(self):
        # coarse meshes against the closed form (the default mesh is checked above)
        rod = _rod()
        wall = _Wall((0, 0.2 * L, 0), (0, -1, 0))
        field = coils.UniformField(B=(0, rod.field_for_lambda(3.0), 0))
        _, force = _tip_wall_reference(rod, 3.0, 0.2 * L - 0.5 * rod.section.diameter)
        for n in (16, 32):
            res = solve_rod(rod, field, [1.0], nodes=n, obstacles=[wall])
            assert abs(res.obstacle_forces(0)[0][1] / force - 1) < 1e-4


class TestEquilibrium:
    def test_clamp_reaction_magnetic_and_contact_forces_balance(self):
        # a gradient field: a magnetic body force as well as the couple
        rod = _rod()
        G = 0.4 * np.array([[-0.5, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -0.5]])
        field = coils.LinearField(B0=(0.0, rod.field_for_lambda(4.0), 0.0), gradient=G)
        wall = _Wall((0, 0.15 * L, 0), (0, -1, 0.1))
        res = solve_rod(rod, field, [1.0], obstacles=[wall], richardson=False)
        P = res._solution.problems[0]
        U = res._solution.states[0]
        V = U.reshape(P.n, P.nv)
        EI = rod.bending_stiffness
        clamp = V[0, 6:9] * EI / L**2  # internal force of the first segment: the support's
        R = P.frames(U)[0]
        m = np.einsum("nij,nj->ni", R, P.mu)
        Gs = field.gradient(P.points(V[:, 0:3]))
        f = np.einsum("nij,ni->nj", Gs, m) * L  # per unit scale, EI/L^2 per unit length
        magnetic = np.sum(P.mesh.w[1:, None] * f[1:], axis=0) * EI / L**2
        contact = -res.obstacle_forces(0)[0]
        total = clamp - magnetic - contact
        assert np.abs(total).max() < 1e-9 * np.abs(clamp).max()


class TestBadInput:
    def test_no_admissible_straight_start(self):
        wall = _Wall((0.5 * L, 0, 0), (-1, 0, 0))  # cuts the straight rod
        with pytest.raises(ValueError, match="admissible straight start"):
            solve_rod(_rod(), coils.UniformField(B=(0, 1e-3, 0)), [1.0], obstacles=[wall])

    def test_not_an_obstacle(self):
        with pytest.raises(ValueError, match=r"obstacles\[0\]"):
            solve_rod(_rod(), coils.UniformField(B=(0, 1e-3, 0)), [1.0], obstacles=[object()])

    def test_planar_model_with_obstacles(self):
        wall = _Wall((0, 0.2 * L, 0), (0, -1, 0))
        with pytest.raises(ValueError, match="spatial"):
            solve_rod(
                _rod(), coils.UniformField(B=(0, 1e-3, 0)), [1.0], obstacles=[wall], model="planar"
            )

    def test_no_contact_data_without_obstacles(self):
        res = solve_rod(_rod(), coils.UniformField(B=(0, 1e-3, 0)), [1.0], nodes=8)
        with pytest.raises(ValueError, match="no obstacles"):
            res.contact_force(0)


class TestInsertion:
    @staticmethod
    def _catheter():
        mag = Magnetization.segments([0.04, 0.01], [0.0, 128e3], [0.0, 0.0])
        return Rod(0.05, 1e6, Circle(1e-3), mag)

    def test_through_a_bend(self):
        vessel = Vessel.bend(
            bend_radius=0.02, angle=np.pi / 2, radius=0.002, straight_before=0.02,
            straight_after=0.03,
        )  # fmt: skip

        def schedule(k, length):
            a = np.pi / 2 * min(1.0, max(0.0, (length - 0.015) / 0.02))
            return coils.UniformField(B=0.01 * np.array([np.cos(a), np.sin(a), 0.0]))

        lengths = np.linspace(0.012, 0.05, 20)
        ins = coilrod.insert(self._catheter(), vessel, lengths, schedule, nodes=48)
        assert len(ins) == lengths.size
        assert ins.min_gap.min() >= -1e-6 * 0.05
        for k in range(len(ins)):  # every contact point inside the lumen, the length as asked
            # (the nodes between the corners of a concave wall cross it by the sagitta)
            assert vessel.gap(ins.contact_points(k)).min() >= -1e-6 * 0.05
            assert ins.min_gap[k] <= vessel.gap(ins.contact_points(k)).min() + 1e-15
            seg = np.linalg.norm(np.diff(ins.centerline(k), axis=0), axis=1).sum()
            assert abs(seg / lengths[k] - 1) < 1e-3  # chord sum of an inextensible rod
        # the tip has gone round the bend: beyond the arc's end (y > bend radius)
        assert ins.tip[-1, 1] > 0.02
        assert np.linalg.norm(ins.wall_force, axis=1).max() > 0
        np.testing.assert_array_equal(
            ins.wall_force_magnitude, np.linalg.norm(ins.wall_force, axis=1)
        )
        # the plot draws no force where there is none (a log axis has no zero)
        import matplotlib.pyplot as plt
        from _figure_checks import assert_readable

        force = np.linalg.norm(ins.wall_force, axis=1)
        assert (force == 0).any()
        fig = ins.plot()
        (line,) = [ln for ln in fig.axes[1].get_lines() if ln.get_label() == "wall force"]
        y = np.asarray(line.get_ydata(), float)
        assert np.all(np.isnan(y[force == 0]))
        np.testing.assert_allclose(y[force > 0], 1e3 * force[force > 0])
        assert_readable(fig)
        plt.close(fig)

    @staticmethod
    def _tip_on_wall_carried(*eps):
        """The tip-on-a-wall cantilever (lambda 6, 16 segments, spatial rod): its solved
        problem and state, and the problems of the same rod longer by each ``eps`` L."""
        from coilrod.rod.solve import build_spatial_problem, make_mesh

        rod = _rod()
        field = coils.UniformField(B=(0, rod.field_for_lambda(6.0), 0))
        wall = Wall((0, 0.2 * L, 0), (0, -1, 0))
        res = solve_rod(rod, field, [1.0], nodes=16, richardson=False, obstacles=[wall],
                        stability=False, model="spatial")  # fmt: skip
        old, u = res._solution.problems[0], res._solution.states[0][0]
        new = []
        for e in eps:
            longer = Rod(L * (1 + e), 1e6, Circle(2e-3), Magnetization(128e3, 0.0))
            new.append(build_spatial_problem(longer, field, make_mesh(longer, 16), np.zeros(3),
                                             np.eye(3), obstacles=[wall], mixed=True))  # fmt: skip
        return old, u, new

    def test_carried_start_keeps_the_tip_contact_force(self):
        # a tip pressed on a wall, carried to a free length longer by 1e-9 L: the start of the
        # insertion step is the solved state (continuity in the length), the tip's contact
        # force included (it was dropped: the tip lay beyond the old arc lengths)
        from coilrod.contact.insertion import _carry

        old, u, (new,) = self._tip_on_wall_carried(1e-9)
        tip_old = u.reshape(old.n, old.nv)[-1, 9]
        assert tip_old > 0  # the tip touches
        start = _carry(old, u, new)
        np.testing.assert_allclose(start.reshape(new.n, new.nv)[-1, 9], tip_old, rtol=1e-6)
        # its error: the tip pushed 1e-9 L into the wall, kappa g ~ 3e-5 against the 1e-9
        # tolerance (without the tip's force: ~2e11)
        assert new.error(new.linearize(start[None], np.array([1.0])), None)[0] < 1e5

    def test_active_set_start_is_second_order_in_the_length(self):
        # an insertion step's start (coilrod.rod.contact_predictor.active_set_start): the
        # tip-contact cantilever carried to free lengths longer by 2 % and 1 %; against the
        # state Newton converges to from the carried shape (Fischer-Burmeister, as insert),
        # the carried shape is first order in the length change, the solution of its
        # linearised complementarity problem second order, with the same contact set
        from coilrod.contact.insertion import _carry
        from coilrod.path.corrector import NewtonOptions, newton
        from coilrod.rod.contact_predictor import active_set_start

        errors = []
        old, u, problems = self._tip_on_wall_carried(2e-2, 1e-2)
        for new in problems:
            new.ncp = "fb"
            start = _carry(old, u, new)
            pred = active_set_start(new, start)
            ref = newton(new, start, 1.0, NewtonOptions(max_iter=40, stagnation=12))
            assert ref.ok
            np.testing.assert_array_equal(
                new.contact_state(pred[None])[2], new.contact_state(ref.u[None])[2]
            )
            shape = [np.abs((x - ref.u).reshape(new.n, new.nv)[:, :6]).max() for x in (start, pred)]
            errors.append(shape)
        (carried2, pred2), (carried1, pred1) = errors
        assert 1.8 < carried2 / carried1 < 2.2
        assert pred2 / pred1 > 3.5
        assert pred1 < 1e-2 * carried1

    def test_a_failed_active_set_start_falls_back_to_the_carried_shape(self, monkeypatch):
        # Newton from a start it cannot use (every node turned 10 rad: beyond the rotation
        # chart, inadmissible) fails at once; the step is tried again from the carried
        # shape (the secant) before it is halved: two solves a step, the tip on the wall
        # (without the second try every halved step failed the same way: ConvergenceError)
        import coilrod.contact.insertion as insertion

        vessel = Vessel.bend(bend_radius=0.02, angle=np.pi / 2, radius=0.002,
                             straight_before=0.02, straight_after=0.03)  # fmt: skip
        field = coils.UniformField(B=(0.0, 0.01, 0.0))
        monkeypatch.setattr(insertion, "active_set_start", lambda p, u: u + 10.0)
        ins = coilrod.insert(self._catheter(), vessel, [0.02, 0.023, 0.026], field, nodes=16)
        np.testing.assert_array_equal(ins.substeps, [1, 2, 2])
        assert ins.contact_nodes[-1][-1]  # the tip pressed on the outer wall
        assert vessel.gap(ins.contact_points(2)).min() >= -1e-6 * 0.05

    def test_step_problems_are_the_public_paths(self):
        # an insertion step's problem built from the device's constants taken once
        # (coilrod.contact._parts.StepProblems) against free_part + make_mesh +
        # build_spatial_problem: the same mesh, node moments and scales, bit for bit -- free
        # lengths inside the tip segment, on a segment edge (0.01 m: the proximal
        # segment's length left exactly 0), across it and the whole rod; a profile off the
        # bending plane; a callable profile (the public path itself)
        from coilrod.contact._parts import StepProblems
        from coilrod.contact.insertion import free_part
        from coilrod.rod.solve import build_spatial_problem, make_mesh

        vessel = Vessel.straight(0.1, 0.002)
        field = coils.UniformField(B=(0.0, 0.01, 0.0))
        tilted = Magnetization.segments([0.02, 0.02, 0.01], [9e4, 0.0, 128e3], [0.3, 0.0, -1.0],
                                        [0.2, 0.0, -0.4])  # fmt: skip
        graded = Magnetization(lambda s: 1e5 * (1 + np.asarray(s)), 0.2, breakpoints=[0.03])
        for mag in (self._catheter().magnetization, tilted, graded):
            rod = Rod(0.05, 1e6, Circle(1e-3), mag)
            problems = StepProblems(rod, 12, np.zeros(3), np.eye(3), 1e-9, [vessel])
            assert problems.fast == (mag is not graded)
            for length in (0.004, 0.01, 0.0173, 0.04, 0.05):
                free = free_part(rod, length)
                ref = build_spatial_problem(free, field, make_mesh(free, 12), np.zeros(3),
                                            np.eye(3), 1e-9, obstacles=[vessel])  # fmt: skip
                got = problems(length, field)
                for name in ("mu", "K", "L", "kappa", "_half", "_row_scale", "_bend_scale"):
                    np.testing.assert_array_equal(getattr(got, name), getattr(ref, name))
                for name in ("s", "h", "w", "edges", "counts"):
                    np.testing.assert_array_equal(getattr(got.mesh, name), getattr(ref.mesh, name))
                assert (got.size, got.nc, got.kl, got.ku) == (ref.size, ref.nc, ref.kl, ref.ku)
            with pytest.raises(ValueError, match="free length"):
                problems(0.06, field)

    def test_zero_field_in_a_straight_tube(self):
        vessel = Vessel.straight(0.1, 0.002, start=(0.0, 0.0, 0.0))
        ins = coilrod.insert(
            self._catheter(), vessel, [0.01, 0.02, 0.03], coils.UniformField(B=(0, 0, 0))
        )
        assert np.abs(ins.tip - np.array([[0.01, 0, 0], [0.02, 0, 0], [0.03, 0, 0]])).max() < 1e-12
        assert np.abs(ins.wall_force).max() == 0.0

    def test_bad_input(self):
        vessel = Vessel.straight(0.1, 0.002)
        cath = self._catheter()
        field = coils.UniformField(B=(0, 0, 0))
        with pytest.raises(ValueError, match="lengths"):
            coilrod.insert(cath, vessel, [0.01, 0.2], field)
        with pytest.raises(ValueError, match="field_schedule"):
            coilrod.insert(cath, vessel, [0.01, 0.02], [field])
        with pytest.raises(ValueError, match="outside"):
            coilrod.insert(cath, vessel, [0.01], field, clamp_position=(0, 0.01, 0),
                           clamp_rotation=np.eye(3))  # fmt: skip


def test_distributed_contact_on_a_flat_support():
    # a uniform body force q per length (a gradient field on M along the axis) lays the rod
    # on a floor delta below the clamp: beam theory gives touchdown at a = (72 EI delta/q)^1/4,
    # a point reaction q a / 3 there and the contact force per length q beyond it
    rod = _rod()
    EI, A, M = rod.bending_stiffness, rod.area, 128e3
    q = EI / L**3
    G = np.zeros((3, 3))
    G[0, 1] = -q / (A * M)
    delta = 1e-3 * L
    a = (72 * EI * delta / q) ** 0.25
    floor = Wall((0, -delta - 1e-3, 0), (0, 1, 0))  # the 2 mm rod's surface delta above it
    field = coils.LinearField(B0=(0, 0, 0), gradient=G)
    for n in (16, 32):  # contact at the polygon's corners: exact on every mesh
        res = solve_rod(rod, field, [1.0], nodes=n, richardson=False, obstacles=[floor],
                        stability=False)  # fmt: skip
        s = res.contact_s
        inner = (s > a + 0.1 * L) & (s < 0.95 * L)
        assert inner.sum() >= n // 4
        assert np.abs(res.contact_force(0)[inner, 1] / q - 1).max() < 1e-9
        assert res.contact_set(0)[inner, 0].all()
        assert not res.contact_set(0)[s < 0.9 * a, 0].any()
        # the total reaction: q (L - a) on the flat part and q a / 3 at the touchdown point
        # (beam theory; the rod's slope ~ delta / a makes the nonlinear terms ~ 1e-6)
        total = q * (L - a) + q * a / 3
        assert abs(res.obstacle_forces(0)[0][1] / -total - 1) < 1.5 / n**2  # touchdown: h^2
        assert res.gaps(0).min() >= -1e-12 * L


def test_distributed_contact_converges_at_second_order():
    # a non-uniform body force q(s) = q0 (1 + 2 s^2 / L^2) (magnetization graded along the
    # rod in a gradient field) lays the rod on a floor: where it lies flat (no curvature, no
    # shear) the contact force per length is q(s) exactly; the discrete one converges at
    # second order in the segment length
    M0 = 128e3
    rod = Rod(L, 1e6, Circle(2e-3), Magnetization(lambda s: M0 * (1 + 2 * (s / L) ** 2), 0.0))
    q0 = rod.bending_stiffness / L**3
    G = np.zeros((3, 3))
    G[0, 1] = -q0 / (rod.area * M0)
    floor = Wall((0, -1e-3 * L - 1e-3, 0), (0, 1, 0))  # 1e-3 L below the rod's surface
    errors = []
    for n in (16, 32):
        res = solve_rod(rod, coils.LinearField(B0=(0, 0, 0), gradient=G), [1.0], nodes=n,
                        richardson=False, obstacles=[floor], stability=False)  # fmt: skip
        s = res.contact_s
        inner = (s > 0.7 * L) & (s < 0.95 * L)
        assert res.contact_set(0)[inner, 0].all()
        q = q0 * (1 + 2 * (s[inner] / L) ** 2)
        errors.append(np.abs(res.contact_force(0)[inner, 1] / q - 1).max())
    assert errors[1] < 3e-4
    assert 3.5 < errors[0] / errors[1] < 4.5  # h^2


def test_richardson_keeps_the_rod_admissible():
    # a wall between the coarse and the fine mesh's free tips: one mesh touches it, the
    # other does not, and the extrapolation of the two would put the tip through the wall
    rod = _rod()
    field = coils.UniformField(B=(0, rod.field_for_lambda(3.0), 0))
    n = 8
    y_c = solve_rod(rod, field, [1.0], nodes=n, richardson=False).tip[0, 1]
    y_f = solve_rod(rod, field, [1.0], nodes=2 * n, richardson=False).tip[0, 1]
    assert (4 * y_f - y_c) / 3 - 0.5 * (y_c + y_f) > 1e-4 * L  # it would cross by that
    r = 0.5 * rod.section.diameter  # the rod's surface touches the wall
    wall = Wall((0, 0.5 * (y_c + y_f) + r, 0), (0, -1, 0))
    res = solve_rod(rod, field, [1.0], nodes=n, obstacles=[wall])
    assert wall.gap(res.centerline(0)).min() >= r - 1e-9 * L
    assert wall.gap(res.tip[0]).min() >= r - 1e-9 * L
    assert res.gaps(0).min() >= -1e-9 * L
    # the returned contact points are those gaps() reports on
    R = res.frames(0)
    h = np.diff(res.s)
    corners = res.centerline(0)[:-1] + 0.5 * h[:, None] * R[:-1, :, 0]
    np.testing.assert_allclose(res.gaps(0)[:-1, 0], wall.gap(corners) - r, atol=1e-15)


def _wall_and_bend_problem(section):
    """A spatial contact problem of 5 segments against a tilted wall and a curved vessel
    wall (a gap hessian), and a random state touching both (off equilibrium)."""
    from coilrod.rod.solve import build_spatial_problem, make_mesh

    rod = Rod(L, 1e6, section, Magnetization(128e3, 0.0))
    G = 0.4 * np.array([[-0.5, 0, 0], [0, 1, 0], [0, 0, -0.5]])
    field = coils.LinearField(B0=(0, 0.01, 0.002), gradient=G)
    bend = Vessel.bend(bend_radius=0.02, angle=np.pi / 2, radius=0.004, straight_before=0.02,
                       straight_after=0.03)  # fmt: skip
    obstacles = [Wall((0, 0.01, 0), (0, -1, 0.2)), bend]
    P = build_spatial_problem(rod, field, make_mesh(rod, 5), np.array([0.02, 0, 0]), np.eye(3),
                              obstacles=obstacles)  # fmt: skip
    rng = np.random.default_rng(0)
    u = P.straight().reshape(P.n, P.nv)
    u[:, 0:3] += 0.01 * rng.standard_normal((P.n, 3))
    u[:, 3:6] += 0.2 * rng.standard_normal((P.n, 3))
    u[:, 6:] = rng.standard_normal((P.n, P.nv - 6))
    return P, u.ravel(), rng


@pytest.mark.parametrize("section", [Circle(2e-3), coilrod.Rectangle(3e-3, 1e-3)])
def test_contact_jacobian_against_finite_differences(section):
    # the corner contact's blocks (force, moment and complementarity rows in a node's
    # positions, rotations and multipliers) against central differences of the residual,
    # at a random state touching a tilted wall and a curved vessel wall
    P, u, rng = _wall_and_bend_problem(section)
    J = P.dense_jacobian(u, 0.7)

    def residual(v):
        return P.linearize(v[None], 0.7, tangent=False).residual[0]

    eps = 1e-6
    fd = np.array([(residual(u + eps * e) - residual(u - eps * e)) / (2 * eps)
                   for e in np.eye(P.size)]).T  # fmt: skip
    assert np.abs(J - fd).max() < 1e-8 * np.abs(J).max()
    # the new moment row is there: the moment rows depend on the multipliers
    lam_cols = (np.arange(P.n)[:, None] * P.nv + 9 + np.arange(P.nc)).ravel()
    moment_rows = (np.arange(1, P.n)[:, None] * P.nv + 3 + np.arange(3)).ravel()
    assert np.abs(J[np.ix_(moment_rows, lam_cols)]).max() > 0
    # the second variation's blocks are computed when a stability count asks for them: a
    # linearization keeps its blocks when a later one reuses the assembly's arrays first
    D, E = P.linearize(u[None], np.array([0.7])).tangent.blocks  # (evaluated now)
    lazy = P.linearize(u[None], np.array([0.7]))
    P.linearize(u[None] + 0.01 * rng.standard_normal(P.size), np.array([0.3]))
    for x, y in zip(lazy.tangent.blocks, (D, E), strict=True):
        np.testing.assert_array_equal(x, y)


def test_compiled_contact_terms_are_the_numpy_twins(monkeypatch):
    # the compiled contact kernel (coilrod.rod._compiled_contact, run as Python through its
    # .py_func: nothing compiles) against its numpy twin (SpatialRod._contact_rows,
    # _contact_blocks, _scatter) on the state of the test above and a perturbed one as a
    # stack of two, for both complementarity functions and every row the gap's: the same
    # residual, the band to rounding, the same second variation; and a load step's
    # prediction band from the kept kernel inputs is the every-rows linearization's.  The
    # compiled contact points (round_points, .py_func) give bitwise the numpy twin's surface
    # gaps (SpatialRod._state_gaps; so3's series at a few nodes and at all), and both the
    # gaps of the frames' first columns (expm) to rounding
    import coilrod.rod._compiled_contact as cc
    import coilrod.rod._compiled_spatial as cs

    P, u, rng = _wall_and_bend_problem(Circle(2e-3))
    U = np.stack([u, u + 1e-3 * rng.standard_normal(P.size)])
    S = np.array([0.7, 0.5])
    G = np.stack([u, 1e-3 * u])  # (every rotation below so3's series switch in the second)
    twin = {}
    for ready in (False, True):
        monkeypatch.setattr(cc._rental, "ready", ready)
        monkeypatch.setattr(cc._points_rental, "ready", ready)
        monkeypatch.setattr(cc, "COMPILE_AFTER", np.inf)
        monkeypatch.setattr(cc, "POINTS_COMPILE_AFTER", np.inf)
        monkeypatch.setattr(cc._rental, "held", lambda: False)
        monkeypatch.setattr(cc._points_rental, "held", lambda: False)
        if ready:  # the kernel and its helpers as Python
            for mod, names in ((cc, ("_cross", "_hat", "_mm", "_sym_term", "_exp_and_jl",
                                     "_put", "contact_core", "round_points")),
                               (cs, ("_hat",))):  # fmt: skip
                for name in names:
                    monkeypatch.setattr(mod, name, getattr(mod, name).py_func)
        P._gaps_memo.clear()
        twin.setdefault("gaps", []).append(np.array(P._state_gaps(G)))
        for mode in ("min", "fb", "every"):
            P.ncp, P._every_rows = ("min", True) if mode == "every" else (mode, False)
            lin = P.linearize(U, S)
            rows = P.linearize(U, S, tangent=False).residual
            D, E = lin.tangent.blocks
            counts = P.negative_count(lin)
            twin.setdefault(mode, []).append((lin.residual, rows, lin.tangent.parts, D, E, counts))
        P._every_rows = False
        P.ncp = "min"
        lin = P.linearize(u[None], np.array([0.7]))  # (a one-state tangent: its inputs kept)
        twin.setdefault("kept", []).append(P._every_active_band(u, 0.7))
        assert (P._kept[2] is None) == ready  # (the kernel's inputs kept, not numpy's blocks)
    for mode in ("min", "fb", "every"):
        (R, rows, ab, D, E, counts), (Rc, rows_c, abc, Dc, Ec, counts_c) = twin[mode]
        np.testing.assert_array_equal(counts_c, counts)
        scale = np.abs(ab).max()
        np.testing.assert_allclose(Rc, R, rtol=1e-14, atol=1e-14 * np.abs(R).max())
        np.testing.assert_array_equal(rows_c, rows)
        np.testing.assert_allclose(abc, ab, rtol=0, atol=1e-14 * scale)
        np.testing.assert_array_equal(abc != 0, ab != 0)
        np.testing.assert_allclose(Dc, D, rtol=0, atol=1e-14 * np.abs(D).max())
        np.testing.assert_array_equal(Ec, E)  # (no contact terms)
    assert (twin["min"][0][2] != 0).sum() < (twin["fb"][0][2] != 0).sum()  # (min: 0 or 1)
    gaps, gaps_c = twin["gaps"]
    np.testing.assert_array_equal(gaps_c, gaps)
    frames = P.surface_gaps(P.node_positions(G), P.frames(G))
    np.testing.assert_allclose(gaps, frames, rtol=0, atol=1e-14)
    (band, rate), (band_c, rate_c) = twin["kept"]
    np.testing.assert_allclose(band_c, band, rtol=0, atol=1e-14 * np.abs(band).max())
    np.testing.assert_array_equal(rate_c, rate)
    every = twin["every"][1][2][:, : P.size]  # the kernel's every-rows band, member 0
    np.testing.assert_array_equal(band_c, every)


def test_the_contact_kernels_cache_goes_stale_with_its_helpers(tmp_path, monkeypatch):
    # numba's cache checks only the defining file, but the contact kernel compiles the
    # helpers of _compiled_spatial in: its cache entry is tied to both files' contents
    # (coils._numba_cache.tie_to_sources).  numba's own loader reads the indices; nothing is
    # compiled
    import hashlib
    from pathlib import Path

    import numba
    from numba.core import config

    import coilrod.rod._compiled_contact as cc
    import coilrod.rod._compiled_spatial as cs
    import coils._numba_cache as nc

    both = hashlib.sha256(Path(cc.__file__).read_bytes() + Path(cs.__file__).read_bytes())
    assert cc.contact_core._cache._cache_file._source_stamp[1] == both.hexdigest()
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path))  # what NUMBA_CACHE_DIR sets
    helper = tmp_path / "helper.py"
    helper.write_text("A = 1\n")

    def twice(x):
        return 2.0 * x

    def tied(*paths):  # a fresh process's dispatcher of twice, tied to paths
        kernel = numba.njit(cache=True)(twice)
        nc.tie_to_sources(kernel, *paths)
        return kernel

    tied(helper)._cache._cache_file._save_index({"sig": "twice.1.nbc"})
    assert tied(helper)._cache._cache_file._load_index() == {"sig": "twice.1.nbc"}  # the same
    helper.write_text("A = 2\n")
    assert tied(helper)._cache._cache_file._load_index() == {}  # changed: compiled anew
    kernel = tied(tmp_path / "missing.py")  # unreadable: no cache rather than a stale one
    assert isinstance(kernel._cache, numba.core.caching.NullCache)
    assert not kernel.overloads


class TestSurface:
    """Contact is with the rod's surface: a circle's radius, a rectangle's half-extent along
    the contact normal."""

    def test_rectangle_tip_on_a_wall(self):
        # a strip (thickness 0.5 mm in the bending plane, width 3 mm across it) bends up onto
        # a wall: the tip section, tilted by the tip angle, touches it with its thickness'
        # half-extent along the wall's normal, (t/2) |n . d_2| (the width lies along the
        # wall); the force is the closed-form elastica's at that tip height
        strip = Rod(L, 1e6, coilrod.Rectangle(width=3e-3, thickness=0.5e-3),
                    Magnetization(128e3, 0.0))  # fmt: skip
        field = coils.UniformField(B=(0, strip.field_for_lambda(3.0), 0))
        d = 0.2 * L
        res = solve_rod(strip, field, [1.0], nodes=16, obstacles=[Wall((0, d, 0), (0, -1, 0))])
        d2 = res.frames(0)[-1][:, 1]
        assert 0.5 < abs(d2[1]) < 0.99  # tilted
        assert abs(res.tip[0, 1] - (d - 0.25e-3 * abs(d2[1]))) < 1e-9 * L
        # (the force acts at the section's corner, off the axis: the tip also carries its
        # couple, so the axis is not the elastica of a tip force alone -- only close to it)
        _, force = _tip_wall_reference(strip, 3.0, res.tip[0, 1])
        assert abs(res.obstacle_forces(0)[0][1] / force - 1) < 1e-2
        assert res.contact_set(0)[-1, 0]
        assert res.gaps(0).min() >= -1e-12 * L

    def test_circle_surface_stops_at_a_tube(self):
        # a straight tube of radius 2.5 mm round the rod's axis, the 2 mm rod pushed
        # sideways: its axis stops 1 mm inside the wall, at 1.5 mm from the tube's axis
        rod = _rod()
        tube = Vessel.straight(2 * L, 2.5e-3, start=(-0.5 * L, 0, 0))
        field = coils.UniformField(B=(0, rod.field_for_lambda(6.0), 0))
        res = solve_rod(rod, field, [1.0], nodes=16, obstacles=[tube])
        assert abs(np.hypot(res.tip[0, 1], res.tip[0, 2]) - 1.5e-3) < 1e-9 * L
        assert tube.gap(res.centerline(0)).min() >= 1e-3 - 1e-9 * L

    def test_a_vessel_narrower_than_the_rod(self):
        rod = _rod()  # 2 mm
        tube = Vessel.straight(2 * L, 0.8e-3, start=(-0.5 * L, 0, 0))
        with pytest.raises(ValueError, match="thicker than the vessel"):
            solve_rod(rod, coils.UniformField(B=(0, 1e-3, 0)), [1.0], obstacles=[tube])
        with pytest.raises(ValueError, match="thicker than the vessel"):
            coilrod.insert(
                rod, Vessel.straight(0.1, 0.8e-3), [0.01], coils.UniformField(B=(0, 0, 0))
            )


def test_close_first_reaches_the_same_state(monkeypatch):
    # Newton steps that end where the first open contact closes (an option) change the path
    # to the state, not the state: the tip-contact cantilever's tip and wall force agree
    from coilrod.rod.spatial import SpatialRod

    rod = _rod()
    wall = Wall((0, 0.2 * L, 0), (0, -1, 0))
    field = coils.UniformField(B=(0, rod.field_for_lambda(6.0), 0))
    out = []
    for close_first in (False, True):
        monkeypatch.setattr(SpatialRod, "close_first", close_first)
        res = solve_rod(rod, field, [1.0], nodes=16, richardson=False, obstacles=[wall],
                        stability=False)  # fmt: skip
        out.append((res.tip[0], res.obstacle_forces(0)[0]))
    np.testing.assert_allclose(out[0][0], out[1][0], rtol=0, atol=1e-9 * L)
    np.testing.assert_allclose(out[0][1], out[1][1], rtol=1e-7)


def test_closing_fraction_of_a_rigid_translation():
    # the straight rod's surface 3 mm below a wall, moved 12 mm up: it touches at 1/4
    from coilrod.rod.solve import build_spatial_problem, make_mesh

    rod = _rod()
    wall = Wall((0, 4e-3, 0), (0, -1, 0))  # the axis 4 mm below: the surface 3 mm
    P = build_spatial_problem(rod, coils.UniformField(B=(0, 1e-3, 0)), make_mesh(rod, 8),
                              np.zeros(3), np.eye(3), obstacles=[wall])  # fmt: skip
    u = P.straight()
    du = np.zeros((P.n, P.nv))
    du[:, 1] = 12e-3 / L
    assert abs(P.closing_fraction(u[None], du.reshape(1, -1))[0] - 0.25) < 1e-12
    assert P.closing_fraction(u[None], -du.reshape(1, -1))[0] == 1.0  # moving away


def test_contact_iterations_do_not_grow_with_the_nodes():
    # load steps across changes of the contact set are predicted by the linearised
    # complementarity problem (coilrod.rod.contact_predictor): the Newton iterations of a
    # tip-contact state and of the rod laid on a flat support at 64 segments stay within
    # 1.5x those at 16 (deterministic counts; before: tip 41 at 16, 83 at 64; flat support
    # 172 and 408)
    rod = _rod()
    field = coils.LinearField(
        B0=(0, rod.field_for_lambda(6.0), 0), gradient=1e-9 * np.diag([-0.5, 1.0, -0.5])
    )
    wall = Wall((0, 0.2 * L, 0), (0, -1, 0))
    q = rod.bending_stiffness / L**3  # the flat support of the test above
    G = np.zeros((3, 3))
    G[0, 1] = -q / (rod.area * 128e3)
    floor = Wall((0, -1e-3 * L - 1e-3, 0), (0, 1, 0))
    for load, obstacle in ((field, wall), (coils.LinearField(B0=(0, 0, 0), gradient=G), floor)):
        its = {}
        for n in (16, 64):
            res = solve_rod(rod, load, [1.0], nodes=n, richardson=False, obstacles=[obstacle],
                            stability=False)  # fmt: skip
            its[n] = int(res.iterations.sum())
            assert res.contact_set(0).any()
        assert its[64] <= 1.5 * its[16]


def test_event_fraction_of_a_release():
    # an active multiplier falling from 2 to -2 along the change reaches zero at 1/2 (linear);
    # one falling to 1 does not release (1)
    from coilrod.rod.solve import build_spatial_problem, make_mesh

    rod = _rod()
    wall = Wall((0, 4e-3, 0), (0, -1, 0))
    P = build_spatial_problem(rod, coils.UniformField(B=(0, 1e-3, 0)), make_mesh(rod, 8),
                              np.zeros(3), np.eye(3), obstacles=[wall])  # fmt: skip
    u = P.straight().reshape(P.n, P.nv)
    u[-1, 9] = 2.0
    du = np.zeros_like(u)
    du[-1, 9] = -4.0
    assert abs(P.event_fraction(u.reshape(1, -1), du.reshape(1, -1))[0] - 0.5) < 1e-15
    du[-1, 9] = -1.0
    assert P.event_fraction(u.reshape(1, -1), du.reshape(1, -1))[0] == 1.0


def test_piecewise_prediction_across_the_tip_closing(monkeypatch):
    # from a free state (scale 0.05) to one with the tip on the wall (0.15): the prediction
    # that switches the contact set where the tip closes lands within 2 % of the change of
    # the converged state (an independent solve), the plain path tangent 150 % off (through
    # the wall); the rate after the closing refactors the band from the tip node's first
    # column alone (band_lu's restart, bitwise a factorisation from column 0: test_rod_physics)
    import coilrod.rod._compiled as rc

    starts, band_lu = [], rc.band_lu
    # the event loop's numpy twin whatever numba's cache holds (its compiled rate calls
    # band_lu inside the kernel: test_rod_physics's rate_step test)
    monkeypatch.setattr(rc, "events_pay", lambda: False)

    def counted(ab, kl, ku, ipiv, start):
        starts.append(start)
        return band_lu(ab, kl, ku, ipiv, start)

    rod = _rod()
    field = coils.LinearField(
        B0=(0, rod.field_for_lambda(6.0), 0), gradient=1e-9 * np.diag([-0.5, 1.0, -0.5])
    )
    wall = Wall((0, 0.2 * L, 0), (0, -1, 0))
    res = solve_rod(rod, field, [0.05, 0.15], nodes=16, richardson=False, obstacles=[wall],
                    stability=False)  # fmt: skip
    P = res._solution.problems[0]
    u0, u1 = res._solution.states[0]
    assert [int(P.contact_state(u[None])[2].sum()) for u in (u0, u1)] == [0, 1]
    monkeypatch.setattr(rc, "band_lu", counted)
    pred = P.piecewise_prediction(u0, 0.05, 0.1)
    monkeypatch.setattr(rc, "band_lu", band_lu)
    assert starts == [0, P.nv * (P.n - 1)]
    lin = P.linearize(u0[None], np.array([0.05]))
    plain = u0 - 0.1 * P.solve(lin, lin.load_rate)[0]
    change = P.distance((u1 - u0)[None])[0]
    assert P.distance((pred - u1)[None])[0] < 0.02 * change
    assert P.distance((plain - u1)[None])[0] > 0.5 * change
    # the prediction above linearized at u0 with every contact row the gap's; after a tangent
    # at u0 (``lin``) it reuses that one's blocks: the same band as a fresh linearization with
    # every row active (bitwise), so the same prediction
    kept = P._every_active_band(u0, 0.05)
    assert kept is not None
    assert P._every_active_band(u0, 0.15) is None  # another scale: not the kept tangent's
    # a state a chord step away (Newton's last iterate): the kept tangent's with ``near``
    off = u0.copy()
    off.reshape(P.n, P.nv)[-1, 3:6] += 1e-6  # (the tip node turned by 1e-6 rad)
    assert P._every_active_band(off, 0.05) is None
    np.testing.assert_array_equal(P._every_active_band(off, 0.05, near=1e-3)[0], kept[0])
    assert P._every_active_band(off, 0.05, near=1e-7) is None
    # the first rate takes the factors of that tangent (factorised by the solve above: its
    # active set, none, is the rate's), not band_lu from column 0: the same prediction
    assert not P._kept_factors()[0].any()
    starts.clear()
    monkeypatch.setattr(rc, "band_lu", counted)
    np.testing.assert_array_equal(P.piecewise_prediction(u0, 0.05, 0.1), pred)
    monkeypatch.setattr(rc, "band_lu", band_lu)
    assert starts == [P.size, P.nv * (P.n - 1)]
    P._every_rows = True
    every = P.linearize(u0[None], np.array([0.05]))
    del P._every_rows
    np.testing.assert_array_equal(kept[0], every.tangent.parts)
    np.testing.assert_array_equal(kept[1], every.load_rate)
    np.testing.assert_array_equal(P.piecewise_prediction(u0, 0.05, 0.1), pred)
    # the event test's gaps by state (node tangents by Rodrigues, remembered): the surface
    # gaps at the state's frames, to rounding
    for u in (u0, u1):
        ref = P.surface_gaps(P.node_positions(u[None]), P.frames(u[None]))
        np.testing.assert_allclose(P._state_gaps(u[None]), ref, rtol=0, atol=1e-15)


def test_event_step_kernel_is_its_numpy_twin(monkeypatch):
    # the contact predictor's event step (coilrod.rod._compiled.event_step, through .py_func:
    # no compiled version for the test) against its numpy twin on a small stack of points: a
    # release first with the open points clear of the wall (gaps by their linearization), one
    # that an open point could precede (the end's gaps asked for), a closing before the end
    # (gaps interpolated), none before it, and fractions clipped where one is negative
    import coilrod.rod._compiled as rc
    from coilrod.rod.contact_predictor import _event_step

    event_step = rc.event_step
    monkeypatch.setattr(rc, "_event_apply", rc._event_apply.py_func)  # (not compiled either)

    rng = np.random.default_rng(3)
    n, nv, nc = 6, 11, 2
    npts, w = (n - 1) * nc, 6 + nc
    cols = (
        (nv * np.arange(1, n)[:, None, None] + np.r_[0:6, 9 : 9 + nc][None, None])
        .repeat(nc, axis=1)
        .reshape(npts, w)
    )
    lin = rng.normal(size=(npts, w))
    c = np.full(n - 1, 0.1)

    def case(lam, d_lam, g0, g1, scale=0.5):
        x, r = rng.normal(size=n * nv) * 0.01, rng.normal(size=n * nv) * 0.01
        x.reshape(n, nv)[1:, 9:] = np.reshape(lam, (n - 1, nc))
        r.reshape(n, nv)[1:, 9:] = np.reshape(d_lam, (n - 1, nc)) / scale
        return [x, r, scale, np.asarray(lam) > 0, np.asarray(g0, float), np.asarray(g1, float)]

    zero = np.zeros(npts)
    lam = zero.copy()
    lam[[7, 9]] = 2.0, 1.0
    d_lam = zero.copy()
    d_lam[[7, 9]] = -8.0, 0.5  # point 7 releases at 1/4
    far, near = np.full(npts, 1.0), np.full(npts, 1.0)
    near[5] = 2.0**-13  # an open point within reach of the wall
    g1 = np.full(npts, 0.5)
    g1[5] = -7 * 2.0**-13  # it closes at 1/8 of the segment (interpolated)
    g1[7] = g1[9] = -1.0  # (active points: their gaps do not count)
    late = g1.copy()
    late[5] = 1e-5  # no closing
    neg = near.copy()
    neg[5] = -1e-3  # an open point through the wall, deeper at the end: clipped to 0
    g1_neg = late.copy()
    g1_neg[5] = -2e-3
    cases = [case(lam, d_lam, far, g1), case(lam, d_lam, near, g1), case(lam, d_lam, near, late),
             case(lam, zero, near, g1), case(lam, zero, neg, g1_neg)]  # fmt: skip
    found = []
    for x, r, scale, active, g0, g1 in cases:
        outs = []
        for step in (event_step.py_func, _event_step):
            args = [x.copy(), r, scale, active.copy(), g0.copy(), g1, np.zeros_like(x), lin,
                    cols, c, nv, nc, 100.0, np.zeros(npts), np.zeros(npts),
                    np.zeros(npts, np.int64)]  # fmt: skip
            with np.errstate(all="ignore"):  # (the event loop's: 0 / 0 off the events)
                codes = [step(False, *args)]
                if codes[0][0] == 1:
                    codes.append(step(True, *args))
            outs.append((codes, args))
        (codes, a), (codes_np, b) = outs
        assert [k for k, _, _ in codes] == [k for k, _, _ in codes_np]
        np.testing.assert_allclose([f for _, f, _ in codes], [f for _, f, _ in codes_np],
                                   rtol=1e-15)  # fmt: skip
        count = codes[-1][2]
        assert count == codes_np[-1][2]
        for i in (0, 3, 4, 6, 15):  # x, active, g0, xd, the switched points
            end = count if i == 15 else None
            np.testing.assert_allclose(a[i][:end], b[i][:end], rtol=1e-14, atol=1e-17)
        found.append(([k for k, _, _ in codes], round(codes[-1][1], 12), a[15][:count].tolist()))
    assert found == [
        ([2], 0.25, [7]),  # the release, no gaps asked for
        ([1, 2], 0.125, [5]),  # the gaps asked for: point 5 closes before 7 releases
        ([1, 2], 0.25, [7]),  # the release alone
        ([1, 2], 0.125, [5]),  # a closing before the end
        ([1, 2], 0.0, [5]),  # clipped to 0
    ]
