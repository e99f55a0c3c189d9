"""Tests of the independent spatial rod reference (tests/_spatial_reference.py).

Every check is against a closed form or a conservation law, never against coilrod's rod solvers:

* (a) planar: uniform axial M in a uniform perpendicular field is the closed-form elastica
  (coilrod.rod.elastica, elliptic integrals), and lambda L / 3 for small loads;
* (b) pure torsion: transverse M in a field in the cross-section plane twists the straight rod;
  the twist obeys the elastica ODE with EI -> GJ;
* (c) out of plane: a field rotated about the clamp tangent rotates the planar solution;
* (d) rigid motion: rotating and translating clamp and field together moves the solution rigidly;
* (e) gradient fields: the first-order (linear beam) response in closed form, tol convergence
  and global force and moment balance at large loads, also in real coil fields;
* the genuinely 3D twisted benchmark (``twisted_case``) and its converged tip.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from _spatial_reference import (
    TWISTED_TIP,
    TWISTED_TIP_FRAME,
    evaluate,
    quaternion_from_rotation,
    rotation_from_quaternion,
    spatial_reference,
    twisted_case,
)
from numpy.polynomial import Polynomial
from scipy.spatial.transform import Rotation

import coils
from coilrod.rod.elastica import elastica

# Reference robot of DESIGN.md: L = 40 mm, circular section D = 2 mm, E = 1 MPa, nu = 0.5.
L = 0.04
D = 2e-3
E = 1e6
M0 = 128e3
EI = E * math.pi * D**4 / 64
GJ = EI / 1.5  # G J = E I / (1 + nu) for a circle
AREA = math.pi * D**2 / 4
#: Field magnitude (T) at which lambda = |M| |B| A L^2 / EI = 1.
B_UNIT = EI / (M0 * AREA * L**2)


def uniform_magnetization(direction, magnitude=M0):
    """Body-frame magnetization callable of constant direction (3,) and magnitude (A/m)."""
    vec = magnitude * np.asarray(direction, dtype=float)

    def magnetization(s):
        return np.broadcast_to(vec, (np.size(s), 3)).copy()

    return magnetization


def rot_x(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def balance(result, area, magnetization, field, x0=(0.0, 0.0, 0.0), points=8):
    """Force and moment of the magnetic loads about the clamp, integrated along the solution.

    Gauss-Legendre with ``points`` nodes on every mesh interval of the solution.

    Returns
    -------
    force, moment : ndarray, shape (3,)
        ``int f ds`` (N) and ``int (tau + (x - x0) x f) ds`` (N m); equal to n(0) and m(0).
    """
    s_nodes = result["s"]
    g, w = np.polynomial.legendre.leggauss(points)
    h = np.diff(s_nodes)
    s = (s_nodes[:-1, None] + 0.5 * h[:, None] * (g + 1)).ravel()
    weights = (0.5 * h[:, None] * w).ravel()
    st = evaluate(result, s)
    mw = np.einsum("kij,kj->ki", st["R"], magnetization(s))
    scale = result["scale"]
    B = scale * field.B(st["x"])
    G = scale * field.gradient(st["x"])
    f = area * np.einsum("kij,ki->kj", G, mw)
    tau = area * np.cross(mw, B)
    force = weights @ f
    moment = weights @ (tau + np.cross(st["x"] - np.asarray(x0, dtype=float), f))
    return force, moment


# -- helpers --------------------------------------------------------------------------------------
def test_quaternion_round_trip(rng):
    for R in Rotation.random(20, random_state=7).as_matrix():
        q = quaternion_from_rotation(R)
        assert abs(np.linalg.norm(q) - 1) < 1e-15
        np.testing.assert_allclose(rotation_from_quaternion(q[:, None])[0], R, atol=1e-15)
    # the 180-degree rotations exercise the other branches of Shepperd's method
    for axis in np.eye(3):
        R = Rotation.from_rotvec(math.pi * axis).as_matrix()
        q = quaternion_from_rotation(R)
        np.testing.assert_allclose(rotation_from_quaternion(q[:, None])[0], R, atol=1e-15)
    # a non-unit quaternion gives the rotation of its direction
    q = rng.normal(size=4)
    np.testing.assert_allclose(
        rotation_from_quaternion(3.0 * q[:, None]),
        rotation_from_quaternion((q / np.linalg.norm(q))[:, None]),
        atol=1e-15,
    )


def test_input_validation():
    mag = uniform_magnetization((1, 0, 0))
    field = coils.UniformField(B=(0, B_UNIT, 0))
    args = (L, (GJ, EI, EI), AREA, mag, field, [1.0])
    with pytest.raises(ValueError, match="clamp_rotation"):
        spatial_reference(*args, clamp_rotation=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="stiffnesses"):
        spatial_reference(L, (GJ, EI), AREA, mag, field, [1.0])
    with pytest.raises(ValueError, match="scales"):
        spatial_reference(L, (GJ, EI, EI), AREA, mag, field, [])
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        spatial_reference(L, (GJ, EI, EI), AREA, lambda s: np.ones(np.size(s)), field, [1.0])


# -- (a) planar elastica ---------------------------------------------------------------------------
def test_planar_matches_closed_form_elastica():
    field = coils.UniformField(B=(0.0, B_UNIT, 0.0))
    mag = uniform_magnetization((1.0, 0.0, 0.0))
    results = spatial_reference(L, (GJ, EI, EI), AREA, mag, field, [1.0, 5.0, 20.0])
    for res in results:
        exact = elastica(res["scale"], math.pi / 2, length=L)
        assert np.max(np.abs(res["tip"][:2] - exact.tip)) <= 1e-9 * L
        assert abs(res["tip"][2]) <= 1e-12 * L
        tangent = res["R"][-1][:, 0]
        angle = math.atan2(tangent[1], tangent[0])
        assert abs(angle - exact.tip_angle) <= 1e-9
        # the planar state: frames are rotations about z, no internal force in a uniform field
        np.testing.assert_allclose(res["R"][:, 2, 2], 1.0, atol=1e-12)
        assert np.max(np.abs(res["n"])) <= 1e-12 * EI / L**2
        orthogonality = res["R"] @ res["R"].transpose(0, 2, 1) - np.eye(3)
        assert np.max(np.abs(orthogonality)) < 1e-13


def test_small_deflection_is_lambda_L_over_3():
    lam = 1e-3
    field = coils.UniformField(B=(0.0, B_UNIT, 0.0))
    res = spatial_reference(L, (GJ, EI, EI), AREA, uniform_magnetization((1, 0, 0)), field, [lam])
    tip = res[0]["tip"]
    # the tip deflection is odd in lambda: the error of lambda / 3 is O(lambda^3)
    assert abs(tip[1] / L - lam / 3) <= 1e-6 * lam
    assert abs(tip[1] - elastica(lam, math.pi / 2, length=L).tip[1]) <= 1e-12 * L


# -- (b) pure torsion ------------------------------------------------------------------------------
@pytest.mark.parametrize(("b", "lams"), [(math.pi / 2, [1.0, 5.0, 20.0]), (2.5, [5.0])])
def test_pure_torsion_is_the_elastica_in_GJ(b, lams):
    """M transverse (along the normal), B in the cross-section plane at angle b from y: the rod
    stays straight and twists, GJ phi'' + A M B sin(b - phi) = 0, phi(0) = 0, phi'(L) = 0."""
    b_t = GJ / (M0 * AREA * L**2)  # lambda_t = A M B L^2 / GJ = 1
    field = coils.UniformField(B=b_t * np.array([0.0, math.cos(b), math.sin(b)]))
    mag = uniform_magnetization((0.0, 1.0, 0.0))
    results = spatial_reference(L, (GJ, EI, 2 * EI), AREA, mag, field, lams)
    for res in results:
        phi_tip = elastica(res["scale"], b, length=L).tip_angle
        R_tip = res["R"][-1]
        assert abs(math.atan2(R_tip[2, 1], R_tip[1, 1]) - phi_tip) <= 1e-9
        np.testing.assert_allclose(R_tip, rot_x(phi_tip), atol=1e-9)
        # the centreline stays straight along x, the tangent stays e1
        straight = np.column_stack([res["s"], np.zeros((res["s"].size, 2))])
        assert np.max(np.abs(res["x"] - straight)) <= 1e-12 * L
        assert np.max(np.abs(res["R"][:, :, 0] - [1.0, 0.0, 0.0])) <= 1e-12
        # the twist is monotone from 0 toward the field angle
        phi = np.arctan2(res["R"][:, 2, 1], res["R"][:, 1, 1])
        assert phi[0] == 0.0
        assert np.all(np.diff(phi) > 0)
        assert phi[-1] < b


def test_antiparallel_field_follows_the_straight_state_past_buckling():
    """Caveat made explicit: natural continuation stays on the symmetric (straight) branch past
    the buckling load pi^2 / 4 of an antiparallel field, where it is unstable."""
    field = coils.UniformField(B=(-B_UNIT, 0.0, 0.0))
    res = spatial_reference(L, (GJ, EI, EI), AREA, uniform_magnetization((1, 0, 0)), field, [3.0])
    assert 3.0 > math.pi**2 / 4
    np.testing.assert_allclose(res[0]["tip"], [L, 0.0, 0.0], atol=1e-12 * L)


# -- (c) a field out of the plane ----------------------------------------------------------------
@pytest.mark.parametrize("alpha", [0.7, 2.4])
def test_out_of_plane_field_rotates_the_planar_solution(alpha):
    """M axial, B = |B| (0, cos a, sin a): the planar solution rotated about x by a (bending
    is isotropic for the circle, so the problem is symmetric about the clamp tangent)."""
    lam = 5.0
    field = coils.UniformField(B=B_UNIT * np.array([0.0, math.cos(alpha), math.sin(alpha)]))
    res = spatial_reference(L, (GJ, EI, EI), AREA, uniform_magnetization((1, 0, 0)), field, [lam])
    res = res[0]
    exact = elastica(lam, math.pi / 2, length=L)
    Q = rot_x(alpha)
    tip = Q @ np.array([exact.tip[0], exact.tip[1], 0.0])
    assert np.max(np.abs(res["tip"] - tip)) <= 1e-9 * L
    np.testing.assert_allclose(res["R"][-1], Q @ rot_z(exact.tip_angle) @ Q.T, atol=1e-9)


# -- (d) rigid motion of clamp and field --------------------------------------------------------
def test_rotating_clamp_and_field_together_rotates_the_solution():
    case = twisted_case()
    G = 10 * B_UNIT / L * np.array([[-0.5, 0.3, 0.1], [0.3, 1.0, 0.2], [0.1, 0.2, -0.5]])
    B0 = case["B"]
    origin = np.array([0.01, -0.005, 0.003])
    Q = Rotation.from_rotvec([0.4, -1.1, 0.7]).as_matrix()
    p = np.array([0.02, -0.01, 0.005])
    common = dict(
        length=case["length"],
        stiffnesses=case["stiffnesses"],
        area=case["area"],
        magnetization=case["magnetization"],
        scales=[1.0],
    )
    plain = spatial_reference(**common, field=coils.LinearField(B0=B0, gradient=G, origin=origin))
    moved = spatial_reference(
        **common,
        field=coils.LinearField(B0=Q @ B0, gradient=Q @ G @ Q.T, origin=p + Q @ origin),
        clamp_position=p,
        clamp_rotation=Q,
    )
    s = np.linspace(0, case["length"], 201)
    a, b = evaluate(plain[0], s), evaluate(moved[0], s)
    assert np.max(np.abs(p + a["x"] @ Q.T - b["x"])) <= 1e-9 * case["length"]
    assert np.max(np.abs(Q @ a["R"] - b["R"])) <= 1e-9
    assert np.max(np.abs(a["n"] @ Q.T - b["n"])) <= 1e-9 * np.max(np.abs(a["n"]))
    assert np.max(np.abs(a["m"] @ Q.T - b["m"])) <= 1e-9 * np.max(np.abs(a["m"]))
    # the case is genuinely three-dimensional, with a force from the gradient
    assert np.max(np.abs(a["x"][:, 2])) > 1e-3 * case["length"]
    assert np.max(np.abs(a["n"])) > 0.1 * np.max(np.abs(a["m"])) / case["length"]


# -- (e) gradient fields ---------------------------------------------------------------------------
def _poly_cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _linear_beam(length, K, area, M_poly, B0, G, origin):
    """First-order response of the straight cantilever to the loads of a linear field.

    Loads on the undeformed rod (x = s e1, R = I) with M_body a polynomial in s:
    tau(t) = A M(t) x B(t e1), f(t) = A G^T M(t); internal moment
    m(s) = int_s^L [tau(t) + (t - s) e1 x f(t)] dt; rotation psi(s) = int_0^s K^-1 m;
    deflection u(L) = int_0^L psi x e1 ds; force n(0) = int_0^L f.  Exact polynomial calculus.

    Returns
    -------
    u_tip : ndarray (3,) m, psi_tip : ndarray (3,) rad, n0 : ndarray (3,) N, m0 : ndarray (3,) N m
    """
    s = Polynomial([0.0, 1.0])
    Bs = [B0[i] - G[i] @ origin + G[i, 0] * s for i in range(3)]
    tau = [area * c for c in _poly_cross(M_poly, Bs)]
    f = [area * sum(G[i, j] * M_poly[i] for i in range(3)) for j in range(3)]
    zero = Polynomial([0.0])
    e1 = [Polynomial([1.0]), zero, zero]
    # int_s^L (t - s) g(t) dt = [T1(L) - T1(s)] - s [T0(L) - T0(s)], T1 = int t g, T0 = int g
    lever = []
    for fj in f:
        T1, T0 = (s * fj).integ(), fj.integ()
        lever.append((T1(length) - T1) - s * (T0(length) - T0))
    e1xf = _poly_cross(e1, lever)
    m = [(c.integ()(length) - c.integ()) + e for c, e in zip(tau, e1xf, strict=True)]
    psi = [(m[i] / K[i]).integ() for i in range(3)]
    u = [c.integ()(length) for c in _poly_cross(psi, e1)]
    n0 = [fj.integ()(length) for fj in f]
    return (
        np.array(u),
        np.array([p(length) for p in psi]),
        np.array(n0),
        np.array([c(0.0) for c in m]),
    )


def test_gradient_field_small_load_matches_linear_beam():
    """Central difference of the tip at scale +-eps against the exact first-order response."""
    K = np.array([0.6 * EI, 4 * EI, EI])
    M_poly = [
        Polynomial([M0, 0.0, -0.3 * M0 / L**2]),
        Polynomial([0.2 * M0, 0.5 * M0 / L]),
        Polynomial([-0.1 * M0, 0.0, 0.4 * M0 / L**2]),
    ]

    def magnetization(s):
        return np.column_stack([p(np.asarray(s, dtype=float)) for p in M_poly])

    G = 3 * B_UNIT / L * np.array([[-0.5, 0.3, 0.1], [0.3, 1.0, 0.2], [0.1, 0.2, -0.5]])
    B0 = B_UNIT * np.array([0.2, 1.0, -0.4])
    origin = np.array([0.01, -0.005, 0.003])
    field = coils.LinearField(B0=B0, gradient=G, origin=origin)
    eps = 1e-4
    res = spatial_reference(L, K, AREA, magnetization, field, [eps, -eps])
    u, psi, n0, m0 = _linear_beam(L, K, AREA, M_poly, B0, G, origin)
    du = (res[0]["tip"] - res[1]["tip"]) / (2 * eps)
    assert np.max(np.abs(du - u)) <= 1e-7 * np.max(np.abs(u))
    dR = (res[0]["R"][-1] - res[1]["R"][-1]) / (2 * eps)
    skew = np.array([dR[2, 1], dR[0, 2], dR[1, 0]])
    assert np.max(np.abs(skew - psi)) <= 1e-7 * np.max(np.abs(psi))
    dn = (res[0]["n"][0] - res[1]["n"][0]) / (2 * eps)
    dm = (res[0]["m"][0] - res[1]["m"][0]) / (2 * eps)
    assert np.max(np.abs(dn - n0)) <= 1e-7 * np.max(np.abs(n0))
    assert np.max(np.abs(dm - m0)) <= 1e-7 * np.max(np.abs(m0))
    # all three components respond: the check is not degenerate
    assert np.min(np.abs(u[1:])) > 1e-3 * np.max(np.abs(u))


def _gradient_problem():
    K = (0.6 * EI, 4 * EI, EI)

    def magnetization(s):
        t = np.asarray(s, dtype=float) / L
        theta, psi = 0.5 * math.pi * t, 0.3 * np.sin(math.pi * t)
        return M0 * np.column_stack(
            [np.cos(theta) * np.cos(psi), np.sin(theta) * np.cos(psi), np.sin(psi)]
        )

    G = 10 * B_UNIT / L * np.array([[-0.5, 0.3, 0.1], [0.3, 1.0, 0.2], [0.1, 0.2, -0.5]])
    field = coils.LinearField(B0=B_UNIT * np.array([0.5, 2.0, 1.0]), gradient=G, origin=(0, 0, 0))
    return K, magnetization, field


def test_gradient_field_large_load_converges_in_tol_and_balances():
    K, magnetization, field = _gradient_problem()
    x0 = np.array([0.001, -0.002, 0.0005])
    coarse = spatial_reference(L, K, AREA, magnetization, field, [1.0], tol=1e-8, clamp_position=x0)
    fine = spatial_reference(L, K, AREA, magnetization, field, [1.0], tol=1e-11, clamp_position=x0)
    s = np.linspace(0, L, 101)
    a, b = evaluate(coarse[0], s), evaluate(fine[0], s)
    assert np.max(np.abs(a["x"] - b["x"])) <= 1e-8 * L
    # a large deflection, with a gradient force comparable to the torque
    assert np.linalg.norm(fine[0]["tip"] - x0 - [L, 0, 0]) > 0.3 * L
    force, moment = balance(fine[0], AREA, magnetization, field, x0)
    assert np.linalg.norm(force) > 0.5 * np.linalg.norm(moment) / L
    assert np.linalg.norm(fine[0]["n"][0] - force) <= 1e-8 * np.linalg.norm(force)
    assert np.linalg.norm(fine[0]["m"][0] - moment) <= 1e-8 * np.linalg.norm(moment)


def test_real_coil_field_balances_and_converges():
    """A Helmholtz pair (y) with a Maxwell pair (x) off centre: Biot-Savart fields, gradients
    varying along the rod."""
    system = coils.HelmholtzPair(0.05, 200, 1.0, axis="y") + coils.MaxwellPair(
        0.05, 200, 1.0, axis="x", center=(0.03, 0.01, -0.01)
    )
    K, magnetization, _ = _gradient_problem()
    b_centre = np.linalg.norm(system.B(np.zeros((1, 3)))[0])
    scale = 3 * B_UNIT / b_centre
    res = spatial_reference(
        L, K, AREA, magnetization, system, [scale], tol=1e-9, estimate_error=True
    )[0]
    assert res["error_tol"] == pytest.approx(1e-10)
    assert res["tip_error"] <= 1e-10 * L
    assert res["max_error"] <= 1e-10 * L
    force, moment = balance(res, AREA, magnetization, system)
    assert np.linalg.norm(res["n"][0] - force) <= 1e-8 * np.linalg.norm(force)
    assert np.linalg.norm(res["m"][0] - moment) <= 1e-8 * np.linalg.norm(moment)


# -- the twisted benchmark ----------------------------------------------------------------------
def test_twisted_case_converged_tip():
    case = twisted_case()
    kw = {k: case[k] for k in ("length", "stiffnesses", "area", "magnetization", "field")}
    length = case["length"]
    tips = {}
    for tol in (1e-8, 1e-10, 1e-11):
        res = spatial_reference(**kw, scales=[1.0], tol=tol)[0]
        tips[tol] = res["tip"]
        if tol == 1e-10:
            print(f"\ntwisted case tip at tol 1e-10 (m): {res['tip'].tolist()!r}")
            print(f"tip frame R(L): {res['R'][-1].tolist()!r}")
            frame = res["R"][-1]
            force, moment = balance(res, kw["area"], kw["magnetization"], kw["field"])
            assert np.linalg.norm(res["m"][0] - moment) <= 1e-9 * np.linalg.norm(moment)
            assert np.max(np.abs(res["n"])) == 0.0  # uniform field: no force at all
    assert np.max(np.abs(tips[1e-10] - tips[1e-11])) <= 1e-10 * length
    assert np.max(np.abs(tips[1e-8] - tips[1e-11])) <= 1e-8 * length
    assert np.max(np.abs(tips[1e-10] - TWISTED_TIP)) <= 1e-10 * length
    assert np.max(np.abs(frame - TWISTED_TIP_FRAME)) <= 1e-10
    # genuinely 3D and twisted: out of plane, and the tip normal leaves the x-y plane
    assert abs(TWISTED_TIP[2]) > 0.03 * length
    assert abs(TWISTED_TIP_FRAME[2, 1]) > 0.1
