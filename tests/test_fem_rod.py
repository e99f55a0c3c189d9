"""FEM against the hard-magnetic elastica (seed eq. 5), the seed's configurations.

The reference is an independent solve of the planar Kirchhoff rod equation of DESIGN.md,

    EI theta'' + A t_z - A sin(theta) int_s^L f_x + A cos(theta) int_s^L f_y = 0,
    theta(0) = 0, theta'(L) = 0,

written as a first-order system (theta, theta', x, y, the two force integrals) and solved by
``scipy.integrate.solve_bvp`` at tolerance 1e-7 with continuation in the load; the field is
evaluated on the deformed centreline.  Robot: L = 40 mm, L/D = 20 (seed), E = 1 MPa.

* Config (A), uniform B along y, M(1), M(2a), M(2b): tip within 1 % of L up to lambda = 10,
  2D (plane stress) and 3D (box and, slow, the circular seed section), order 2.
* Config (B), B0 along y plus the Maxwell gradient g diag(-1/2, 1, -1/2), M(3): within 2 %.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_bvp

import coilrod
import coils
from coilrod import presets

L = presets.SEED_LENGTH
D = L / 20
LAMBDAS = np.linspace(1.0, 10.0, 10)


def elastica_tips(rod, field, scales, n=201, tol=1e-7, substeps=4):
    """Tip positions (k, 2), m, of the planar Kirchhoff rod at each field scale."""
    EI, A = rod.bending_stiffness, rod.area
    mag = rod.magnetization
    x = np.linspace(0.0, rod.length, n)
    y = np.zeros((6, n))
    y[2] = x
    tips, prev, sol = [], 0.0, None
    for target in scales:
        for sc in np.linspace(prev, target, substeps + 1)[1:]:

            def rhs(s, Y, sc=sc):
                th, ka, px, py, Fx, Fy = Y
                a = th + mag.angle(s)
                mm = mag.magnitude(s)
                m = np.stack([mm * np.cos(a), mm * np.sin(a), 0 * s], 1)
                pts = np.stack([px, py, 0 * s], 1)
                B, G = sc * field.B(pts), sc * field.gradient(pts)
                tz = m[:, 0] * B[:, 1] - m[:, 1] * B[:, 0]
                f = np.einsum("nik,ni->nk", G, m)  # f = G^T m
                return np.vstack(
                    [
                        ka,
                        -(A * tz - np.sin(th) * Fx + np.cos(th) * Fy) / EI,
                        np.cos(th),
                        np.sin(th),
                        -A * f[:, 0],
                        -A * f[:, 1],
                    ]
                )

            def bc(ya, yb):
                return np.array([ya[0], ya[2], ya[3], yb[1], yb[4], yb[5]])

            sol = solve_bvp(rhs, bc, x, y, tol=tol, max_nodes=100000)
            assert sol.success, sol.message
            x, y = sol.x, sol.y
        prev = target
        tips.append(sol.sol(rod.length)[2:4])
    return np.array(tips)


def _tip_error(res, ref):
    return np.linalg.norm(res.tip[:, :2] - ref, axis=1) / L


MAGNETIZATIONS = {
    "M1": presets.M1(),
    "M2a": presets.M2(variant="a"),
    "M2b": presets.M2(variant="b"),
}


@pytest.mark.parametrize("name", list(MAGNETIZATIONS))
@pytest.mark.parametrize(("dim", "elements"), [(2, (20, 1)), (3, (20, 1, 1))])
def test_config_A_matches_elastica(name, dim, elements):
    rod = coilrod.Rod(L, 1e6, coilrod.Rectangle(D, D), MAGNETIZATIONS[name])
    field = coils.UniformField((0.0, rod.field_for_lambda(1.0), 0.0))
    ref = elastica_tips(rod, field, LAMBDAS)
    res = coilrod.solve_fem(rod, field, LAMBDAS, dim=dim, order=2, elements=elements)
    assert res.converged.all()
    err = _tip_error(res, ref)
    assert err.max() < 0.01, err
    # not a trivial comparison: the tip moves by more than a tenth of the length
    assert np.linalg.norm(ref - [L, 0.0], axis=1).max() > 0.1 * L


@pytest.mark.slow
def test_config_A_seed_circle_3d():
    """The seed robot itself: circular section (O-grid, quadratic geometry), M(1)."""
    rod = presets.seed_rod(presets.M1())
    field = coils.UniformField((0.0, rod.field_for_lambda(1.0), 0.0))
    lams = np.array([2.5, 5.0, 7.5, 10.0])
    ref = elastica_tips(rod, field, lams)
    res = coilrod.solve_fem(rod, field, lams, dim=3, elements=(10, 2, 1))
    assert _tip_error(res, ref).max() < 0.01


@pytest.mark.parametrize(("dim", "elements"), [(2, (20, 1)), (3, (20, 1, 1))])
def test_config_B_M3_matches_elastica(dim, elements):
    rod = coilrod.Rod(L, 1e6, coilrod.Rectangle(D, D), presets.M3())
    b = rod.field_for_lambda(5.0)
    g = 5.0 * rod.bending_stiffness / (rod.magnetization.max_magnitude(L) * rod.area * L**3)
    field = coils.LinearField((0.0, b, 0.0), coils.maxwell_gradient(g), (0.0, 0.0, 0.0))
    scales = np.linspace(0.2, 1.0, 5)
    ref = elastica_tips(rod, field, scales)
    res = coilrod.solve_fem(rod, field, scales, dim=dim, elements=elements)
    assert _tip_error(res, ref).max() < 0.02


def test_config_A_M1_closed_form_elastica():
    """Second, closed-form reference for M(1): coilrod.elastica (elliptic integrals)."""
    from coilrod.rod.elastica import elastica

    rod = coilrod.Rod(L, 1e6, coilrod.Rectangle(D, D), presets.M1())
    field = coils.UniformField((0.0, rod.field_for_lambda(1.0), 0.0))
    lams = [2.0, 6.0, 10.0]
    ref = np.array([elastica(lam, np.pi / 2, length=L).tip[:2] for lam in lams])
    res = coilrod.solve_fem(rod, field, lams, dim=2, elements=(20, 1))
    assert _tip_error(res, ref).max() < 0.01


def test_small_load_linear_beam_theory():
    """lambda -> 0: tip deflection lambda/3 L (uniform distributed couple, cantilever)."""
    rod = coilrod.Rod(L, 1e6, coilrod.Rectangle(D, D), presets.M1())
    field = coils.UniformField((0.0, rod.field_for_lambda(1.0), 0.0))
    res = coilrod.solve_fem(rod, field, [1e-3], dim=2, elements=(20, 2))
    # Timoshenko correction of a plane-stress strip is O((h/L)^2) = 0.25 %
    assert res.tip[0, 1] / L == pytest.approx(1e-3 / 3, rel=5e-3)


def test_mesh_and_order_convergence():
    """Tip error against the elastica falls with refinement and with the element order.

    Linear elements lock in bending (shear locking); quadratic ones converge fast.  The rate
    asserted for the quadratic 2D strip between 5 and 10 elements along the rod is >= 2 (the
    remaining gap to the 1D rod model is the O((h/L)^2) continuum effect, far below).
    """
    rod = coilrod.Rod(L, 1e6, coilrod.Rectangle(D, D), presets.M1())
    field = coils.UniformField((0.0, rod.field_for_lambda(1.0), 0.0))
    lam = [2.0]
    ref = elastica_tips(rod, field, lam)
    err = {}
    for order, n in [(1, 10), (1, 40), (2, 5), (2, 10)]:
        res = coilrod.solve_fem(rod, field, lam, dim=2, order=order, elements=(n, 1))
        err[order, n] = _tip_error(res, ref)[0]
    assert err[1, 40] < 0.5 * err[1, 10]  # linear: converging but slowly
    assert err[2, 10] < err[1, 40]  # quadratic with 4x fewer elements beats linear
    assert np.log2(err[2, 5] / err[2, 10]) > 2.0


def test_real_coil_field_matches_rod_solver():
    """Real (Biot-Savart) Helmholtz + Maxwell pairs, off-centre rod: the FEM strip against
    coilrod.solve_rod (an independent discretisation of the same rod equation)."""
    rod = coilrod.Rod(L, 1e6, coilrod.Rectangle(D, D), presets.M3())
    field = coils.HelmholtzPair(0.06, 300, 1.0, axis="y") + coils.MaxwellPair(
        0.06, 300, 1.0, axis="y", center=(0.02, 0.0, 0.0)
    )
    # scale the currents to lambda ~ 4 at the centre field
    unit = rod.field_for_lambda(1.0) / np.linalg.norm(field.B([[0.0, 0.0, 0.0]]))
    scales = unit * np.array([1.0, 2.0, 4.0])
    ref = coilrod.solve_rod(rod, field, scales).tip[:, :2]
    res = coilrod.solve_fem(rod, field, scales, dim=2, elements=(20, 1))
    assert _tip_error(res, ref).max() < 0.01
    assert np.linalg.norm(ref[-1] - [L, 0.0]) > 0.1 * L
