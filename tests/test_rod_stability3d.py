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
    """Discrete 3D energy (J) of node frames (..., n, 3, 3) in a uniform field B (T): bending
    and torsion sum psi^T K psi / (2 h) with psi = log(R_i^T R_{i+1}), magnetic
    -sum w A m . B with the trapezoid weights w and the node magnetization M(s_i) in the body
    frame; shape (...)."""
    h = np.diff(s)
    w = np.zeros(s.size)
    w[:-1] += h / 2
    w[1:] += h / 2
    rel = np.einsum("...nji,...njk->...nik", frames[..., :-1, :, :], frames[..., 1:, :, :])
    psi = Rotation.from_matrix(rel.reshape(-1, 3, 3)).as_rotvec().reshape(rel.shape[:-1])
    K = np.asarray(rod.stiffnesses, float)
    bend = np.sum(np.einsum("...ni,i,...ni->...n", psi, K, psi) / (2 * h), axis=-1)
    M = rod.magnetization.vector3(s)
    m = np.einsum("...nij,nj->...ni", frames, M)
    return bend - rod.area * np.sum(w * (m @ np.asarray(B, float)), axis=-1)


def _out_of_plane_hessian(rod, s, theta, B, d=1e-4):
    """Central-difference Hessian (J/rad^2) of :func:`_energy_3d` in world rotations about x
    and y of the free nodes, at the planar state with node angles theta (every perturbed
    state evaluated in one batch)."""
    n = s.size
    base = Rotation.from_euler("z", np.asarray(theta)[:, None]).as_matrix()
    free = 2 * (n - 1)
    i, j = np.triu_indices(free)
    e = np.eye(free) * d
    signs = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]])  # the four corners of (i, j)
    v = signs[:, None, 0, None] * e[i] + signs[:, None, 1, None] * e[j]  # (4, pairs, free)
    rv = np.zeros(v.shape[:2] + (n, 3))
    rv[..., 1:, :2] = v.reshape(v.shape[:2] + (n - 1, 2))
    frames = Rotation.from_rotvec(rv.reshape(-1, 3)).as_matrix().reshape(rv.shape + (3,))
    E = _energy_3d(rod, s, frames @ base, B)  # (4, pairs)
    H = np.zeros((free, free))
    H[i, j] = H[j, i] = (E[0] - E[1] - E[2] + E[3]) / (4 * d * d)
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


def _spatial_odd_blocks(problem, lin, fields=None):
    """The odd (out-of-plane) slices of the spatial rod's own second-variation blocks at the
    planar states of ``lin`` (its numpy reference pass: nothing compiled)."""
    from coilrod.rod.so3 import about_z
    from coilrod.rod.spatial import SpatialRod, numpy_core

    mu = np.zeros((problem.n, 3))
    mu[:, :2] = problem.mu
    rod3 = SpatialRod(
        problem.mesh, mu, problem.out_of_plane.stiffness, problem.field, problem.L,
        problem.clamp, about_z(problem.theta0), mixed=not problem.uniform,
    )  # fmt: skip
    if fields is not None:
        rod3._b_uniform = fields[:, None, :]
    U3 = problem.out_of_plane.spatial_states(lin.u)
    _, _, _, (D, E) = rod3._assemble(U3, lin.scale, True, core=numpy_core, band=False)
    odd = np.array([0, 1]) if problem.uniform else np.array([2, 5, 6, 7])
    return D[:, :, odd][:, :, :, odd], E[:, :, odd][:, :, :, odd]


def test_planar_blocks_equal_the_spatial_rods_own():
    # the out-of-plane block assembled from planar states (nothing of the spatial rod
    # compiled for a planar run) against the spatial rod's own blocks at the same states:
    # random states, a rectangle with GJ != EI_y != EI_z; uniform layout with one field per
    # member (a fan of directions), mixed layout in a Maxwell pair's field (gradient and
    # curvature terms, internal forces)
    from coilrod.rod.planar import PlanarRod
    from coilrod.rod.solve import build_problem, make_mesh, rod_stiffnesses

    rng = np.random.default_rng(1)
    rod = coilrod.Rod(
        0.04,
        1e6,
        coilrod.Rectangle(3e-3, 1e-3),
        coilrod.Magnetization.segments([0.02, 0.02], [128e3, 64e3], [0.3, -1.0]),
        poisson_ratio=0.3,
    )
    problem = build_problem(rod, _uniform(8e-3, 70.0), make_mesh(rod, 16), np.zeros(3), 0.4)
    theta = 0.4 + np.cumsum(rng.normal(0.0, 0.3, (3, problem.n)), axis=1)
    theta[:, 0] = 0.4
    lin = problem.linearize(theta, np.array([0.3, 1.0, 2.5]))
    for fields in (None, rng.normal(0.0, 5e-3, (3, 3)) * [1, 1, 0]):
        D, E = _spatial_odd_blocks(problem, lin, fields)
        D2, E2 = problem.out_of_plane.odd_blocks(lin, fields)
        np.testing.assert_allclose(D2, D, rtol=0, atol=1e-12 * np.abs(D).max())
        np.testing.assert_allclose(E2, E, rtol=0, atol=1e-12 * np.abs(E).max())
    maxwell = coils.MaxwellPair(radius=0.08, turns=200, current=2.0, axis="y", center=(0.02, 0, 0))
    field = maxwell + coils.UniformField(B=(0.0, 2e-3, 0.0))
    mesh = make_mesh(rod, 8)
    # every other node's magnetization, contiguous as the solver's own (a strided view is
    # another numba specialisation of the planar kernel: a second compile in a cold test run)
    mu = np.ascontiguousarray(problem.mu[::2])
    mixed = PlanarRod(mesh, mu, field, rod.length, np.zeros(3), 0.4, mixed=True)
    mixed.with_out_of_plane(rod_stiffnesses(rod))
    U = np.stack([mixed.from_theta(t[::2], 1.5) for t in theta])
    U[:, 3::5] += rng.normal(0.0, 0.5, (3, mixed.n))  # forces off their equilibrium values
    lin = mixed.linearize(U, np.array([0.5, 1.5, 4.0]))
    D, E = _spatial_odd_blocks(mixed, lin)
    D2, E2 = mixed.out_of_plane.odd_blocks(lin)
    np.testing.assert_allclose(D2, D, rtol=0, atol=1e-12 * np.abs(D).max())
    np.testing.assert_allclose(E2, E, rtol=0, atol=1e-12 * np.abs(E).max())


@pytest.mark.parametrize("mixed", [False, True])
def test_straight_rod_buckles_out_of_plane_at_the_euler_load_of_its_weak_axis(mixed):
    # a straight clamped rod magnetized along its axis in an antiparallel field is an Euler
    # column: it buckles about each section axis at lambda = (pi^2 / 4) EI / EI_z (closed
    # form).  A strip of width w < thickness t (I_y / I_z = (w / t)^2 = 1/4) leaves its plane
    # first, at pi^2 / 16; the planar rod must count that mode, and the in-plane one at pi^2/4
    from coilrod.rod.planar import PlanarRod
    from coilrod.rod.solve import _node_moments, make_mesh, rod_stiffnesses

    rod = coilrod.Rod(0.04, 1e6, coilrod.Rectangle(1e-3, 2e-3), coilrod.Magnetization(128e3, 0.0))
    field = coils.UniformField(B=(-rod.field_for_lambda(1.0), 0.0, 0.0))
    mesh = make_mesh(rod, 16)
    problem = PlanarRod(
        mesh, _node_moments(rod, mesh, dim=2), field, rod.length, np.zeros(3), 0.0, mixed=mixed
    ).with_out_of_plane(rod_stiffnesses(rod))
    out_c, in_c = np.pi**2 / 16, np.pi**2 / 4
    scales = np.array([0.98 * out_c, 1.02 * out_c, 0.98 * in_c, 1.02 * in_c])
    lin = problem.linearize(np.stack([problem.straight()] * 4), scales)
    total, odd = problem.negative_counts(lin)
    np.testing.assert_array_equal(odd, [0, 1, 1, 1])
    np.testing.assert_array_equal(total, [0, 1, 1, 2])
    mu = problem.stability(lin, precise=True)  # the 3D figure changes sign at the weak load
    assert mu[0] > 0 > mu[1]


def test_a_planar_solve_in_a_coil_field_leaves_the_spatial_rod_alone():
    # the 3D stability of planar states (count and eigenvalue) needs nothing of the spatial
    # rod: neither its module nor its compiled kernels are loaded (a cold start compiles
    # them for seconds)
    import subprocess
    import sys
    from pathlib import Path

    code = (
        "import sys, coils, coilrod\n"
        "from coilrod import presets\n"
        "rod = presets.seed_rod()\n"
        "pair = coils.HelmholtzPair(radius=0.08, turns=200, current=1.0, axis='y')\n"
        "res = coilrod.solve_rod(rod, pair, [20.0], nodes=4)\n"
        "assert res.stable.all() and res.min_eigenvalue[0] > 0, res.min_eigenvalue\n"
        "loaded = sorted(m for m in sys.modules if m.startswith('coilrod.rod.'))\n"
        "print(' '.join(loaded))\n"
    )
    root = Path(__file__).resolve().parent.parent
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=root, capture_output=True, text=True, check=True
    )
    loaded = out.stdout.split()
    assert "coilrod.rod.out_of_plane" in loaded  # it did count the out-of-plane modes
    assert "coilrod.rod.spatial" not in loaded
    assert "coilrod.rod._compiled_spatial" not in loaded


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


def test_large_out_of_plane_blocks_take_the_sparse_eigenvalue(monkeypatch):
    # past _DENSE unknowns the out-of-plane eigenvalue comes from ARPACK on a sparse LU: the
    # same figure as the dense spectrum, stable (positive) and buckled (negative) alike, in
    # both layouts (the straight strip of the Euler test, its weak-axis load +-2 %)
    from coilrod.rod import out_of_plane
    from coilrod.rod.planar import PlanarRod
    from coilrod.rod.solve import _node_moments, make_mesh, rod_stiffnesses

    rod = coilrod.Rod(0.04, 1e6, coilrod.Rectangle(1e-3, 2e-3), coilrod.Magnetization(128e3, 0.0))
    field = coils.UniformField(B=(-rod.field_for_lambda(1.0), 0.0, 0.0))
    mesh = make_mesh(rod, 12)
    scales = np.array([0.98, 1.02]) * np.pi**2 / 16
    for mixed in (False, True):
        problem = PlanarRod(
            mesh, _node_moments(rod, mesh, dim=2), field, rod.length, np.zeros(3), 0.0,
            mixed=mixed,
        ).with_out_of_plane(rod_stiffnesses(rod))  # fmt: skip
        lin = problem.linearize(np.stack([problem.straight()] * 2), scales)
        counts = problem.out_of_plane.odd_count(lin)
        dense = problem.out_of_plane.lowest(lin, None, counts)
        monkeypatch.setattr(out_of_plane, "_DENSE", 4)
        sparse = problem.out_of_plane.lowest(lin, None, counts)
        monkeypatch.undo()
        np.testing.assert_array_equal(counts, [0, 1])
        assert dense[0] > 0 > dense[1]
        np.testing.assert_allclose(sparse, dense, rtol=1e-8)


def test_inertia_count_numpy_and_compiled_agree_with_dense_eigenvalues(monkeypatch):
    # the block LDL^T count (coilrod.rod._inertia) by its numpy version (cold start) and its
    # compiled version: the same counts, and the negative eigenvalues of the dense matrix
    # (numpy eigvalsh, independent), also with double eigenvalues (two identical halves: the
    # sign of the determinant does not change); compiling starts when COMPILE_AFTER says so
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
    monkeypatch.setattr(inertia._rental, "held", lambda: False)
    for name in ("numpy", "compiled"):
        monkeypatch.setattr(inertia._rental, "spent", 0.0)
        monkeypatch.setattr(inertia._rental, "ready", name == "compiled")
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
        assert inertia._rental.ready == (name == "compiled")
    monkeypatch.setattr(inertia._rental, "ready", False)
    monkeypatch.setattr(inertia, "COMPILE_AFTER", 0.0)
    inertia.block_tridiagonal_inertia(*cases[0])
    assert inertia._rental.ready
