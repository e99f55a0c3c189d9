"""Extreme and awkward numbers on the public API: far points, points a few ulp from a switch
between formulas.  Each check has an independent reference (the point dipole, whose field a
finite magnet's tends to as (size / distance)^2; the closed form on the other side of a
switch)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.constants import mu_0

import coils
import coils.magnets

FAR = getattr(coils.magnets, "FAR", 8.0)  # (the switch; absent before it was added)

#: Directions of the far points: the axes and two oblique ones.
DIRECTIONS = np.array(
    [[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [0.6, -0.48, 0.64], [-0.8, 0.36, 0.48]]
)

MAGNETS = {
    "cylinder": coils.CylinderMagnet(10e-3, 10e-3, 1e6, center=(0.01, 0.02, -0.03), axis=(1, 2, 3)),
    "ring": coils.CylinderMagnet(10e-3, 4e-3, -8e5, inner_diameter=4e-3, axis="x"),
    "cuboid": coils.CuboidMagnet((10e-3, 6e-3, 3e-3), (2e5, -1e5, 1e6), center=(0.01, 0, 0)),
}


@pytest.mark.parametrize("name", MAGNETS)
def test_a_magnet_far_away_is_its_dipole_to_rounding(name):
    """At 1e4 and 1e8 sizes B, gradient and hessian are finite and the dipole's to
    (size / distance)^2 (plus rounding): the closed forms lost every digit of B there (their
    nearly equal terms cancel; a cuboid's B was off 2e8 times its size at 1e8 sizes)."""
    magnet = MAGNETS[name]
    dipole = magnet.dipole()
    for dist in (5e-1, 5e5):  # m: 1e2 and 1e8 sizes (5 mm)
        pts = magnet.center + dist * DIRECTIONS
        ours, ref = magnet.B_gradient_hessian(pts), dipole.B_gradient_hessian(pts)
        for a, b in zip(ours, ref, strict=True):
            assert np.isfinite(a).all()
            rel = np.abs(a - b).max() / np.abs(b).max()
            assert rel <= (5e-4 if dist < 1 else 1e-12)


@pytest.mark.parametrize("name", MAGNETS)
def test_a_magnets_field_is_continuous_where_the_far_sum_takes_over(name):
    """Just inside and just outside the switch to the far sum (FAR half-diagonals) B, the
    gradient and the hessian agree to 1e-12 relative: the closed form and the quadrature are
    two independent evaluations of the same field."""
    magnet = MAGNETS[name]
    if isinstance(magnet, coils.CylinderMagnet):
        half = np.hypot(magnet.radius, 0.5 * magnet.height)
        frame = magnet.rotation
    else:
        half = 0.5 * np.linalg.norm(magnet.size)
        frame = magnet.rotation
    dirs = DIRECTIONS @ frame.T
    inside = magnet.center + FAR * half * (1 - 1e-14) * dirs
    outside = magnet.center + FAR * half * (1 + 1e-14) * dirs
    for a, b in zip(
        magnet.B_gradient_hessian(inside), magnet.B_gradient_hessian(outside), strict=True
    ):
        assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max()


def test_a_cuboid_on_its_charged_face_gives_the_continuous_normal_field():
    """Exactly on a face normal to M, B_z is the value one ulp inside and one ulp outside (the
    normal component is continuous there); it was off by J/2 (the face's atan terms were
    dropped instead of taking their limit).  Both poles, and one magnetised along x."""
    for M, axis in (((0.0, 0.0, 1e6), 2), ((8e5, 0.0, 0.0), 0)):
        cube = coils.CuboidMagnet((1e-2, 8e-3, 6e-3), M)
        h = 0.5 * cube.size[axis]
        for face in (h, -h):
            pts = np.tile([1e-3, 2e-3, -1.5e-3], (3, 1))
            pts[:, axis] = [np.nextafter(face, 0.0), face, np.nextafter(face, 2 * face)]
            Bn = cube.B(pts)[:, axis]
            assert abs(Bn[1] - Bn[0]) <= 1e-12 * abs(Bn[0])
            assert abs(Bn[1] - Bn[2]) <= 1e-12 * abs(Bn[0])


def test_a_dipole_field_that_leaves_float64_is_an_error_not_nan():
    """1e-150 m from a dipole the field overflows, 1e200 m away the kernel's r^2 does: a
    ValueError naming the point, not NaN (both were NaN); 1e-20 m and 1e100 m are finite and
    the closed form's r^-3 law."""
    dip = coils.Dipole((0.0, 0.0, 1.0))
    for r in (1e-150, 1e200):
        with pytest.raises(ValueError, match=r"points\[0\]"):
            dip.B_gradient_hessian([[r, 0.0, 0.0]])
    for r in (1e-20, 1e100):
        B = dip.B([[r, 0.0, 0.0]])
        assert B[0, 2] == pytest.approx(-mu_0 / (4 * np.pi) / r**3, rel=1e-13)


def test_a_grid_box_thinner_than_its_coordinates_can_resolve_is_refused():
    """A box 5e-324 m thick had a zero spacing and interpolated NaN."""
    pair = coils.HelmholtzPair(0.08, 100, 1.0, axis="y")
    with pytest.raises(ValueError, match="box must be wider"):
        coils.GriddedField(pair, (0.0, 0.0, 0.0), (np.nextafter(0.0, 1.0), 1e-3, 1e-3), shape=3)


def test_refining_the_rod_mesh_converges_monotonically_with_a_breakpoint_off_the_grid():
    """A magnetization jump at 0.3 L (off every dyadic node): the one-mesh tips of 16 ... 128
    segments approach the Richardson value of 256 monotonically, their errors shrinking 4x
    per doubling (h^2; the reference is independent of the meshes tested).  Rounding each
    piece's count afresh had 64 segments farther off than 32 (errors -1.1e-7, -1.9e-7 m)."""
    import coilrod

    L = 0.04
    mag = coilrod.Magnetization.segments([0.3 * L, 0.7 * L], [128e3, -64e3], [0.0, 0.0])
    rod = coilrod.Rod(L, 1e6, coilrod.Circle(2e-3), mag)
    field = coils.UniformField(B=(0.0, 5e-3, 0.0))
    ref = coilrod.solve_rod(rod, field, [1.0], nodes=256, stability=False).tip[0, 1]
    err = np.array(
        [
            coilrod.solve_rod(rod, field, [1.0], nodes=n, richardson=False, stability=False).tip[
                0, 1
            ]
            - ref
            for n in (16, 32, 64, 128)
        ]
    )
    assert np.all(np.sign(err) == np.sign(err[0]))
    ratios = err[:-1] / err[1:]
    assert np.all(np.abs(ratios - 4.0) < 0.1), ratios


def test_the_straight_tip_as_target_needs_no_current():
    """Target = the unloaded tip (L, 0): every field along +x and every one along -x below
    buckling holds it there; the least-power one is zero current (exact)."""
    import coilrod

    rod = coilrod.Rod(0.04, 1e6, coilrod.Circle(2e-3), coilrod.Magnetization(128e3, 0.0))
    system = coils.presets.three_axis_helmholtz()
    for model in ("ideal", "real"):  # (was: -1.66 A on the x pair, 3.8 W)
        sol = coilrod.solve_currents(rod, system, [0.04, 0.0], model=model, steps=2)
        assert np.abs(sol.currents).max() <= 1e-6
        assert sol.miss <= 1e-7 * rod.length
