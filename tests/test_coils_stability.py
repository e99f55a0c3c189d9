"""Numerical stability of the coil fields (stress tests, fast enough for CI).

Near the axis (series branch of the kernel), near the wire, far away, from millimetre to metre
coils, milliampere to kiloampere currents, rotated and translated frames, and 10^6 points in
chunks: every result finite and as accurate as at a generic point, or a clear error.
"""

import numpy as np
import pytest
from scipy.constants import mu_0

import coils
from coils.loop import _M_SERIES, loop_field_cyl

pytestmark = pytest.mark.stress


def test_continuous_across_series_switch():
    # modulus m = 4 a rho / beta^2 crosses the series threshold; both branches must agree
    a, z = 1.0, 0.3
    rho = np.linspace(1e-4, 0.5, 20001)
    m = 4 * a * rho / (a**2 + rho**2 + z**2 + 2 * a * rho)
    k = np.searchsorted(m, _M_SERIES)
    rho_switch = rho[k]
    r = rho_switch * (1 + np.array([-1e-12, 1e-12]))
    out = np.array(loop_field_cyl(r, np.full(2, z), a))
    np.testing.assert_allclose(out[:, 0], out[:, 1], rtol=1e-11)


@pytest.mark.parametrize("rho", [0.0, 1e-300, 1e-200, 1e-15, 1e-9, 1e-6, 1e-3, 0.05, 0.2])
def test_near_axis_matches_on_axis_expansion(rho):
    # near the axis B_rho = -rho/2 dBz/dz(0, z) + O(rho^3): closed-form check of the series branch
    a, current, z = 0.1, 5.0, 0.037
    coil = coils.Coil(a, 1, current, axis="z")
    B, G = coil.B_and_gradient([[rho, 0.0, z]])
    bz0 = mu_0 * current * a**2 / (2 * (a**2 + z**2) ** 1.5)
    dbz0 = -3 * mu_0 * current * a**2 * z / (2 * (a**2 + z**2) ** 2.5)
    assert np.all(np.isfinite(B))
    assert np.all(np.isfinite(G))
    tol = max(1e-14, 10 * (rho / a) ** 2)
    assert B[0, 0] == pytest.approx(-0.5 * rho * dbz0, rel=tol, abs=1e-300)
    assert B[0, 2] == pytest.approx(bz0, rel=tol)
    assert G[0, 2, 2] == pytest.approx(dbz0, rel=tol)
    assert G[0, 0, 0] + G[0, 1, 1] == pytest.approx(-dbz0, rel=tol)


@pytest.mark.parametrize("distance", [1e-2, 1e-4, 1e-6, 1e-8])
def test_near_the_wire_tends_to_straight_wire(distance):
    # close to the wire the loop looks like an infinite straight wire: |B| -> mu0 I / (2 pi d)
    a, current = 0.1, 1.0
    coil = coils.Coil(a, 1, current, axis="z")
    d = distance * a
    pts = np.array([[a + d, 0, 0], [a - d, 0, 0], [a, 0, d], [a, 0, -d]])
    B, G = coil.B_and_gradient(pts)
    assert np.all(np.isfinite(B))
    assert np.all(np.isfinite(G))
    wire = mu_0 * current / (2 * np.pi * d)
    np.testing.assert_allclose(
        np.linalg.norm(B, axis=1), wire, rtol=3 * distance * (1 + abs(np.log(distance)))
    )
    # the gradient of a straight wire has magnitude mu0 I / (2 pi d^2) per component pair
    np.testing.assert_allclose(
        np.linalg.norm(G, axis=(1, 2)),
        np.sqrt(2) * wire / d,
        rtol=3 * distance * (1 + abs(np.log(distance))),
    )
    # a 40-digit evaluation of the closed form agrees to machine precision (magpylib's kernel
    # itself drifts by ~1e-8 relative at 1e-8 R from the wire, so it is no reference here)
    ref = np.array([mp_loop_B(p, a, current) for p in pts])
    np.testing.assert_allclose(B, ref, rtol=0, atol=1e-14 * wire)


def mp_loop_B(point, a, current, dps=40):
    """Simpson's closed form for the loop field evaluated with mpmath at ``dps`` digits."""
    mpmath = pytest.importorskip("mpmath")
    with mpmath.workdps(dps):
        x, y, z = (mpmath.mpf(float(v)) for v in point)
        a = mpmath.mpf(a)
        rho = mpmath.sqrt(x * x + y * y)
        al2 = (rho - a) ** 2 + z**2
        be2 = (rho + a) ** 2 + z**2
        m = 1 - al2 / be2
        K, E, be = mpmath.ellipk(m), mpmath.ellipe(m), mpmath.sqrt(be2)
        C = mpmath.mpf(mu_0) * current / mpmath.pi
        bz = C / (2 * al2 * be) * ((a * a - rho * rho - z * z) * E + al2 * K)
        br = C * z / (2 * al2 * be * rho) * ((a * a + rho * rho + z * z) * E - al2 * K)
        return [float(br * x / rho), float(br * y / rho), float(bz)]


@pytest.mark.parametrize("radius", [1e-3, 1e-2, 1.0, 10.0])
@pytest.mark.parametrize("current", [1e-3, 1.0, 1e3])
def test_scale_and_current_invariance(radius, current, rng):
    # B R / (mu0 N I) and G R^2 / (mu0 N I) depend only on x / R
    unit = coils.HelmholtzPair(1.0, 10, 1.0, axis="y")
    coil = coils.HelmholtzPair(radius, 10, current, axis="y")
    xi = rng.uniform(-0.4, 0.4, (100, 3))
    B1, G1 = unit.B_and_gradient(xi)
    B, G = coil.B_and_gradient(radius * xi)
    np.testing.assert_allclose(B * radius / current, B1, rtol=1e-13, atol=1e-15 * np.abs(B1).max())
    np.testing.assert_allclose(
        G * radius**2 / current, G1, rtol=1e-12, atol=1e-13 * np.abs(G1).max()
    )


def test_rotation_and_translation_invariance(rng):
    from scipy.spatial.transform import Rotation

    base = coils.MaxwellPair(0.1, 100, 2.0, axis="z")
    rot = Rotation.random(random_state=7)
    Rm = rot.as_matrix()
    shift = np.array([0.3, -1.2, 0.05])
    moved = coils.MaxwellPair(0.1, 100, 2.0, axis=Rm[:, 2], center=shift)
    p = rng.uniform(-0.06, 0.06, (200, 3))
    B0, G0 = base.B_and_gradient(p)
    B1, G1 = moved.B_and_gradient(p @ Rm.T + shift)
    np.testing.assert_allclose(B1, B0 @ Rm.T, atol=1e-14 * np.abs(B0).max())
    np.testing.assert_allclose(
        G1, np.einsum("ia,kab,jb->kij", Rm, G0, Rm), atol=1e-13 * np.abs(G0).max()
    )


def test_million_points_chunked():
    pair = coils.HelmholtzPair(0.1, 100, 2.0, axis="y")
    pts = np.random.default_rng(3).uniform(-0.04, 0.04, (1_000_000, 3))
    B, G = pair.B_and_gradient(pts)
    assert B.shape == (1_000_000, 3)
    assert G.shape == (1_000_000, 3, 3)
    assert np.all(np.isfinite(B))
    assert np.all(np.isfinite(G))
    # chunk boundaries do not change results
    k = [0, 65535, 65536, 65537, 999_999]
    B2, G2 = pair.B_and_gradient(pts[k])
    np.testing.assert_array_equal(B[k], B2)
    np.testing.assert_array_equal(G[k], G2)


def test_far_field_finite_and_small():
    coil = coils.Coil(1e-3, 1, 1.0)
    B, G = coil.B_and_gradient([[1e3, 2e3, -5e2]])
    assert np.all(np.isfinite(B))
    assert np.all(np.isfinite(G))
    assert 0 < np.linalg.norm(B) < 1e-20


def test_hessian_is_symmetric_and_harmonic(rng):
    pair = coils.MaxwellPair(0.1, 100, 2.0, axis="y")
    H = pair.hessian(rng.uniform(-0.03, 0.03, (20, 3)))
    scale = np.abs(H).max()
    # d2B_i/dx_j dx_l symmetric in all indices (curl-free) and harmonic (trace over j, l)
    np.testing.assert_allclose(H, H.transpose(0, 2, 1, 3), atol=1e-6 * scale)
    np.testing.assert_allclose(np.einsum("kijj->ki", H), 0, atol=1e-6 * scale)
