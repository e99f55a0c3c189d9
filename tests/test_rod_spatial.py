"""The spatial Kirchhoff rod (coilrod.rod.spatial) and solve_rod(model=...): discrete
consistency (exact Jacobian), the planar limit, rotation invariance, torsion against the
closed-form elastica, stability (double eigenvalues), model choice and bad input."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import coils
from coilrod import Circle, ConvergenceError, Magnetization, Rectangle, Rod, solve_rod, trace_rod
from coilrod.path.protocol import Linearization
from coilrod.rod import so3
from coilrod.rod.elastica import elastica
from coilrod.rod.mesh import RodMesh
from coilrod.rod.solve import rod_stiffnesses
from coilrod.rod.spatial import SpatialRod, numpy_core

L = 0.04


def _rod(section=None, angle=0.0, magnitude=128e3):
    return Rod(L, 1e6, section or Circle(2e-3), Magnetization(magnitude, angle))


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


GRADIENT = np.array([[1.0, 2.0, 0.5], [2.0, -3.0, 1.0], [0.5, 1.0, 2.0]])  # symmetric, traceless


# -- rotations --------------------------------------------------------------------------------
class TestSO3:
    def test_exp_log_round_trip_and_orthonormality(self):
        rng = np.random.default_rng(0)
        phi = rng.normal(size=(500, 3))
        phi *= (rng.uniform(0, np.pi - 1e-6, 500) / np.linalg.norm(phi, axis=1))[:, None]
        R = so3.expm(phi)
        assert np.abs(R @ np.swapaxes(R, -1, -2) - np.eye(3)).max() < 1e-14
        assert np.allclose(np.linalg.det(R), 1.0, atol=1e-14)
        assert np.abs(so3.logm(R) - phi).max() < 1e-12

    def test_exp_matches_scipy(self):
        rng = np.random.default_rng(1)
        phi = rng.normal(size=(50, 3)) * 2
        phi[:5] *= 1e-9  # the series branch
        assert np.abs(so3.expm(phi) - Rotation.from_rotvec(phi).as_matrix()).max() < 1e-14

    def test_log_near_pi(self):
        axis = _unit([0.3, -0.5, 0.8])
        for angle in (np.pi - 1e-9, np.pi - 1e-4, np.pi):
            R = Rotation.from_rotvec(angle * axis).as_matrix()
            out = so3.logm(R)
            assert abs(np.linalg.norm(out) - angle) < 1e-7
            assert np.abs(Rotation.from_rotvec(out).as_matrix() - R).max() < 1e-12

    def test_left_jacobian_definition(self):
        rng = np.random.default_rng(2)
        for phi in rng.normal(size=(5, 3)) * 1.5:
            d = 1e-7 * rng.normal(size=3)
            lhs = so3.expm(phi + d)
            rhs = so3.expm(so3.left_jacobian(phi) @ d) @ so3.expm(phi)
            assert np.abs(lhs - rhs).max() < 1e-13

    def test_inverse_jacobian_coefficient_against_closed_form(self):
        # the closed form is exact (no cancellation) at moderate angles
        t = np.array([0.999, 1.2, 2.0, 3.0])
        c, dc = so3.inv_right_jacobian_coefficients(t)
        exact = 1 / t**2 - (1 + np.cos(t)) / (2 * t * np.sin(t))
        assert np.allclose(c, exact, rtol=1e-13)
        eps = 1e-6
        cp, _ = so3.inv_right_jacobian_coefficients(t + eps)
        cm, _ = so3.inv_right_jacobian_coefficients(t - eps)
        assert np.allclose(dc, (cp - cm) / (2 * eps) / t, rtol=1e-7)
        # series branch: J_r^-1 J_r = I
        psi = np.array([0.3, -0.2, 0.1])
        th = np.linalg.norm(psi)
        cc, _ = so3.inv_right_jacobian_coefficients(np.array(th))
        P = so3.hat(psi)
        Jr_inv = np.eye(3) + 0.5 * P + cc * P @ P
        assert np.abs(Jr_inv @ so3.left_jacobian(-psi) - np.eye(3)).max() < 1e-15


# -- the discrete problem -----------------------------------------------------------------------
FIELDS = {
    "uniform": coils.UniformField(B=(0.3, 1.0, 0.5)),
    "linear": coils.LinearField(B0=(0.1, 1.0, 0.4), gradient=5 * GRADIENT, origin=(0, 0, 0)),
    "helmholtz": coils.HelmholtzPair(0.05, 100, 2.0, axis="y"),
}


class TestDiscreteProblem:
    @pytest.mark.parametrize("name", list(FIELDS))
    def test_jacobian_and_load_rate_against_differences(self, name):
        rng = np.random.default_rng(1)
        mesh = RodMesh(6)
        mu = rng.normal(size=(mesh.n, 3)) * 3
        R0 = so3.expm(np.array([0.3, -0.2, 0.5]))
        P = SpatialRod(
            mesh, mu, [0.6, 4.0, 1.0], FIELDS[name], L, np.array([1e-3, 2e-3, -3e-3]), R0
        )
        u = P.straight() + 0.3 * rng.normal(size=P.size)
        c, eps = 0.7, 1e-6
        J = P.dense_jacobian(u, c)
        Jfd = np.empty_like(J)
        for i in range(P.size):
            e = np.zeros(P.size)
            e[i] = eps
            Jfd[:, i] = (P.residual(u + e, c) - P.residual(u - e, c)) / (2 * eps)
        assert np.abs(J - Jfd).max() < 1e-7 * np.abs(Jfd).max()
        rate = P.linearize(u, c).load_rate[0]
        fd = (P.residual(u, c + eps) - P.residual(u, c - eps)) / (2 * eps)
        assert np.abs(rate - fd).max() < 1e-7 * max(np.abs(fd).max(), 1.0)

    def test_turn_limit_of_the_rotation_chart(self):
        """A node turned beyond max_turn relative to the clamp is inadmissible (along an axis
        or along the diagonal, where each component is below the limit), one just within
        it is not."""
        P = SpatialRod(RodMesh(4), np.zeros((5, 3)), [0.6, 4.0, 1.0], FIELDS["uniform"], L,
                       np.zeros(3), np.eye(3))  # fmt: skip
        cases = {
            (1.01, "axis"): False, (1.01, "diagonal"): False, (0.99, "axis"): True,
            (0.99, "diagonal"): True,
        }  # fmt: skip
        for (factor, direction), admissible in cases.items():
            d = _unit([1, 0, 0] if direction == "axis" else [1, 1, 1])
            phi = np.zeros((5, 3))
            phi[3] = factor * P.max_turn * d
            P.last_failure = ""
            lin = P.linearize(P.from_rotations(phi), 0.5)
            assert bool(lin.ok[0]) is admissible
            assert ("rotation chart" in P.last_failure) is not admissible

    def test_mesh_constants_cached_by_value(self):
        """The set-up's cached mesh constants follow the stiffness, mesh and layout by value
        (closed form on the uniform mesh: (1/h_{i-1} + 1/h_i) / w_i = 2 N^2 at every node,
        times max K), and are read-only (a problem cannot spoil another's)."""
        N, mu = 4, np.zeros((5, 3))
        K = np.array([0.6, 1.0, 1.0])
        args = (FIELDS["uniform"], L, np.zeros(3), np.eye(3))
        first = SpatialRod(RodMesh(N), mu, K, *args)
        K[0] = 3.0  # the caller's array changed in place: a new key, not a stale hit
        stiff = SpatialRod(RodMesh(N), mu, K, *args)
        mixed = SpatialRod(RodMesh(N), mu, K, *args, mixed=True)
        fine = SpatialRod(RodMesh(2 * N), np.zeros((9, 3)), K, *args)
        assert first._bend_max == 2 * N**2
        assert stiff._bend_max == 6 * N**2
        assert fine._bend_max == 6 * (2 * N) ** 2
        assert first._row_scale.shape == (5, 3)
        assert mixed._row_scale.shape == (5, 9)
        assert np.array_equal(mixed._row_scale[1:, 0:3], np.full((4, 3), float(N)))
        with pytest.raises(ValueError, match="read-only"):
            first._bend_scale[0] = 0.0

    @pytest.mark.parametrize("name", ["uniform", "helmholtz"])
    def test_band_gather_and_reused_arrays(self, name):
        """The band gathered from the compiled blocks equals the general scatter of the
        blocks, and a linearization keeps its numbers when later ones reuse the assembly's
        arrays (the second variation of the mixed layout, computed on use, included)."""
        rng = np.random.default_rng(5)
        mesh = RodMesh(6)
        P = SpatialRod(
            mesh, rng.normal(size=(mesh.n, 3)), [0.6, 4.0, 1.0], FIELDS[name], L,
            np.zeros(3), so3.expm(np.array([0.3, -0.2, 0.5])),
        )  # fmt: skip
        U = np.stack([P.straight() + 0.2 * rng.normal(size=P.size) for _ in range(2)])
        S = np.array([0.4, 0.9])
        first = P.linearize(U, S)
        ab, D, E = first.tangent.parts.copy(), *first.tangent.blocks  # (evaluated now)
        blk = P._workspace(2, True)["blk"]
        names = ["m_prev", "m_diag", "m_next"] + (
            [] if P.uniform else ["p_phiprev", "p_phi", "m_x", "m_Fprev", "m_F", "f_xnext",
                                  "f_phinext"]
        )  # fmt: skip
        blocks = {nm: blk[:, 1 : P.n - 1 if P._BLK_SLOTS[nm][1] else P.n, P._BLK_SLOTS[nm][0]]
                  for nm in names}  # fmt: skip
        I3 = np.eye(3)
        blocks["clamp_phi"] = I3
        if not P.uniform:
            blocks.update({"clamp_x": I3, "p_x": I3, "p_xprev": -I3, "f_F": I3, "f_Fnext": -I3})
        assert np.array_equal(ab, P._scatter(2, blocks))
        # S[::-1].copy(): a contiguous array, as the solver passes (a reversed view is another
        # numba specialisation of the kernel: a second compile of ~2 s in a cold test run)
        late = P.linearize(U[::-1] + 0.1, S[::-1].copy())  # the same stack size: the same workspace
        P.linearize(U[:1], S[:1], tangent=False)
        again = P.linearize(U, S)
        assert np.array_equal(first.residual, again.residual)
        assert np.array_equal(first.load_rate, again.load_rate)
        for x, y in zip((D, E), again.tangent.blocks, strict=True):
            assert np.array_equal(x, y)
        assert not np.array_equal(late.residual, first.residual)
        lazy = P.linearize(U, S)
        P.linearize(U[::-1] + 0.1, S[::-1].copy())  # before the lazy blocks are asked for
        for x, y in zip(lazy.tangent.blocks, (D, E), strict=True):
            assert np.array_equal(x, y)

    def test_compiled_pass_numpy_pass_and_reference_agree(self):
        # the per-node pass three ways: compiled (spatial_core), its numpy twin that runs
        # before compiling pays (bitwise the same numbers: a process's results do not change
        # when it compiles) and numpy_core (independent, built on so3: to 1e-12); rotations
        # in every branch -- zero (series), segments turning < 1 rad and > 1 rad (series and
        # closed form of J_r^-1) and by pi - 1e-4 and pi - 1e-9 (the log's axis from the
        # symmetric part) -- in a uniform field and a coil pair's (gradient, hessian rows)
        from coilrod.rod._compiled_spatial import spatial_core
        from coilrod.rod._spatial_numpy import spatial_core_numpy

        rng = np.random.default_rng(3)
        mesh = RodMesh(7)
        axis = _unit([0.3, -0.5, 0.8])
        for name in ("uniform", "helmholtz"):
            P = SpatialRod(
                mesh, rng.normal(size=(mesh.n, 3)), [0.6, 4.0, 1.0], FIELDS[name], L,
                np.array([1e-3, 2e-3, -3e-3]), so3.expm(np.array([0.3, -0.2, 0.5])),
            )  # fmt: skip
            U = np.stack([P.straight() + q * rng.normal(size=P.size) for q in (0, 0.2, 1, 1)])
            phi = P.rotations(U)  # a view of U
            phi[2:, 3] = 0.0
            phi[2, 4], phi[3, 4] = (np.pi - 1e-4) * axis, (np.pi - 1e-9) * axis
            S = np.array([0.3, 0.7, 1.1, 0.9])
            for tangent in (True, False):
                out = [
                    P._assemble(U, S, tangent, core=core)
                    for core in (spatial_core, spatial_core_numpy, numpy_core)
                ]
                flat = [list(o[: 3 if tangent else 2]) + list(o[3] or ()) for o in out]
                for a, b, ref in zip(*flat, strict=True):
                    np.testing.assert_array_equal(b, a)
                    assert np.abs(a - ref).max() <= 1e-12 * max(np.abs(ref).max(), 1.0)
            # a diverged Newton iterate: infinite and NaN angles give the same NaNs
            bad = U[1:3].copy()
            P.rotations(bad)[0, 2, 1], P.rotations(bad)[1, 3, 0] = np.inf, np.nan
            a, b = (
                P._assemble(bad, S[:2], True, core=c) for c in (spatial_core, spatial_core_numpy)
            )
            for x, y in zip(list(a[:3]) + list(a[3]), list(b[:3]) + list(b[3]), strict=True):
                assert np.isnan(x).any()
                np.testing.assert_array_equal(y, x)
            # the compiled pass's member statistics (error, largest rotation component,
            # finiteness: what error and linearize read) against error's numpy numbers and
            # the direct tests, bitwise: the states above, diverged ones, stacked and alone
            for V, Sv in [(U, S), (bad, S[:2])] + [(U[j : j + 1], S[j : j + 1]) for j in (0, 3)]:
                R, R1 = P._assemble(V, Sv, False, core=spatial_core)[:2]
                stats = P._stats
                lin = Linearization(u=V, scale=Sv, residual=R, ok=None)  # (no stats: numpy)
                lin.load_rate = R1
                with np.errstate(all="ignore"):
                    np.testing.assert_array_equal(stats[:, 0], P.error(lin, None))
                np.testing.assert_array_equal(stats[:, 1], np.abs(P.rotations(V)).max(axis=(1, 2)))
                np.testing.assert_array_equal(stats[:, 2] > 0, np.isfinite(R).all(axis=1))
                assert np.isinf(stats[:, 0]).any() == (V is bad)

    def test_the_pass_gets_contiguous_field_inputs(self):
        # _assemble calls the compiled pass directly once its rental is over: strided field
        # inputs (the magnet pose's Hessian is a view) would compile a second version of it
        # (2 s on a cold cache); they are made C-contiguous first, with the same numbers
        from coilrod.rod._spatial_numpy import spatial_core_numpy

        mesh = RodMesh(4)
        P = SpatialRod(mesh, np.ones((mesh.n, 3)), [0.6, 4.0, 1.0], FIELDS["helmholtz"], L,
                       np.zeros(3), np.eye(3))  # fmt: skip
        U, S = np.stack([P.straight()] * 2), np.array([0.5, 1.0])
        X = np.ascontiguousarray(U.reshape(2, P.n, P.nv)[:, :, 0:3])
        B, G, H = P._field_by_member(X, True)
        strided = []
        for a in (G, H):
            big = np.zeros(a.shape + (2,))
            big[..., 0] = a
            strided.append(big[..., 0])  # the same values, not contiguous
        seen = []

        def core(*args):
            seen.append([args[i].flags.c_contiguous for i in (4, 5, 6)])  # B, G, H
            return spatial_core_numpy(*args)

        out = [P._assemble(U, S, True, core=core, fields=f) for f in ((B, G, H), (B, *strided))]
        assert all(all(flags) for flags in seen)
        for a, b in zip(list(out[0][:3]) + list(out[0][3]), list(out[1][:3]) + list(out[1][3]),
                        strict=True):  # fmt: skip
            np.testing.assert_array_equal(b, a)

    def test_spatial_pass_runs_numpy_until_compiling_pays(self, monkeypatch):
        # spatial_pass: the numpy pass while the estimated cost of the numpy calls so far stays
        # within COMPILE_AFTER, then the compiled pass (here a stand-in: the rule, not numba);
        # at once if numba's cache holds the kernel or this process compiled it
        import coilrod.rod._compiled_spatial as cs
        import coils._numba_cache as nc
        from coilrod.rod._spatial_numpy import spatial_core_numpy

        calls = []

        class Kernel:
            overloads: dict = {}

            def __call__(self, *args):
                calls.append(args[0].shape)
                spatial_core_numpy(*args)

        mu, K = np.ones((5, 3)), [0.6, 4.0, 1.0]
        P = SpatialRod(RodMesh(4), mu, K, FIELDS["uniform"], L, np.zeros(3), np.eye(3))
        U, S = np.stack([P.straight()] * 2), np.array([0.5, 1.0])
        cost = cs._NUMPY_CALL_S[1] + cs._NUMPY_NODE_S[1] * 2 * P.n
        for on_disk, overloads, after, numpy_calls in [
            (False, {}, 2.5 * cost, 2),
            (True, {}, np.inf, 0),
            (False, {"compiled": 1}, np.inf, 0),
        ]:
            kernel = Kernel()
            kernel.overloads = overloads
            monkeypatch.setattr(cs, "spatial_core", kernel)
            monkeypatch.setattr(nc, "on_disk", lambda dispatcher, seen=on_disk: seen)
            monkeypatch.setattr(cs._rental, "spent", 0.0)
            monkeypatch.setattr(cs._rental, "ready", False)
            monkeypatch.setattr(cs, "COMPILE_AFTER", after)
            calls.clear()
            for _ in range(3):
                P._assemble(U, S, True)
            assert len(calls) == 3 - numpy_calls
            assert cs._rental.ready == (numpy_calls < 3)

    def test_the_cache_is_looked_at_once_per_kernel(self, monkeypatch, tmp_path):
        # on_disk (every ski rental asks it at each call until it compiles) stats numba's
        # index file at the first question only; another kernel gets its own look
        from types import SimpleNamespace

        import coils._numba_cache as nc

        class Kernel:  # what on_disk reads of a numba dispatcher
            def __init__(self, path):
                self._cache = SimpleNamespace(_cache_file=SimpleNamespace(_index_path=str(path)))

        monkeypatch.setattr(nc, "_seen", {})
        first = Kernel(tmp_path / "first.nbi")
        assert not nc.on_disk(first)
        (tmp_path / "first.nbi").write_text("")
        assert not nc.on_disk(first)  # not looked at again
        (tmp_path / "second.nbi").write_text("")
        assert nc.on_disk(Kernel(tmp_path / "second.nbi"))

    def test_second_variation_is_symmetric_at_equilibrium(self):
        rod = _rod(Rectangle(3e-3, 1.5e-3), angle=0.3)
        field = coils.LinearField(B0=(1e-3, 5e-3, 2e-3), gradient=0.05 * GRADIENT)
        res = solve_rod(rod, field, [1.0], richardson=False, nodes=12)
        P = res._solution.problems[0]
        U = res._solution.states[0]
        D, E = P.linearize(U, np.array([1.0])).tangent.blocks
        assert np.abs(D - np.swapaxes(D, -1, -2)).max() < 1e-8 * np.abs(D).max()


# -- the planar limit ---------------------------------------------------------------------------
class TestPlanarLimit:
    @pytest.mark.parametrize(
        "field",
        [
            coils.UniformField(B=(0.0, 12e-3, 0.0)),
            coils.HelmholtzPair(0.05, 100, 2.0, axis="y"),
            coils.MaxwellPair(0.05, 200, 2.0, axis="y", center=(0.0, -0.02, 0.0)),
        ],
        ids=["uniform", "helmholtz", "maxwell"],
    )
    def test_spatial_reproduces_planar(self, field):
        mag = Magnetization.segments([0.01, 0.01, 0.02], [100e3, 50e3, 128e3], [0.0, 1.2, 0.0])
        rod = Rod(L, 1e6, Circle(2e-3), mag)
        scales = [0.25, 0.5, 1.0]
        p = solve_rod(rod, field, scales, model="planar", clamp_angle=0.2)
        s = solve_rod(rod, field, scales, model="spatial", clamp_angle=0.2)
        assert (p.model, s.model) == ("planar", "spatial")
        assert np.abs(p.tip - s.tip).max() < 1e-8 * L
        assert np.abs(p.tip_angle - s.tip_angle).max() < 1e-8
        for k in range(len(scales)):
            assert np.abs(p.frames(k) - s.frames(k)).max() < 1e-8
            assert np.abs(p.centerline(k) - s.centerline(k)).max() < 1e-8 * L
        assert np.array_equal(p.stable, s.stable)

    def test_auto_picks_planar_for_in_plane_loads(self):
        rod = _rod()
        for field in (coils.UniformField(B=(0, 5e-3, 0)), coils.HelmholtzPair(0.05, 100, 2.0)):
            assert solve_rod(rod, field, [1.0], nodes=8).model == "planar"


# -- 3D physics ---------------------------------------------------------------------------------
class TestSpatialPhysics:
    def test_rotation_invariance(self):
        rod = _rod(Rectangle(3e-3, 1.5e-3), angle=0.3)
        b = rod.field_for_lambda(5.0) * _unit([0.3, 1.0, 0.5])
        Q = Rotation.from_rotvec([0.4, -1.1, 0.7])
        Qm = Q.as_matrix()
        cases = [
            (coils.UniformField(B=b), coils.UniformField(B=Qm @ b)),
            (
                coils.LinearField(B0=b, gradient=0.05 * GRADIENT),
                coils.LinearField(B0=Qm @ b, gradient=Qm @ (0.05 * GRADIENT) @ Qm.T),
            ),
        ]
        for f, fr in cases:
            r = solve_rod(rod, f, [0.5, 1.0])
            r2 = solve_rod(rod, fr, [0.5, 1.0], clamp_rotation=Q)
            assert r.model == r2.model == "spatial"
            assert np.abs(r.tip @ Qm.T - r2.tip).max() < 1e-12 * L
            assert np.abs(Qm @ r.frames(1) - r2.frames(1)).max() < 1e-12

    def test_out_of_plane_field_is_the_planar_solution_rotated_about_the_axis(self):
        # M axial, B in the y-z plane: the rod bends in the plane of B (symmetry about x)
        rod = _rod()
        lam, beta = 4.0, 0.7
        b = rod.field_for_lambda(lam)
        res = solve_rod(rod, coils.UniformField(B=(0, b * np.cos(beta), b * np.sin(beta))), [1.0])
        assert res.model == "spatial"
        ref = elastica(lam, np.pi / 2, length=L)
        expect = np.array([ref.tip[0], ref.tip[1] * np.cos(beta), ref.tip[1] * np.sin(beta)])
        assert np.abs(res.tip[0] - expect).max() < 1e-7 * L

    def test_pure_torsion_against_closed_form(self):
        # M along the normal; B in the y-z plane at beta from y: a straight rod twisting by
        # phi(s), GJ phi'' + A M B sin(beta - phi) = 0 -- the elastica with EI -> GJ
        rod = _rod(angle=np.pi / 2)
        GJ = rod_stiffnesses(rod)[0] * rod.bending_stiffness
        for lam_t, beta in ((0.5, 1.0), (3.0, 2.0)):
            b = lam_t * GJ / (128e3 * rod.area * L**2)
            field = coils.UniformField(B=(0.0, b * np.cos(beta), b * np.sin(beta)))
            res = solve_rod(rod, field, [1.0])
            frames = res.frames(0)
            twist = np.arctan2(frames[-1, 2, 1], frames[-1, 1, 1])
            ref = elastica(lam_t, beta, length=L)
            assert abs(twist - ref.tip_angle) < 1e-8
            assert np.abs(res.centerline(0)[:, 1:]).max() < 1e-12 * L  # stays straight
            assert abs(res.tip[0, 0] - L) < 1e-12 * L

    def test_small_deflection_out_of_plane(self):
        # M axial, B along z: the tip moves lambda L / 3 along z
        rod = _rod()
        lam = 1e-4
        res = solve_rod(rod, coils.UniformField(B=(0, 0, rod.field_for_lambda(lam))), [1.0])
        assert abs(res.tip[0, 2] / (lam * L / 3) - 1) < 1e-3
        assert abs(res.tip[0, 1]) < 1e-14 * L

    def test_frames_orthonormal_and_tangent_to_the_centreline(self):
        rod = Rod(L, 1e6, Rectangle(3e-3, 1e-3), Magnetization(128e3, 0.4))
        field = coils.LinearField(B0=(3e-3, 8e-3, 4e-3), gradient=0.08 * GRADIENT)
        res = solve_rod(rod, field, [1.0], nodes=128)
        R = res.frames(0)
        assert np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max() < 1e-12
        x = res.centerline(0)
        chord = np.diff(x, axis=0) / np.diff(res.s)[:, None]
        mid = 0.5 * (R[:-1, :, 0] + R[1:, :, 0])
        assert np.abs(chord - mid).max() < 1e-3  # O(h^2) of a curved tangent

    def test_global_moment_balance_of_a_torque_loaded_rod(self):
        # uniform field: zero resultant force; the clamp moment equals the total torque
        rod = _rod(Rectangle(3e-3, 1.5e-3), angle=0.3)
        b = rod.field_for_lambda(3.0) * _unit([0.3, 1.0, 0.5])
        res = solve_rod(rod, coils.UniformField(B=b), [1.0], nodes=64, richardson=False)
        P = res._solution.problems[0]
        U = res._solution.states[0]
        R = P.frames(U)[0]
        m = np.einsum("nij,nj->ni", R, P.mu)
        # node 0 sits in the clamp: its own torque goes straight into the support
        torque = np.sum(P.mesh.w[1:, None] * np.cross(m[1:], b), axis=0)
        psi0 = so3.logm(R[0].T @ R[1])
        cc, _ = so3.inv_right_jacobian_coefficients(np.linalg.norm(psi0))
        g = P.K * psi0 / P.mesh.h[0]
        Jg = g - 0.5 * np.cross(psi0, g) + cc * np.cross(psi0, np.cross(psi0, g))
        clamp_moment = R[1] @ Jg  # internal moment carried by the first segment
        assert np.abs(clamp_moment - torque).max() < 1e-8 * np.abs(torque).max()


# -- stability ----------------------------------------------------------------------------------
class TestStability:
    def test_double_eigenvalue_of_the_antiparallel_circle_is_reported(self):
        rod = _rod()
        b = rod.field_for_lambda(1.0)
        with pytest.warns(Warning, match="lost stability"):
            res = solve_rod(rod, coils.UniformField(B=(-b, 0, 0)), [2.0, 2.3, 2.6, 3.0])
        assert res.model == "planar"
        with pytest.warns(Warning, match="lost stability"):
            res = solve_rod(
                rod, coils.UniformField(B=(-b, 0, 0)), [2.0, 2.3, 2.6, 3.0], model="spatial"
            )
        assert res.stable.tolist() == [True, True, False, False]
        event = [e for e in res.instabilities if e["kind"] == "bifurcation"][0]
        assert abs(event["scale"] - np.pi**2 / 4) < 1e-4
        assert res.min_eigenvalue[2] < 0

    def test_imperfect_antiparallel_follows_the_stable_branch(self):
        rod = _rod()
        b = rod.field_for_lambda(1.0)
        field = coils.UniformField(B=(-b, 1e-6 * b, 1e-6 * b))
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            res = solve_rod(rod, field, np.linspace(0.5, 4.0, 8))
        assert res.stable.all()
        lam4 = elastica(4.0, np.pi - 1e-6 * np.sqrt(2), length=L)
        # the tip swings into the plane of the imperfection (45 deg between y and z)
        radial = np.hypot(res.tip[-1, 1], res.tip[-1, 2])
        assert abs(res.tip[-1, 0] - lam4.tip[0]) < 1e-5 * L
        assert abs(radial - abs(lam4.tip[1])) < 1e-5 * L
        assert abs(res.tip[-1, 1] - res.tip[-1, 2]) < 1e-6 * L

    def test_straight_rod_eigenvalue_is_the_softest_mode(self):
        rod = Rod(L, 1e6, Rectangle(3e-3, 1.5e-3), Magnetization(128e3, 0.0))
        res = solve_rod(rod, coils.UniformField(B=(0, 0, 1e-9)), [1e-9], nodes=64)
        k = rod_stiffnesses(rod)
        # second order in h on the coarse mesh (64 segments)
        assert abs(res.min_eigenvalue[0] / (k.min() * np.pi**2 / 4) - 1) < 1e-4

    def test_trace_rod_spatial_matches_planar(self):
        rod = _rod(angle=np.pi)
        b = rod.field_for_lambda(1.0)
        f = coils.UniformField(B=(b * np.cos(0.2), b * np.sin(0.2), 0))
        p1 = trace_rod(rod, f, 0.0, (0, 8), model="planar", max_steps=60)
        p2 = trace_rod(rod, f, 0.0, (0, 8), model="spatial", max_steps=60)
        assert p2.model == "spatial"
        assert len(p1) == len(p2)
        assert np.abs(p1.tip - p2.tip).max() < 1e-10 * L
        assert np.abs(p1.frames(3) - p2.frames(3)).max() < 1e-10


# -- model choice and input ------------------------------------------------------------------
class TestModelChoice:
    def test_out_of_plane_loads_choose_spatial(self):
        rod = _rod()
        assert solve_rod(rod, coils.UniformField(B=(0, 5e-3, 1e-4)), [1.0], nodes=8).model == (
            "spatial"
        )
        off = coils.HelmholtzPair(0.05, 100, 2.0, axis="y")
        res = solve_rod(rod, off, [1.0], nodes=8, clamp_position=(0, 0, 0.01))
        assert res.model == "spatial"
        tilted = Rotation.from_rotvec([0.1, 0, 0])
        res = solve_rod(
            rod, coils.UniformField(B=(0, 5e-3, 0)), [1.0], nodes=8, clamp_rotation=tilted
        )
        assert res.model == "spatial"

    def test_planar_refuses_out_of_plane_loads(self):
        with pytest.raises(ValueError, match="B_z"):
            solve_rod(_rod(), coils.UniformField(B=(0, 5e-3, 1e-4)), [1.0], model="planar")
        with pytest.raises(ValueError, match="model must be one of"):
            solve_rod(_rod(), coils.UniformField(B=(0, 5e-3, 0)), [1.0], model="3d")

    def test_clamp_rotation_about_z_is_planar_and_matches_the_angle(self):
        rod = _rod()
        f = coils.UniformField(B=(0, 5e-3, 0))
        a = solve_rod(rod, f, [1.0], clamp_angle=0.3)
        b = solve_rod(rod, f, [1.0], clamp_rotation=Rotation.from_rotvec([0, 0, 0.3]))
        assert b.model == "planar"
        assert np.abs(a.tip - b.tip).max() < 1e-15

    @pytest.mark.parametrize(
        ("bad", "match"),
        [
            (np.diag([1.0, 1.0, 1.01]), "orthonormal"),
            (np.diag([1.0, 1.0, -1.0]), "reflection"),
            (np.full((3, 3), np.nan), "finite"),
            (np.eye(2), "shape"),
            ("x", "rotation"),
        ],
    )
    def test_bad_clamp_rotation(self, bad, match):
        with pytest.raises(ValueError, match=f"clamp_rotation.*{match}|{match}.*clamp_rotation"):
            solve_rod(_rod(), coils.UniformField(B=(0, 5e-3, 0)), [1.0], clamp_rotation=bad)

    def test_angle_and_rotation_together(self):
        with pytest.raises(ValueError, match="either"):
            solve_rod(
                _rod(),
                coils.UniformField(B=(0, 5e-3, 0)),
                [1.0],
                clamp_angle=0.1,
                clamp_rotation=np.eye(3),
            )

    @pytest.mark.parametrize("euler", ["xyz", "zyx", "zxz", "yzy"])
    def test_gimbal_lock_clamp_rotations(self, euler):
        # middle angle at the singular value of each convention: the rotation is well defined
        mid = np.pi / 2 if euler[0] != euler[2] else 0.0
        Q = Rotation.from_euler(euler, [0.7, mid + 1e-12, -0.4])
        rod = _rod(Rectangle(3e-3, 1.5e-3), angle=0.5)
        b = rod.field_for_lambda(3.0) * _unit([0.2, 1.0, -0.6])
        res = solve_rod(rod, coils.UniformField(B=Q.apply(b)), [1.0], clamp_rotation=Q)
        ref = solve_rod(rod, coils.UniformField(B=b), [1.0], model="spatial")
        assert np.abs(ref.tip @ Q.as_matrix().T - res.tip).max() < 1e-12 * L


class TestStress:
    def test_random_magnetizations_at_large_lambda_converge_or_raise(self):
        rng = np.random.default_rng(3)
        for _ in range(3):
            mags = rng.uniform(20e3, 128e3, 4)
            angs = rng.uniform(-np.pi, np.pi, 4)
            rod = Rod(L, 1e6, Circle(2e-3), Magnetization.segments([L / 4] * 4, mags, angs))
            b = rod.field_for_lambda(100.0) * _unit(rng.normal(size=3))
            try:
                res = solve_rod(rod, coils.UniformField(B=b), np.linspace(0.05, 1, 20), nodes=128)
            except ConvergenceError as err:
                message = str(err)
                assert "solve_rod" in message  # noqa: PT017  (either outcome is allowed)
                continue
            assert np.all(np.isfinite(res.tip))
            assert np.all(np.abs(np.linalg.norm(res.tip, axis=1)) <= L * (1 + 1e-9))

    def test_large_twist(self):
        rod = _rod(angle=np.pi / 2)
        GJ = rod_stiffnesses(rod)[0] * rod.bending_stiffness
        lam_t, beta = 30.0, 3.0
        b = lam_t * GJ / (128e3 * rod.area * L**2)
        res = solve_rod(
            rod,
            coils.UniformField(B=(0, b * math.cos(beta), b * math.sin(beta))),
            np.linspace(0.1, 1, 10),
            nodes=128,
        )
        frames = res.frames(len(res) - 1)
        twist = np.arctan2(frames[-1, 2, 1], frames[-1, 1, 1])
        ref = elastica(lam_t, beta, length=L)
        assert abs(twist - ref.tip_angle) < 1e-6


class TestAgainstFEM:
    """The spatial rod against the 3D continuum (neo-Hookean + magnetic, scikit-fem), whose
    offset from rod theory is about 0.5 % L for the seed robot (L/D = 20; the planar
    comparisons in test_fem_rod.py see the same)."""

    def test_elevation(self):
        from coilrod import presets, solve_fem

        base = presets.seed_rod(presets.M1())
        mag = Magnetization(base.magnetization.max_magnitude(base.length), 0.0, elevation=0.5)
        rod = Rod(base.length, base.youngs_modulus, base.section, mag)
        lams = [2.0, 5.0]
        field = coils.UniformField(B=(0.0, rod.field_for_lambda(1.0), 0.0))
        fem = solve_fem(rod, field, lams, dim=3, order=2, elements=(20, 1, 1))
        res = solve_rod(rod, field, lams)
        assert res.model == "spatial"
        gap = np.linalg.norm(fem.tip - res.tip, axis=1) / rod.length
        assert gap.max() < 0.0075, gap
        assert np.all(np.abs(res.tip[:, 2]) > 0.05 * rod.length)  # the elevation lifts it

    def test_out_of_plane_field(self):
        from coilrod import presets, solve_fem

        rod = presets.seed_rod(presets.M1())
        beta, lams = 0.6, [2.0, 5.0]
        b = rod.field_for_lambda(1.0)
        field = coils.UniformField(B=(0.0, b * np.cos(beta), b * np.sin(beta)))
        fem = solve_fem(rod, field, lams, dim=3, order=2, elements=(20, 1, 1))
        res = solve_rod(rod, field, lams)
        assert res.model == "spatial"
        gap = np.linalg.norm(fem.tip - res.tip, axis=1) / rod.length
        assert gap.max() < 0.0075, gap
        # both bend in the plane of B (its angle about x), and dropping B_z would be 28 % L off
        assert np.allclose(np.arctan2(fem.tip[:, 2], fem.tip[:, 1]), beta, atol=2e-3)
        planar = solve_rod(rod, coils.UniformField(B=(0.0, b * np.cos(beta), 0.0)), lams)
        assert (np.linalg.norm(fem.tip - planar.tip, axis=1) / rod.length).min() > 0.2


class TestAgainstBVP:
    """Out-of-plane equilibria against an independent solve_bvp of the 3D Kirchhoff equations
    (tests/rod3d_bvp_reference.py, tol 1e-10): <= 1e-6 L with default settings."""

    @staticmethod
    def _reference(rod, field, scales, **kw):
        from rod3d_bvp_reference import spatial_reference

        K = rod_stiffnesses(rod) * rod.bending_stiffness
        mag = rod.magnetization

        return spatial_reference(rod.length, K, rod.area, mag.vector3, field, scales, **kw)

    @pytest.mark.parametrize("kind", ["uniform", "linear", "maxwell"])
    def test_out_of_plane_fields(self, kind):
        rod = _rod(Rectangle(3e-3, 1.5e-3), angle=0.3)
        B = rod.field_for_lambda(5.0) * _unit([0.3, 1.0, 0.5])
        field = {
            "uniform": coils.UniformField(B=B),
            "linear": coils.LinearField(B0=B, gradient=0.05 * GRADIENT),
            "maxwell": coils.MaxwellPair(0.05, 300, 2.0, axis="z", center=(0.01, 0.0, -0.02))
            + coils.UniformField(B=B),
        }[kind]
        scales = [0.5, 1.0]
        res = solve_rod(rod, field, scales)
        assert res.model == "spatial"
        ref = self._reference(rod, field, scales)
        for k in range(len(scales)):
            assert np.abs(res.tip[k] - ref[k]["tip"]).max() < 1e-6 * L
            assert np.abs(res.frames(k)[-1] - ref[k]["R"][-1]).max() < 1e-6

    def test_elevation_and_rectangle(self):
        # an elevated magnetization on a rectangle (EI_y = 4 EI_z, GJ from the exact series)
        rod = Rod(L, 1e6, Rectangle(3e-3, 1.5e-3), Magnetization(128e3, 0.3, elevation=0.4))
        field = coils.UniformField(B=rod.field_for_lambda(5.0) * _unit([0.3, 1.0, 0.5]))
        res = solve_rod(rod, field, [0.5, 1.0])
        ref = self._reference(rod, field, [0.5, 1.0])
        for k in range(2):
            assert np.abs(res.tip[k] - ref[k]["tip"]).max() < 1e-6 * L
        planar_guess = solve_rod(
            Rod(L, 1e6, Rectangle(3e-3, 1.5e-3), Magnetization(128e3, 0.3)), field, [1.0]
        )
        assert np.abs(planar_guess.tip[0] - ref[1]["tip"]).max() > 1e-2 * L  # it matters

    def test_clamp_rotation_and_position(self):
        rod = _rod(Rectangle(3e-3, 1.5e-3), angle=-0.4)
        Q = Rotation.from_euler("zyx", [30, -50, 20], degrees=True).as_matrix()
        field = coils.LinearField(
            B0=rod.field_for_lambda(4.0) * _unit([0.2, -1.0, 0.4]), gradient=0.05 * GRADIENT
        )
        clamp = (0.003, -0.002, 0.004)
        res = solve_rod(rod, field, [1.0], clamp_rotation=Q, clamp_position=clamp)
        ref = self._reference(rod, field, [1.0], clamp_rotation=Q, clamp_position=clamp)
        assert np.abs(res.tip[0] - ref[0]["tip"]).max() < 1e-6 * L


def test_twisted_benchmark_of_the_independent_reference(monkeypatch):
    """The recorded tip and tip frame of tests/_spatial_reference.py's twisted case (solve_bvp
    with an exact Jacobian, converged to 1e-13 L; GJ = 0.6 EI_z, EI_y = 4 EI_z, an elevated
    magnetization, an oblique field at lambda = 5) against solve_rod with the defaults.  GJ is
    a chosen value no Poisson ratio gives for this section, so the stiffness ratios are set."""
    from _spatial_reference import TWISTED_TIP, TWISTED_TIP_FRAME, twisted_case

    import coilrod.rod.solve as solve_module

    case = twisted_case()
    rod = Rod(
        case["length"], case["youngs_modulus"], Rectangle(case["width"], case["thickness"]),
        Magnetization(case["magnitude"], case["theta_m"], elevation=case["psi_m"]),
    )  # fmt: skip
    monkeypatch.setattr(solve_module, "rod_stiffnesses", lambda rod: np.array([0.6, 4.0, 1.0]))
    res = solve_rod(rod, coils.UniformField(B=case["B"]), [1.0])
    assert res.model == "spatial"
    assert np.abs(res.tip[0] - TWISTED_TIP).max() < 1e-6 * case["length"]
    assert np.abs(res.frames(0)[-1] - TWISTED_TIP_FRAME).max() < 1e-6
