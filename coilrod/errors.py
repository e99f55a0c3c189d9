"""Exceptions raised by coilrod solvers."""

from __future__ import annotations

__all__ = ["ConvergenceError", "UnitsWarning"]


class UnitsWarning(UserWarning):
    """A value that no magnetic soft continuum robot has in the unit expected (a length over
    1 m, a section over a third of the length, a modulus outside 1 kPa - 10 GPa, a
    magnetization over 2 MA/m): most likely millimetres or MPa typed for metres or Pa."""


class ConvergenceError(RuntimeError):
    """A solver could not reach the requested load.

    Attributes
    ----------
    reached : float
        The largest load scale (fraction of the requested field) at which a converged
        equilibrium was found; 0.0 if none.
    target : float
        The scale the solver was trying to reach.
    residual : float
        The residual norm of the last failed attempt (NaN if it produced none).
    """

    def __init__(
        self,
        message: str,
        reached: float = 0.0,
        target: float = float("nan"),
        residual: float = float("nan"),
    ):
        super().__init__(message)
        self.reached = reached
        self.target = target
        self.residual = residual
