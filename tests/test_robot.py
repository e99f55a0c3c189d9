"""The robot description for the spatial rod: sections, elastic moduli and the 3D
magnetization, each checked against a reference independent of the code.

* sections: second moments by direct integration of y^2 and z^2 over the section; the
  Saint-Venant torsion constant against Timoshenko & Goodier's table (Theory of Elasticity,
  3rd ed., section 109: J = k1 a b^3), Roark's thin-strip formula, a finite-difference solve of
  Prandtl's stress function (Richardson-extrapolated) and two theorems: the perpendicular-axis
  theorem for the circle (J = I_y + I_z) and Saint-Venant's J < I_y + I_z for a warping section;
* rod: G = E / (2 (1 + nu)) at the textbook values of nu, GJ / EI = 1 / (1 + nu) for a circle,
  and nu validated on the open/closed ends of (-1, 0.5];
* magnetization: the body vector against spherical coordinates built from rotation matrices,
  |M| preserved, elevation 0 reproducing the planar vector bit for bit, segments, validation;
* node magnetization in 3D: trapezoid weights times node values integrate a profile with a jump
  (and a linear one) exactly, against the integral of the profile by hand;
* planar-only consumers refuse an out-of-plane magnetization instead of dropping it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import coilrod
import coils
from coilrod import Circle, Magnetization, Rectangle, Rod, presets
from coilrod.rod.mesh import RodMesh, node_magnetization

# -- sections: second moments -------------------------------------------------------------------


def _gauss_moments(width: float, thickness: float) -> tuple[float, float]:
    """(int z^2 dA, int y^2 dA) over [-t/2, t/2] x [-w/2, w/2] by 3-point Gauss (exact)."""
    x, w = np.polynomial.legendre.leggauss(3)
    y, z = thickness / 2 * x, width / 2 * x
    wy, wz = thickness / 2 * w, width / 2 * w
    Iy = float(np.sum(wy[:, None] * wz[None, :] * z[None, :] ** 2))
    Iz = float(np.sum(wy[:, None] * wz[None, :] * y[:, None] ** 2))
    return Iy, Iz


@pytest.mark.parametrize(("width", "thickness"), [(3e-3, 2e-3), (5e-3, 0.84e-3), (1.0, 1.0)])
def test_rectangle_second_moments_are_the_integrals(width, thickness):
    sec = Rectangle(width=width, thickness=thickness)
    Iy, Iz = _gauss_moments(width, thickness)
    assert sec.second_moment_y == pytest.approx(Iy, rel=1e-13, abs=0)
    assert sec.second_moment == pytest.approx(Iz, rel=1e-13, abs=0)


def test_circle_second_moments_and_polar_moment():
    D = 2e-3
    sec = Circle(D)
    # int z^2 dA over the disk in polar coordinates: int_0^R r^3 dr int_0^2pi sin^2 = pi R^4 / 4
    r, wr = np.polynomial.legendre.leggauss(4)
    R = D / 2
    radial = np.sum(R / 2 * wr * (R / 2 * (r + 1)) ** 3)
    phi = np.linspace(0, 2 * np.pi, 64, endpoint=False)  # exact for sin^2 (trigonometric)
    Iy = radial * np.sum(np.sin(phi) ** 2) * (2 * np.pi / 64)
    assert sec.second_moment_y == pytest.approx(Iy, rel=1e-13, abs=0)
    assert sec.second_moment == pytest.approx(Iy, rel=1e-13, abs=0)
    # perpendicular-axis theorem: the circle does not warp, J is the polar moment I_y + I_z
    assert sec.torsion_constant == pytest.approx(
        sec.second_moment_y + sec.second_moment, rel=1e-15, abs=0
    )


# -- sections: the torsion constant ------------------------------------------------------------

#: Timoshenko & Goodier (1970), section 109, table: k1 of J = k1 a b^3 against a / b (3 digits).
TIMOSHENKO_K1 = {
    1.0: 0.141,
    1.2: 0.166,
    1.5: 0.196,
    2.0: 0.229,
    2.5: 0.249,
    3.0: 0.263,
    4.0: 0.281,
    5.0: 0.291,
    10.0: 0.312,
}


@pytest.mark.parametrize(("ratio", "k1"), sorted(TIMOSHENKO_K1.items()))
def test_torsion_constant_matches_timoshenko_table(ratio, k1):
    b = 1e-3
    for sec in (Rectangle(width=ratio * b, thickness=b), Rectangle(width=b, thickness=ratio * b)):
        # the table is rounded to 3 digits: half a unit of the last one
        assert sec.torsion_constant / (ratio * b * b**3) == pytest.approx(k1, abs=5e-4)


def test_torsion_constant_of_a_square_is_0_1406():
    # Roark's Formulas for Stress and Strain (7th ed.), table 10.7, case 4: K = 2.25 a^4 with a
    # the half side, i.e. 0.1406 s^4 (2.25 / 16 = 0.140625: four digits)
    s = 2e-3
    assert Rectangle(s, s).torsion_constant / s**4 == pytest.approx(0.1406, abs=5e-5)


@pytest.mark.parametrize("ratio", [10.0, 100.0, 1e4])
def test_thin_strip_limit(ratio):
    """Roark (table 10.7, case 4): J = a b^3 [1/3 - 0.21 (b/a) (1 - b^4 / (12 a^4))], whose
    0.21 is the exact strip asymptote 0.2100... b/a to its two printed digits: it differs by
    a few 1e-5 (b/a) relative."""
    a, b = ratio * 1e-4, 1e-4
    J = Rectangle(width=a, thickness=b).torsion_constant
    roark = a * b**3 * (1 / 3 - 0.21 * (b / a) * (1 - b**4 / (12 * a**4)))
    assert J == pytest.approx(roark, rel=3e-4 / ratio, abs=0)
    # and the strip tends to a b^3 / 3 from below
    assert 0 < 1 - J / (a * b**3 / 3) < 0.64 / ratio


def _prandtl_torsion_constant(a: float, b: float, n: int) -> float:
    """J = 2 int phi dA with lap(phi) = -2 in the a x b rectangle, phi = 0 on its boundary:
    second-order finite differences on a square grid of n cells across b."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    h = b / n
    nx, ny = round(a / h), n

    def second_difference(m):
        return sp.diags([1.0, -2.0, 1.0], [-1, 0, 1], shape=(m - 1, m - 1)) / h**2

    lap = sp.kron(second_difference(nx), sp.identity(ny - 1)) + sp.kron(
        sp.identity(nx - 1), second_difference(ny)
    )
    phi = spsolve(lap.tocsc(), np.full((nx - 1) * (ny - 1), -2.0))
    return 2.0 * phi.sum() * h * h


@pytest.mark.parametrize("ratio", [1.0, 2.0])
def test_torsion_constant_matches_prandtl_stress_function(ratio):
    b = 1.0
    coarse, fine = (_prandtl_torsion_constant(ratio * b, b, n) for n in (32, 64))
    extrapolated = (4 * fine - coarse) / 3  # second-order differences: error ~ h^2
    exact = Rectangle(width=ratio * b, thickness=b).torsion_constant
    assert abs(fine / exact - 1) < 1e-3  # the plain solve is close ...
    assert extrapolated == pytest.approx(exact, rel=1e-5, abs=0)  # ... and converges to the series


def test_rectangle_warps_circle_of_equal_area_is_stiffest():
    for w, t in ((2e-3, 2e-3), (5e-3, 1e-3)):
        rect = Rectangle(w, t)
        # Saint-Venant: warping makes J smaller than the polar moment I_y + I_z ...
        assert rect.torsion_constant < rect.second_moment + rect.second_moment_y
        # ... and among sections of equal area the circle has the largest J (A^2 / (2 pi))
        assert rect.torsion_constant < rect.area**2 / (2 * math.pi)


def test_torsion_constant_is_scale_consistent():
    # J scales as length^4: metres against millimetres
    assert Rectangle(5.0, 0.84).torsion_constant * 1e-12 == pytest.approx(
        Rectangle(5e-3, 0.84e-3).torsion_constant, rel=1e-14, abs=0
    )


# -- rod: elastic moduli -----------------------------------------------------------------------

ROD = presets.seed_rod()


@pytest.mark.parametrize(("nu", "G_over_E"), [(0.5, 1 / 3), (0.25, 0.4), (0.0, 0.5), (-0.5, 1.0)])
def test_shear_modulus_from_poisson_ratio(nu, G_over_E):
    rod = dataclasses.replace(ROD, poisson_ratio=nu)
    assert rod.shear_modulus / rod.youngs_modulus == pytest.approx(G_over_E, rel=1e-15)


@pytest.mark.parametrize("nu", [0.5, 0.3, 0.0])
def test_circle_twists_more_easily_than_it_bends(nu):
    # circle: GJ / EI = (E / (2 (1 + nu))) (pi D^4 / 32) / (E pi D^4 / 64) = 1 / (1 + nu)
    rod = dataclasses.replace(ROD, poisson_ratio=nu)
    GJ, EIy, EIz = rod.stiffnesses
    assert GJ == rod.torsional_stiffness
    assert GJ / EIz == pytest.approx(1 / (1 + nu), rel=1e-14, abs=0)
    assert EIy == EIz == rod.bending_stiffness


def test_stiffnesses_of_a_rectangle_are_twist_out_of_plane_in_plane():
    E, w, t, nu = 2e6, 5e-3, 1e-3, 0.25
    rod = Rod(0.02, E, Rectangle(width=w, thickness=t), presets.M1(), poisson_ratio=nu)
    GJ, EIy, EIz = rod.stiffnesses
    assert EIz == pytest.approx(E * w * t**3 / 12, rel=1e-15, abs=0) == rod.bending_stiffness
    assert EIy == pytest.approx(E * t * w**3 / 12, rel=1e-15, abs=0)
    # a flat strip (w / t = 5, Timoshenko's k1 = 0.291) twists far more easily than it bends
    # out of its plane
    assert GJ == pytest.approx(E / 2.5 * 0.291 * w * t**3, abs=5e-4 * E / 2.5 * w * t**3)


def test_default_poisson_ratio_is_incompressible_and_carried_by_replace():
    rod = Rod(0.04, 1e6, Circle(2e-3), Magnetization(128e3))
    assert rod.poisson_ratio == 0.5
    assert rod.shear_modulus == pytest.approx(1e6 / 3, rel=1e-15)
    rod = Rod(0.04, 1e6, Circle(2e-3), Magnetization(128e3), poisson_ratio=0.3)
    assert dataclasses.replace(rod, youngs_modulus=2e6).poisson_ratio == 0.3
    assert dataclasses.replace(rod, youngs_modulus=2e6).shear_modulus == pytest.approx(
        2e6 / 2.6, rel=1e-15
    )


@pytest.mark.parametrize("nu", [0.5, 0.4999, -0.999, 0, np.float32(0.25), np.array(0.1)])
def test_poisson_ratio_accepted(nu):
    rod = Rod(0.04, 1e6, Circle(2e-3), Magnetization(1e5), poisson_ratio=nu)
    assert type(rod.poisson_ratio) is float
    assert rod.poisson_ratio == float(nu)


@pytest.mark.parametrize(
    "nu", [-1.0, -1, 0.5000001, 1.0, float("nan"), float("inf"), True, "0.3", None, 1j, [0.3]]
)
def test_poisson_ratio_rejected_names_it(nu):
    with pytest.raises(ValueError, match="poisson_ratio"):
        Rod(0.04, 1e6, Circle(2e-3), Magnetization(1e5), poisson_ratio=nu)


# -- magnetization in 3D -----------------------------------------------------------------------
S = np.linspace(0.0, 0.04, 17)


def _rotation_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _rotation_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


@pytest.mark.parametrize(("angle", "elevation"), [(0.3, 0.7), (-2.0, -1.2), (1.0, math.pi / 2)])
def test_vector3_is_the_tangent_turned_by_angle_then_lifted_by_elevation(angle, elevation):
    m = Magnetization(2e5, angle, elevation)
    # e_x turned about -y by the elevation (toward +z), then about z by the angle
    expected = 2e5 * (_rotation_z(angle) @ _rotation_y(-elevation) @ np.array([1.0, 0, 0]))
    np.testing.assert_allclose(m.vector3(S), np.tile(expected, (S.size, 1)), atol=1e-10 * 2e5)
    # vector() is its projection on the bending plane
    np.testing.assert_array_equal(m.vector(S), m.vector3(S)[:, :2])
    assert not m.is_planar


def test_vector3_keeps_the_magnitude_along_profiles():
    m = Magnetization(
        lambda s: 1e5 * (1 + 10 * s), lambda s: 40 * s - 0.5, lambda s: np.sin(100 * s)
    )
    np.testing.assert_allclose(np.linalg.norm(m.vector3(S), axis=1), 1e5 * (1 + 10 * S), 1e-15)
    np.testing.assert_allclose(m.elevation(S), np.sin(100 * S), rtol=0, atol=0)
    assert not m.is_planar
    assert not m.is_constant


def test_zero_elevation_reproduces_the_planar_vector_exactly():
    for m in (presets.M1(), presets.M2(), presets.M3(), presets.M41(), presets.M42()):
        assert m.is_planar  # the seed's cases keep their planar meaning
        v3 = m.vector3(S)
        np.testing.assert_array_equal(v3[:, :2], m.vector(S))
        np.testing.assert_array_equal(v3[:, 2], 0.0)
        np.testing.assert_array_equal(m.elevation(S), 0.0)
    assert Magnetization(1e5, 0.2, 0.0).is_planar
    assert Magnetization(1e5, 0.2, -0.0).is_planar
    # a callable elevation is not looked into: it counts as out of plane
    assert not Magnetization(1e5, 0.2, lambda s: 0.0 * s).is_planar


def test_segments_with_elevations():
    lengths, mags = [0.01, 0.03], [1e5, 2e5]
    m = Magnetization.segments(lengths, mags, [0.0, 1.0], [0.5, -0.25], label="two")
    s = np.array([0.005, 0.02])
    np.testing.assert_array_equal(m.segment_elevations, [0.5, -0.25])
    np.testing.assert_array_equal(m.elevation(s), [0.5, -0.25])
    expected = np.array(
        [
            [1e5 * math.cos(0.5), 0.0, 1e5 * math.sin(0.5)],
            [
                2e5 * math.cos(1.0) * math.cos(0.25),
                2e5 * math.sin(1.0) * math.cos(0.25),
                -2e5 * math.sin(0.25),
            ],
        ]
    )
    np.testing.assert_allclose(m.vector3(s), expected, rtol=1e-15, atol=1e-10)
    assert not m.is_planar
    assert "elevations=[0.5, -0.25]" in repr(m)
    # one elevation for every segment; all zero is planar
    m = Magnetization.segments(lengths, mags, 0.0, 0.3)
    np.testing.assert_array_equal(m.segment_elevations, [0.3, 0.3])
    m = Magnetization.segments(lengths, mags)
    assert m.is_planar
    np.testing.assert_array_equal(m.segment_elevations, [0.0, 0.0])


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: Magnetization(1e5, 0.0, float("nan")), "elevation must be finite"),
        (lambda: Magnetization(1e5, 0.0, -float("inf")), "elevation must be finite"),
        (lambda: Magnetization(1e5, 0.0, "30 deg"), "elevation must be a real number"),
        (lambda: Magnetization(1e5, 0.0, True), "elevation must be a real number"),
        (
            lambda: Magnetization.segments([0.02, 0.02], [1e5, 1e5], 0.0, [0.1, np.nan]),
            "segment elevations must be finite",
        ),
        (
            lambda: Magnetization.segments([0.02, 0.02], [1e5, 1e5], 0.0, [0.1]),
            "as many magnitudes, angles and elevations as lengths",
        ),
        (
            lambda: Magnetization.segments([0.02, 0.02], [1e5, 1e5], 0.0, float("inf")),
            "segment elevation must be finite",
        ),
        (
            lambda: Magnetization(1e5, 0.0, lambda s: np.where(s > 0.01, np.nan, 0.1)).vector3(S),
            "magnetization elevation is not finite",
        ),
        (
            lambda: Magnetization(1e5, 0.0, lambda s: np.where(s > 0.01, np.inf, 0.1)).vector(S),
            "magnetization elevation is not finite",
        ),
    ],
)
def test_bad_elevation_names_it(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_breakpoints_and_label_are_keyword_only():
    # the old third positional parameter cannot be misread as an elevation
    with pytest.raises(TypeError):
        Magnetization(1e5, 0.0, 0.0, (0.01,))
    m = Magnetization(1e5, 0.0, 0.2, breakpoints=[0.01], label="lifted")
    assert m.breakpoints == (0.01,)
    assert repr(m) == "Magnetization(lifted; elevation=0.2)"
    assert repr(Magnetization(1e5, 0.5)) == "Magnetization(magnitude=100000.0, angle=0.5)"


# -- node magnetization in 3D: exact integration across jumps -----------------------------------


def test_node_magnetization_3d_integrates_a_jump_exactly():
    L, b = 0.04, 0.0137  # the jump is at an awkward fraction of L
    m = Magnetization.segments([b, L - b], [1.3e5, 0.4e5], [0.2, -1.1], [0.9, -0.4])
    mesh = RodMesh(24, np.array([b / L]))
    nodes = node_magnetization(m, mesh, L, dim=3)
    assert nodes.shape == (mesh.n, 3)
    integral = (mesh.w * L) @ nodes  # trapezoid rule with the node values, A/m m
    # by hand: each segment's constant vector times its length
    by_hand = b * np.array(
        [
            1.3e5 * math.cos(0.2) * math.cos(0.9),
            1.3e5 * math.sin(0.2) * math.cos(0.9),
            1.3e5 * math.sin(0.9),
        ]
    ) + (L - b) * np.array(
        [
            0.4e5 * math.cos(-1.1) * math.cos(-0.4),
            0.4e5 * math.sin(-1.1) * math.cos(-0.4),
            0.4e5 * math.sin(-0.4),
        ]
    )
    np.testing.assert_allclose(integral, by_hand, rtol=1e-13)
    # the planar layout is the first two components
    np.testing.assert_array_equal(node_magnetization(m, mesh, L), nodes[:, :2])
    np.testing.assert_array_equal(node_magnetization(m, mesh, L, dim=2), nodes[:, :2])


def test_node_magnetization_3d_integrates_a_linear_profile_exactly():
    # |M| linear in s, fixed direction: the trapezoid rule is exact
    L, M0, angle, elevation = 0.04, 2e5, 0.4, 0.6
    m = Magnetization(lambda s: M0 * s / L, angle, elevation)
    mesh = RodMesh(16)
    integral = (mesh.w * L) @ node_magnetization(m, mesh, L, dim=3)
    direction = np.array(
        [
            math.cos(angle) * math.cos(elevation),
            math.sin(angle) * math.cos(elevation),
            math.sin(elevation),
        ]
    )
    np.testing.assert_allclose(integral, M0 * L / 2 * direction, rtol=1e-12)


def test_node_magnetization_cache_never_returns_a_stale_or_shared_result():
    # constant profiles are cached (coilrod.rod.mesh): every input the result depends on is in
    # the key, the caller's copy is its own, and the cache stays bounded.  Reference: the
    # closed form |M| (cos a cos e, sin a cos e, sin e) at every node (constant profile).
    from coilrod.rod import mesh as mesh_module

    L, mesh = 0.04, RodMesh(8)
    for angle, elevation in [(0.0, 0.0), (0.3, 0.0), (0.3, 0.2), (-0.0, 0.0)]:
        for M0 in (1e5, 2e5):
            m = Magnetization(M0, angle, elevation)
            want = M0 * np.array(
                [
                    math.cos(angle) * math.cos(elevation),
                    math.sin(angle) * math.cos(elevation),
                    math.sin(elevation),
                ]
            )
            for _ in range(2):  # a miss, then a hit
                got = node_magnetization(m, mesh, L, dim=3)
                np.testing.assert_allclose(got, np.broadcast_to(want, got.shape), rtol=1e-14)
                got[:] = np.nan  # the caller's copy: must not poison the next call
    # a changed mesh (same object, mutated nodes) is a new key
    m = Magnetization(1e5, 0.3)
    before = node_magnetization(m, mesh, L)
    mesh.s, mesh.h, mesh.w = RodMesh(4).s, RodMesh(4).h, RodMesh(4).w
    assert node_magnetization(m, mesh, L).shape == (5, 2) != before.shape
    # a constant that differs only in the sign of zero keeps its own bits
    plus = node_magnetization(Magnetization(1e5, 0.0), mesh, L)
    minus = node_magnetization(Magnetization(1e5, -0.0), mesh, L)
    assert not np.signbit(plus[:, 1]).any()
    assert np.signbit(minus[:, 1]).all()
    assert len(mesh_module._CONSTANT_CACHE) <= mesh_module._CACHE_SIZE


def test_rod_mesh_cache_gives_every_mesh_its_own_arrays():
    # meshes are cached by value (coilrod.rod.mesh): a mesh changed by its caller must not
    # change the next one; reference: the nodes by hand (two uniform pieces split at 0.25)
    first = RodMesh(8, [0.25])
    want = np.concatenate([np.linspace(0, 0.25, 3)[:-1], np.linspace(0.25, 1.0, 7)])
    np.testing.assert_allclose(first.s, want, rtol=0, atol=1e-15)
    for a in (first.s, first.h, first.w, first.edges, first.counts):
        a[...] = 0
    again = RodMesh(8, [0.25]).refined()
    np.testing.assert_allclose(again.s[::2], want, rtol=0, atol=1e-15)
    np.testing.assert_allclose(again.w.sum(), 1.0, rtol=1e-15)
    assert RodMesh(8.0, [0.25]).n == RodMesh(8, np.array([[0.25]])).n == 9


def test_planar_rod_mesh_constants_cache_is_by_value_and_private():
    # PlanarRod caches a mesh's constants (coilrod.rod.planar) by the mesh's h and w:
    # reference 1/h and 1/w by hand; a problem's changes stay its own
    from coilrod.rod.planar import PlanarRod

    field = coils.UniformField(B=(0.0, 1e-3, 0.0))

    def problem(mesh):
        return PlanarRod(mesh, np.ones((mesh.n, 2)), field, 0.04, np.zeros(3), 0.0)

    first = problem(RodMesh(8, [0.25]))
    first._inv_h[:] = np.nan
    first._k_diag[:] = np.nan
    again = problem(RodMesh(8, [0.25]))
    np.testing.assert_array_equal(again._inv_h, 1.0 / again.mesh.h)
    np.testing.assert_array_equal(again._inv_w, 1.0 / again.mesh.w)
    other = RodMesh(8, [0.25])
    other.h, other.w = other.h * 2, other.w * 2  # a changed mesh: new constants
    np.testing.assert_array_equal(problem(other)._inv_h, 0.5 / again.mesh.h)


@pytest.mark.parametrize("dim", [1, 4, True, "3", None])
def test_node_magnetization_dim_is_2_or_3(dim):
    with pytest.raises(ValueError, match="dim must be 2 or 3"):
        node_magnetization(presets.M1(), RodMesh(8), 0.04, dim=dim)


# -- planar-only consumers refuse an out-of-plane magnetization --------------------------------
LIFTED = dataclasses.replace(ROD, magnetization=Magnetization(128e3, 0.0, 0.3))
PLANAR_ONLY = [
    ("workspace", lambda: coilrod.workspace(LIFTED, 0.01, directions=4, magnitudes=1)),
    ("optimize_magnetization", lambda: coilrod.optimize_magnetization(LIFTED, 1, 0.01)),
    (
        "calibration",
        lambda: coilrod.calibrate(LIFTED, np.array([[0, 1e-3, 0], [0, 2e-3, 0]]), [1e-3, 2e-3]),
    ),
    (
        "2D FEM",
        lambda: coilrod.solve_fem(LIFTED, coils.UniformField((0, 1e-3, 0)), [1.0], dim=2),
    ),
]


@pytest.mark.parametrize(("model", "call"), PLANAR_ONLY, ids=[p[0] for p in PLANAR_ONLY])
def test_planar_consumers_refuse_an_elevation(model, call):
    with pytest.raises(ValueError, match=f"out-of-plane elevation; the planar {model}"):
        call()


def test_rod_solvers_take_the_spatial_model_for_an_elevation():
    """solve_rod, trace_rod and the sensitivities run the spatial rod for an elevation (and
    model='planar' refuses it) instead of dropping the out-of-plane part."""
    field = coils.UniformField((0, 1e-3, 0))
    assert coilrod.solve_rod(LIFTED, field, [1.0], nodes=16).model == "spatial"
    assert coilrod.trace_rod(LIFTED, field, 0.0, (0, 1), max_steps=3).model == "spatial"
    with pytest.raises(ValueError, match="elevation"):
        coilrod.solve_rod(LIFTED, field, [1.0], model="planar")
