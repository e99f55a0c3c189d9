"""Load steps that end where the contact set changes (the spatial rod's contact predictor).

A contact state is a piecewise-smooth function of the load: between changes of the active set
(a contact point closing on the wall, or an active one whose force per length falls to zero
and releases) the path is smooth and the path tangent of the active set predicts it to second
order; across a change the tangent is wrong at first order (it lets the rod penetrate the
wall, or keeps pulling it onto the wall), and semi-smooth Newton then spends iterations
finding the new set point by point.  :func:`event_fraction` gives the fraction of a predicted
change at which the first such event happens; the path engine's trial step
(:meth:`coilrod.path.stepping._Tracker.trial`) ends there, so that every corrector starts
from a prediction with the right contact set.
"""

from __future__ import annotations

import numpy as np

__all__ = ["event_fraction"]

#: An active multiplier below this fraction of the largest one is taken as already released
#: (its sign change is left to Newton: ending a step there would stall the stepping).
_RELEASE_FLOOR = 1e-6


def event_fraction(problem, U: np.ndarray, dU: np.ndarray) -> np.ndarray:
    """Fraction (k,) of the changes ``dU`` (k, size) of states ``U`` (k, size) at which the
    first contact event of the spatial rod ``problem`` happens, 1 if none does: an open
    contact point closing (:meth:`~coilrod.rod.spatial.SpatialRod.closing_fraction`,
    evaluated on the changed state) or an active multiplier (contact force per length)
    reaching zero (linear in ``dU``)."""
    U, dU = np.atleast_2d(U), np.atleast_2d(dU)
    k = U.shape[0]
    if not problem.nc or problem.uniform:
        return np.ones(k)
    frac = problem.closing_fraction(U, dU)
    lam = U.reshape(k, problem.n, problem.nv)[:, 1:, 9:]
    d_lam = dU.reshape(k, problem.n, problem.nv)[:, 1:, 9:]
    floor = _RELEASE_FLOOR * np.abs(lam).max(axis=(1, 2), keepdims=True)
    releasing = (lam > floor) & (lam + d_lam < 0.0)
    with np.errstate(all="ignore"):
        release = np.where(releasing, lam / -d_lam, 1.0)
    return np.minimum(frac, release.min(axis=(1, 2)))
