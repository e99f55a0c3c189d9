"""The closed-form hessian of the coil fields, ``H[k, i, j, l] = d2B_i/(dx_j dx_l)``.

Cross-checks, each against something independent of the hessian kernel:
- Richardson-extrapolated central differences of the exact gradient at random points
  (Helmholtz, Maxwell, a single coil with arbitrary axis and centre, a finite winding);
- a 40-digit mpmath reference: on the axis the closed form of d2B_z/dz2 (by hand from
  mu0 I a^2 / (2 (a^2 + z^2)^{3/2})), off the axis (1e-12 a, 1e-6 a) and near the wire (1e-6 a)
  mpmath derivatives of the loop's elliptic-integral field (Simpson et al. 2001);
- Maxwell equations in free space: H symmetric in all three indices and traceless in each pair;
- scale invariance: H R^3 / (mu0 N I) depends only on x / R;
- the on-winding checks of B and the gradient apply to the hessian too.
"""

import mpmath as mp
import numpy as np
import pytest
from scipy.constants import mu_0

import coils


def richardson_hessian(field, pts, h):
    """d(gradient)/dx_l by central differences at steps h and h/2, Richardson-extrapolated."""

    def central(step):
        out = np.empty((len(pts), 3, 3, 3))
        for axis in range(3):
            e = np.zeros(3)
            e[axis] = step
            out[..., axis] = (field.gradient(pts + e) - field.gradient(pts - e)) / (2 * step)
        return out

    return (4 * central(h / 2) - central(h)) / 3


FIELDS = {
    "helmholtz": coils.HelmholtzPair(0.1, 100, 2.0, axis="y"),
    "maxwell": coils.MaxwellPair(0.1, 100, 2.0, axis="y", center=(0.02, 0.0, 0.0)),
    "coil, oblique axis": coils.Coil(
        0.05, 30, -1.5, axis=(0.3, -0.5, 0.8), center=(0.01, 0.02, -0.03)
    ),
    "finite winding": coils.HelmholtzPair(
        0.08, 200, 1.0, axis=(1.0, 1.0, 0.0), winding=(0.02, 0.015), filaments=(3, 2)
    ),
}


@pytest.mark.parametrize("name", FIELDS)
def test_matches_richardson_differences_of_gradient(name, rng):
    field = FIELDS[name]
    pts = rng.uniform(-0.04, 0.04, (40, 3))
    H = field.hessian(pts)
    ref = richardson_hessian(field, pts, 1e-3 * field.length_scale)
    assert np.abs(H - ref).max() < 1e-9 * np.abs(ref).max()


# -- 40-digit mpmath reference for one loop (radius a, current I, axis z) ------------------------
A_LOOP, I_LOOP = 0.1, 3.0


def _mp_B(x, y, z, a=A_LOOP, current=I_LOOP):
    """B (T) of one loop at (x, y, z) from the elliptic-integral closed form, in mpmath."""
    a, current = mp.mpf(a), mp.mpf(current)  # a float a * a would round at 1e-17
    rho2 = x * x + y * y
    rho = mp.sqrt(rho2)
    alpha2 = a * a + rho2 + z * z - 2 * a * rho
    beta2 = a * a + rho2 + z * z + 2 * a * rho
    m = 1 - alpha2 / beta2
    C = mp.mpf(mu_0) * current / mp.pi
    K, E = mp.ellipk(m), mp.ellipe(m)
    brho_over_rho = (
        C * z / (2 * alpha2 * mp.sqrt(beta2) * rho2) * ((a * a + rho2 + z * z) * E - alpha2 * K)
    )
    bz = C / (2 * alpha2 * mp.sqrt(beta2)) * ((a * a - rho2 - z * z) * E + alpha2 * K)
    return brho_over_rho * x, brho_over_rho * y, bz


def mp_hessian(point):
    """H (3, 3, 3) at a point off the axis, by mpmath differentiation at 60 digits."""
    H = np.empty((3, 3, 3))
    with mp.workdps(60):
        p = [mp.mpf(float(c)) for c in point]
        for i in range(3):
            for j in range(3):
                for l_ in range(j, 3):
                    order = [0, 0, 0]
                    order[j] += 1
                    order[l_] += 1
                    val = mp.diff(lambda *q, i=i: _mp_B(*q)[i], p, tuple(order))
                    H[i, j, l_] = H[i, l_, j] = float(val)
    return H


def on_axis_hessian(z, a=A_LOOP, current=I_LOOP):
    """H on the axis from b(z) = mu0 I a^2 / (2 (a^2 + z^2)^{3/2}), at 40 digits.

    b'' = 3/2 mu0 I a^2 (4 z^2 - a^2) / (a^2 + z^2)^{7/2} = H_zzz; axisymmetry and div B = 0 give
    H_zxx = H_zyy = -b''/2 (and the permutations of the indices); every other entry is zero.
    """
    with mp.workdps(40):
        a_, z_ = mp.mpf(a), mp.mpf(z)
        b2 = float(
            1.5 * mp.mpf(mu_0) * current * a_**2 * (4 * z_**2 - a_**2) / (a_**2 + z_**2) ** 3.5
        )
    H = np.zeros((3, 3, 3))
    H[2, 2, 2] = b2
    for k in range(2):
        H[2, k, k] = H[k, 2, k] = H[k, k, 2] = -0.5 * b2
    return H


@pytest.mark.parametrize("z", [0.0, 0.013, -0.07, 0.3])
def test_on_axis_matches_closed_form(z):
    loop = coils.Coil(A_LOOP, 1, I_LOOP, axis="z")
    H = loop.hessian([[0.0, 0.0, z]])[0]
    ref = on_axis_hessian(z)
    assert np.abs(H - ref).max() < 1e-14 * np.abs(ref).max()


@pytest.mark.parametrize(
    ("rho", "z"),
    [
        (1e-12 * A_LOOP, 0.037),
        (1e-6 * A_LOOP, 0.037),
        (1e-6 * A_LOOP, 0.0),
        (0.3 * A_LOOP, 0.021),
        (1.7 * A_LOOP, -0.05),
    ],
)
def test_off_axis_matches_mpmath(rho, z):
    loop = coils.Coil(A_LOOP, 1, I_LOOP, axis="z")
    point = np.array([rho * 0.6, rho * 0.8, z])
    H = loop.hessian([point])[0]
    ref = mp_hessian(point)
    assert np.abs(H - ref).max() < 1e-13 * np.abs(ref).max()


@pytest.mark.parametrize("angle", [0.0, 1.0, 2.5, 4.0])
@pytest.mark.parametrize(("direction", "tol"), [((1.0, 0.0), 1e-13), ((0.8, -0.6), 1e-9)])
def test_near_wire_matches_mpmath(angle, direction, tol):
    # 1e-6 a from the wire, where H ~ 1/d^3 is ~10^18 times its value at the centre.  Off the
    # coordinate planes rho = hypot(x, y) rounds by eps a, which moves the point by eps a / d
    # relative to d: the hessian's conditioning, not the kernel, limits the agreement to ~1e-10.
    loop = coils.Coil(A_LOOP, 1, I_LOOP, axis="z")
    d = 1e-6 * A_LOOP
    rho, z = A_LOOP + d * np.cos(angle), d * np.sin(angle)
    point = np.array([rho * direction[0], rho * direction[1], z])
    H = loop.hessian([point])[0]
    ref = mp_hessian(point)
    assert np.abs(H - ref).max() < tol * np.abs(ref).max()


@pytest.mark.parametrize("name", FIELDS)
def test_symmetric_and_traceless(name, rng):
    H = FIELDS[name].hessian(rng.uniform(-0.05, 0.05, (200, 3)))
    scale = np.abs(H).max(axis=(1, 2, 3))[:, None, None, None]
    for perm in [(0, 2, 1, 3), (0, 3, 2, 1), (0, 1, 3, 2), (0, 2, 3, 1), (0, 3, 1, 2)]:
        assert np.all(np.abs(H - H.transpose(perm)) <= 1e-14 * scale)
    traces = np.einsum("kijj->ki", H)
    assert np.all(np.abs(traces) <= 1e-14 * scale[:, :, 0, 0])


def test_scale_invariance(rng):
    # H R^3 / (mu0 N I) is a function of x / R alone: millimetre and metre coils agree
    xi = rng.uniform(-0.6, 0.6, (50, 3))
    out = []
    for radius, turns, current in [(1e-3, 10, 0.01), (1.0, 500, 40.0), (0.2, 1, -3.0)]:
        pair = coils.MaxwellPair(radius, turns, current, axis="x", center=(radius, 0, 0))
        H = pair.hessian(radius * (xi + [1.0, 0, 0]))
        out.append(H * radius**3 / (mu_0 * turns * current))
    scale = np.abs(out[0]).max()
    for other in out[1:]:
        assert np.abs(other - out[0]).max() < 1e-13 * scale


def test_on_winding_raises():
    coil = coils.Coil(0.1, 50, 1.0, axis="y", winding=(0.01, 0.01))
    with pytest.raises(ValueError, match="inside a coil winding"):
        coil.hessian([[0.1, 0.002, 0.0]])
    loop = coils.Coil(0.1, 1, 1.0, axis="z")
    with pytest.raises(ValueError, match="lies on a coil winding"):
        loop.hessian([[0.0, 0.1, 0.0]])
