"""Independent references from magpylib: B from its own loop kernel, gradients from a
Richardson-extrapolated central difference of that B (4th order, ~1e-11 relative)."""

import numpy as np


def magpylib_B(coil, points):
    """B (n, 3) in T from magpylib's Circle sources built from the coil's filaments."""
    return coil.to_magpylib().getB(np.asarray(points, dtype=float))


def magpylib_gradient(coil, points, step):
    """G[k, i, j] = dB_i/dx_j (n, 3, 3) in T/m by Richardson-extrapolated central differences."""
    col = coil.to_magpylib()
    pts = np.asarray(points, dtype=float)
    G = np.empty((len(pts), 3, 3))
    for j in range(3):
        d = np.zeros(3)
        d[j] = step
        d1 = (col.getB(pts + d) - col.getB(pts - d)) / (2 * step)
        d2 = (col.getB(pts + 2 * d) - col.getB(pts - 2 * d)) / (4 * step)
        G[:, :, j] = (4 * d1 - d2) / 3
    return G
