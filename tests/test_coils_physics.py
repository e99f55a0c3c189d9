"""Physics consistency of the coil fields.

Cross-checks, each against something independent of our kernel:
- closed forms: on-axis loop field and its axial derivative, Helmholtz centre field
  (4/5)^{3/2} mu0 N I / R, Maxwell centre gradient 48 sqrt(3)/7^{5/2} mu0 N I / R^2;
- magpylib: B of every source (its own Bulirsch-cel kernel) and the gradient by Richardson
  finite differences of magpylib's B, at random points, for arbitrary axes and centres;
- Maxwell equations in free space: the gradient is symmetric and traceless;
- far field: B, gradient and hessian of a loop tend to the dipole's closed forms (moment
  I pi a^2) out to 10^12 R; div B = 0 and curl B = 0 hold far away (G and H symmetric and
  traceless) for a Helmholtz and a Maxwell pair (accuracy against mpmath far away is in
  test_coils_stability.py);
- superposition: a system equals the sum of its parts, scaling is linear in the current;
- ideal vs computed: the Helmholtz 1% region (|z| < 0.314 R on axis, rho < 0.378 R in the
  mid-plane), the Maxwell gradient along the axis against the two-loop closed form.
"""

import math

import numpy as np
import pytest
from _magpylib_ref import magpylib_B, magpylib_gradient
from scipy.constants import mu_0

import coils
from coils import deviation, uniformity


def on_axis_loop(a, current, z):
    """B_z and dB_z/dz on the axis of a loop (closed forms), T and T/m."""
    bz = mu_0 * current * a**2 / (2 * (a**2 + z**2) ** 1.5)
    dbz = -3 * mu_0 * current * a**2 * z / (2 * (a**2 + z**2) ** 2.5)
    return bz, dbz


class TestClosedForms:
    def test_loop_on_axis(self):
        a, current = 0.07, 3.0
        coil = coils.Coil(a, 1, current, axis="z")
        z = np.linspace(-0.3, 0.3, 13)
        pts = np.column_stack([0 * z, 0 * z, z])
        B, G = coil.B_and_gradient(pts)
        bz, dbz = on_axis_loop(a, current, z)
        np.testing.assert_allclose(B[:, 2], bz, rtol=1e-14)
        np.testing.assert_allclose(B[:, :2], 0, atol=1e-16 * bz.max())
        np.testing.assert_allclose(G[:, 2, 2], dbz, rtol=1e-12, atol=1e-14 * np.abs(dbz).max())
        # on the axis dB_x/dx = dB_y/dy = -1/2 dB_z/dz
        np.testing.assert_allclose(
            G[:, 0, 0], -0.5 * dbz, rtol=1e-12, atol=1e-14 * np.abs(dbz).max()
        )

    @pytest.mark.parametrize("axis", ["x", "y", "z", (1.0, 2.0, -0.5)])
    def test_helmholtz_centre_field(self, axis):
        radius, turns, current = 0.15, 120, 2.5
        pair = coils.HelmholtzPair(radius, turns, current, axis=axis, center=(0.01, -0.02, 0.3))
        B = pair.B(pair.center)[0]
        expected = (4 / 5) ** 1.5 * mu_0 * turns * current / radius
        np.testing.assert_allclose(B, expected * pair.axis, rtol=1e-14, atol=1e-18)
        # the centre is a stationary point of a symmetric pair: no gradient
        assert np.abs(pair.gradient(pair.center)).max() < 1e-12 * expected / radius

    @pytest.mark.parametrize("axis", ["x", "y", "z", (0.3, -1.0, 0.2)])
    def test_maxwell_centre_gradient(self, axis):
        radius, turns, current = 0.2, 300, 1.5
        pair = coils.MaxwellPair(radius, turns, current, axis=axis, center=(0.1, 0.0, -0.2))
        G = pair.gradient(pair.center)[0]
        g = 48 * math.sqrt(3) / 7**2.5 * mu_0 * turns * current / radius**2
        n = pair.axis
        expected = g * (np.outer(n, n) - 0.5 * (np.eye(3) - np.outer(n, n)))
        np.testing.assert_allclose(G, expected, rtol=1e-13, atol=1e-13 * g)
        assert np.linalg.norm(pair.B(pair.center)) < 1e-14 * g * radius
        assert pair.center_gradient == pytest.approx(g, rel=1e-15)

    def test_maxwell_default_spacing_cancels_third_derivative(self):
        # sqrt(3) R is the spacing at which d^3 B_z/dz^3 vanishes at the centre: the on-axis
        # gradient is flat to second order, so its departure grows as z^4 (closed form check)
        pair = coils.MaxwellPair(1.0, 1, 1.0, axis="z")
        z = np.array([0.01, 0.02, 0.04])
        G = pair.gradient(np.column_stack([0 * z, 0 * z, z]))[:, 2, 2]
        g0 = pair.center_gradient
        rel = np.abs(G / g0 - 1)
        slope = np.polyfit(np.log(z), np.log(rel), 1)[0]
        assert slope == pytest.approx(4.0, abs=0.05)


class TestAgainstMagpylib:
    @pytest.mark.parametrize(
        "make",
        [
            lambda: coils.Coil(0.05, 10, 1.0, axis=(1, 1, 0), center=(0.01, 0.02, -0.03)),
            lambda: coils.HelmholtzPair(0.1, 100, 2.0, axis="y"),
            lambda: coils.MaxwellPair(0.1, 100, -2.0, axis=(0.2, 0.3, 1.0), center=(0, 0.1, 0)),
            lambda: coils.HelmholtzPair(
                0.1, 100, 2.0, axis="x", winding=(0.02, 0.015), filaments=(3, 2)
            ),
        ],
    )
    def test_B_and_gradient(self, make, rng):
        coil = make()
        pts = coil.center + rng.uniform(-0.15, 0.15, (300, 3))
        # keep away from the windings, where finite differences lose accuracy
        from coils.coaxial import winding_mask

        pts = pts[~winding_mask(coil, pts, 0.1)]
        B, G = coil.B_and_gradient(pts)
        Bm = magpylib_B(coil, pts)
        scale_b = np.abs(Bm).max()
        np.testing.assert_allclose(B, Bm, rtol=0, atol=1e-13 * scale_b)
        Gm = magpylib_gradient(coil, pts, step=1e-4 * coil.length_scale)
        scale_g = np.abs(Gm).max()
        np.testing.assert_allclose(G, Gm, rtol=0, atol=1e-10 * scale_g)

    def test_gradient_is_symmetric_and_traceless(self, rng):
        coil = coils.CoilSystem(
            [
                coils.HelmholtzPair(0.1, 100, 2.0, axis="y"),
                coils.MaxwellPair(0.12, 80, 1.0, axis="x", center=(0.01, 0, 0)),
            ]
        )
        G = coil.gradient(rng.uniform(-0.05, 0.05, (500, 3)))
        scale = np.abs(G).max()
        np.testing.assert_allclose(G, G.transpose(0, 2, 1), atol=1e-14 * scale)
        np.testing.assert_allclose(np.trace(G, axis1=1, axis2=2), 0, atol=1e-14 * scale)


def dipole_field(p, moment):
    """B (n, 3), G (n, 3, 3), H (n, 3, 3, 3) of a point dipole at the origin (closed forms).

    ``B = k (3 r (m.r) / r^5 - m / r^3)`` with ``k = mu0 / 4 pi``, and its derivatives
    ``G_ij = 3k/r^5 [m_i r_j + m_j r_i + (m.r) d_ij - 5 (m.r) r_i r_j / r^2]``,
    ``H_ijl = 3k [(d_ij m_l + d_il m_j + d_jl m_i)/r^5 - 5 r_l X_ij / r^7
    - 5 (m_l r_i r_j + (m.r)(d_il r_j + d_jl r_i)) / r^7 + 35 (m.r) r_i r_j r_l / r^9]``
    with ``X_ij = (m.r) d_ij + r_i m_j + m_i r_j``.
    """
    k = mu_0 / (4 * math.pi)
    r = np.linalg.norm(p, axis=1)[:, None]
    mr = (p @ moment)[:, None]
    eye = np.eye(3)
    B = k * (3 * p * mr / r**5 - moment / r**3)
    X = mr[:, :, None] * eye + p[:, :, None] * moment + moment[:, None] * p[:, None, :]
    r3 = r[:, :, None]
    G = 3 * k * (X / r3**5 - 5 * mr[:, :, None] * p[:, :, None] * p[:, None, :] / r3**7)
    r4 = r[:, :, None, None]
    mr4 = mr[:, :, None, None]
    H = (
        3
        * k
        * (
            (np.einsum("ij,l->ijl", eye, moment) + np.einsum("il,j->ijl", eye, moment))[None]
            / r4**5
            + np.einsum("jl,i->ijl", eye, moment)[None] / r4**5
            - 5 * np.einsum("kl,kij->kijl", p, X) / r4**7
            - 5 * np.einsum("l,ki,kj->kijl", moment, p, p) / r4**7
            - 5
            * mr4
            * (np.einsum("il,kj->kijl", eye, p) + np.einsum("jl,ki->kijl", eye, p))
            / r4**7
            + 35 * mr4 * np.einsum("ki,kj,kl->kijl", p, p, p) / r4**9
        )
    )
    return B, G, H


class TestFarField:
    @pytest.mark.parametrize("distance", [1e2, 1e3, 1e5, 1e8, 1e12])
    def test_tends_to_dipole(self, distance, rng):
        # B, gradient and hessian of a loop tend to those of a dipole of moment I pi a^2; the
        # quadrupole vanishes, so the relative corrections are O((a/r)^2)
        a, current = 0.01, 2.0
        coil = coils.Coil(a, 1, current, axis="z")
        d = rng.normal(size=(50, 3))
        d /= np.linalg.norm(d, axis=1)[:, None]
        d = np.vstack([d, [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, -0.6, 0.8]]])
        p = distance * a * d
        ref = dipole_field(p, np.array([0.0, 0.0, current * math.pi * a**2]))
        tol = 5 / distance**2 + 1e-14
        for x, r in zip(coil.B_gradient_hessian(p), ref, strict=True):
            axes = tuple(range(1, x.ndim))
            err = np.sqrt(np.sum((x - r) ** 2, axis=axes) / np.sum(r**2, axis=axes))
            assert err.max() < tol

    @pytest.mark.parametrize("distance", [10.0, 1e4, 1e8, 1e20])
    def test_maxwell_equations_far_away(self, distance, rng):
        # div B = 0 and curl B = 0: G symmetric and traceless, H symmetric in all indices and
        # traceless in each pair, to rounding of each, also where the pair's dipoles cancel
        for field in (
            coils.HelmholtzPair(0.1, 100, 2.0, axis=(0.3, -0.5, 0.8)),
            coils.MaxwellPair(0.1, 100, 2.0, axis="y", center=(0.1, 0.0, 0.0)),
        ):
            d = rng.normal(size=(30, 3))
            p = field.center + distance * 0.1 * d / np.linalg.norm(d, axis=1)[:, None]
            _, G, H = field.B_gradient_hessian(p)
            g = np.linalg.norm(G, axis=(1, 2))[:, None, None]
            assert np.all(np.abs(G - G.transpose(0, 2, 1)) <= 1e-14 * g)
            assert np.all(np.abs(np.trace(G, axis1=1, axis2=2)) <= 1e-14 * g[:, 0, 0])
            h = np.sqrt(np.sum(H**2, axis=(1, 2, 3)))[:, None, None, None]
            for perm in [(0, 2, 1, 3), (0, 3, 2, 1), (0, 1, 3, 2)]:
                assert np.all(np.abs(H - H.transpose(perm)) <= 1e-14 * h)
            assert np.all(np.abs(np.einsum("kijj->ki", H)) <= 1e-14 * h[:, :, 0, 0])


class TestSuperposition:
    def test_system_is_sum_of_parts(self, rng):
        h = coils.HelmholtzPair(0.1, 100, 2.0, axis="y")
        m = coils.MaxwellPair(0.15, 50, 1.0, axis="z", center=(0.0, 0.01, 0.0))
        u = coils.UniformField((1e-3, 0, 0))
        system = coils.CoilSystem([h, m, u])
        pts = rng.uniform(-0.04, 0.04, (200, 3))
        B, G = system.B_and_gradient(pts)
        np.testing.assert_allclose(B, h.B(pts) + m.B(pts) + u.B(pts), rtol=1e-14, atol=1e-20)
        np.testing.assert_allclose(G, h.gradient(pts) + m.gradient(pts), rtol=1e-13, atol=1e-20)
        np.testing.assert_allclose((h + m).B(pts), h.B(pts) + m.B(pts), rtol=1e-14)
        # independent: magpylib sums the filaments of the whole system itself
        np.testing.assert_allclose(
            system.to_magpylib().getB(pts), B - u.B(pts), atol=1e-13 * np.abs(B).max()
        )

    def test_linear_in_current(self, rng):
        pts = rng.uniform(-0.04, 0.04, (50, 3))
        a = coils.MaxwellPair(0.1, 100, 1.0).gradient(pts)
        b = coils.MaxwellPair(0.1, 100, -3.5).gradient(pts)
        np.testing.assert_allclose(b, -3.5 * a, rtol=0, atol=1e-14 * np.abs(b).max())
        np.testing.assert_allclose(
            (2.0 * coils.MaxwellPair(0.1, 100, 1.0)).gradient(pts), 2 * a, rtol=1e-15
        )


class TestIdealVsComputed:
    def test_helmholtz_uniformity_region(self):
        rep = uniformity(coils.HelmholtzPair(radius=0.08, turns=50, current=1.0, axis="y"), 0.01)
        # published extents of the 1% region of a Helmholtz pair
        assert rep.axial / 0.08 == pytest.approx(0.314, abs=5e-4)
        assert rep.radial / 0.08 == pytest.approx(0.378, abs=5e-4)
        assert rep.sphere <= rep.axial

    def test_helmholtz_inside_matches_ideal_outside_not(self, rng):
        R = 0.1
        pair = coils.HelmholtzPair(R, 100, 2.0, axis="y")
        ideal = pair.ideal()
        assert isinstance(ideal, coils.LinearField)
        assert ideal.uniform
        d = rng.normal(size=(400, 3))
        d /= np.linalg.norm(d, axis=1)[:, None]
        inside = 0.3 * R * d
        dev_in = np.linalg.norm(pair.B(inside) - ideal.B(inside), axis=1) / np.linalg.norm(ideal.B0)
        assert dev_in.max() < 0.01
        # just outside the axial extent, on the axis, it departs by more than 1%
        outside = np.array([[0.0, 0.33 * R, 0.0], [0.0, -0.33 * R, 0.0], [0.4 * R, 0, 0]])
        assert np.all(deviation(pair, outside) > 0.01)

    def test_maxwell_departs_from_ideal_as_on_axis_closed_form(self):
        R, N, I = 0.1, 100, 2.0
        pair = coils.MaxwellPair(R, N, I, axis="y")
        ideal = pair.ideal()
        g = pair.center_gradient
        np.testing.assert_allclose(
            ideal.G, coils.maxwell_gradient(g, axis=1), rtol=1e-13, atol=1e-13 * g
        )
        y = np.linspace(-0.6 * R, 0.6 * R, 25)
        pts = np.column_stack([0 * y, y, 0 * y])
        G = pair.gradient(pts)
        h = math.sqrt(3) * R / 2
        _, up = on_axis_loop(R, N * I, y - h)
        _, low = on_axis_loop(R, -N * I, y + h)
        np.testing.assert_allclose(G[:, 1, 1], up + low, rtol=1e-12)
        # the relative departure is what the closed form says, and exceeds 10% at 0.6 R
        assert abs((up + low)[-1] / g - 1) > 0.1
        np.testing.assert_allclose(
            deviation(pair, pts, quantity="gradient") * np.linalg.norm(ideal.G),
            np.linalg.norm(G - ideal.G, axis=(1, 2)),
            rtol=1e-12,
        )
