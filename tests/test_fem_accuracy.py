"""FEM accuracy at its real discretisation error, against references independent of its code.

* Small loads with nu = 0 (no Poisson coupling, hence no boundary layer at the clamp): the
  continuum's tip deflection is Euler-Bernoulli's ``lambda L / 3`` (M axial, B perpendicular)
  plus Timoshenko's shear deflection with Cowper's (1966) shear coefficient -- the magnetic
  load of a uniform field is a uniform shear traction on the end face, so the elastic body
  sees an end-loaded cantilever.  Every (section, dim, order) the API accepts, on three
  meshes: the error falls under refinement, to below 1e-4 of the deflection for quadratic
  elements in 3D (a 1 % error in the magnetic load fails 100 times over).  The O-grid
  circle's discrete section (quadratic arcs, or the polygon of the linear mesh) has its area
  and second moment computed by hand from its boundary.
* Out of the plane (3D box, nu = 0): M along the binormal (elevation pi/2) in a field along
  the tangent bends the beam in the x-z plane toward -z (torque m x B = |M| B e_y), by a
  distributed couple instead of an end shear: beam theory with the shear of the uniform couple
  state, and exactly (on any mesh) the in-plane case minus a uniform shear.
* The clamp layer in 3D (nu = 0.4995, nearly incompressible): the fully clamped face stops
  the section's lateral contraction, which stiffens the body over a length of about its
  thickness -- an O(h/L) effect, about -1 % of the deflection at L/h = 20.  A mesh
  convergence study at two slendernesses asserts the observed rate, extrapolates each to the
  mesh-converged limit and shows that the limit's gap to the rod (shear removed) halves with
  h/L and extrapolates to zero: the rod is the slender limit of the continuum.  A 2 % load
  error would leave a 2 % gap at h/L -> 0.
"""

from __future__ import annotations

import numpy as np
import pytest
from skfem import Basis, ElementHex1, ElementHex2

import coilrod
import coils
from coilrod import presets
from coilrod.fem.mesh import box_mesh, equivalent_height

L = 0.04
LAM = 1e-3  # linear regime: geometric non-linearity ~ LAM^2


def _cowper(section, nu: float) -> float:
    """Cowper's (1966) shear coefficient of a rectangle or a circle."""
    if isinstance(section, coilrod.Circle):
        return 6 * (1 + nu) / (7 + 6 * nu)
    return 10 * (1 + nu) / (12 + 11 * nu)


def _timoshenko_ratio(section, nu: float, area: float, second_moment: float) -> float:
    """Shear over bending deflection of an end-loaded cantilever, 3 E I / (kappa G A L^2)."""
    E_over_G = 2 * (1 + nu)
    return 3 * E_over_G * second_moment / (_cowper(section, nu) * area * L**2)


def _deflection_ratio(rod, nu, dim, elements, order=2, mesh=None):
    """Tip deflection over ``LAM L / 3`` (``LAM`` from the rod's nominal A and I)."""
    field = coils.UniformField((0.0, rod.field_for_lambda(1.0), 0.0))
    res = coilrod.solve_fem(
        rod, field, [LAM], dim=dim, order=order, elements=elements, poisson_ratio=nu, mesh=mesh
    )
    return res.tip[0, 1] / (LAM * L / 3), res


def _ogrid_section(radius: float, core: int, quadratic: bool) -> tuple[float, float]:
    """Area (m^2) and second moment about z (m^4) of the O-grid's section, from its boundary
    alone: ``4 core`` vertices on the circle at -45 deg + k 90 deg / core, joined by straight
    edges (linear mesh) or by the quadratic (Lagrange) arcs through the edge midpoints moved
    radially onto the circle (quadratic mesh).  Green's theorem, ``A = oint y dz`` and
    ``I = oint y^3 / 3 dz``, with Gauss-Legendre rules exact for the polynomial integrands."""
    n = 4 * core
    theta = np.radians(-45.0 + 90.0 / core * np.arange(n + 1))
    t, w = np.polynomial.legendre.leggauss(4)
    t, w = (t + 1) / 2, w / 2
    area = second = 0.0
    for k in range(n):
        a, b = radius * np.array([[np.cos(theta[j]), np.sin(theta[j])] for j in (k, k + 1)])
        if quadratic:
            mid = 0.5 * (theta[k] + theta[k + 1])
            m = radius * np.array([np.cos(mid), np.sin(mid)])
            pts = np.outer((1 - t) * (1 - 2 * t), a) + np.outer(4 * t * (1 - t), m)
            pts += np.outer(t * (2 * t - 1), b)
            d = np.outer(4 * t - 3, a) + np.outer(4 - 8 * t, m) + np.outer(4 * t - 1, b)
        else:
            pts, d = np.outer(1 - t, a) + np.outer(t, b), np.tile(b - a, (t.size, 1))
        area += np.sum(w * pts[:, 0] * d[:, 1])
        second += np.sum(w * pts[:, 0] ** 3 / 3 * d[:, 1])
    return area, second


def test_ogrid_section_by_hand():
    """The hand geometry above against closed forms: the polygon's area n R^2 sin(2 pi/n) / 2
    and second moment n R^4 sin(2 pi / n) (2 + cos(2 pi / n)) / 24, and the quadratic arcs'
    area, that of the polygon plus n parabolic segments (2/3 chord x sagitta, Archimedes)."""
    R = 1.3e-3
    for core in (1, 2, 3):
        n, a = 4 * core, 2 * np.pi / (4 * core)
        A1, I1 = _ogrid_section(R, core, False)
        assert A1 == pytest.approx(n * R**2 * np.sin(a) / 2, rel=1e-13)
        assert I1 == pytest.approx(n * R**4 * np.sin(a) * (2 + np.cos(a)) / 24, rel=1e-13)
        A2, _ = _ogrid_section(R, core, True)
        segment = 2 / 3 * (2 * R * np.sin(a / 2)) * (R * (1 - np.cos(a / 2)))
        assert A2 == pytest.approx(A1 + n * segment, rel=1e-13)


def _section_of_mesh(rod, dim: int, order: int, elements) -> tuple[float, float]:
    """Area and second moment (about z; in 2D per unit width) of the section the mesh has,
    by hand (not from the mesh), and the mesh's own quadrature of them must agree."""
    sec = rod.section
    if dim == 2:
        h = equivalent_height(sec)
        return h, h**3 / 12
    if isinstance(sec, coilrod.Circle):
        return _ogrid_section(sec.diameter / 2, elements[1], order == 2)
    return sec.area, sec.second_moment


# (section, dim, order, meshes from coarse to fine, largest error on the finest)
CONVERGENCE = [
    (coilrod.Rectangle(L / 20, L / 20), 2, 1, [(10, 1), (20, 1), (40, 1)], 0.15),
    (coilrod.Rectangle(L / 20, L / 20), 2, 2, [(5, 1), (10, 1), (20, 1)], 1e-3),
    (coilrod.Circle(L / 20), 2, 1, [(10, 1), (20, 1), (40, 1)], 0.15),
    (coilrod.Circle(L / 20), 2, 2, [(5, 1), (10, 1), (20, 1)], 1e-3),
    (coilrod.Rectangle(L / 20, L / 20), 3, 1, [(10, 1, 1), (20, 2, 2), (40, 4, 4)], 0.15),
    (coilrod.Rectangle(L / 20, L / 20), 3, 2, [(5, 1, 1), (10, 1, 1), (20, 1, 1)], 1e-4),
    (coilrod.Circle(L / 20), 3, 1, [(10, 2, 1), (20, 2, 2), (40, 2, 4)], 0.15),
    (coilrod.Circle(L / 20), 3, 2, [(5, 2, 1), (10, 2, 1), (20, 2, 1)], 1e-4),
]


@pytest.mark.parametrize(("section", "dim", "order", "meshes", "finest"), CONVERGENCE)
def test_small_load_converges_to_beam_theory_with_shear(section, dim, order, meshes, finest):
    """Every (section, dim, order) solve_fem accepts, nu = 0 (no clamp layer): the tip over
    ``LAM L / 3`` tends to Euler-Bernoulli with the section's own A and I (by hand:
    ``_section_of_mesh``) plus Timoshenko's shear, the error falling under refinement (linear
    elements lock in bending: slowly).  Linear elements on the quadratic O-grid (issue 23) gave
    0.095, 0.099, 0.100 at 20, 40, 160 elements."""
    rod = coilrod.Rod(L, 1e6, section, presets.M1())
    errors = []
    for elements in meshes:
        ratio, res = _deflection_ratio(rod, 0.0, dim, elements, order)
        A_h, I_h = _section_of_mesh(rod, dim, order, elements)
        if dim == 3:  # the mesh's own quadrature of its section agrees with the hand geometry
            elem = ElementHex2() if order == 2 else ElementHex1()
            basis = Basis(res.mesh, elem, intorder=7)
            y = basis.global_coordinates()[1]
            assert basis.dx.sum() / L == pytest.approx(A_h, rel=1e-12)
            assert (basis.dx * y**2).sum() / L == pytest.approx(I_h, rel=1e-12)
            A, I = rod.area, section.second_moment
        else:
            A, I = equivalent_height(section), equivalent_height(section) ** 3 / 12
        # the load M B A_h over the stiffness E I_h, over the nominal lambda's M B A / (E I)
        expected = (A_h / A) / (I_h / I) * (1 + _timoshenko_ratio(section, 0.0, A_h, I_h))
        errors.append(abs(ratio / expected - 1))
        assert abs(res.tip[0, 0] - L) < 1e-5 * L  # shortening is second order
    assert all(b < a / 1.5 for a, b in zip(errors[:-1], errors[1:], strict=True)), errors
    assert errors[-1] < finest, errors


def test_shear_is_resolved():
    """The Timoshenko term in the references above is larger than their tolerance."""
    section = coilrod.Rectangle(L / 20, L / 20)
    assert _timoshenko_ratio(section, 0.0, section.area, section.second_moment) > 1e-3


def _clamp_gap(thickness_ratio: int):
    """Richardson-extrapolated gap of the 3D continuum (nu = 0.4995) to ``LAM L / 3`` with
    elements 2h, h and h/2 long (2 x 2 across the section), and the observed order."""
    h = L / thickness_ratio
    rod = coilrod.Rod(L, 1e6, coilrod.Rectangle(h, h), presets.M1())
    n0 = thickness_ratio // 2
    # uniform layers (no clamp grading, which would break the halving of h)
    meshes = [box_mesh(L, h, h, n, 2, 2) for n in (n0, 2 * n0, 4 * n0)]
    t = [_deflection_ratio(rod, 0.4995, 3, None, mesh=m)[0] for m in meshes]
    p = np.log2((t[1] - t[0]) / (t[2] - t[1]))
    limit = t[2] + (t[2] - t[1]) / (2**p - 1)
    shear = _timoshenko_ratio(rod.section, 0.4995, rod.area, rod.section.second_moment)
    return limit - 1 - shear, p, t


# uniform meshes on purpose (the coarsest, 2 sections long, gets the ungraded clamp's warning)
@pytest.mark.filterwarnings("ignore:mesh. an element:coilrod.StabilityWarning")
def test_clamp_layer_is_order_h_over_L_and_vanishes_in_the_rod_limit():
    gap20, p20, t20 = _clamp_gap(20)
    gap40, p40, t40 = _clamp_gap(40)
    # monotone convergence at a rate below the smooth 4 (tests/test_fem_mesh.py): the clamped
    # edge of a nearly incompressible body is a stress singularity
    for p, t in ((p20, t20), (p40, t40)):
        assert t[0] < t[1] < t[2]
        assert 1.2 < p < 2.0, p
    # about -1 % at L/h = 20: the continuum is stiffer than the rod ...
    assert -0.013 < gap20 < -0.007, gap20
    # ... by a boundary layer of the clamp: O(h/L), halved at L/h = 40 ...
    assert 1.7 < gap20 / gap40 < 2.3, (gap20, gap40)
    # ... so the continuum tends to the rod as h/L -> 0 (linear extrapolation in h/L)
    assert abs(2 * gap40 - gap20) < 1.5e-3, (gap20, gap40)


def test_out_of_plane_magnetization_bends_in_the_x_z_plane():
    """M = |M| e_z (elevation pi/2) in B = B e_x.  Torque per volume m x B = |M| B e_y: a
    rotation about +y, which turns the tip toward -z.  The magnetic stress -B (x) M loads the
    faces z = +-h/2 with the tractions B (M . n) = +-|M| B e_x: a couple |M| B A per length, no
    end shear.  With nu = 0 this is exactly (i) the uniform shear sigma_xz = |M| B, affine,
    u_z = |M| B x / G, plus (ii) the cantilever with the end force -|M| B A e_z (the end shear
    of the test above), so tip_z / (lambda L / 3) = -(1 + s / kappa) + s, s = 3 E I / (G A L^2),
    kappa Cowper's: (ii) at its discretisation error, and the sum with the in-plane case
    (M axial, B along y) equal to s to round-off on the same mesh.  The FEM sensitivity to B_x
    of this linear response is tip_z / B_x; magnitudes and angles of a non-planar
    magnetization are refused."""
    import math

    section = coilrod.Rectangle(L / 20, L / 20)
    lifted = coilrod.Rod(L, 1e6, section, coilrod.Magnetization(128e3, 0.0, math.pi / 2))
    b = lifted.field_for_lambda(1.0)
    res = coilrod.solve_fem(
        lifted,
        coils.UniformField((b, 0.0, 0.0)),
        [LAM],
        dim=3,
        elements=(20, 1, 1),
        poisson_ratio=0.0,
    )
    ratio = res.tip[0] / (LAM * L / 3)
    A, I = lifted.area, section.second_moment_y
    s = 3 * 2 * I / (A * L**2)  # E / G = 2 (1 + nu) = 2
    kappa = _cowper(section, 0.0)
    assert ratio[2] == pytest.approx(-(1 + s / kappa) + s, rel=1e-4)
    assert ratio[2] < -0.99  # toward -z, the size of lambda L / 3
    assert abs(ratio[1]) < 1e-12  # no in-plane deflection
    # the in-plane case on the same mesh differs by the uniform shear state only
    in_plane, _ = _deflection_ratio(coilrod.Rod(L, 1e6, section, presets.M1()), 0.0, 3, (20, 1, 1))
    assert in_plane + ratio[2] == pytest.approx(s, abs=1e-8)
    # FEM sensitivities: the response is linear in B_x; planar groups are refused
    d = coilrod.sensitivities(res, 0, wrt="B")
    assert d.tip[0, 2] == pytest.approx(res.tip[0, 2] / b, rel=1e-5)  # at scale LAM
    assert "angles" not in coilrod.sensitivities(res, 0).groups
    with pytest.raises(ValueError, match="out-of-plane elevation"):
        coilrod.sensitivities(res, 0, wrt=["scale", "angles"])
