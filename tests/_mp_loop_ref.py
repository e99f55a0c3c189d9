"""High-precision references for circular loops, independent of the coils kernels.

``biot_savart`` integrates the Biot-Savart law around the loop with mpmath, with B, its
gradient and its hessian differentiated analytically under the integral sign::

    B_i    = C int e_ikl dl_k R_l |R|^-3                      (C = mu0 I / 4 pi, R = x - x')
    dB_i/dx_j = C int e_ikl dl_k (d_lj |R|^-3 - 3 R_l R_j |R|^-5)
    d2B_i/dx_j dx_m = C int e_ikl dl_k (-3 (d_lj R_m + d_lm R_j + d_jm R_l) |R|^-5
                                         + 15 R_l R_j R_m |R|^-7)

The integrand is periodic and analytic in the angle, so the trapezoidal rule converges
exponentially: with ``cosh(y) = (r^2 + a^2) / (2 a rho)`` its error decays as ``exp(-y N)``, and
``N`` is chosen for the requested digits.  The working precision grows with ``log10(r / a)``,
since the far field is a small difference of large terms (no cancellation-free algebra is
assumed).  Points are taken exactly as the float64 values given.
"""

import math

import mpmath as mp
import numpy as np
from scipy.constants import mu_0


def _levi_civita():
    eps = np.zeros((3, 3, 3), dtype=int)
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        eps[i, j, k] = 1
        eps[i, k, j] = -1
    return eps


_EPS = _levi_civita()


def biot_savart(point, a, current, z0=0.0, digits=40):
    """B (3,), G (3, 3), H (3, 3, 3) of one loop (axis z, plane z = z0, radius a), as mpf.

    Parameters
    ----------
    point : sequence of 3 floats
        Field point, m.
    a : float
        Loop radius, m.
    current : float
        Current (A), counter-clockwise about +z.
    z0 : float
        Height of the loop plane, m.
    digits : int
        Correct digits wanted (the working precision adds what the far-field cancellation
        costs).
    """
    x = [mp.mpf(float(v)) for v in point]
    x[2] -= mp.mpf(float(z0))
    rho = float(math.hypot(float(x[0]), float(x[1])))
    r = max(float(mp.sqrt(x[0] ** 2 + x[1] ** 2 + x[2] ** 2)), 1e-300)
    lost = max(0.0, 2 * math.log10(max(r / a, a / r, 1.0)))
    dps = int(digits + lost + 15)
    with mp.workdps(dps):
        x = [mp.mpf(float(v)) for v in point]
        x[2] -= mp.mpf(float(z0))
        A = mp.mpf(float(a))
        if rho == 0.0:
            n = 8
        else:
            c = (r * r + a * a) / (2 * a * rho)
            y = math.acosh(c) if c < 1e300 else 690.0
            n = int(math.ceil((dps * math.log(10) + 20) / y)) + 8
        n += n % 2
        C = mp.mpf(mu_0) * mp.mpf(float(current)) / (4 * mp.pi)
        B = [mp.mpf(0)] * 3
        G = [[mp.mpf(0)] * 3 for _ in range(3)]
        H = [[[mp.mpf(0)] * 3 for _ in range(3)] for _ in range(3)]
        for k in range(n):
            phi = 2 * mp.pi * k / n
            cs, sn = mp.cos(phi), mp.sin(phi)
            dl = (-A * sn, A * cs, mp.mpf(0))
            R = (x[0] - A * cs, x[1] - A * sn, x[2])
            R2 = R[0] ** 2 + R[1] ** 2 + R[2] ** 2
            iR = 1 / mp.sqrt(R2)
            i3, i5, i7 = iR**3, iR**5, iR**7
            # v[i][l] = e_ikl dl_k: the integrands are sum_l v[i][l] * (...)_l
            v = [
                [sum(_EPS[i, kk, ll] * dl[kk] for kk in range(3)) for ll in range(3)]
                for i in range(3)
            ]
            for i in range(3):
                B[i] += sum(v[i][ll] * R[ll] for ll in range(3)) * i3
                vR = sum(v[i][ll] * R[ll] for ll in range(3))
                for j in range(3):
                    G[i][j] += v[i][j] * i3 - 3 * vR * R[j] * i5
                    for m in range(j, 3):
                        t = -3 * (v[i][j] * R[m] + v[i][m] * R[j] + (vR if j == m else 0)) * i5
                        t += 15 * vR * R[j] * R[m] * i7
                        H[i][j][m] += t
        w = 2 * mp.pi / n * C
        B = [b * w for b in B]
        G = [[g * w for g in row] for row in G]
        for i in range(3):
            for j in range(3):
                for m in range(j, 3):
                    H[i][j][m] *= w
                    H[i][m][j] = H[i][j][m]
        return B, G, H


def as_float(B, G, H):
    """The mpf results of :func:`biot_savart` (or sums of them) as float64 arrays."""
    return (
        np.array([float(b) for b in B]),
        np.array([[float(g) for g in row] for row in G]),
        np.array([[[float(h) for h in row] for row in plane] for plane in H]),
    )


def loops(point, filaments, digits=40):
    """B, G, H (float64) of coaxial loops on the z axis, rows ``(z0, radius, current)``."""
    total = None
    for z0, a, current in filaments:
        B, G, H = biot_savart(point, a, current, z0, digits)
        if total is None:
            total = (B, G, H)
        else:
            with mp.workdps(mp.mp.dps + 700):  # exact enough sums of the mpf parts
                total = (
                    [p + q for p, q in zip(total[0], B, strict=True)],
                    [
                        [p + q for p, q in zip(r, s, strict=True)]
                        for r, s in zip(total[1], G, strict=True)
                    ],
                    [
                        [
                            [p + q for p, q in zip(r, s, strict=True)]
                            for r, s in zip(P, S, strict=True)
                        ]
                        for P, S in zip(total[2], H, strict=True)
                    ],
                )
    return as_float(*total)
