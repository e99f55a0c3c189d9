"""Matplotlib field maps: |B| or the deviation from ideal, with the uniformity contour."""

from __future__ import annotations

import numpy as np

from ._validate import as_bool, as_choice, as_count, as_vector, positive
from .coaxial import coaxial_parts, winding_mask
from .field import Field, as_field
from .region import deviation

__all__ = ["plot_field_map", "plane_grid"]

_PLANES = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2), "yx": (1, 0), "zx": (2, 0), "zy": (2, 1)}


def plane_grid(plane: str, center, half_width: float, n: int = 121):
    """Points on a square grid in a coordinate plane.

    Parameters
    ----------
    plane : str
        Coordinate plane, e.g. "xy" (first letter horizontal).
    center : array-like, shape (3,)
        Centre of the square, m.
    half_width : float
        Half its side, m (> 0).
    n : int
        Points per side (>= 2).

    Returns
    -------
    points : ndarray, shape (n*n, 3)
        m.
    U, V : ndarray, shape (n, n)
        In-plane coordinates, m.
    (i, j) : tuple of int
        Indices of the plane's axes.
    """
    i, j = _PLANES[as_choice(plane, "plane", tuple(_PLANES))]
    c = as_vector(center, "center")
    hw = positive(half_width, "half_width")
    n = as_count(n, "n", 2)
    u = np.linspace(c[i] - hw, c[i] + hw, n)
    v = np.linspace(c[j] - hw, c[j] + hw, n)
    U, V = np.meshgrid(u, v)
    pts = np.tile(c, (U.size, 1))
    pts[:, i] = U.ravel()
    pts[:, j] = V.ravel()
    return pts, U, V, (i, j)


def plot_field_map(
    field: Field,
    plane: str = "xy",
    center=None,
    half_width: float | None = None,
    *,
    tol: float = 0.01,
    show: str = "deviation",
    n: int = 121,
    ax=None,
    streamlines: bool = True,
):
    """Map a field over a plane, with the contour where it departs ``tol`` from its ideal.

    Parameters
    ----------
    field : Field
        Coil, pair or system (must provide ``ideal()`` for ``show="deviation"``).
    plane : str
        Coordinate plane, e.g. "xy" (first letter horizontal).
    center : array-like, shape (3,), optional
        Centre of the map, m; default ``field.center``.
    half_width : float, optional
        Half the side of the square map, m; default the field's length scale.
    tol : float
        Relative tolerance of the uniformity contour (drawn in white), > 0.
    show : {"deviation", "magnitude"}
        Colour: log10 of the relative deviation from ideal, or |B| in mT.
    n : int
        Grid points per side (>= 2).
    ax : matplotlib Axes, optional
    streamlines : bool
        Overlay in-plane field lines.

    Returns
    -------
    matplotlib Axes
    """
    import matplotlib.pyplot as plt

    field = as_field(field)
    show = as_choice(show, "show", ("deviation", "magnitude"))
    streamlines = as_bool(streamlines, "streamlines")
    tol = positive(tol, "tol")
    center = getattr(field, "center", np.zeros(3)) if center is None else center
    half_width = field.length_scale if half_width is None else half_width
    pts, U, V, (i, j) = plane_grid(plane, center, half_width, n)
    mask = winding_mask(field, pts, 0.02)
    B = np.full((len(pts), 3), np.nan)
    B[~mask] = field.B(pts[~mask])
    dev = np.full(len(pts), np.nan)
    dev[~mask] = deviation(field, pts[~mask])
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 5))
    if show == "deviation":
        with np.errstate(divide="ignore"):
            data = np.log10(np.maximum(dev, 1e-12)).reshape(U.shape)
        im = ax.pcolormesh(U * 1e3, V * 1e3, data, cmap="viridis", shading="auto", vmin=-6, vmax=0)
        label = (
            "log10 |grad B - G_ideal| / |G_ideal|"
            if not np.any(field.ideal().B0)
            else "log10 |B - B_ideal| / |B_ideal(centre)|"
        )
    else:
        im = ax.pcolormesh(
            U * 1e3,
            V * 1e3,
            1e3 * np.linalg.norm(B, axis=1).reshape(U.shape),
            cmap="magma",
            shading="auto",
        )
        label = "|B| (mT)"
    plt.colorbar(im, ax=ax, label=label)
    cs = ax.contour(
        U * 1e3, V * 1e3, dev.reshape(U.shape), levels=[tol], colors="white", linewidths=1.5
    )
    ax.clabel(cs, fmt={tol: f"{100 * tol:g}%"}, fontsize=8)
    if streamlines:
        Bu = np.nan_to_num(B[:, i].reshape(U.shape))
        Bv = np.nan_to_num(B[:, j].reshape(U.shape))
        ax.streamplot(
            U * 1e3,
            V * 1e3,
            Bu,
            Bv,
            color=(1, 1, 1, 0.35),
            density=0.8,
            linewidth=0.6,
            arrowsize=0.6,
        )
    # where the windings cross this plane
    k = 3 - i - j
    t = np.linspace(0.0, 2 * np.pi, 721)
    for part in coaxial_parts(field):
        for z0, a, _ in part.filaments:
            ring = (
                part.center
                + z0 * part.axis
                + a * np.outer(np.cos(t), part.rotation[:, 0])
                + a * np.outer(np.sin(t), part.rotation[:, 1])
            )
            off = ring[:, k] - pts[0, k]
            cross = np.nonzero(np.sign(off[:-1]) != np.sign(off[1:]))[0]
            ax.plot(1e3 * ring[cross, i], 1e3 * ring[cross, j], "o", color="tab:orange", ms=4)
    ax.set_xlim(1e3 * U.min(), 1e3 * U.max())
    ax.set_ylim(1e3 * V.min(), 1e3 * V.max())
    ax.set_xlabel(f"{'xyz'[i]} (mm)")
    ax.set_ylabel(f"{'xyz'[j]} (mm)")
    ax.set_aspect("equal")
    ax.set_title(f"{type(field).__name__}: {100 * tol:g}% contour")
    return ax
