"""Pseudo-arclength continuation of a discrete rod problem in its load scale.

Unknowns ``z = (u, c)``: the state and the field scale.  Each step predicts along the (secant)
tangent and corrects with Newton on ``R(u, c) = 0`` bordered by the arclength condition
``<tau, z - z_pred> = 0``, solved by block elimination with two banded solves, so the path can
turn back at a limit point (fold).  The norm weighs the rms of the node angles (rad) and the
scale in units of ``span``.
"""

from __future__ import annotations

import numpy as np

from .newton import NewtonOptions

__all__ = ["ArcLength"]

#: Largest change of any node angle between two path points, rad.
MAX_TURN = 0.15


class ArcLength:
    """Path follower for a :class:`~coilrod.rod_discrete.DiscreteRod`.

    Parameters
    ----------
    problem : DiscreteRod
    span : float
        Scale unit of the arclength norm (e.g. the range to be traced).
    opts : NewtonOptions
    step : float, optional
        Initial arclength step (default 0.02 span-units); it adapts between 1e-8 and 4 times
        the initial value.
    """

    def __init__(self, problem, span: float, opts: NewtonOptions, step: float | None = None):
        self.problem = problem
        self.span = max(float(span), 1e-300)
        self.opts = opts
        self.ds0 = 0.02 if step is None else float(step) / self.span
        self.weights = np.zeros(problem.size)
        self.weights[np.arange(problem.n) * (problem.size // problem.n)] = 1.0 / problem.n

    def _norm(self, du, dc):
        return float(np.sqrt(np.dot(self.weights * du, du) + (dc / self.span) ** 2))

    def follow(self, u, c, direction: int, max_steps: int):
        """Yield ``(u, c, residual)`` of successive path points after ``(u, c)``.

        Stops after ``max_steps`` points or when the step cannot be shortened further.
        """
        problem = self.problem
        tau_u, tau_c = self._tangent(u, c)
        if tau_c * direction < 0:
            tau_u, tau_c = -tau_u, -tau_c
        ds = self.ds0
        for _ in range(max_steps):
            while True:
                u_pred, c_pred = u + ds * tau_u, c + ds * tau_c
                u_new, c_new, ok, res, it = self._correct(u_pred, c_pred, tau_u, tau_c)
                if ok:
                    gap = self._norm(u_new - u_pred, c_new - c_pred)
                    turn = np.max(np.abs(problem.theta(u_new) - problem.theta(u)))
                    if gap <= 0.3 * ds and turn <= MAX_TURN:
                        break
                ds /= 2
                if ds < 1e-8:
                    return
            tangent = self._tangent(u_new, c_new)
            if tangent is None:  # singular (a bifurcation point): fall back on the secant
                norm = self._norm(u_new - u, c_new - c)
                tangent = (u_new - u) / norm, (c_new - c) / norm
            else:  # keep the orientation of the path
                step_dir = np.dot(self.weights * tangent[0], u_new - u) + (
                    tangent[1] * (c_new - c) / self.span**2
                )
                if step_dir < 0:
                    tangent = -tangent[0], -tangent[1]
            tau_u, tau_c = tangent
            u, c = u_new, c_new
            yield u, c, res
            ds = min(ds * (1.5 if it <= 3 else 1.0), 4 * self.ds0)

    def _tangent(self, u, c):
        """Unit tangent ``(-J^{-1} dR/dc, 1)`` of the path (orientation: increasing scale);
        at a fold it tends to the null vector of J.  None if J is numerically singular."""
        problem = self.problem
        try:
            with np.errstate(over="raise", invalid="raise", divide="raise", under="ignore"):
                a = -problem.solve(problem.jacobian(u, c), problem.load_derivative(u, c))
                norm = self._norm(a, 1.0)
                out = a / norm, 1.0 / norm
        except (np.linalg.LinAlgError, FloatingPointError, ValueError):
            return None
        return out if np.all(np.isfinite(out[0])) else None

    def _correct(self, u, c, tau_u, tau_c):
        """Newton on R(u, c) = 0 and <tau, z - z_pred> = 0 (bordered block elimination)."""
        problem, opts = self.problem, self.opts
        wt = self.weights * tau_u
        ct = tau_c / self.span**2
        u0, c0 = u.copy(), float(c)
        for it in range(opts.max_iter + 1):
            try:
                with np.errstate(over="raise", invalid="raise", divide="raise", under="ignore"):
                    r = problem.residual(u, c)
            except (ValueError, FloatingPointError):
                return u, c, False, np.inf, it
            res = problem.residual_norm(r)
            arc = np.dot(wt, u - u0) + ct * (c - c0)
            if res <= max(opts.tol, problem.tol_floor) and abs(arc) <= 1e-10:
                return u, c, True, res, it
            if it == opts.max_iter:
                break
            try:
                with np.errstate(over="raise", invalid="raise", divide="raise", under="ignore"):
                    jac = problem.jacobian(u, c)
                    y = problem.solve(jac, np.stack([-r, problem.load_derivative(u, c)], axis=1))
            except (np.linalg.LinAlgError, FloatingPointError, ValueError):
                return u, c, False, res, it
            y1, y2 = y[:, 0], y[:, 1]
            denom = ct - np.dot(wt, y2)
            if denom == 0 or not np.isfinite(denom):
                return u, c, False, res, it
            dc = (-arc - np.dot(wt, y1)) / denom
            du = y1 - dc * y2
            rot = np.max(np.abs(problem.theta(du)))
            t = min(1.0, opts.max_rotation / rot) if rot > 0 else 1.0
            u, c = u + t * du, c + t * dc
        return u, c, False, res, opts.max_iter
