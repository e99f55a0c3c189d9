"""FEM accuracy at its real discretisation error, against references independent of its code.

* Small loads with nu = 0 (no Poisson coupling, hence no boundary layer at the clamp): the
  continuum's tip deflection is Euler-Bernoulli's ``lambda L / 3`` (M axial, B perpendicular)
  plus Timoshenko's shear deflection with Cowper's (1966) shear coefficient -- the magnetic
  load of a uniform field is a uniform shear traction on the end face, so the elastic body
  sees an end-loaded cantilever.  2D strip, 3D box and 3D O-grid circle (whose discrete
  section's area and second moment are integrated here); tolerance 1e-4 of the deflection,
  so a 1 % error in the magnetic load fails 100 times over.
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
from skfem import Basis, ElementHex2

import coilrod
import coils
from coilrod import presets

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


def _deflection_ratio(rod, nu, dim, elements):
    """Tip deflection over ``LAM L / 3`` (``LAM`` from the rod's nominal A and I)."""
    field = coils.UniformField((0.0, rod.field_for_lambda(1.0), 0.0))
    res = coilrod.solve_fem(rod, field, [LAM], dim=dim, elements=elements, poisson_ratio=nu)
    return res.tip[0, 1] / (LAM * L / 3), res


@pytest.mark.parametrize(
    ("dim", "section", "elements"),
    [
        (2, coilrod.Rectangle(L / 20, L / 20), (40, 2)),
        (3, coilrod.Rectangle(L / 20, L / 20), (20, 1, 1)),
        (3, coilrod.Circle(L / 20), (20, 2, 1)),  # the default O-grid
    ],
)
def test_small_load_matches_beam_theory_with_shear(dim, section, elements):
    rod = coilrod.Rod(L, 1e6, section, presets.M1())
    ratio, res = _deflection_ratio(rod, 0.0, dim, elements)
    A, I = rod.area, rod.section.second_moment
    lam_ratio = 1.0  # the mesh's lambda over the nominal one
    if isinstance(section, coilrod.Circle):
        # the O-grid's section (quadratic arcs) is a little smaller than the circle:
        # integrate its area and second moment over the mesh, 4 x 4 x 4 points per element
        basis = Basis(res.mesh, ElementHex2(), intorder=7)
        y = basis.global_coordinates()[1]
        A_h, I_h = basis.dx.sum() / L, (basis.dx * y**2).sum() / L
        assert A_h / A - 1 == pytest.approx(-7.8e-4, abs=1e-4)  # what the docstring says
        lam_ratio = (A_h / A) / (I_h / I)
        A, I = A_h, I_h
    expected = lam_ratio * (1 + _timoshenko_ratio(section, 0.0, A, I))
    assert ratio == pytest.approx(expected, rel=1e-4), (ratio, expected)
    assert expected - 1 > 1e-3  # the shear term is resolved, not below the tolerance
    assert abs(res.tip[0, 0] - L) < 1e-5 * L  # shortening is second order


def _clamp_gap(thickness_ratio: int):
    """Richardson-extrapolated gap of the 3D continuum (nu = 0.4995) to ``LAM L / 3`` with
    elements 2h, h and h/2 long (2 x 2 across the section), and the observed order."""
    h = L / thickness_ratio
    rod = coilrod.Rod(L, 1e6, coilrod.Rectangle(h, h), presets.M1())
    n0 = thickness_ratio // 2
    t = [_deflection_ratio(rod, 0.4995, 3, (n, 2, 2))[0] for n in (n0, 2 * n0, 4 * n0)]
    p = np.log2((t[1] - t[0]) / (t[2] - t[1]))
    limit = t[2] + (t[2] - t[1]) / (2**p - 1)
    shear = _timoshenko_ratio(rod.section, 0.4995, rod.area, rod.section.second_moment)
    return limit - 1 - shear, p, t


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
