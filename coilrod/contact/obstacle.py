"""What every rigid obstacle offers a contact model: the gap function and its derivatives.

The **gap** ``g(p)`` (m) is the signed distance of a point from the obstacle's wall: ``g > 0``
on the admissible side (inside a vessel, on the side a wall's normal points to), ``g < 0`` for
a point that penetrates it (``-g`` is then how far it is from the admissible region).  Its
gradient is the unit normal pointing into the admissible side, its hessian the wall's
curvature seen from the point.  A contact model needs nothing else:

=====================  ====================================================================
``evaluate(p, order)``  gap, gradient and hessian together (one nearest-point search)
``gap(p)``              (n,) m
``gap_gradient(p)``     (n, 3), unit vectors
``gap_hessian(p)``      (n, 3, 3), 1/m
``contains(p)``         (n,) bool, ``gap >= 0``
``check_start(p)``      ValueError if a starting configuration is not admissible
``bounds``              (2, 3) box, m
``plot(ax)``            the outline in the x-y plane
``friction``            Coulomb coefficient mu >= 0 of the wall (0: frictionless)
``with_friction(mu)``   a copy with another friction coefficient (presets, meshes)
=====================  ====================================================================

Obstacles are immutable (:mod:`coils._immutable`): their attributes cannot be assigned and
their arrays are read-only, so a wall or a vessel always is the one its gaps describe; make a
changed copy with ``replace(**changes)`` (the parameters of the constructor, or of the preset
that built it: ``vessel.replace(radius=2e-3)``).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import NamedTuple

import numpy as np

from coils._immutable import Immutable
from coils._validate import as_count, as_points, nonnegative

__all__ = ["Obstacle", "GapEvaluation"]


def as_friction(friction, name: str = "friction") -> float:
    """A Coulomb friction coefficient: a finite float >= 0 (ValueError naming ``name``)."""
    if isinstance(friction, bool | np.bool_ | str | bytes):  # float(True) is 1.0, float("1")
        raise ValueError(f"{name} must be a number >= 0; got {friction!r}")
    try:
        mu = float(friction)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number >= 0; got {friction!r}") from None
    if not np.isfinite(mu) or mu < 0:
        raise ValueError(f"{name} must be a finite Coulomb coefficient >= 0; got {friction!r}")
    return mu


def _mm(x: float) -> str:
    return f"{1e3 * x:.4g} mm"


def _point_mm(p) -> str:
    return "(" + ", ".join(f"{1e3 * v:.4g}" for v in p) + ") mm"


class GapEvaluation(NamedTuple):
    """Gap of ``n`` points and, if asked for, its derivatives.

    Attributes
    ----------
    gap : ndarray, shape (n,)
        Signed distance to the wall, m (> 0 admissible).
    gradient : ndarray, shape (n, 3), or None
        ``d gap / d p``: the unit normal into the admissible side.
    hessian : ndarray, shape (n, 3, 3), or None
        ``d2 gap / d p2``, 1/m (symmetric).
    """

    gap: np.ndarray
    gradient: np.ndarray | None
    hessian: np.ndarray | None


class Obstacle(Immutable, ABC):
    """Base class of rigid obstacles (:class:`~coilrod.contact.Wall`,
    :class:`~coilrod.contact.Vessel`, :class:`~coilrod.contact.VesselNetwork`).

    Subclasses implement ``_evaluate(points, order)`` on validated points (shape (n, 3), n >= 1)
    returning ``(gap, gradient or None, hessian or None)``, the property ``bounds`` and
    ``_draw(ax, **kwargs)``; the public methods are defined here once.  The obstacles of
    :mod:`coilrod.contact` are immutable (``_immutable = True``; a user's subclass opts in by
    setting it): ``replace(**changes)`` returns a changed copy.
    """

    #: How a point with a negative gap is described in messages ("outside the vessel").
    _outside = "outside the obstacle"
    #: Coulomb friction coefficient mu >= 0 of the wall (0: frictionless contact).
    friction = 0.0

    def with_friction(self, friction):
        """A copy of this obstacle whose wall has the Coulomb friction coefficient
        ``friction`` (mu >= 0; ValueError naming ``friction`` otherwise): for presets and
        meshes, whose constructors do not take it (``Vessel.bend(...).with_friction(0.1)``).
        """
        mu = as_friction(friction)
        if not self.__dict__.get("_frozen", False):
            import copy

            new = copy.copy(self)
            new.friction = mu
            return new
        params = self.__dict__.get("_params")
        if params is not None and "friction" in params:
            params = {**params, "friction": mu}
        return self._evolve(params, friction=mu)

    def replace(self, **changes):
        """A copy with some construction parameters changed (see
        :meth:`coils._immutable.Immutable.replace`), keeping the wall's friction: a preset's
        parameters do not hold it (``Vessel.bend(...).with_friction(0.2).replace(radius=...)``
        was frictionless), and ``friction=mu`` is accepted there too."""
        params = self.__dict__.get("_params") or {}
        mu = self.friction
        if "friction" not in params and "friction" in changes:
            mu = as_friction(changes.pop("friction"))
        new = super().replace(**changes)
        if "friction" not in params and getattr(new, "friction", 0.0) != mu:
            new = new.with_friction(mu)
        return new

    # -- the gap and its derivatives ------------------------------------------------------------
    def evaluate(self, points, order: int = 2) -> GapEvaluation:
        """Gap of ``points`` and its derivatives up to ``order``, from one nearest-point search.

        Parameters
        ----------
        points : array-like, shape (n, 3) or (3,)
            Points, m (a single point is treated as shape (1, 3)).
        order : int
            0: the gap only; 1: and its gradient; 2: and its hessian.

        Returns
        -------
        GapEvaluation
            ``gap`` (n,) m, ``gradient`` (n, 3) or None, ``hessian`` (n, 3, 3) 1/m or None.
        """
        order = as_count(order, "order", minimum=0, maximum=2)
        pts = as_points(points)
        n = len(pts)
        if n == 0:
            return GapEvaluation(
                np.zeros(0),
                np.zeros((0, 3)) if order >= 1 else None,
                np.zeros((0, 3, 3)) if order >= 2 else None,
            )
        return GapEvaluation(*self._evaluate(pts, order))

    def gap(self, points) -> np.ndarray:
        """Signed distance to the wall, shape (n,), m: > 0 admissible, < 0 penetration.

        Parameters
        ----------
        points : array-like, shape (n, 3) or (3,)
            m.
        """
        return self.evaluate(points, 0).gap

    def gap_gradient(self, points) -> np.ndarray:
        """``d gap / d point``, shape (n, 3): the unit normal into the admissible side."""
        return self.evaluate(points, 1).gradient

    def gap_hessian(self, points) -> np.ndarray:
        """``d2 gap / d point2``, shape (n, 3, 3), 1/m: zero for a wall, the wall's curvature
        terms for a tube; exact where the gap is twice differentiable."""
        return self.evaluate(points, 2).hessian

    def contains(self, points) -> np.ndarray:
        """True where ``gap >= 0`` (the point is admissible), shape (n,)."""
        return self.gap(points) >= 0.0

    def check_start(self, points, name: str = "points", tol: float = 0.0) -> None:
        """Raise ValueError unless every point is admissible (``gap >= -tol``).

        Parameters
        ----------
        points : array-like, shape (n, 3) or (3,)
            E.g. a straight rod's nodes or the clamp, m.
        name : str
            What the points are, for the message ("clamp", "rod nodes").
        tol : float
            Penetration accepted (m), e.g. rounding of nodes lying on a wall.

        Raises
        ------
        ValueError
            "clamp at (0, 4.2, 0) mm lies 3.2 mm outside the vessel", or for several points
            "rod nodes[17] at (...) mm lies 0.8 mm outside the vessel (5 of 41 rod nodes are;
            the deepest, rod nodes[40], by 2.1 mm)".
        """
        if not isinstance(name, str):
            raise ValueError(f"name must be a string; got {name!r}")
        tol = nonnegative(tol, "tol")
        pts = as_points(points, name)
        gap = self.gap(pts)
        bad = np.flatnonzero(gap < -tol)
        if bad.size == 0:
            return
        first = int(bad[0])
        label = name if len(pts) == 1 else f"{name}[{first}]"
        msg = f"{label} at {_point_mm(pts[first])} lies {_mm(-gap[first])} {self._outside}"
        if len(pts) > 1 and bad.size > 1:
            deep = int(bad[np.argmin(gap[bad])])
            msg += (
                f" ({bad.size} of {len(pts)} {name} are; the deepest, {name}[{deep}], by "
                f"{_mm(-gap[deep])})"
            )
        raise ValueError(msg)

    # -- geometry -------------------------------------------------------------------------------
    @property
    @abstractmethod
    def bounds(self) -> np.ndarray:
        """Axis-aligned bounding box, shape (2, 3) (lower, upper), m."""

    def plot(self, ax=None, **kwargs):
        """Draw the obstacle in the x-y plane (projection along z) with matplotlib.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            New axes if None.
        **kwargs
            Line properties of the walls (``color``, ``linewidth``, ...).

        Returns
        -------
        matplotlib.axes.Axes
        """
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots()
        self._draw(ax, **kwargs)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        return ax

    @abstractmethod
    def _evaluate(self, points: np.ndarray, order: int):
        """(gap, gradient or None, hessian or None) of validated points (n, 3)."""

    @abstractmethod
    def _draw(self, ax, **kwargs):
        """Draw the obstacle's walls in the x-y plane on ``ax``."""
