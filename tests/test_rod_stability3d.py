"""Stability of planar states in 3D (issue "Decisions users can trust", item 1).

A planar state can be stable among in-plane perturbations and buckle out of the plane.  The
references here are independent of the solvers:

* a finite-difference Hessian of the discrete 3D energy (bending about both section axes and
  torsion, with the exact relative rotations from scipy's ``Rotation``) over out-of-plane
  rotations of the nodes, at the planar solver's own states;
* the spatial rod (``model="spatial"``), which follows the same planar path with every mode;
* a property family over random magnetizations and field directions.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import coilrod
import coils
from coilrod import presets
from coilrod.path.events import StabilityWarning


def _uniform(b, degrees):
    a = np.deg2rad(degrees)
    return coils.UniformField(B=(b * np.cos(a), b * np.sin(a), 0.0))


def _energy_3d(rod, s, frames, B):
    """Discrete 3D energy (J) of node frames (n, 3, 3) in a uniform field B (T): bending and
    torsion sum psi^T K psi / (2 h) with psi = log(R_i^T R_{i+1}), magnetic -sum w A m . B
    with the trapezoid weights w and the node magnetization M(s_i) in the body frame."""
    h = np.diff(s)
    w = np.zeros(s.size)
    w[:-1] += h / 2
    w[1:] += h / 2
    rel = np.einsum("nji,njk->nik", frames[:-1], frames[1:])
    psi = Rotation.from_matrix(rel).as_rotvec()
    K = np.asarray(rod.stiffnesses, float)
    bend = np.sum(np.einsum("ni,i,ni->n", psi, K, psi) / (2 * h))
    M = rod.magnetization.vector3(s)
    m = np.einsum("nij,nj->ni", frames, M)
    return bend - rod.area * np.sum(w * (m @ np.asarray(B, float)))


def _out_of_plane_hessian(rod, s, theta, B, d=1e-4):
    """Central-difference Hessian (J/rad^2) of :func:`_energy_3d` in world rotations about x
    and y of the free nodes, at the planar state with node angles theta."""
    n = s.size
    base = Rotation.from_euler("z", np.asarray(theta)[:, None]).as_matrix()
    free = 2 * (n - 1)

    def energy(v):
        rv = np.zeros((n, 3))
        rv[1:, :2] = v.reshape(n - 1, 2)
        frames = Rotation.from_rotvec(rv).as_matrix() @ base
        return _energy_3d(rod, s, frames, B)

    H = np.zeros((free, free))
    e = np.eye(free) * d
    for i in range(free):
        for j in range(i, free):
            H[i, j] = H[j, i] = (
                energy(e[i] + e[j])
                - energy(e[i] - e[j])
                - energy(-e[i] + e[j])
                + energy(-e[i] - e[j])
            ) / (4 * d * d)
    return H


class TestPlanarStatesIn3D:
    def test_m2b_buckles_out_of_plane_against_a_finite_difference_hessian(self):
        # the seed's M(2b) at 255 deg, 20 mT: stable in the plane at every scale, but the 3D
        # energy's Hessian over out-of-plane rotations is indefinite from scale 0.25 on
        rod = presets.seed_rod(presets.M2(variant="b"))
        field = _uniform(20e-3, 255.0)
        scales = np.array([0.125, 0.375, 0.625, 1.0])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", StabilityWarning)
            res = coilrod.solve_rod(rod, field, scales, nodes=12, richardson=False)
        assert res.model == "planar"
        assert res.stable_in_plane.all()
        ref = []
        for k, c in enumerate(scales):
            H = _out_of_plane_hessian(
                rod, res.s, res.theta(k), c * np.asarray(field.B([0, 0, 0]))[0]
            )
            ref.append(np.linalg.eigvalsh(H).min() > 0)
        assert ref == [True, False, False, False]
        np.testing.assert_array_equal(res.stable, ref)
        # the eigenvalue is the 3D one: negative where the Hessian is indefinite
        assert np.all((res.min_eigenvalue > 0) == np.array(ref))
        assert np.all(res.min_eigenvalue_in_plane > 0)

    def test_out_of_plane_bifurcation_is_reported_like_any_other(self):
        # M(4.2) at 150 deg, 20 mT: unstable in 3D between scales ~0.22 and ~0.43; the planar
        # solver reports both crossings (mode "out-of-plane"), at the spatial rod's scales
        rod = presets.seed_rod(presets.M42())
        field = _uniform(20e-3, 150.0)
        scales = np.linspace(0.05, 0.6, 12)
        with pytest.warns(StabilityWarning, match="out of its plane"):
            planar = coilrod.solve_rod(rod, field, scales, nodes=24)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", StabilityWarning)
            spatial = coilrod.solve_rod(rod, field, scales, nodes=24, model="spatial")
        assert planar.model == "planar"
        np.testing.assert_array_equal(planar.stable, spatial.stable)
        assert planar.stable_in_plane.all()
        assert not planar.stable.all()
        kinds = [(e["kind"], e["mode"], e["stable"]) for e in planar.instabilities]
        assert kinds == [
            ("bifurcation", "out-of-plane", False),
            ("bifurcation", "out-of-plane", True),
        ]
        crit_p = [e["scale"] for e in planar.instabilities]
        crit_s = [e["scale"] for e in spatial.instabilities]
        np.testing.assert_allclose(crit_p, crit_s, rtol=1e-6)
        assert 0.2 < crit_p[0] < 0.24
        assert 0.41 < crit_p[1] < 0.45
        np.testing.assert_allclose(
            planar.min_eigenvalue, spatial.min_eigenvalue, rtol=1e-6, atol=1e-8
        )

    def test_in_plane_figures_stay_available(self):
        # the straight rod buckling in an antiparallel field is an in-plane bifurcation too
        rod = presets.seed_rod(presets.M1())
        lam_c = np.pi**2 / 4
        field = coils.UniformField(
            B=(-rod.field_for_lambda(1.0), 1e-9 * rod.field_for_lambda(1.0), 0)
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", StabilityWarning)
            res = coilrod.solve_rod(rod, field, [0.5 * lam_c, 0.9 * lam_c], nodes=16)
        assert res.stable.all()
        assert res.stable_in_plane.all()
        assert np.all(res.min_eigenvalue <= res.min_eigenvalue_in_plane + 1e-12)


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    angles=st.tuples(st.floats(-np.pi, np.pi), st.floats(-np.pi, np.pi)),
    direction=st.floats(0.0, 360.0),
    b=st.floats(2e-3, 25e-3),
)
def test_planar_and_spatial_agree_on_stability_of_in_plane_states(angles, direction, b):
    rod = coilrod.Rod(
        0.04,
        1e6,
        coilrod.Circle(2e-3),
        coilrod.Magnetization.segments([0.02, 0.02], [128e3, 96e3], list(angles)),
    )
    field = _uniform(b, direction)
    scales = np.linspace(0.25, 1.0, 4)
    out = {}
    for model in ("planar", "spatial"):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", StabilityWarning)
                out[model] = coilrod.solve_rod(rod, field, scales, nodes=12, model=model)
        except coilrod.ConvergenceError:
            out[model] = None
    if out["planar"] is None or out["spatial"] is None:
        return  # a path that ends (both models would have to fail alike: not the point here)
    np.testing.assert_allclose(out["planar"].tip, out["spatial"].tip, atol=1e-9 * rod.length)
    np.testing.assert_array_equal(out["planar"].stable, out["spatial"].stable)


def test_planar_blocks_equal_the_spatial_rods_own():
    # the numpy second variation at planar states (uniform fields: nothing compiled for a
    # planar run) against the spatial rod's blocks at the same states, random states and
    # one field per member (a fan of directions), a rectangle with GJ != EI_y != EI_z
    from coilrod.rod.out_of_plane import uniform_blocks
    from coilrod.rod.solve import build_problem, make_mesh

    rng = np.random.default_rng(1)
    rod = coilrod.Rod(
        0.04,
        1e6,
        coilrod.Rectangle(3e-3, 1e-3),
        coilrod.Magnetization.segments([0.02, 0.02], [128e3, 64e3], [0.3, -1.0]),
        poisson_ratio=0.3,
    )
    problem = build_problem(rod, _uniform(8e-3, 70.0), make_mesh(rod, 16), np.zeros(3), 0.4)
    twin = problem.out_of_plane.twin
    theta = 0.4 + np.cumsum(rng.normal(0.0, 0.3, (3, problem.n)), axis=1)
    theta[:, 0] = 0.4
    scales = np.array([0.3, 1.0, 2.5])
    for fields in (twin._b_uniform, rng.normal(0.0, 5e-3, (3, 1, 3)) * [1, 1, 0]):
        twin._b_uniform = fields
        _, _, _, (D, E) = twin._assemble(
            problem.out_of_plane.spatial_states(theta), scales, True, band=False
        )
        D2, E2 = uniform_blocks(theta, scales, twin, fields)
        np.testing.assert_allclose(D2, D, rtol=0, atol=1e-12 * np.abs(D).max())
        np.testing.assert_allclose(E2, E, rtol=0, atol=1e-12 * np.abs(E).max())


def test_scenes_and_sweep_rows_report_the_3d_figure():
    # the M(2b) case as a scene: its rows say unstable where the rod would leave its plane
    from _scenes import scene_with

    from coilrod.scene import parse_scene
    from coilrod.scene.runner import run_scene

    a = np.deg2rad(255.0)
    scene = parse_scene(
        scene_with(
            robot__magnetization={"preset": "M2b"},
            field__B="20 mT",
            field__direction=[float(np.cos(a)), float(np.sin(a)), 0.0],
            load__steps=2,
        )
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StabilityWarning)
        result = run_scene(scene, progress=False)
    run = result.run("rod", "ideal")
    assert run.result.model == "planar"
    np.testing.assert_array_equal(run.stable, [False, False])
    assert run.result.stable_in_plane.all()


def test_inertia_count_numpy_and_compiled_agree_with_dense_eigenvalues(monkeypatch):
    # the block LDL^T count (coilrod.rod._inertia) by its numpy version (cold start) and its
    # compiled version: the same counts, and the negative eigenvalues of the dense matrix
    # (numpy eigvalsh, independent), also with double eigenvalues (two identical halves: the
    # sign of the determinant does not change); compiling starts when COMPILE_AFTER says so
    import coilrod.rod._compiled as rc
    import coilrod.rod._inertia as inertia

    rng = np.random.default_rng(5)
    cases = []
    for trial in range(12):
        b, n = 2 * int(rng.integers(1, 5)), int(rng.integers(1, 8))
        D = rng.normal(size=(2, n, b, b)) + rng.normal() * 3 * np.eye(b)
        E = rng.normal(size=(2, max(n - 1, 0), b, b))
        if trial % 2:  # double eigenvalues
            h = b // 2
            D[:, :, h:, h:], D[:, :, :h, h:], D[:, :, h:, :h] = D[:, :, :h, :h], 0.0, 0.0
            E[:, :, h:, h:], E[:, :, :h, h:], E[:, :, h:, :h] = E[:, :, :h, :h], 0.0, 0.0
        cases.append((D, E))
    monkeypatch.setattr(rc, "_on_disk", lambda dispatcher: False)
    for name in ("numpy", "compiled"):
        monkeypatch.setattr(inertia, "_rent", 0.0)
        monkeypatch.setattr(inertia, "_compiled_ready", name == "compiled")
        monkeypatch.setattr(inertia, "COMPILE_AFTER", np.inf)
        for D, E in cases:
            neg, _ = inertia.block_tridiagonal_inertia(D, E)
            k, n, b = D.shape[:3]
            for m in range(k):
                A = np.zeros((n * b, n * b))
                for i in range(n):
                    A[i * b : (i + 1) * b, i * b : (i + 1) * b] = 0.5 * (D[m, i] + D[m, i].T)
                    if i < n - 1:
                        A[i * b : (i + 1) * b, (i + 1) * b : (i + 2) * b] = E[m, i]
                        A[(i + 1) * b : (i + 2) * b, i * b : (i + 1) * b] = E[m, i].T
                ev = np.linalg.eigvalsh(A)
                assert np.abs(ev).min() > 1e-9 * np.abs(ev).max()  # no count at a threshold
                assert neg[m] == np.count_nonzero(ev < 0), name
        assert inertia._compiled_ready == (name == "compiled")
    monkeypatch.setattr(inertia, "_compiled_ready", False)
    monkeypatch.setattr(inertia, "COMPILE_AFTER", 0.0)
    inertia.block_tridiagonal_inertia(*cases[0])
    assert inertia._compiled_ready
