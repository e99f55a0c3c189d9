"""Numerical stability of the coil fields (stress tests, fast enough for CI).

Each against something independent of the kernel:
- far away (10 R .. 10^10 R, 10^100 .. 10^300 m; on the axis, in the loop plane, oblique):
  B, gradient and hessian against a high-precision mpmath Biot-Savart integral
  (tests/_mp_loop_ref.py), relative error <= 1e-12 of the norm of each quantity, also for a
  Maxwell pair (whose dipoles cancel) and a finite winding; underflow gives the correctly
  rounded subnormal or 0, overflowing coordinates a ValueError;
- the switches between the kernel's branches (multipole radius, series / elliptic switch,
  series tables): both sides against the reference and against each other;
- near the axis (series branch) against the on-axis expansion, near the wire against the
  straight wire and a 40-digit closed form;
- the elliptic integrals called by the compiled kernel: scipy's to the last bit, and mpmath;
- millimetre to metre coils, milliampere to kiloampere, rotated and translated frames, 10^6
  points: every result finite and as accurate as at a generic point, or a clear error.
"""

import math

import mpmath as mp
import numpy as np
import pytest
from _mp_loop_ref import loops
from scipy.constants import mu_0

import coils

pytestmark = pytest.mark.stress

A_LOOP, I_LOOP = 0.1, 3.0
DIRECTIONS = {
    "axis": (0.0, 0.0, 1.0),
    "-axis": (0.0, 0.0, -1.0),
    "loop plane": (1.0, 0.0, 0.0),
    "plane, oblique": (0.6, -0.8, 0.0),
    "oblique": (0.3, -0.5, 0.81),
    "near the axis": (1e-7, 0.0, -1.0),
    "near the plane": (0.0, 1.0, 1e-9),
}


def rel_err(x, ref):
    """|x - ref| / |ref| over all entries (Frobenius norms, scaled so that tiny values do not
    underflow when squared); 0 if both vanish."""
    s = max(np.abs(ref).max(), np.abs(x).max())
    if s == 0:
        return 0.0
    num, den = np.linalg.norm((x - ref) / s), np.linalg.norm(ref / s)
    return num / den if den > 0 else num


def assert_matches_reference(field, point, filaments, tol=1e-12):
    """B, G, H of ``field`` at ``point`` against the mpmath Biot-Savart reference: relative
    error of the norm <= tol, or, where the reference is subnormal or 0, within the last bits
    of the correctly rounded value."""
    B, G, H = field.B_gradient_hessian(point)
    Br, Gr, Hr = loops(point, filaments)
    for name, x, ref in (("B", B[0], Br), ("G", G[0], Gr), ("H", H[0], Hr)):
        assert np.all(np.isfinite(x)), name
        if np.abs(ref).max() >= np.finfo(float).tiny:  # normal range: relative to the norm
            assert rel_err(x, ref) <= tol, (name, x, ref)
        else:  # subnormal or underflow: a few units in the last place of a subnormal
            assert np.abs(x - ref).max() <= tol * np.abs(ref).max() + 2e-323, (name, x, ref)


# -- far field ------------------------------------------------------------------------------------
@pytest.mark.parametrize("direction", DIRECTIONS)
@pytest.mark.parametrize("distance", [2.0, 3.9, 4.1, 10.0, 1e2, 1e3, 1e6, 1e8, 1e10, 1e15])
def test_loop_far_field_matches_biot_savart(distance, direction):
    # distance in loop radii; 3.9 and 4.1 straddle the multipole switch (coils.multipole.SWITCH);
    # beyond it one distance every two or three decades (the series' truncation error only
    # falls with the distance; 1e100 ... 1e300 below)
    loop = coils.Coil(A_LOOP, 1, I_LOOP, axis="z")
    d = np.array(DIRECTIONS[direction])
    point = distance * A_LOOP * d / np.linalg.norm(d)
    assert_matches_reference(loop, point, [(0.0, A_LOOP, I_LOOP)])


@pytest.mark.parametrize("direction", ["axis", "loop plane", "oblique"])
@pytest.mark.parametrize("distance", [1e100, 1e102, 1e200, 1e300])
def test_loop_field_at_astronomical_distances(distance, direction):
    # a 1 m loop with 1 kA: B ~ 6e-4 / r^3 T is normal at 1e100 m, subnormal at 1e102 m and
    # underflows beyond; every output is finite and the correctly rounded value (0 included)
    loop = coils.Coil(1.0, 1, 1e3, axis="z", center=(0.0, 0.0, 0.0))
    d = np.array(DIRECTIONS[direction])
    point = distance * d / np.linalg.norm(d)
    assert_matches_reference(loop, point, [(0.0, 1.0, 1e3)])


def test_coordinates_overflow_is_an_error():
    # 1.5e308 - (-1e308) overflows: no inf or NaN reaches the result
    coil = coils.Coil(0.1, 1, 1.0, axis="x", center=(-1e308, 0.0, 0.0))
    with pytest.raises(ValueError, match="point 1 is too far from the coil centre"):
        coil.B([[0.0, 0.0, 0.0], [1.5e308, 0.0, 0.0]])
    # the largest finite coordinates themselves are fine (the field underflows to 0)
    B, G, H = coils.Coil(0.1, 1, 1.0).B_gradient_hessian([[1.7e308, -1.7e308, 1.7e308]])
    assert not np.any(B)
    assert not np.any(G)
    assert not np.any(H)


def test_field_overflow_is_an_error():
    # a 1e-200 m loop: B ~ mu0 I / a is representable, its hessian ~ mu0 I / a^3 is not
    coil = coils.Coil(1e-200, 1, 1.0, axis="z")
    p = [[0.0, 0.0, 3e-201]]
    assert np.all(np.isfinite(coil.B(p)))
    with pytest.raises(ValueError, match="field at point 0 overflows double precision"):
        coil.hessian(p)


@pytest.mark.parametrize("distance", [3.0, 1e3, 1e6, 1e8])
@pytest.mark.parametrize("direction", ["axis", "loop plane", "oblique"])
def test_maxwell_pair_far_field(distance, direction):
    # the two dipoles cancel: a sum over filaments would lose distance / spacing digits
    # (1e-8 relative at 1e8 R); the group's multipole series keeps full precision
    R, NI = 0.1, 50.0
    pair = coils.MaxwellPair(R, 1, NI, axis="z")
    h = pair.spacing / 2
    d = np.array(DIRECTIONS[direction])
    point = distance * R * d / np.linalg.norm(d)
    assert_matches_reference(pair, point, [(-h, R, -NI), (h, R, NI)])


def test_finite_winding_far_field():
    coil = coils.HelmholtzPair(0.1, 50, 2.0, axis="z", winding=(0.02, 0.015), filaments=(3, 2))
    point = 1e4 * np.array([0.03, -0.05, 0.081])
    assert_matches_reference(coil, point, coil.filaments)


# -- switches between the branches of the kernel --------------------------------------------------
@pytest.mark.parametrize("direction", ["axis", "loop plane", "oblique"])
@pytest.mark.parametrize("kind", ["loop", "maxwell"])
def test_continuous_across_multipole_switch(kind, direction):
    from coils.multipole import SWITCH

    if kind == "loop":
        field = coils.Coil(A_LOOP, 1, I_LOOP, axis="z")
    else:
        field = coils.MaxwellPair(A_LOOP, 1, I_LOOP, axis="z")
    d = np.array(DIRECTIONS[direction])
    d /= np.linalg.norm(d)
    r_switch = SWITCH * field.radius_bound
    inner, outer = r_switch * (1 - 2e-15) * d, r_switch * (1 + 2e-15) * d
    assert np.linalg.norm(inner) < r_switch < np.linalg.norm(outer)
    (Bi, Gi, Hi), (Bo, Go, Ho) = (field.B_gradient_hessian(p) for p in (inner, outer))
    assert rel_err(Bo, Bi) < 1e-13
    assert rel_err(Go, Gi) < 1e-13
    assert rel_err(Ho, Hi) < 1e-13
    assert_matches_reference(field, outer, field.filaments)
    assert_matches_reference(field, inner, field.filaments)


def test_multipole_and_filament_sums_agree_around_switch(rng):
    # the two formulas at the same points, 2 to 8 group radii away (both converge there)
    from coils.loop import loop_invariants
    from coils.multipole import group_moments, multipole_invariants

    fil = np.array([[-0.04, 0.1, 3.0], [0.05, 0.08, -2.0], [0.0, 0.12, 1.0]])
    moments = group_moments(fil, mu_0)
    r = moments.d * rng.uniform(2.0, 8.0, 200)
    theta = rng.uniform(0, np.pi, 200)
    rho, z = r * np.sin(theta), r * np.cos(theta)
    far = multipole_invariants(rho, z, moments)
    near = sum(loop_invariants(rho, z - z0, a, cur, mu_0)[:, :6] for z0, a, cur in fil)
    # each invariant against its size at that distance (invariant k falls as r^-(3..7))
    powers = np.array([4, 3, 5, 6, 6, 7])
    size = np.abs(near * r[:, None] ** powers).max(axis=0) / r[:, None] ** powers
    assert np.all(np.abs(far - near) <= 1e-13 * size)


def _boundaries():
    """Every w at which the kernel changes table or branch (coils.loop)."""
    from coils.loop import W_SERIES, W_TAYLOR, _series_intervals

    return sorted({W_SERIES, W_TAYLOR} | {low for low, _ in _series_intervals()})


@pytest.mark.parametrize("z", [0.0, 0.37, -0.55])
def test_continuous_across_series_tables(z):
    # t = 2 a rho / s = sqrt(w): at rho (1 + k 1e-15), k = -3, -1, 1, 3, around every table
    # edge, the step across the edge (k = -1 -> 1) equals the mean of the steps on either side
    # (the field's own change) to rounding: no jump from a wrong table or branch
    from coils.loop import loop_invariants

    a = 1.0
    # size of each invariant along this line
    scale = np.abs(loop_invariants(np.linspace(0, 0.9, 91), z, a, 1.0)[:, :6]).max(axis=0)
    for w in _boundaries():
        t = math.sqrt(w)
        rho = (a - math.sqrt(a * a - t * t * (a * a + z * z))) / t  # smaller root
        f = loop_invariants(rho * (1 + 1e-15 * np.array([-3, -1, 1, 3])), z, a, 1.0)[:, :6]
        jump = (f[2] - f[1]) - 0.5 * ((f[1] - f[0]) + (f[3] - f[2]))
        assert np.all(np.abs(jump) <= 1e-14 * scale), w


@pytest.mark.parametrize("w_edge", ["W_SERIES", "W_TAYLOR"])
def test_branch_edges_match_reference(w_edge):
    import coils.loop

    w = getattr(coils.loop, w_edge)
    a, z = A_LOOP, 0.37 * A_LOOP
    t = math.sqrt(w)
    rho = (a - math.sqrt(a * a - t * t * (a * a + z * z))) / t
    loop = coils.Coil(a, 1, I_LOOP, axis="z")
    for r in rho * (1 + np.array([-1e-14, 1e-14])):
        assert_matches_reference(loop, np.array([0.6 * r, 0.8 * r, z]), [(0.0, a, I_LOOP)])


# -- elliptic integrals in the compiled kernel ----------------------------------------------------
def test_elliptic_integrals_are_scipys():
    from numba import njit
    from scipy.special import ellipe, ellipkm1

    import coils.loop

    km1, e = coils.loop.ellipkm1, coils.loop.ellipe

    @njit
    def compiled(p, m, K, E):
        for i in range(p.shape[0]):
            K[i] = km1(p[i])
            E[i] = e(m[i])

    p = np.concatenate([np.logspace(-300, 0, 301), np.random.default_rng(1).uniform(0, 1, 500)])
    m = 1.0 - p
    K, E = np.empty_like(p), np.empty_like(p)
    compiled(p, m, K, E)
    np.testing.assert_array_equal(K, ellipkm1(p))  # the same C functions: bit for bit
    np.testing.assert_array_equal(E, ellipe(m))
    with mp.workdps(360):  # and 1e-15 relative against mpmath, m -> 0 and m -> 1 included
        for pk, k, ek in zip(p[::10], K[::10], E[::10], strict=True):
            mk = 1 - mp.mpf(float(pk))
            assert abs(k - mp.ellipk(mk)) <= 1e-15 * abs(mp.ellipk(mk))
            assert abs(ek - mp.ellipe(mk)) <= 1e-15 * mp.ellipe(mk)


# -- near the axis and near the wire ---------------------------------------------------------------
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
    with mp.workdps(dps):
        x, y, z = (mp.mpf(float(v)) for v in point)
        a = mp.mpf(a)
        rho = mp.sqrt(x * x + y * y)
        al2 = (rho - a) ** 2 + z**2
        be2 = (rho + a) ** 2 + z**2
        m = 1 - al2 / be2
        K, E, be = mp.ellipk(m), mp.ellipe(m), mp.sqrt(be2)
        C = mp.mpf(mu_0) * current / mp.pi
        bz = C / (2 * al2 * be) * ((a * a - rho * rho - z * z) * E + al2 * K)
        br = C * z / (2 * al2 * be * rho) * ((a * a + rho * rho + z * z) * E - al2 * K)
        return [float(br * x / rho), float(br * y / rho), float(bz)]


# -- scales, frames, many points ------------------------------------------------------------------
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


def test_million_points():
    pair = coils.HelmholtzPair(0.1, 100, 2.0, axis="y")
    pts = np.random.default_rng(3).uniform(-0.04, 0.04, (1_000_000, 3))
    B, G = pair.B_and_gradient(pts)
    assert B.shape == (1_000_000, 3)
    assert G.shape == (1_000_000, 3, 3)
    assert np.all(np.isfinite(B))
    assert np.all(np.isfinite(G))
    # spot checks against the independent reference
    for k in (0, 65536, 999_999):
        Br, Gr, _ = loops(pts[k] @ pair.rotation, pair.filaments)
        assert rel_err(B[k], pair.rotation @ Br) < 1e-13
        assert rel_err(G[k], pair.rotation @ Gr @ pair.rotation.T) < 1e-13


def test_hessian_is_symmetric_and_harmonic(rng):
    pair = coils.MaxwellPair(0.1, 100, 2.0, axis="y")
    H = pair.hessian(rng.uniform(-0.03, 0.03, (20, 3)))
    scale = np.abs(H).max()
    # d2B_i/dx_j dx_l symmetric in all indices (curl-free) and harmonic (trace over j, l)
    np.testing.assert_allclose(H, H.transpose(0, 2, 1, 3), atol=1e-6 * scale)
    np.testing.assert_allclose(np.einsum("kijj->ki", H), 0, atol=1e-6 * scale)


def test_kernels_compile_once_for_sealed_or_writable_inputs(monkeypatch):
    # issue 19: numba compiles one version of a kernel per argument layout (CI starts with an
    # empty cache: seconds each); read-only (sealed, broadcast) and writable inputs reach each
    # kernel in one layout, with the same numbers
    from coils import _compiled, coaxial
    from coils.loop import _invariants, loop_invariants, loop_point
    from coils.multipole import group_moments, multipole_invariants, multipole_point

    rho, z = np.array([0.2, 0.5]), np.array([0.3, -0.4])
    by_scalar = [loop_invariants(rho[i : i + 1], z[i], 1.0)[0] for i in range(2)]
    assert np.array_equal(loop_invariants(rho, z, 1.0), np.array(by_scalar))
    assert len(_invariants.signatures) == 1
    monkeypatch.setattr(coaxial._rental, "ready", True)  # the compiled pass, not numpy's
    loop = coils.Coil(A_LOOP, 1, I_LOOP, axis="z")
    pts = np.array([[0.01, 0.02, 0.03], [0.02, -0.01, 0.05]])
    sealed = pts.copy()
    sealed.flags.writeable = False
    assert np.array_equal(loop.B(pts), loop.B(sealed))
    assert len(_compiled.coaxial_field.signatures) == 1
    # functions the coil pass calls, called by the invariants' kernels too (no version of
    # their own when the callers come from numba's disk cache: at most one)
    assert len(loop_point.signatures) <= 1
    multipole_invariants(rho, z, group_moments(np.array([[0.0, 0.1, 1.0]]), mu_0))
    assert len(multipole_point.signatures) <= 1
