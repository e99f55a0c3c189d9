"""Newton's method with load stepping, a tangent predictor, step cutting and a line search.

The load is the field multiplied by a scale.  Between two requested scales the solver steps
with an adaptive increment: it predicts the next state with the path tangent
``dz/ds = -K^-1 dr/ds`` (one back-substitution with the last factorisation; the linear response
starts the path) plus a second-order term from the change of that tangent since the previous
state, corrects with Newton, halves the step when Newton fails (divergence, ``det F <= 0``,
non-finite field, too many iterations) and doubles it again after easy steps.  A step is
converged when the residual norm is below ``rtol * max(|internal force|, |magnetic load|)``
(plus a round-off floor ~ eps K V / L), the element pressure equations hold to
``100 rtol G / K`` AND the last Newton increment is below ``utol * L``.

Line search: a full Newton update is accepted if it keeps ``det F > 0`` and a finite field and
does not raise the residual norm more than ``FULL_STEP_GROWTH`` times (full steps legitimately
raise it during large rotations); otherwise the update is halved until the energy (displacement
formulation) or the residual norm decreases, and the step is cut if that fails.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from coilrod.errors import ConvergenceError

from .linalg import determinant_sign

__all__ = ["NewtonOptions", "SolveStats", "continuation"]


@dataclass(frozen=True)
class NewtonOptions:
    """Tolerances and limits of the load-stepping Newton solver.

    Attributes
    ----------
    rtol : float
        Residual tolerance relative to the force scale.
    utol : float
        Increment tolerance relative to the rod length.
    max_iterations : int
        Newton iterations per load step before the step is cut.
    max_cuts : int
        Consecutive step halvings allowed before ``ConvergenceError``.
    predictor : {"tangent", "secant", "none"}
        Extrapolation of the state to the next load step.
    line_search : bool
        Backtrack Newton updates that neither lower the energy nor the residual.
    """

    rtol: float = 1e-8
    utol: float = 1e-6
    max_iterations: int = 25
    max_cuts: int = 16
    predictor: str = "tangent"
    line_search: bool = True


@dataclass
class SolveStats:
    """Counters of one continuation: Newton iterations, evaluations and factorisations."""

    iterations: list = field(default_factory=list)  # Newton iterations per requested scale
    det_signs: list = field(default_factory=list)  # sign of det(tangent) per requested scale
    evaluations: int = 0
    factorizations: int = 0
    cuts: int = 0
    steps: int = 0


#: A full Newton step is accepted if it raises the residual norm by at most this factor.
FULL_STEP_GROWTH = 1e4


class _Fail(Exception):
    def __init__(self, residual: float):
        self.residual = residual


def _newton(asm, u, s, opts, stats, atol):
    """Newton iterations at scale ``s`` from ``u``; returns (u, evaluation, lu, iterations)."""
    L = asm.length
    ctol = 100 * opts.rtol * asm.shear / asm.bulk  # volumetric-constraint tolerance
    ev = asm.evaluate(u, s, tangent=True)
    stats.evaluations += 1
    if not ev.ok:
        raise _Fail(math.nan)
    last_du = math.inf
    r0 = None
    for it in range(opts.max_iterations + 1):
        rnorm = float(np.linalg.norm(ev.residual))
        fref = max(ev.internal_norm, abs(s) * float(np.linalg.norm(ev.load_rate)))
        r0 = rnorm if r0 is None else r0
        res_ok = rnorm <= opts.rtol * fref + atol and ev.constraint_norm <= ctol
        # round-off floor: an increment at round-off level with a residual near tolerance
        stalled = last_du <= 1e-3 * opts.utol * L and rnorm <= 100 * opts.rtol * fref
        if (res_ok and (last_du <= opts.utol * L or rnorm <= atol)) or stalled:
            return u, ev, it
        if it == opts.max_iterations or not np.isfinite(rnorm) or rnorm > 1e8 * max(r0, atol):
            raise _Fail(rnorm)
        lu = asm.factorize(ev)
        stats.factorizations += 1
        asm._lu = lu
        du = asm.newton_step(ev, lu)
        if not np.all(np.isfinite(du)):
            raise _Fail(rnorm)
        slope = float(ev.residual @ du[: asm.nfree])
        alpha, trial = 1.0, None
        for _ in range(10 if opts.line_search else 1):
            cand = asm.evaluate(u + alpha * du, s, tangent=alpha == 1.0)
            stats.evaluations += 1
            if cand.ok:
                if not opts.line_search:
                    trial = cand
                    break
                # the mixed formulation's energy is a saddle function: no descent test
                decrease = (not asm.mixed) and cand.energy <= ev.energy + 1e-4 * alpha * slope
                rn = np.linalg.norm(cand.residual)
                smaller = rn < (1 - 1e-4 * alpha) * rnorm
                # a full Newton step may raise the residual moderately (rotations): accept it
                # unless it grows by more than FULL_STEP_GROWTH
                full_ok = alpha == 1.0 and rn <= FULL_STEP_GROWTH * rnorm
                if decrease or smaller or full_ok:
                    trial = cand
                    break
            alpha *= 0.5
        if trial is None:
            raise _Fail(rnorm)
        if trial.tangent is None:
            trial = asm.evaluate(u + alpha * du, s, tangent=True)
            stats.evaluations += 1
        u = u + alpha * du
        last_du = alpha * asm.increment_norm(du)
        ev = trial
    raise _Fail(rnorm)  # pragma: no cover


def continuation(asm, scales, opts: NewtonOptions, progress=None):
    """Equilibria at each of ``scales`` in order, continued from the unloaded state.

    Parameters
    ----------
    asm : Assembler
    scales : ndarray, shape (n,)
        Load scales (multipliers of the field), visited in order.
    opts : NewtonOptions
    progress : callable, optional
        Called with ``(k, scale)`` after each converged requested scale.

    Returns
    -------
    states : list of ndarray, shape (n_free,)
        Converged free-dof displacements, one per scale.
    stats : SolveStats

    Raises
    ------
    ConvergenceError
        When a requested scale cannot be reached within ``opts.max_cuts`` halvings; its
        ``reached`` is the last converged scale and ``result_states`` the states so far.
    """
    stats = SolveStats()
    u = np.zeros(asm.size)
    s_cur = 0.0
    rate = None  # du/ds at the current state
    prev_rate = None  # (du/ds, s) at the previous state, for the curvature of the path
    prev = None  # (u, s) of the previous converged state, for the secant predictor
    # absolute force floor: round-off of the volumetric terms, ~ eps K (volume / length)
    atol = 1e4 * np.finfo(float).eps * max(asm.bulk, asm.shear) * asm.w.sum() / asm.length
    states = []
    asm._lu = None
    ev0 = asm.evaluate(u, 0.0, tangent=True)  # the unloaded, stable reference state
    stats.evaluations += 1
    stats.factorizations += 1
    lu0 = asm.factorize(ev0)
    sign0 = determinant_sign(lu0)
    if opts.predictor != "none":  # the linear response starts the path
        rate = asm.load_tangent(ev0, lu0)
    for target in scales:
        target = float(target)
        h = target - s_cur
        cuts = 0  # consecutive failures
        its_here = 0
        steps_here = 0
        while True:
            s_try = target if abs(h) >= abs(target - s_cur) else s_cur + h
            ds = s_try - s_cur
            u0 = u
            if opts.predictor == "tangent" and rate is not None:
                u0 = u + ds * rate
                if prev_rate is not None and prev_rate[1] != s_cur:
                    # second-order (Hermite) term from the change of the tangent
                    curv = (rate - prev_rate[0]) / (s_cur - prev_rate[1])
                    u0 = u0 + 0.5 * ds * ds * curv
            elif opts.predictor == "secant" and prev is not None and prev[1] != s_cur:
                u0 = u + ds * (u - prev[0]) / (s_cur - prev[1])
            elif opts.predictor == "secant" and rate is not None:  # first step: linear response
                u0 = u + ds * rate
            try:
                u_new, ev, its = _newton(asm, u0, s_try, opts, stats, atol)
            except _Fail as fail:
                cuts += 1
                stats.cuts += 1
                if cuts > opts.max_cuts or ds == 0.0 or steps_here > 100 * opts.max_cuts:
                    err = ConvergenceError(
                        f"FEM load stepping stopped at scale {s_cur:.6g} of the field; could "
                        f"not reach {target:.6g} (last step {ds:.3g}, {cuts - 1} cuts, "
                        f"residual {fail.residual:.3g})",
                        reached=s_cur,
                        target=target,
                        residual=fail.residual,
                    )
                    err.result_states = states
                    err.stats = stats
                    raise err from None
                h = ds / 2.0
                continue
            stats.steps += 1
            steps_here += 1
            its_here += its
            if opts.predictor == "tangent" and asm._lu is not None:
                prev_rate = (rate, s_cur) if rate is not None else None
                rate = asm.load_tangent(ev, asm._lu)
                if not np.all(np.isfinite(rate)):
                    rate, prev_rate = None, None
            prev = (u, s_cur)
            u, s_cur = u_new, s_try
            if s_cur == target:
                break
            h = 2.0 * ds if its <= 4 and cuts == 0 else ds
            cuts = 0
        stats.iterations.append(its_here)
        # stability from the last Newton factorisation (within utol * L of the state); a step
        # that converged without iterating left none at this state: factorise its tangent
        if asm._lu is None or its == 0:
            asm._lu = asm.factorize(ev)
            stats.factorizations += 1
        stats.det_signs.append(determinant_sign(asm._lu) * sign0)
        states.append(u.copy())
        if progress is not None:
            progress(len(states) - 1, target)
    return states, stats
