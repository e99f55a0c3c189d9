"""A rigid plane wall: the admissible side is the half-space its normal points into."""

from __future__ import annotations

import numpy as np

from coils._immutable import sealed
from coils._validate import as_axis, as_vector

from .obstacle import Obstacle, _point_mm, as_friction

__all__ = ["Wall"]


class Wall(Obstacle):
    """Rigid plane through ``point`` with unit ``normal`` pointing into the admissible side.

    ``gap(p) = n . (p - point)`` (exact), gradient ``n``, hessian zero.

    Parameters
    ----------
    point : array-like, shape (3,)
        A point of the plane, m.
    normal : array-like, shape (3,), or str
        Normal towards the admissible side (normalised here), or an axis name ``"y"``,
        ``"-x"``; a zero, NaN or infinite normal raises ValueError naming ``normal``.
    friction : float
        Coulomb friction coefficient mu >= 0 of the wall (0, the default: frictionless; see
        :class:`~coilrod.rod.spatial.SpatialRod` for the friction law).

    Attributes
    ----------
    friction : float
    point, normal : ndarray, shape (3,)
        Read-only (m; unit vector).  A wall is immutable: ``wall.replace(point=...)`` gives a
        moved copy.

    Examples
    --------
    >>> floor = Wall(point=(0, -0.01, 0), normal=(0, 2, 0))
    >>> floor.normal.tolist()
    [0.0, 1.0, 0.0]
    >>> floor.gap([[0.0, 0.0, 0.0], [0.0, -0.02, 0.0]]).tolist()
    [0.01, -0.01]
    """

    _outside = "behind the wall"
    _immutable = True

    def __init__(self, point, normal, friction=0.0):
        self.friction = as_friction(friction)
        self.point = sealed(as_vector(point, "point"))
        self.normal = sealed(as_axis(normal, "normal"))
        self._offset = float(self.normal @ self.point)

    def __repr__(self) -> str:
        n = ", ".join(f"{v:.4g}" for v in self.normal)
        mu = f", friction={self.friction:g}" if self.friction else ""
        return f"Wall(point={_point_mm(self.point)}, normal=({n}){mu})"

    def _evaluate(self, points: np.ndarray, order: int):
        # n.p - n.p0 loses digits for far points; (p - p0).n does not
        gap = (points - self.point) @ self.normal
        grad = np.broadcast_to(self.normal, points.shape).copy() if order >= 1 else None
        hess = np.zeros((len(points), 3, 3)) if order >= 2 else None
        return gap, grad, hess

    @property
    def bounds(self) -> np.ndarray:
        """Unbounded: ``[[-inf] * 3, [inf] * 3]``."""
        return np.array([[-np.inf] * 3, [np.inf] * 3])

    def _draw(self, ax, extent: float | None = None, **kwargs):
        """The wall's trace in the plane z = 0 with ticks on the solid side, across the axes'
        current limits (or ``extent`` m either side of the wall's point if they are empty)."""
        nxy = self.normal[:2]
        norm2 = float(nxy @ nxy)
        if norm2 < 1e-24:  # a wall parallel to the x-y plane has no trace
            return
        # the line nxy . x = offset (z = 0): its point nearest to the wall's point
        base = self.point[:2] + (self._offset - nxy @ self.point[:2]) / norm2 * nxy
        n2 = nxy / np.sqrt(norm2)
        along = np.array([-n2[1], n2[0]])
        if extent is None:
            if ax.has_data():
                (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
                corners = np.array([[x0, y0], [x0, y1], [x1, y0], [x1, y1]])
                t = (corners - base) @ along
                lo, hi = float(t.min()), float(t.max())
            else:
                lo, hi = -0.01, 0.01
        else:
            lo, hi = -float(extent), float(extent)
        ends = base + np.outer([lo, hi], along)
        kwargs.setdefault("color", "k")
        kwargs.setdefault("linewidth", 1.5)
        ax.plot(ends[:, 0], ends[:, 1], **kwargs)
        ticks = base + np.outer(np.linspace(lo, hi, 25), along)
        tick = 0.03 * (hi - lo) * n2
        for a in ticks:
            ax.plot(
                [a[0], a[0] - tick[0] + 0.5 * tick[1]],
                [a[1], a[1] - tick[1] - 0.5 * tick[0]],
                color=kwargs["color"],
                linewidth=0.6,
            )
