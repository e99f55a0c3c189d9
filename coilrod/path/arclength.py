"""Pseudo-arclength continuation: follow an equilibrium path through limit points (folds).

Unknowns ``z = (u, c)``: the state and the load scale.  Each step predicts along the path tangent
and corrects with Newton on ``R(u, c) = 0`` bordered by the arclength condition
``<tau, z - z_pred> = 0``, solved by block elimination with the model's tangent (two solves per
iteration), so the path can turn back at a fold.  The norm weighs the state with the model's
:meth:`~coilrod.path.protocol.PathProblem.arclength_weights` and the scale in units of ``span``.
"""

from __future__ import annotations

import numpy as np

from .corrector import NewtonOptions, as_batched
from .protocol import PathProblem

__all__ = ["ArcLength"]

#: Largest change of the state (model distance) between two path points.
MAX_TURN = 0.15


class ArcLength:
    """Path follower in (state, scale) for any :class:`~coilrod.path.protocol.PathProblem`.

    Parameters
    ----------
    problem : PathProblem
    span : float
        Scale unit of the arclength norm (e.g. the range to be traced).
    opts : NewtonOptions, optional
    step : float, optional
        Initial arclength step in scale units (default 0.02 span); it adapts between 1e-8 span
        and ``max_step``.
    max_step : float, optional
        Largest arclength step in scale units (default 4 times the initial step).
    max_turn : float
        Largest :meth:`~coilrod.path.protocol.PathProblem.distance` between two path points.
    """

    def __init__(
        self,
        problem: PathProblem,
        span: float,
        opts: NewtonOptions | None = None,
        step: float | None = None,
        max_turn: float = MAX_TURN,
        max_step: float | None = None,
    ):
        self.problem = as_batched(problem)
        self.span = max(float(span), 1e-150)  # (1 / span)^2 stays finite
        self.opts = NewtonOptions() if opts is None else opts
        self.ds0 = 0.02 if step is None else float(step) / self.span
        self.max_turn = float(max_turn)
        top = 4 * self.ds0 if max_step is None else float(max_step) / self.span
        self.ds_max = max(top, self.ds0)
        self.weights = problem.arclength_weights()

    def _norm(self, du, dc) -> float:
        return float(np.sqrt(np.dot(self.weights * du, du) + (dc / self.span) ** 2))

    def _lin(self, u, c, tangent=True):
        return self.problem.linearize(u[None], np.array([c]), tangent)

    def _solve(self, lin, rhs):
        with np.errstate(all="ignore"):
            out = self.problem.solve(lin, rhs[None])[0]
        if not np.all(np.isfinite(out)):
            raise np.linalg.LinAlgError("singular tangent")
        return out

    def tangent(self, u, c, lin=None):
        """Unit path tangent ``(du, dc)`` at a converged state, oriented to increasing scale
        (at a fold it tends to the null vector of the tangent); None if the tangent is singular.
        """
        lin = self._lin(u, c) if lin is None else lin
        try:
            a = -self._solve(lin, self.problem.d_residual_d_scale(lin)[0])
        except np.linalg.LinAlgError:
            return None
        norm = self._norm(a, 1.0)
        return a / norm, 1.0 / norm

    def follow(self, u, c, direction: int, max_steps: int, lin=None):
        """Yield ``(u, c, error, lin)`` of successive path points after ``(u, c)``.

        Stops after ``max_steps`` points or when the step cannot be shortened further.
        """
        t = self.tangent(u, c, lin)
        if t is None:
            return
        tau_u, tau_c = t
        if tau_c * direction < 0:
            tau_u, tau_c = -tau_u, -tau_c
        ds = self.ds0
        for _ in range(max_steps):
            while True:
                u_pred, c_pred = u + ds * tau_u, c + ds * tau_c
                out = self._correct(u_pred, c_pred, tau_u, tau_c)
                if out is not None:
                    u_new, c_new, err, it, new_lin = out
                    gap = self._norm(u_new - u_pred, c_new - c_pred)
                    turn = self.problem.distance((u_new - u)[None])[0]
                    if gap <= 0.3 * ds and turn <= self.max_turn:
                        break
                ds /= 2
                if ds < 1e-8:
                    return
            t = self.tangent(u_new, c_new, new_lin)
            if t is None:  # singular (a bifurcation point): fall back on the secant
                norm = self._norm(u_new - u, c_new - c)
                t = (u_new - u) / norm, (c_new - c) / norm
            else:  # keep the orientation of the path
                along = np.dot(self.weights * t[0], u_new - u) + t[1] * (c_new - c) / self.span**2
                if along < 0:
                    t = -t[0], -t[1]
            tau_u, tau_c = t
            u, c = u_new, c_new
            yield u, c, err, new_lin
            ds = min(ds * (1.5 if it <= 3 else 1.0), self.ds_max)

    def _correct(self, u, c, tau_u, tau_c):
        """Newton on R(u, c) = 0 and <tau, z - z_pred> = 0 (bordered block elimination);
        ``(u, c, error, iterations, lin)`` or None if it does not converge."""
        P, opts = self.problem, self.opts
        wt = self.weights * tau_u
        ct = tau_c / self.span**2
        u0, c0 = u.copy(), float(c)
        du_last = None
        for it in range(opts.max_iter + 1):
            lin = self._lin(u, c)
            if not bool(np.asarray(lin.ok).ravel()[0]):
                return None
            err = float(P.error(lin, None if du_last is None else du_last[None])[0])
            arc = np.dot(wt, u - u0) + ct * (c - c0)
            if err <= 1.0 and abs(arc) <= 1e-10:
                return u, c, err, it, lin
            if it == opts.max_iter or not np.isfinite(err):
                return None
            try:
                y1 = self._solve(lin, -lin.residual[0])
                y2 = self._solve(lin, P.d_residual_d_scale(lin)[0])
            except np.linalg.LinAlgError:
                return None
            denom = ct - np.dot(wt, y2)
            if denom == 0 or not np.isfinite(denom):
                return None
            dc = (-arc - np.dot(wt, y1)) / denom
            du = y1 - dc * y2
            t = min(1.0, float(P.step_limit(u[None], du[None])[0]))
            u, c = u + t * du, c + t * dc
            du_last = t * du
        return None
