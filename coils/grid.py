"""Gridded cache of a field over a box: tricubic Hermite interpolation with consistent derivatives.

:class:`GriddedField` samples a (costly) field once on a regular grid of an axis-aligned box and
answers later queries by interpolation.  Each component ``B_i`` is interpolated by a tricubic
Hermite polynomial per cell (Lekien & Marsden 2005 style): in local coordinates
``u, v, w in [0, 1]`` of a cell of size ``hx x hy x hz``

    B_i(u, v, w) = sum_{a, b, c = 0..3}  C[cell, i, a, b, c]  u^a v^b w^c,

whose 64 coefficients match, at the 8 corners, the value, the three first derivatives, the three
mixed second derivatives ``d2/dxdy, d2/dxdz, d2/dydz`` and ``d3/dxdydz``.  The interpolant is
C1 across cells.  The gradient and hessian returned are the exact first and second derivatives of
that polynomial, so B, gradient and hessian are mutually consistent (the gradient is the
derivative of the B the solver sees, which Newton tangents need).

Node data: B and its gradient are taken exactly from the wrapped field
(``field.B_and_gradient``); the mixed derivatives are second-order central differences of the
exact gradient along the grid, averaged over the equivalent index orders.  The grid is padded by
one ghost layer of nodes outside the box so the differences are central at the box faces too
(one-sided second order if the field cannot be evaluated there, e.g. on a winding).  Their
``O(h^2)`` error enters the interpolant multiplied by the size ``O(h^2)`` (or ``O(h^3)``) of
the cross-derivative basis functions, so the interpolation error stays ``O(h^4)`` for B and
``O(h^3)`` for the gradient (``O(h^2)`` for the hessian), the orders of tricubic Hermite
interpolation with exact data.  ``cross="hessian"`` takes the second mixed derivatives from
``field.hessian`` instead (closed form for coils; same order).
"""

from __future__ import annotations

import math

import numpy as np

from ._immutable import sealed
from ._validate import (
    as_choice,
    as_count,
    as_points,
    as_triple,
    as_vector,
    positive,
)
from .clearance import Box, check_clear
from .field import Field, as_field

__all__ = ["GriddedField"]

#: Points interpolated per chunk (the gathered coefficients take 1.5 kB per point).
GRID_CHUNK = 4096
#: Sample points used by the error estimate: every cell up to this many cells, else a subset.
CHECK_CELLS = 20000
#: Cells nearest the windings (filament circles) checked densely by the error estimate.
NEAR_CELLS = 256
#: Local coordinates (per axis) of the dense check of those cells: the peaks of the value
#: (1/2) and derivative (1/2 +- sqrt(3)/6) errors of a 1D cubic Hermite interpolant, points
#: between them and on the faces (the box faces nearest a winding hold the largest gradient
#: errors); 7^3 = 343 points per cell.
_DENSE = np.array([0.0, 0.2113248654, 0.36, 0.5, 0.64, 0.7886751346, 1.0])
#: Local coordinate where the derivative error of a 1D cubic Hermite interpolant peaks.
_GAUSS_OFFSET = math.sqrt(3.0) / 6.0
#: Bytes of coefficients per cell (3 components x 64 monomials, float64).
CELL_BYTES = 3 * 64 * 8


def _hermite_matrix() -> np.ndarray:
    """The 64 x 64 map from corner data to monomial coefficients of a tricubic.

    Derived from the monomial basis: row ``8 * corner + deriv`` of the forward matrix holds the
    derivative ``d^(dx+dy+dz)/(du^dx dv^dy dw^dz)`` of every monomial ``u^a v^b w^c`` (column
    ``16 a + 4 b + c``) at ``corner = (cx, cy, cz) in {0, 1}^3`` (``corner = 4 cx + 2 cy + cz``,
    ``deriv = 4 dx + 2 dy + dz``).  The forward matrix is inverted; its inverse has integer
    entries, which are rounded exactly.
    """
    p = np.arange(4)
    # T[d, x, p]: d-th derivative (d = 0, 1) of t^p at t = x (x = 0, 1)
    T = np.zeros((2, 2, 4))
    for x in (0, 1):
        T[0, x] = float(x) ** p
        T[1, x, 1:] = p[1:] * float(x) ** (p[1:] - 1)
    # forward[cx, cy, cz, dx, dy, dz, a, b, c]
    forward = np.einsum(
        "upa,vqb,wrc->uvwpqrabc", T.transpose(1, 0, 2), T.transpose(1, 0, 2), T.transpose(1, 0, 2)
    ).reshape(64, 64)
    inverse = np.linalg.inv(forward)
    rounded = np.rint(inverse)
    if not np.allclose(inverse, rounded, atol=1e-9):  # pragma: no cover - a derivation bug
        raise RuntimeError("tricubic Hermite inverse is not integer")
    return rounded


_HERMITE_INV = _hermite_matrix()


def _cell_count(nodes: np.ndarray) -> float:
    """Cells of a grid with ``nodes`` (3,) nodes per axis, as a float (inf rather than overflow)."""
    return math.prod(float(n) - 1.0 for n in nodes)


def _size(nbytes: float) -> str:
    """A byte count for humans: '307 MB', '1.5 TB'."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes:.0f} B"


def _powers(t: np.ndarray, order: int) -> np.ndarray:
    """Monomials ``t^p`` (p = 0..3) and their first ``order`` derivatives: shape (n, order+1, 4)."""
    n = t.shape[0]
    P = np.zeros((n, order + 1, 4))
    t2 = t * t
    P[:, 0, 0] = 1.0
    P[:, 0, 1] = t
    P[:, 0, 2] = t2
    P[:, 0, 3] = t2 * t
    if order >= 1:
        P[:, 1, 1] = 1.0
        P[:, 1, 2] = 2.0 * t
        P[:, 1, 3] = 3.0 * t2
    if order >= 2:
        P[:, 2, 2] = 2.0
        P[:, 2, 3] = 6.0 * t
    return P


class GriddedField(Field):
    """A field cached on a regular grid over a box and interpolated (tricubic Hermite).

    Parameters
    ----------
    field : Field
        The field to cache (a coil, a pair, a :class:`~coils.CoilSystem`, ...).
    lower, upper : array-like, shape (3,)
        Opposite corners of the axis-aligned box, m (``lower < upper`` on every axis).
    shape : int or array-like of 3 ints, optional
        Grid nodes per axis (>= 2).  Give at most one of ``shape`` and ``spacing``.
    spacing : float or array-like, shape (3,), optional
        Largest node spacing per axis, m; the box is divided evenly so the spacing used
        (:attr:`spacing`) is at most this.
    tol : float
        Used when neither ``shape`` nor ``spacing`` is given: the grid is refined until the
        estimated relative errors of B and of the gradient (:attr:`error_B`,
        :attr:`error_gradient`) are at most ``tol`` and ``tol_gradient``.
    tol_gradient : float, optional
        Tolerance of the gradient's relative error (default: ``tol``).  The gradient converges
        one order slower than B, and near the centre of a Helmholtz pair it is small compared
        with ``|B| / R``, so its relative error is the harder target.
    outside : {"raise", "direct"}
        Points outside the box raise ``ValueError`` naming the point, or (``"direct"``) are
        evaluated with the wrapped field.
    cross : {"grid", "hessian"}
        Source of the mixed second derivatives at the nodes: central differences of the exact
        gradient along the grid (default, no extra evaluations) or ``field.hessian``.
    max_cells : int
        Largest grid (cells) any construction may build -- explicit ``shape`` or ``spacing``
        too; each cell stores :data:`CELL_BYTES` = 1.5 kB (a build briefly needs about three
        times that).  A larger request raises ``ValueError`` before anything is allocated.

    Raises
    ------
    ValueError
        If the box meets a winding cross-section or comes within ``ON_WIRE_TOL`` x radius of a
        filament of ``field`` (an exact test, :mod:`coils.clearance`, made before any
        sampling: the direct field is undefined there and a grid could step over a thin
        winding), if the grid would exceed ``max_cells``, or on bad parameters.

    Attributes
    ----------
    shape : ndarray of int, shape (3,)
        Nodes per axis.
    spacing : ndarray, shape (3,)
        Node spacing per axis, m.
    error_B, error_gradient : float
        Estimated relative interpolation errors, ``max |B - B_field| / max |B_field|`` and
        ``max |G - G_field| / max |G_field|`` (largest entries over the sample points), measured
        against the wrapped field at three points per cell: the centre (where the error of a
        cubic peaks), a point where the error of its derivative peaks (``1/2 +- sqrt(3)/6`` on
        each axis, random signs) and a uniformly random point; over every cell, or a random
        subset of :data:`CHECK_CELLS` cells for larger grids.  And where the field is least
        smooth, every one of the :data:`NEAR_CELLS` cells nearest a filament (winding) of
        the field, on a 7 x 7 x 7 lattice of points each (the errors grow like ``(h/d)^4``
        and ``(h/d)^3`` at a distance ``d`` from a filament).
    ghost : bool
        True if the mixed derivatives used a ghost layer of nodes one spacing outside the box
        (central differences everywhere); False if the field could not be evaluated there.

    Notes
    -----
    Immutable (:mod:`coils._immutable`): its arrays are read-only and ``replace(**changes)``
    builds a new grid (e.g. ``grid.replace(field=system.with_currents(I))``).

    Interpolation error ``O(h^4)`` for B, ``O(h^3)`` for the gradient and ``O(h^2)`` for the
    hessian (node data: exact B and gradient, mixed derivatives to ``O(h^2)``; see the module
    docstring).  The gradient is the exact derivative of the interpolated B and the hessian that
    of the interpolated gradient (piecewise, discontinuous across cell faces).

    Examples
    --------
    >>> from coils import GriddedField, MaxwellPair
    >>> pair = MaxwellPair(radius=0.1, turns=100, current=2.0, axis="y")
    >>> grid = GriddedField(pair, lower=(-0.02, -0.02, -0.02), upper=(0.02, 0.02, 0.02))
    >>> bool(grid.error_B <= 1e-6 and grid.error_gradient <= 1e-6)
    True
    >>> B, G = grid.B_and_gradient([[0.0, 0.01, 0.0]])
    >>> round(float(B[0, 1]), 10), round(float(G[0, 1, 1]), 7)   # T, T/m; direct: same digits
    (0.0001611664, 0.0161133)
    """

    uniform = False
    linear = False
    _immutable = True

    def __init__(
        self,
        field: Field,
        lower,
        upper,
        shape=None,
        spacing=None,
        tol: float = 1e-6,
        tol_gradient: float | None = None,
        outside: str = "raise",
        cross: str = "grid",
        max_cells: int = 200_000,
    ):
        self.field = as_field(field)
        self.lower = sealed(as_vector(lower, "lower"))
        self.upper = sealed(as_vector(upper, "upper"))
        if np.any(self.lower >= self.upper):
            raise ValueError(
                f"lower must be below upper on every axis; got lower={self.lower.tolist()}, "
                f"upper={self.upper.tolist()}"
            )
        thin = (self.upper - self.lower) <= 1e-9 * np.maximum(
            np.abs(self.lower), np.abs(self.upper)
        )
        with np.errstate(over="ignore", divide="ignore"):
            thin |= ~np.isfinite(1.0 / (self.upper - self.lower))
        if thin.any():
            raise ValueError(
                f"the box must be wider than 1e-9 of its coordinates on every axis (its "
                f"spacing must be representable); got lower={self.lower.tolist()}, "
                f"upper={self.upper.tolist()}"
            )
        self.outside = as_choice(outside, "outside", ("raise", "direct"))
        self.cross = as_choice(cross, "cross", ("grid", "hessian"))
        if shape is not None and spacing is not None:
            raise ValueError("give at most one of shape and spacing")
        self.tol = positive(tol, "tol")
        self.tol_gradient = (
            self.tol if tol_gradient is None else positive(tol_gradient, "tol_gradient")
        )
        self.max_cells = as_count(max_cells, "max_cells")
        extent = self.upper - self.lower
        self._slack = 1e-12 * extent
        nodes = None
        if shape is not None:
            nodes = as_triple(shape, "shape", integer=True)
            if np.any(nodes < 2):
                raise ValueError(f"shape needs at least 2 nodes per axis; got {nodes.tolist()}")
            nodes = self._within_limit(nodes, f"shape={shape!r}")
        elif spacing is not None:
            h = as_triple(spacing, "spacing")
            nodes = self._within_limit(self._nodes_for(h), f"spacing={spacing!r} m")
        # exact geometry, before any sampling: nodes could step over a thin winding
        check_clear(field, Box(self.lower, self.upper), what="the grid box")
        if nodes is None:
            self._refine_to_tol()
        else:
            self._build(nodes)
            self._store_error_estimate()

    # -- construction ---------------------------------------------------------------------------
    def _nodes_for(self, h: np.ndarray) -> np.ndarray:
        """Nodes per axis (floats: a tiny spacing gives a huge count, not an overflow)."""
        extent = self.upper - self.lower
        with np.errstate(over="ignore"):
            return np.maximum(np.ceil(extent / h - 1e-9) + 1, 2)

    def _within_limit(self, nodes: np.ndarray, asked: str) -> np.ndarray:
        """Node counts (3,) as ints, or ValueError if the grid exceeds ``max_cells`` cells."""
        cells = _cell_count(nodes)
        if cells > self.max_cells:
            count = f"{cells:.0f}" if cells < 1e15 else f"{cells:.3g}"
            raise ValueError(
                f"{asked} asks for {count} cells ({_size(cells * CELL_BYTES)} of coefficients), "
                f"above max_cells={self.max_cells} ({_size(self.max_cells * CELL_BYTES)}); "
                f"use a coarser grid or a smaller box, or raise max_cells"
            )
        return nodes.astype(int)

    def _refine_to_tol(self) -> None:
        extent = self.upper - self.lower
        h = np.full(3, extent.max() / 8.0)
        for _ in range(12):
            nodes = self._nodes_for(h)
            cells = _cell_count(nodes)
            if cells > self.max_cells:
                # largest grid of this aspect within the limit, tried once before giving up
                shrink = (cells / self.max_cells) ** (1.0 / 3.0)
                nodes = np.maximum(np.floor((nodes - 1) / shrink) + 1, 2)
                at_limit = True
            else:
                at_limit = False
            self._build(self._within_limit(nodes, "the automatic refinement"))
            eb, eg = self._store_error_estimate()
            if eb <= self.tol and eg <= self.tol_gradient:
                return
            if at_limit:
                break
            # h^4 law for B, h^3 for the gradient; 10% margin, at most 2.5x finer per step
            factor = 0.9 * min(
                (self.tol / max(eb, 1e-300)) ** 0.25,
                (self.tol_gradient / max(eg, 1e-300)) ** (1.0 / 3.0),
            )
            h = self.spacing * min(max(factor, 0.4), 0.9)
        raise ValueError(
            f"tol={self.tol:g}, tol_gradient={self.tol_gradient:g} not reached: the grid of "
            f"{self.shape.tolist()} nodes ({self.n_cells} cells, max_cells={self.max_cells}) "
            f"gives error_B={self.error_B:.3g}, error_gradient={self.error_gradient:.3g}; "
            f"loosen tol, shrink the box (keep it away from the windings) or raise max_cells"
        )

    def _build(self, nodes: np.ndarray) -> None:
        nodes = np.asarray(nodes, dtype=int)
        self.shape = nodes
        self.cells = nodes - 1
        self.n_cells = int(np.prod(self.cells))
        self.spacing = (self.upper - self.lower) / self.cells
        axes = [
            np.linspace(lo, hi, n) for lo, hi, n in zip(self.lower, self.upper, nodes, strict=False)
        ]
        B, G, ghost = self._node_data(axes)
        self.ghost = ghost
        nx, ny, nz = nodes
        hx, hy, hz = self.spacing

        def diff(f, axis):
            n = f.shape[axis]
            return np.gradient(f, self.spacing[axis], axis=axis, edge_order=2 if n >= 3 else 1)

        def crop(f):
            return f[1:-1, 1:-1, 1:-1] if ghost else f

        if self.cross == "hessian":
            X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
            H = self.field.hessian(X).reshape(nx, ny, nz, 3, 3, 3)
            fxy, fxz, fyz = H[..., 0, 1], H[..., 0, 2], H[..., 1, 2]
            fxyz = (diff(fxy, 2) + diff(fxz, 1) + diff(fyz, 0)) / 3.0
        else:
            gx, gy, gz = G[..., 0], G[..., 1], G[..., 2]  # each (nx, ny, nz, 3)
            fxy = 0.5 * (diff(gx, 1) + diff(gy, 0))
            fxz = 0.5 * (diff(gx, 2) + diff(gz, 0))
            fyz = 0.5 * (diff(gy, 2) + diff(gz, 1))
            fxyz = (diff(diff(gx, 1), 2) + diff(diff(gy, 0), 2) + diff(diff(gz, 0), 1)) / 3.0
            B, G, fxy, fxz, fyz, fxyz = map(crop, (B, G, fxy, fxz, fyz, fxyz))
        # node data in local (unit-cell) units, deriv index 4 dx + 2 dy + dz
        data = np.stack(
            [
                B,
                G[..., 2] * hz,
                G[..., 1] * hy,
                fyz * (hy * hz),
                G[..., 0] * hx,
                fxz * (hx * hz),
                fxy * (hx * hy),
                fxyz * (hx * hy * hz),
            ],
            axis=-1,
        )  # (nx, ny, nz, 3, 8)
        cx, cy, cz = self.cells
        corners = [
            data[i : i + cx, j : j + cy, k : k + cz] for i in (0, 1) for j in (0, 1) for k in (0, 1)
        ]
        cell_data = np.stack(corners, axis=3)  # (cx, cy, cz, 8 corners, 3, 8 derivs)
        cell_data = cell_data.transpose(0, 1, 2, 4, 3, 5).reshape(self.n_cells * 3, 64)
        self._coef = cell_data @ _HERMITE_INV.T  # (n_cells * 3, 64), monomial 16 a + 4 b + c
        self._coef = self._coef.reshape(self.n_cells, 192)

    def _node_data(self, axes):
        """Exact B and gradient at the nodes, with one ghost layer outside the box if possible.

        The ghost layer lets the mixed derivatives use central differences at the box faces;
        where the wrapped field cannot be evaluated there (a winding), one-sided differences
        are used instead.  Returns ``(B, G, ghost)`` shaped on the (possibly padded) grid.
        """
        if self.cross == "grid":
            padded = [
                np.concatenate([[a[0] - h], a, [a[-1] + h]])
                for a, h in zip(axes, self.spacing, strict=True)
            ]
            try:
                return (*self._sample(padded), True)
            except ValueError:
                pass
        return (*self._sample(axes), False)

    def _sample(self, axes):
        shape = tuple(len(a) for a in axes)
        X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        B, G = self.field.B_and_gradient(X)
        return B.reshape(*shape, 3), G.reshape(*shape, 3, 3)

    @property
    def nbytes(self) -> int:
        """Memory held by the cell coefficients, bytes."""
        return int(self._coef.nbytes)

    @property
    def length_scale(self) -> float:
        return self.field.length_scale

    # -- error estimate ------------------------------------------------------------------------
    def error_estimate(self, points=None, seed: int = 0) -> tuple[float, float]:
        """Estimate the relative interpolation errors of B and of the gradient.

        Parameters
        ----------
        points : array-like, shape (n, 3), optional
            Points (m, inside the box) to compare at.  Default: three points per cell (see
            :attr:`error_B`), over all cells or a random subset of :data:`CHECK_CELLS`, and
            343 points in each of the :data:`NEAR_CELLS` cells nearest a winding.
        seed : int
            Seed of the random choices.

        Returns
        -------
        error_B, error_gradient : float
            ``max |B - B_field| / max |B_field|`` and the same for the gradient (largest entries
            over the points).  The construction's estimate (``points`` None, ``seed`` 0) is
            :attr:`error_B` and :attr:`error_gradient`; later calls do not change them (the
            grid is immutable).
        """
        rng = np.random.default_rng(as_count(seed, "seed", 0))
        if points is None:
            if self.n_cells <= CHECK_CELLS:
                cells = np.arange(self.n_cells)
            else:
                cells = rng.choice(self.n_cells, CHECK_CELLS, replace=False)
            ijk = np.stack(np.unravel_index(cells, self.cells), axis=1)
            signs = rng.choice([-1.0, 1.0], size=ijk.shape)
            local = np.concatenate(
                [
                    np.full(ijk.shape, 0.5),
                    0.5 + _GAUSS_OFFSET * signs,
                    rng.uniform(0.0, 1.0, ijk.shape),
                ]
            )
            pts = self.lower + (np.concatenate([ijk, ijk, ijk]) + local) * self.spacing
            near = self._cells_nearest_windings(NEAR_CELLS)
            if near.size:  # where the field is least smooth: every one of them, densely
                ijk = np.stack(np.unravel_index(near, self.cells), axis=1)
                lattice = np.stack(np.meshgrid(_DENSE, _DENSE, _DENSE, indexing="ij"), -1)
                local = lattice.reshape(-1, 3)
                dense = (ijk[:, None, :] + local[None, :, :]).reshape(-1, 3)
                pts = np.concatenate([pts, self.lower + dense * self.spacing])
        else:
            pts = as_points(points)
        B, G, _ = self._interpolate(self._check_inside(pts, force_raise=True), 1)
        Bf, Gf = self.field.B_and_gradient(pts)
        return _relative(B - Bf, Bf), _relative(G - Gf, Gf)

    def _store_error_estimate(self) -> tuple[float, float]:
        """The default :meth:`error_estimate`, stored as :attr:`error_B`, :attr:`error_gradient`
        (during construction)."""
        self.error_B, self.error_gradient = self.error_estimate()
        return self.error_B, self.error_gradient

    def _cells_nearest_windings(self, count: int) -> np.ndarray:
        """Flat indices of the ``count`` cells whose centres lie nearest a filament circle of
        the wrapped field (nearest first); empty if it has no coaxial windings.

        The interpolation error of a field ``~ 1/d`` at distance ``d`` from a filament scales
        like ``(h/d)^4`` (B) and ``(h/d)^3`` (gradient), so those cells hold the largest errors
        of the box: a random subset of cells can miss them.
        """
        from .clearance import _groups

        parts = list(_groups(self.field))
        if not parts or count <= 0:
            return np.empty(0, dtype=np.intp)
        axes = [
            lo + (np.arange(n) + 0.5) * h
            for lo, n, h in zip(self.lower, self.cells, self.spacing, strict=True)
        ]
        centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        dist = np.full(len(centres), np.inf)
        for part in parts:
            local = part.to_local(centres)
            rho = np.hypot(local[:, 0], local[:, 1])
            for z0, a, _ in np.asarray(part.filaments, float).reshape(-1, 3):
                np.minimum(dist, np.hypot(rho - a, local[:, 2] - z0), out=dist)
        count = min(count, len(dist))
        near = np.argpartition(dist, count - 1)[:count]
        return near[np.argsort(dist[near])]

    # -- evaluation ----------------------------------------------------------------------------
    def _check_inside(self, pts: np.ndarray, force_raise: bool = False) -> np.ndarray:
        """Validated points -> boolean mask of points outside the box (raises if not allowed)."""
        out = np.any((pts < self.lower - self._slack) | (pts > self.upper + self._slack), axis=1)
        if np.any(out) and (force_raise or self.outside == "raise"):
            k = int(np.argmax(out))
            raise ValueError(
                f"point {k} at {pts[k].tolist()} m lies outside the grid box "
                f"lower={self.lower.tolist()}, upper={self.upper.tolist()}; enlarge the box or "
                f"pass outside='direct' to evaluate such points with the wrapped field"
            )
        if force_raise:
            return pts
        return out

    def _interpolate(self, pts: np.ndarray, order: int):
        """B (order 0), + gradient (1), + hessian (2) of the interpolant at inside points."""
        n = pts.shape[0]
        B = np.empty((n, 3))
        G = np.empty((n, 3, 3)) if order >= 1 else None
        H = np.empty((n, 3, 3, 3)) if order >= 2 else None
        inv_h = 1.0 / self.spacing
        buf = np.empty((min(n, GRID_CHUNK), 192))
        for start in range(0, n, GRID_CHUNK):
            sl = slice(start, min(start + GRID_CHUNK, n))
            s = (pts[sl] - self.lower) * inv_h
            idx = np.clip(np.floor(s).astype(np.intp), 0, self.cells - 1)
            t = s - idx
            cell = (idx[:, 0] * self.cells[1] + idx[:, 1]) * self.cells[2] + idx[:, 2]
            m = cell.shape[0]
            c = np.take(self._coef, cell, axis=0, out=buf[:m])  # (m, 3 * 64)
            PU, PV, PW = (_powers(t[:, a], order) for a in range(3))
            # contract w, then v, then u; D[(du, dv, dw)] = d^(du+dv+dw) B / du^du dv^dv dw^dw
            Tw = np.matmul(c.reshape(m, 48, 4), PW.transpose(0, 2, 1))  # (m, 48, order+1)
            Tw = Tw.reshape(m, 3, 4, 4, order + 1)
            D = {}
            for dw in range(order + 1):
                Sv = np.matmul(Tw[..., dw].reshape(m, 12, 4), PV.transpose(0, 2, 1))
                Sv = Sv.reshape(m, 3, 4, order + 1)
                for dv in range(order + 1 - dw):
                    Ru = np.matmul(Sv[..., dv], PU.transpose(0, 2, 1))  # (m, 3, order+1)
                    for du in range(order + 1 - dw - dv):
                        D[du, dv, dw] = Ru[..., du]
            B[sl] = D[0, 0, 0]
            if order >= 1:
                G[sl, :, 0] = D[1, 0, 0] * inv_h[0]
                G[sl, :, 1] = D[0, 1, 0] * inv_h[1]
                G[sl, :, 2] = D[0, 0, 1] * inv_h[2]
            if order >= 2:
                for j in range(3):
                    for k in range(j, 3):
                        e = [0, 0, 0]
                        e[j] += 1
                        e[k] += 1
                        H[sl, :, j, k] = H[sl, :, k, j] = D[tuple(e)] * (inv_h[j] * inv_h[k])
        return B, G, H

    def _dispatch(self, pts: np.ndarray, order: int):
        out = self._check_inside(pts)
        if not np.any(out):
            return self._interpolate(pts, order)
        inside = ~out
        res = self._interpolate(pts[inside], order)
        full = []
        direct = {
            0: lambda p: (self.field.B(p),),
            1: lambda p: self.field.B_and_gradient(p),
            2: lambda p: (*self.field.B_and_gradient(p), self.field.hessian(p)),
        }[order](pts[out])
        for q in range(order + 1):
            arr = np.empty((pts.shape[0],) + res[q].shape[1:])
            arr[inside] = res[q]
            arr[out] = direct[q]
            full.append(arr)
        return tuple(full) + (None,) * (2 - order)

    def _B(self, pts):
        return self._dispatch(pts, 0)[0]

    def _gradient(self, pts):
        return self._dispatch(pts, 1)[1]

    def _B_and_gradient(self, pts):
        B, G, _ = self._dispatch(pts, 1)
        return B, G

    def _hessian(self, pts):
        return self._dispatch(pts, 2)[2]

    def __repr__(self):
        return (
            f"GriddedField({self.field!r}, lower={self.lower.tolist()}, "
            f"upper={self.upper.tolist()}, shape={self.shape.tolist()})"
        )


def _relative(diff: np.ndarray, ref: np.ndarray) -> float:
    """``max |diff| / max |ref|`` over all entries (0 when both vanish, inf if only ref does)."""
    num = float(np.abs(diff).max(initial=0.0))
    den = float(np.abs(ref).max(initial=0.0))
    if den == 0.0:
        return 0.0 if num == 0.0 else math.inf
    return num / den
