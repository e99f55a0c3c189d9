"""Damped Newton iteration and load stepping for a :class:`~coilrod.rod_discrete.DiscreteRod`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["NewtonOptions", "newton", "step_to"]


@dataclass(frozen=True)
class NewtonOptions:
    """Newton settings (non-dimensional).

    Attributes
    ----------
    tol : float
        Converged when the scaled residual max-norm (moment per length in EI/L^2, position
        mismatch per length, force per length in EI/L^3) is below ``tol``.
    max_iter : int
        Newton iterations per attempt.
    max_rotation : float
        Largest change of any node angle in one Newton step, rad (longer steps are shortened).
    min_step : float
        Smallest load sub-step, as a fraction of the requested step, before giving up.
    max_correction : float
        Largest change of any node angle between the tangent prediction and the converged
        state of a load step, rad.  A larger correction means the step may have jumped to
        another branch (over a fold): the step is shortened instead.
    """

    tol: float = 1e-9
    max_iter: int = 15
    max_rotation: float = 0.5
    min_step: float = 1e-6
    max_correction: float = 0.25


def _finite(a: np.ndarray) -> bool:
    """True if every entry is finite (one reduction: a sum is NaN/inf iff an entry is, short
    of overflow, which is rejected too)."""
    return bool(np.isfinite(np.sum(a)))


_RAISE = {"over": "raise", "invalid": "raise", "divide": "raise", "under": "ignore"}


def _evaluate(problem, u, scale):
    """(residual, Jacobian, scaled residual norm); norm inf if the field cannot be evaluated."""
    try:
        with np.errstate(**_RAISE):
            r, jac = problem.evaluate(u, scale)
            res = problem.residual_norm(r)
    except (ValueError, FloatingPointError):
        return None, None, float("inf")
    if not np.isfinite(res):  # the max-norm is finite iff every entry is
        return None, None, float("inf")
    return r, jac, res


def newton(problem, u0: np.ndarray, scale: float, opts: NewtonOptions):
    """Solve ``problem.residual(u, scale) = 0`` from ``u0``.

    Each iterate is evaluated once (residual and Jacobian together); the step is shortened so
    that no node angle turns by more than ``opts.max_rotation`` and backtracked until the
    residual decreases.

    Returns
    -------
    u : ndarray
        The last iterate.
    ok : bool
        True if the scaled residual reached ``opts.tol`` (or the problem's round-off floor
        ``problem.tol_floor`` if larger).
    res : float
        Scaled residual norm of ``u`` (inf if the iteration produced non-finite numbers).
    iterations : int
    jac : object or None
        The Jacobian at ``u`` (for a tangent or a stability check).
    """
    u = u0.copy()
    tol = max(opts.tol, problem.tol_floor)
    r, jac, res = _evaluate(problem, u, scale)
    if r is None:
        return u, False, res, 0, None
    slow = 0
    for it in range(1, opts.max_iter + 1):
        if res <= tol:
            return u, True, res, it - 1, jac
        try:
            with np.errstate(**_RAISE):
                du = -problem.solve(jac, r)
        except (np.linalg.LinAlgError, FloatingPointError, ValueError):
            return u, False, res, it, jac
        rot = np.max(np.abs(problem.theta(du)))
        if not (np.isfinite(rot) and _finite(du)):
            return u, False, res, it, jac
        t = min(1.0, opts.max_rotation / rot) if rot > 0 else 1.0
        for _ in range(6):  # backtracking on the residual norm
            trial = u + t * du
            r_new, jac_new, res_new = _evaluate(problem, trial, scale)
            if r_new is not None and (res_new < res or res_new <= tol):
                break
            t *= 0.5
        else:
            return u, False, res, it, jac
        slow = slow + 1 if res_new > 0.5 * res else 0
        u, r, jac, res = trial, r_new, jac_new, res_new
        if slow >= 3 and res > tol:  # stagnating: let the caller shorten the load step
            return u, False, res, it, jac
    return u, res <= tol, res, opts.max_iter, jac


@dataclass
class StepResult:
    """Outcome of one continuation step."""

    u: np.ndarray
    ok: bool
    residual: float
    iterations: int
    reached: float
    tangent: np.ndarray | None = None
    jac: object = None  # Jacobian at ``u`` when known


def step_to(
    problem,
    u: np.ndarray,
    scale_from: float,
    scale_to: float,
    opts: NewtonOptions,
    predict: bool = True,
    tangent: np.ndarray | None = None,
    previous=None,
) -> StepResult:
    """Move a converged state from ``scale_from`` to ``scale_to``, sub-stepping on failure.

    A tangent predictor ``du/dscale = -J^{-1} dR/dscale`` (if ``predict``) starts each
    sub-step; with ``previous = (u_prev, scale_prev)``, an earlier state of the same branch,
    the first attempt adds the quadratic term of the Hermite extrapolation through both
    states.  The step is halved after each failed attempt (or a correction larger than
    ``opts.max_correction``) down to ``opts.min_step`` of the full step.

    Returns
    -------
    StepResult
        ``ok`` False with ``reached`` the last scale converged if the target was not reached.
    """
    total = scale_to - scale_from
    current, reached = u, scale_from
    step = total
    iters = 0
    res = float("inf")
    failures = 0
    last_jac = None
    if predict and tangent is None:
        tangent = _tangent(problem, u, scale_from)
    while True:
        remaining = scale_to - reached
        if abs(remaining) <= 1e-14 * max(1.0, abs(scale_to)):
            return StepResult(current, True, res, iters, scale_to, tangent, last_jac)
        if abs(step) > abs(remaining):
            step = remaining
        target = scale_to if step == remaining else reached + step
        guess = current if tangent is None else current + (target - reached) * tangent
        if tangent is not None and previous is not None and reached == scale_from:
            h = scale_from - previous[1]
            if h != 0 and abs(target - reached) <= 4 * abs(h):
                curv = (previous[0] - u + tangent * h) / (h * h)
                guess = guess + curv * (target - reached) ** 2
        new, ok, res_try, it, jac = newton(problem, guess, target, opts)
        iters += it
        if ok and tangent is not None:
            ok = np.max(np.abs(problem.theta(new) - problem.theta(guess))) <= opts.max_correction
        if ok:
            failures = 0
            if predict:
                tangent = _tangent(problem, new, target, jac)
            current, reached, res, last_jac = new, target, res_try, jac
            step *= 2.0  # grow back after a successful sub-step
            continue
        res = res_try
        step /= 2.0
        failures += 1
        if abs(step) < opts.min_step * abs(total) or (
            failures % 4 == 0 and _near_fold(problem, current, reached)
        ):
            return StepResult(current, False, res, iters, reached, tangent)


def _near_fold(problem, u: np.ndarray, scale: float) -> bool:
    """True if the smallest second-variation eigenvalue at ``u`` is below 5 % of the straight
    rod's: the load steps are failing because the branch turns back (a limit point)."""
    try:
        mu = problem.min_eigenvalue(u, scale)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return False
    return mu < 0.05 * problem.mu0


def _tangent(problem, u: np.ndarray, scale: float, jac=None) -> np.ndarray | None:
    """du/dscale = -J^{-1} dR/dscale at a converged state (None if J is singular)."""
    try:
        with np.errstate(**_RAISE):
            if jac is None:
                jac = problem.jacobian(u, scale)
            t = -problem.solve(jac, problem.load_derivative(u, scale))
    except (np.linalg.LinAlgError, FloatingPointError, ValueError):
        return None
    return t if _finite(t) else None
