"""Several vessels joined into one lumen (a branching network): the union of their lumens."""

from __future__ import annotations

import numpy as np

from ._lumens import _draw_lumens
from .obstacle import Obstacle, as_friction

__all__ = ["VesselNetwork"]


class VesselNetwork(Obstacle):
    """The union of the admissible regions of several obstacles (typically
    :class:`~coilrod.contact.Vessel` s joined at junctions): ``gap = max`` of the members' gaps.

    A point is admissible if it is inside any member.  The gap is the exact penetration depth
    outside all members (the distance to the union); at a junction, where two tubes' walls
    cross, the gap is continuous and its gradient jumps (the member with the larger gap gives
    the gradient and hessian; at a tie, the first).  Contrast a list of obstacles handed to a
    solver, whose admissible regions intersect.

    Parameters
    ----------
    vessels : sequence of Obstacle
        At least one (stored as the tuple ``vessels``; immutable, ``replace(vessels=...)``
        gives a changed copy).
    friction : float, optional
        Coulomb friction coefficient mu >= 0 of the network's wall, what the contact models
        use (the members' own coefficients are not looked at again).  Default: the members'
        common coefficient; members with different ones are a ValueError unless it is given.

    Examples
    --------
    >>> from coilrod.contact import Vessel
    >>> main = Vessel([[0, 0, 0], [0.04, 0, 0]], 1e-3)
    >>> side = Vessel([[0.02, 0, 0], [0.02, 0.02, 0]], 1e-3, ends=("round", "extend"))
    >>> net = VesselNetwork([main, side])
    >>> net.contains([[0.02, 0.01, 0.0], [0.01, 0.01, 0.0]]).tolist()
    [True, False]
    """

    _outside = "outside the vessels"
    _immutable = True

    def __init__(self, vessels, friction=None):
        try:
            members = list(vessels)
        except TypeError:
            raise ValueError(
                f"vessels must be a sequence of obstacles; got {type(vessels).__name__}"
            ) from None
        if not members:
            raise ValueError("vessels must hold at least one obstacle; got none")
        for k, v in enumerate(members):
            if not isinstance(v, Obstacle):
                raise ValueError(
                    f"vessels[{k}] must be a Vessel (or another obstacle); got {type(v).__name__}"
                )
        self.vessels = tuple(members)
        if friction is None:  # (a network of rough vessels was frictionless: the solver
            # reads the network's coefficient, the class's 0)
            mus = [as_friction(getattr(v, "friction", 0.0), f"vessels[{k}].friction")
                   for k, v in enumerate(members)]  # fmt: skip
            if len(set(mus)) > 1:
                raise ValueError(
                    f"the vessels' friction coefficients differ ({', '.join(f'{m:g}' for m in mus)}"
                    "): a network's wall has one; give it as friction=mu"
                )
            friction = mus[0]
        self.friction = as_friction(friction)

    def __repr__(self) -> str:
        mu = f", friction={self.friction:g}" if self.friction else ""
        return f"VesselNetwork([{', '.join(repr(v) for v in self.vessels)}]{mu})"

    def __len__(self) -> int:
        return len(self.vessels)

    def _evaluate(self, points: np.ndarray, order: int):
        # each member at every point with the derivatives asked for, its winners' rows taken:
        # a member's search of these points is remembered (a vessel's last searches), where a
        # search of its winners alone would be a new one; the numbers of a point do not
        # depend on the others evaluated with it
        each = [v._evaluate(points, order) for v in self.vessels]
        if len(each) == 1:
            return each[0]
        gaps = np.stack([e[0] for e in each], axis=1)
        who = np.argmax(gaps, axis=1)
        gap = gaps[np.arange(len(points)), who]
        if order == 0:
            return gap, None, None
        grad = np.empty((len(points), 3))
        hess = np.empty((len(points), 3, 3)) if order >= 2 else None
        for k, (_, gr, he) in enumerate(each):
            rows = np.flatnonzero(who == k)
            if rows.size:
                grad[rows] = gr[rows]
                if order >= 2:
                    hess[rows] = he[rows]
        return gap, grad, hess

    @property
    def bounds(self) -> np.ndarray:
        """Box (2, 3) enclosing every member's box, m."""
        boxes = np.stack([v.bounds for v in self.vessels])
        return np.array([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])

    def _draw(self, ax, **kwargs):
        """The outline of the union of the vessels' lumens (the walls across a junction's
        opening are not drawn) and the other members."""
        vessels = [v for v in self.vessels if hasattr(v, "_shadow")]  # tubes (Vessel)
        if vessels:
            _draw_lumens(ax, vessels, **kwargs)
        for v in self.vessels:
            if not hasattr(v, "_shadow"):
                v._draw(ax, **kwargs)
