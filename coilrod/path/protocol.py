"""The small protocol through which every model drives the path-following engine.

A model discretises its equilibrium equations as ``R(u, scale) = 0``: ``u`` the unknowns
(shape ``(size,)``), ``scale`` the load multiplier (the applied field times ``scale``).  The
engine needs, at a state, the residual, the (factorised) tangent ``dR/du``, the load derivative
``dR/dscale`` and the stability of the equilibrium; a model computes them together from one
evaluation of its fields in :meth:`PathProblem.linearize` and returns a :class:`Linearization`.

Models whose evaluations vectorise over several states set ``batched = True``: then every
method also takes stacks ``u`` of shape ``(k, size)`` with ``scale`` of shape ``(k,)`` and
returns stacked results, and the engine corrects several load states in one pass (chunks of a
smooth path; the independent refined-mesh solves of a Richardson extrapolation).
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

__all__ = ["Linearization", "PathProblem"]


@dataclass
class Linearization:
    """A model evaluated at a state: residual, tangent and whatever the model needs to reuse.

    Attributes
    ----------
    u : ndarray, shape (size,) or (k, size)
        The state(s).
    scale : float or ndarray, shape (k,)
        The load scale(s).
    residual : ndarray, same shape as ``u``
        ``R(u, scale)`` in the model's units (meaningless where ``ok`` is False).
    ok : bool or ndarray of bool, shape (k,)
        False where the state is inadmissible: the field cannot be evaluated there (a point on
        a coil winding), a continuum element is inverted, or a number is not finite.
    tangent : object
        The model's tangent (``dR/du``, factorised lazily by :meth:`PathProblem.solve`), or
        None if not computed.
    """

    u: np.ndarray
    scale: float | np.ndarray
    residual: np.ndarray
    ok: bool | np.ndarray
    tangent: object = None


class PathProblem(ABC):
    """What a model provides to the engine (:mod:`coilrod.path`).

    Required: :meth:`linearize`, :meth:`solve`, :meth:`d_residual_d_scale`, :meth:`error`
    and :meth:`stability`.  The others have defaults.  The named conveniences
    :meth:`residual` and :meth:`tangent` evaluate one state.

    Attributes
    ----------
    size : int
        Number of unknowns.
    batched : bool
        The methods accept stacks of states (see the module docstring).
    max_correction : float
        Largest :meth:`distance` between the predicted and the converged state of a load step
        (in the units of :meth:`distance`); a larger correction means the step may have jumped
        to another branch, so the step is shortened instead.
    max_step_change : float
        Largest predicted :meth:`distance` between two consecutive states of a load step: the
        step is shortened where the path tangent is large (near a fold or the knee of an
        imperfect bifurcation), so the stepping resolves the path instead of leaping across.
    cheap_tangent : bool
        The tangent costs about as much as the residual (e.g. a tridiagonal one): Newton then
        never uses chord iterations, which would only add evaluations.
    full_step_growth : float
        A full Newton step is accepted if it raises :meth:`error` by at most this factor
        (large rotations legitimately raise a residual transiently); otherwise the step is
        backtracked until :meth:`error` decreases.
    """

    size: int
    batched: bool = False
    max_correction: float = np.inf
    max_step_change: float = np.inf
    cheap_tangent: bool = False
    full_step_growth: float = 1.0

    # -- required -----------------------------------------------------------------------------
    @abstractmethod
    def linearize(self, u: np.ndarray, scale, tangent: bool = True) -> Linearization:
        """Residual (and, if ``tangent``, the tangent) at ``u`` and ``scale``; never raises for
        an inadmissible state (``ok`` False instead)."""

    @abstractmethod
    def solve(self, lin: Linearization, rhs: np.ndarray) -> np.ndarray:
        """``(dR/du)^-1 rhs`` with the tangent of ``lin``; ``rhs`` has the shape of ``lin.u``.

        Raises ``numpy.linalg.LinAlgError`` if the tangent is singular."""

    @abstractmethod
    def d_residual_d_scale(self, lin: Linearization) -> np.ndarray:
        """``dR/dscale`` at the state of ``lin`` (fixed ``u``), shape of ``lin.u``."""

    @abstractmethod
    def error(self, lin: Linearization, du: np.ndarray | None) -> float | np.ndarray:
        """Convergence measure of ``lin`` (the state is converged iff it is at most 1).

        ``du`` is the last Newton increment that led to the state (None before the first);
        models whose criterion also bounds the increment use it."""

    @abstractmethod
    def stability(self, lin: Linearization, precise: bool = False) -> float | np.ndarray:
        """Stability of the equilibrium ``lin``: positive if stable, non-positive if not.

        With ``precise`` the value is the model's smallest eigenvalue of the second variation
        (in the model's units); without, it may be any cheap indicator with the right sign
        (e.g. +-1 from the sign of the tangent's determinant relative to the unloaded state)."""

    # -- defaults -----------------------------------------------------------------------------
    def branch_stability(self, lin: Linearization, precise: bool = False) -> float | np.ndarray:
        """Stability among the states the model itself can follow (like :meth:`stability`),
        for the engine's fold handling: an arclength run around a fold lands where this is
        positive.  Default :meth:`stability`; a model whose :meth:`stability` also counts
        modes it cannot follow (the planar rod's out-of-plane modes) gives its own here."""
        return self.stability(lin, precise)

    def step_limit(self, u: np.ndarray, du: np.ndarray) -> float | np.ndarray:
        """Largest fraction (<= 1) of the Newton increment ``du`` to take from ``u``."""
        return 1.0 if np.ndim(u) == 1 else np.ones(len(u))

    def distance(self, du: np.ndarray) -> float | np.ndarray:
        """Size of a state increment in the model's natural units (max-norm by default)."""
        return float(np.max(np.abs(du))) if du.ndim == 1 else np.max(np.abs(du), axis=1)

    def arclength_weights(self) -> np.ndarray:
        """Weights ``w`` of the state part of the arclength norm ``sqrt(sum w du^2 + ...)``."""
        return np.full(self.size, 1.0 / self.size)

    def with_tangent(self, lin: Linearization, other: Linearization) -> Linearization:
        """``lin`` (a state evaluated without tangent) paired with the tangent of ``other``
        (for chord iterations of :func:`~coilrod.path.corrector.newton`); same members."""
        if type(lin) is Linearization:  # copy.copy's result, without its reduce protocol
            out = object.__new__(Linearization)
            out.__dict__.update(lin.__dict__)
        else:
            out = copy.copy(lin)
        out.tangent = other.tangent
        return out

    # -- conveniences (the protocol's named quantities at one state) --------------------------
    def residual(self, u: np.ndarray, scale: float) -> np.ndarray:
        """``R(u, scale)``, shape (size,)."""
        return self.linearize(u, scale, tangent=False).residual

    def tangent(self, u: np.ndarray, scale: float) -> Linearization:
        """The linearization at ``(u, scale)`` whose tangent :meth:`solve` uses."""
        return self.linearize(u, scale, tangent=True)
