"""Events along an equilibrium path: loss or gain of stability, folds, bifurcations, snaps."""

from __future__ import annotations

__all__ = ["StabilityWarning"]


class StabilityWarning(UserWarning):
    """An equilibrium branch followed by the solver lost (or regained) stability."""
