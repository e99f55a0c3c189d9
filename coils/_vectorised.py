"""The near-zone pass of :mod:`coils._compiled` in vectorised numpy (no compilation).

The same formulas, in the same order, as :func:`coils.loop.loop_point` and
:func:`coils._compiled._global` (the latter called as plain Python on arrays), over all points
at once, for the points of a call that all lie in the near zone of their group and clear of
every filament and winding cross-section.  It serves the first evaluations of a process: the
compiled pass costs about 3 s of compilation in a fresh environment, which pays only after
thousands of evaluations of the size a rod solve makes (:mod:`coils.coaxial` decides which pass
runs; the measured figures are in the README's cold-start section).  Results are bitwise those
of the compiled pass: the same IEEE operations in the same order (the compiled near zone does
not contract products into fused multiply-adds, so that this holds), so that a process gives
the same numbers before and after it compiles, and so do the workers of a distributed sweep.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ellipe, ellipkm1

from . import loop
from ._compiled import _global

__all__ = ["near_pass"]

#: :func:`coils._compiled._global` as plain Python: it runs on arrays as it does on floats.
global_entries = _global.py_func

_INV_PI = 1.0 / np.pi

# distinct entries (19: B 3, G 6, H 10) -> flat positions in B (3), G (9), H (27)
_G_SLOTS = np.array([0, 1, 2, 1, 3, 4, 2, 4, 5])
_H_SLOTS = np.array(
    [0, 1, 4, 1, 2, 5, 4, 5, 7, 1, 2, 5, 2, 3, 6, 5, 6, 8, 4, 5, 7, 5, 6, 8, 7, 8, 9]
)


def _padded_tables():
    """``coils.loop.SERIES`` with every table's coefficients beyond its length set to 0, so
    that a Horner pass over all columns gives the compiled sums exactly (the series about 0,
    whose length depends on w, is cut per point in :func:`_series_phi`)."""
    tab = loop.SERIES.copy()
    cols = np.arange(tab.shape[1])
    tab[:48][cols[None, :] >= loop.SERIES_LENGTHS[:48, None]] = 0.0
    return tab


_SERIES = _padded_tables()


def _series_rows(w):
    """Rows of ``SERIES`` chosen as :func:`coils.loop._series_table` does (``0 <= w < 3/4``)."""
    bits = w.view(np.int64)
    E = bits >> 52
    idx = np.full(w.shape, 48, dtype=np.int64)
    top = E == 1022
    idx[top] = (bits[top] >> 47) & 31
    mid = E == 1021
    idx[mid] = 16 + ((bits[mid] >> 49) & 7)
    low = ~top & ~mid & (w >= loop.W_TAYLOR)
    idx[low] = 24 + 4 * (1020 - E[low]) + ((bits[low] >> 50) & 3)
    return idx


def _series_phi(w, want_H):
    """phi, phi', phi'' (and F, F') by the power series (``w < 3/4``)."""
    idx = _series_rows(w)
    delta = (w - loop.SERIES_CENTRES[idx])[:, None]
    coef = _SERIES[idx]  # (m, terms, 4)
    about0 = idx == 48  # the series about 0: as many terms as the compiled pass takes
    if about0.any():
        E = w[about0].view(np.int64) >> 52
        n = loop.SERIES_TERMS[np.minimum(1022 - E, 64)]
        coef[about0] *= (np.arange(coef.shape[1]) < n[:, None])[:, :, None]
    F = np.zeros((w.size, 4))
    for j in range(coef.shape[1] - 1, -1, -1):  # F = F delta + c_j, in place (same roundings)
        F *= delta
        F += coef[:, j]
    if not want_H:
        F[:, 3] = 0.0
    F0, F1, F2, F3 = F.T
    return 0.75 * F0 + w * F1, 1.75 * F1 + w * F2, 2.75 * F2 + w * F3, F0, F1


def _elliptic_phi(t, w, alpha2, inv_s, want_H):
    """phi, phi', phi'' and K, E by the closed forms (``w >= 3/4``)."""
    v = alpha2 * inv_s
    p = 1.0 + t
    K = ellipkm1(v / p)
    E = ellipe(2.0 * t / p)
    Ev = E / v
    sp = np.sqrt(p)
    f0 = 2.0 * _INV_PI * (Ev - K) / (w * sp)
    f1 = ((2.0 - 2.5 * w) * K + 2.0 * (2.0 * w - 1.0) * Ev) * _INV_PI / (v * w * w * p * sp)
    f2 = np.zeros_like(w)
    if want_H:
        f2 = ((93.0 * w * (w - 1.0) + 32.0) * Ev - (45.0 * w * w - 69.0 * w + 32.0) * K) / (
            8.0 * np.pi * v * v * w * w * w * p * p * sp
        )
    return f0, f1, f2, K, E


def loop_arrays(a, A, C2, u, rho, z, want_B, want_G, want_H):
    """:func:`coils.loop.loop_point` at many (filament, point) pairs: all arguments arrays of
    one shape (m,); returns the six invariants ``Q, Bz, b1, q1, c1, d1`` (m,) each (zeros
    where not wanted)."""
    z2 = z * z
    a2 = a * a
    s = a2 + u + z2
    inv_s = 1.0 / s
    alpha2 = (rho - a) * (rho - a) + z2
    t = np.minimum(2.0 * a * rho * inv_s, 1.0)
    w = t * t
    h = (a - rho) * (a + rho) + z2
    f0, f1, f2, Bz = (np.empty_like(w) for _ in range(4))
    ser = w < loop.W_SERIES
    ell = ~ser
    if ser.all():  # the common case (clear of the wires): views instead of masked copies
        ser = slice(None)
    if isinstance(ser, slice) or ser.any():
        ws = w[ser]
        f0[ser], f1[ser], f2[ser], F0, F1 = _series_phi(ws, want_H)
        if want_B:
            iv = inv_s[ser]
            Bz[ser] = (
                0.5
                * A[ser]
                * iv
                * np.sqrt(iv)
                * ((1.0 - 1.5 * u[ser] * iv) * F0 + ws * h[ser] * iv * F1)
            )
    if ell.any():
        f0[ell], f1[ell], f2[ell], K, E = _elliptic_phi(
            t[ell], w[ell], alpha2[ell], inv_s[ell], want_H
        )
        if want_B:
            ae, re, ze, ar = a[ell], rho[ell], z2[ell], alpha2[ell]
            Bz[ell] = (
                C2[ell]
                * (((ae - re) * (ae + re) - ze) * E + ar * K)
                / (ar * np.sqrt(s[ell] + 2.0 * ae * re))
            )
    if not want_B:
        Bz[:] = 0.0
    inv_s3 = inv_s * inv_s * inv_s
    S = inv_s * inv_s * np.sqrt(inv_s)
    S7 = S * inv_s
    P = S * f0
    Q = A * z * P
    zero = np.zeros_like(w)
    if not (want_G or want_H):
        return Q, Bz, zero, zero, zero, zero
    w_u = 4.0 * a2 * h * inv_s3
    w_z = -16.0 * a2 * u * z * inv_s3
    S_u = -2.5 * S7
    S_z = -5.0 * z * S7
    P_u = S_u * f0 + S * f1 * w_u
    P_z = S_z * f0 + S * f1 * w_z
    b1 = A * (P + z * P_z)
    q1 = 2.0 * A * z * P_u
    if not want_H:
        return Q, Bz, b1, q1, zero, zero
    S9 = S7 * inv_s
    inv_s4 = inv_s3 * inv_s
    w_uz = 16.0 * a2 * z * (2.0 * u - a2 - z2) * inv_s4
    w_zz = -16.0 * a2 * u * (s - 6.0 * z2) * inv_s4
    S_zz = -5.0 * S7 + 35.0 * z2 * S9
    S_uz = 17.5 * z * S9
    P_zz = S_zz * f0 + 2.0 * S_z * f1 * w_z + S * (f2 * w_z * w_z + f1 * w_zz)
    P_uz = S_uz * f0 + S_u * f1 * w_z + S_z * f1 * w_u + S * (f2 * w_u * w_z + f1 * w_uz)
    c1 = A * (2.0 * P_z + z * P_zz)
    d1 = 2.0 * A * (P_u + z * P_uz)
    return Q, Bz, b1, q1, c1, d1


def near_pass(pts, center, axis, fil, wind, params, flags, factor, B, G, H) -> bool:
    """Add the field of one coaxial group to B (n, 3), G (n, 9), H (n, 27) as the compiled
    pass does (arguments as for :func:`coils._compiled._make_kernel`), if every point lies in
    the near zone, clear of the filaments and windings, with a finite result; otherwise leave
    the outputs untouched and return False (the caller runs the compiled pass, which handles
    the far zone and names the offending points)."""
    want_B, want_G, want_H = bool(flags & 1), bool(flags & 2), bool(flags & 4)
    inv_L, fB, fG, fH = params[0], factor * params[1], factor * params[2], factor * params[3]
    with np.errstate(all="ignore"):
        d = pts - center
        dx, dy, dz = d.T
        if not np.all(dx * dx + dy * dy + dz * dz <= params[4]):  # far, or not finite
            return False
        dx, dy, dz = dx * inv_L, dy * inv_L, dz * inv_L
        nx, ny, nz = axis
        zl = dx * nx + dy * ny + dz * nz
        r = (dx - zl * nx, dy - zl * ny, dz - zl * nz)
        u = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
        rho = np.sqrt(u)
        for z0, a, hw, hh in wind:
            if np.any((np.abs(zl - z0) < hw) & (np.abs(rho - a) < hh)):
                return False
        # all filaments at once: arrays (f, n), flattened
        z0, a, A, C2, inv_a2 = (np.repeat(col, len(pts)) for col in fil.T)
        zi = np.tile(zl, len(fil)) - z0
        rho_f = np.tile(rho, len(fil))
        if not np.all(((rho_f - a) * (rho_f - a) + zi * zi) * inv_a2 >= params[7]):
            return False
        parts = loop_arrays(a, A, C2, np.tile(u, len(fil)), rho_f, zi, want_B, want_G, want_H)
        inv = []
        for x in parts:  # summed filament by filament, as the compiled pass does
            acc = np.zeros(len(pts))
            for row in x.reshape(len(fil), -1):
                acc += row
            inv.append(acc)
        Q, Bz, b1, q1, c1, d1 = inv
        q2 = np.where(u > 1e-200, -(4.0 * q1 + c1) / u, 0.0) if want_H else 0.0
        v = global_entries(*r, nx, ny, nz, u, Q, Bz, b1, q1, q2, c1, d1, want_G, want_H)
        out = []
        if want_B:
            out.append((B, fB * np.column_stack(v[0:3])))
        if want_G:
            out.append((G, fG * np.column_stack(v[3:9])[:, _G_SLOTS]))
        if want_H:
            out.append((H, fH * np.column_stack(v[9:19])[:, _H_SLOTS]))
        if not all(np.all(np.isfinite(x)) for _, x in out):
            return False
    for target, x in out:
        target += x
    return True
