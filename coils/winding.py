"""Filament models of a coil's winding cross-section.

A multi-turn coil of ``turns`` turns carrying ``current`` has ampere-turns ``N I`` spread over a
rectangular winding cross-section ``width`` (along the axis) by ``height`` (radial), centred on
the mean radius.  Two models place circular filaments in that section:

* :func:`gauss_filaments`: tensor Gauss-Legendre quadrature of a uniform current density -- a
  few filaments reproduce the field of the distributed winding to high order away from it;
* :func:`turn_filaments`: one filament per turn on a regular layer grid (the turn-by-turn model
  used as the reference in the filament-count study).
"""

from __future__ import annotations

import numpy as np

from ._validate import as_count, finite_scalar, positive

__all__ = ["gauss_filaments", "turn_filaments", "winding_section"]


def winding_section(radius: float, width, height) -> tuple[float, float]:
    """Validated winding cross-section ``(width, height)`` (m, > 0) of a coil of mean radius
    ``radius`` (m): the section must not reach the axis, ``height < 2 radius``."""
    width = positive(width, "winding width")
    height = positive(height, "winding height")
    if height >= 2 * radius:
        raise ValueError(f"winding height {height} m must be below twice the radius {radius} m")
    return width, height


def _section(z0, radius, width, height) -> tuple[float, float, float, float]:
    """Validated (z0 m, radius m > 0, width m > 0, height m in (0, 2 radius))."""
    z0 = finite_scalar(z0, "z0")
    radius = positive(radius, "radius")
    return (z0, radius, *winding_section(radius, width, height))


def gauss_filaments(
    z0: float,
    radius: float,
    ampere_turns: float,
    width: float,
    height: float,
    n_axial: int = 2,
    n_radial: int = 2,
) -> np.ndarray:
    """Gauss-Legendre filaments of a uniform rectangular winding.

    Parameters
    ----------
    z0 : float
        Axial position of the winding centre in the coil frame, m.
    radius : float
        Mean radius, m.
    ampere_turns : float
        Total current through the cross-section, ``N I`` in A.
    width, height : float
        Winding extent along the axis and radially, m.
    n_axial, n_radial : int
        Quadrature points in each direction.

    Returns
    -------
    ndarray, shape (n_axial * n_radial, 3)
        Rows ``(z, radius, current)`` in (m, m, A).  Currents are weighted so that they sum to
        ``ampere_turns``; the radial weights are plain Gauss weights (uniform current density in
        the section, as in a layer-wound coil).
    """
    z0, radius, width, height = _section(z0, radius, width, height)
    ampere_turns = finite_scalar(ampere_turns, "ampere_turns")
    na = as_count(n_axial, "n_axial")
    nr = as_count(n_radial, "n_radial")
    xa, wa = np.polynomial.legendre.leggauss(na)
    xr, wr = np.polynomial.legendre.leggauss(nr)
    Z, Rr = np.meshgrid(z0 + 0.5 * width * xa, radius + 0.5 * height * xr, indexing="ij")
    W = np.outer(wa, wr) / 4.0
    return np.column_stack([Z.ravel(), Rr.ravel(), ampere_turns * W.ravel()])


def turn_filaments(
    z0: float,
    radius: float,
    current: float,
    width: float,
    height: float,
    n_axial: int,
    n_radial: int,
) -> np.ndarray:
    """One filament per turn: ``n_axial`` turns per layer, ``n_radial`` layers.

    Turns sit at the centres of an ``n_axial x n_radial`` grid of equal wire cells filling the
    winding section.

    Parameters
    ----------
    z0 : float
        Axial position of the winding centre in the coil frame, m.
    radius : float
        Mean radius, m.
    current : float
        Current of each turn, A.
    width, height : float
        Winding extent along the axis and radially, m (``height < 2 radius``).
    n_axial, n_radial : int
        Turns per layer and layers.

    Returns
    -------
    ndarray, shape (n_axial * n_radial, 3)
        Rows ``(z, radius, current)`` in (m, m, A).
    """
    z0, radius, width, height = _section(z0, radius, width, height)
    current = finite_scalar(current, "current")
    na = as_count(n_axial, "n_axial")
    nr = as_count(n_radial, "n_radial")
    za = z0 + width * ((np.arange(na) + 0.5) / na - 0.5)
    rr = radius + height * ((np.arange(nr) + 0.5) / nr - 0.5)
    Z, Rr = np.meshgrid(za, rr, indexing="ij")
    return np.column_stack([Z.ravel(), Rr.ravel(), np.full(Z.size, current)])
