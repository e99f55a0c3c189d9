"""The mixed kernel of :mod:`coilrod.rod._compiled` in vectorised numpy (nothing to compile).

The same equations with the same IEEE operations in the same order, over all members and nodes
at once, so that the results are bitwise those of the compiled kernel (a process's numbers do
not change when it compiles).  :func:`coilrod.rod._compiled.mixed_assembly` runs this until
compiling pays (about 2 s of compilation on a cold cache against ~0.5 ms per call here;
README, "Cold start").
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from ._libm import libm

__all__ = ["mixed_assembly_numpy"]

_D = 10  # row of the diagonal in band storage (KL + KU)
# band entries of node i >= 1, (row, column) relative to r = 5 i, in the order of _values
_ROWS = [2, 2, 2, 2, 2, 2, 0, 1, 0, 1, 0, 1, 0, 1, -2, -1, -2, -1, -2, -1, -2, -2, -1, -1]
_COLS = [-3, 2, 0, 1, 3, 4, 0, 1, -5, -4, -3, -3, 2, 2, -2, -1, 3, 4, 2, 2, 0, 1, 0, 1]


@lru_cache(maxsize=16)
def _pattern(k: int, n: int):
    """Band-storage (row, column) indices, each (k, 24, n - 1), of the entries of
    :func:`_values`; those of the moment rows' ``theta_{i+1}`` entries (k, n - 2); and those
    of the five clamp rows (5 k,)."""
    size = 5 * n
    r = 5 * np.arange(1, n)
    off = (size * np.arange(k))[:, None, None]
    dr = np.array(_ROWS)[None, :, None]
    dc = np.array(_COLS)[None, :, None]
    rows = np.broadcast_to(_D + dr - dc, (k, len(_ROWS), n - 1))
    cols = off + r[None, None, :] + dc
    up_cols = (size * np.arange(k))[:, None] + r[None, :-1] + 7
    fixed = np.array([0, 1, 2, size - 2, size - 1])
    clamp_cols = (size * np.arange(k)[:, None] + fixed).ravel()
    return (rows, cols), (np.full(up_cols.shape, _D - 5), up_cols), clamp_cols


def _node_terms(U, B, G, H, has_h, L, mu, k, n):
    """cos, sin, tau, m.b, f, g (times L) and df/dx (times L^2) at every node (k, n) each."""
    th = U[:, 2::5]
    # libm's cos and sin, as the compiled kernel calls them (numpy's own may differ in the last
    # bit on some CPUs, and the two kernels must agree bitwise; NaN at an infinite angle)
    c = libm(math.cos, th)
    si = libm(math.sin, th)
    a0 = c * mu[:, 0] - si * mu[:, 1]
    a1 = si * mu[:, 0] + c * mu[:, 1]
    p0 = -a1
    p1 = a0
    B = B.reshape(k, n, 3)
    G = G.reshape(k, n, 3, 3)
    t = {"cs": c, "sn": si}
    t["tau"] = p0 * B[..., 0] + p1 * B[..., 1]
    t["mb"] = a0 * B[..., 0] + a1 * B[..., 1]
    t["f0"] = L * (G[..., 0, 0] * a0 + G[..., 1, 0] * a1)
    t["f1"] = L * (G[..., 0, 1] * a0 + G[..., 1, 1] * a1)
    t["g0"] = L * (G[..., 0, 0] * p0 + G[..., 1, 0] * p1)
    t["g1"] = L * (G[..., 0, 1] * p0 + G[..., 1, 1] * p1)
    H = H.reshape(k, n, 3, 3, 3) if has_h else None
    for a in range(2):
        for b in range(2):
            t[f"d{a}{b}"] = (
                L * L * (H[..., 0, a, b] * a0 + H[..., 1, a, b] * a1) if has_h else np.zeros((k, n))
            )
    total = t["tau"] + t["mb"] + t["f0"] + t["f1"] + t["g0"] + t["g1"]
    total += t["d00"] + t["d01"] + t["d10"] + t["d11"] + U[:, 0::5] + U[:, 1::5]
    total += U[:, 3::5] + U[:, 4::5]
    return t, np.isfinite(total).all(axis=1)


def _residual(U, s, t, h, w, theta0, R, R1):
    """Fill R, R1 (k, 5n) as :func:`coilrod.rod._compiled._residual` does."""
    cs, sn = t["cs"], t["sn"]
    th, Fx, Fy = U[:, 2::5], U[:, 3::5], U[:, 4::5]
    hh = 0.5 * h
    R1[:] = 0.0
    R[:, 0:2] = U[:, 0:2]
    R[:, 5::5] = U[:, 5::5] - U[:, 0:-5:5] - hh * (cs[:, :-1] + cs[:, 1:])
    R[:, 6::5] = U[:, 6::5] - U[:, 1:-5:5] - hh * (sn[:, :-1] + sn[:, 1:])
    R[:, 2] = th[:, 0] - theta0
    bend = (th[:, 1:] - th[:, :-1]) / h
    bend[:, :-1] -= (th[:, 2:] - th[:, 1:-1]) / h[1:]
    cw = 0.5 * h * w[1:]
    tp0, tp1 = -sn[:, 1:], cs[:, 1:]
    r1 = -w[1:] * t["tau"][:, 1:] - (tp0 * cw * t["f0"][:, 1:] + tp1 * cw * t["f1"][:, 1:])
    R1[:, 7::5] = r1
    R[:, 7::5] = bend + s * r1 - (tp0 * w[1:] * Fx[:, 1:] + tp1 * w[1:] * Fy[:, 1:])
    r1x = -w[1:] * t["f0"][:, 1:]
    r1y = -w[1:] * t["f1"][:, 1:]
    R1[:, 3:-5:5] = r1x
    R1[:, 4:-5:5] = r1y
    R[:, 3:-5:5] = Fx[:, :-1] - U[:, 8::5] + s * r1x
    R[:, 4:-5:5] = Fy[:, :-1] - U[:, 9::5] + s * r1y
    R[:, -2] = Fx[:, -1]
    R[:, -1] = Fy[:, -1]
    return np.isfinite(R).all(axis=1)


def _values(U, s, t, h, w):
    """The 24 band entries of every node i >= 1 (k, 24, n - 1), in the order of ``_ROWS``."""
    cs, sn = t["cs"][:, 1:], t["sn"][:, 1:]
    csm, snm = t["cs"][:, :-1], t["sn"][:, :-1]
    f0, f1, g0, g1 = (t[q][:, 1:] for q in ("f0", "f1", "g0", "g1"))
    d00, d01, d10, d11 = (t[q][:, 1:] for q in ("d00", "d01", "d10", "d11"))
    wi = w[1:]
    cw = 0.5 * h * wi
    hh = 0.5 * h
    sw = s * wi
    tp0, tp1 = -sn, cs
    bend = 1.0 / h
    bend[:-1] += 1.0 / h[1:]
    one = np.ones_like(cs)
    v = [np.broadcast_to(-1.0 / h, cs.shape)]
    v.append(
        bend
        + s * wi * t["mb"][:, 1:]
        + cs * (wi * U[:, 8::5] + s * cw * f0)
        + sn * (wi * U[:, 9::5] + s * cw * f1)
        - s * cw * (tp0 * g0 + tp1 * g1)
    )
    v.append(-s * (wi * g0 + cw * (tp0 * d00 + tp1 * d10)))
    v.append(-s * (wi * g1 + cw * (tp0 * d01 + tp1 * d11)))
    v += [-wi * tp0, -wi * tp1, one, one, -one, -one]
    v += [hh * snm, -hh * csm, hh * sn, -hh * cs, one, one, -one, -one]
    v += [-sw * g0, -sw * g1, -sw * d00, -sw * d01, -sw * d10, -sw * d11]
    return np.stack(v, axis=1)


def mixed_assembly_numpy(U, S, B, G, H, has_h, L, mu, h, w, theta0, tangent, R, R1, ab, finite):
    """:func:`coilrod.rod._compiled.mixed_assembly` (same arguments, same results) in numpy."""
    k, n = U.shape[0], w.shape[0]
    s = S[:, None]
    with np.errstate(all="ignore"):
        t, ok = _node_terms(U, B, G, H, has_h, L, mu, k, n)
        ok &= _residual(U, s, t, h, w, theta0, R, R1)
        if tangent:
            (rows, cols), (up_rows, up_cols), clamp = _pattern(k, n)
            ab[rows, cols] = _values(U, s, t, h, w)
            ab[up_rows, up_cols] = -1.0 / h[1:]
            ab[_D, clamp] = 1.0
    finite[:] = ok
