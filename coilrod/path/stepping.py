"""Load stepping along an equilibrium path: predictor, Newton corrector, cuts, events.

:func:`follow_load` continues an equilibrium from a start state (the unloaded model at scale 0)
through a list of requested load scales, in order.  Every step -- the first one from the start
included -- is the same:

1. **predict** the state at the trial scale with the path tangent ``du/ds = -J^-1 dR/ds`` plus
   a second-order (Hermite) term from the previous state;
2. **correct** with :func:`~coilrod.path.corrector.newton`;
3. **accept** if Newton converged, the correction is within the model's ``max_correction``
   (a larger one means the step may have jumped to another branch), the step agrees with the
   trapezoidal rule of the path rates at its two ends (a state reached over a fold, on another
   branch, does not, even when it is close to the prediction) and the stability did not
   change -- if it did, the step is **cut** until the change is located within
   ``bifurcation_tol`` of the requested step: a change that persists at that resolution is a
   bifurcation on this branch (reported as an event; the solver stays on its branch), while a
   jump onto another branch (e.g. over the knee of an imperfect bifurcation) disappears as the
   steps resolve the path;
   A path-dependent model (friction) with a ``touchdown_force`` method also has a step in
   which a contact point first touches cut (a secant toward the touch) until that point
   carries at most the model's ``touchdown_tol``: its slip is then measured from where it
   touched, not from where it was before the step (else the answer moves with the steps);
4. otherwise **halve** the step (and double it again after easy steps);
5. a step that cannot be shortened further (``min_step``) means the branch ends: the path is
   followed around the limit point by pseudo-arclength continuation
   (:class:`~coilrod.path.arclength.ArcLength`) until it is stable again beyond it -- the
   snap-through of a quasi-statically loaded structure (an event; a path that passes beyond
   without turning back, e.g. at a vertical inflection, is continued without one) -- or, if it
   does not come back, :class:`~coilrod.errors.ConvergenceError` says how far the load got.

The requested scales must be finite.  Known limits (pinned by strict xfails in
``tests/test_path_stepping.py``): stability is sampled at the accepted states only, so a window
of instability inside one step on a branch whose state does not change is not seen; a start
whose tangent is singular cannot be left; a symmetric pitchfork on a *curved* trivial branch is
an imperfect one at the Newton tolerance (the engine then stops with an error or follows a
buckled branch).

For batched models, smooth stretches are corrected in chunks: the next requested scales are
predicted together from the branch and corrected in one batched Newton; the leading run that
converged with small corrections and unchanged stability is accepted, the rest is stepped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConvergenceError
from .arclength import ArcLength
from .corrector import NewtonOptions, as_batched, newton, take
from .protocol import Linearization, PathProblem

_EPS = float(np.finfo(float).eps)

__all__ = ["PathOptions", "PathPoint", "PathRun", "follow_load"]


@dataclass(frozen=True)
class PathOptions:
    """Settings of the load stepping.

    Attributes
    ----------
    newton : NewtonOptions
    min_step : float
        Smallest load sub-step, as a fraction of the requested step, before the branch is
        taken to end (a limit point) or the load to be unreachable.
    bifurcation_tol : float
        A change of stability is located to this fraction of the requested step (> min_step).
    change_growth : float
        The predicted change of the state in a step may exceed the last step's by this factor
        (see ``_Tracker.change_limit``).
    relative_correction : float
        A step is also rejected (and cut) when the Newton correction exceeds this fraction of
        the predicted change of the state (plus 1e-3 of the model's ``max_correction``): on a
        smooth path the predictor's error is of higher order than the change, while a jump to
        another branch (over a fold) is not.
    stability : bool
        Check the stability of every accepted state (cut steps that change it, report events).
    chunk : int
        Batched models: requested scales predicted and corrected together on smooth stretches
        (1 disables chunking).
    snaps : int
        Snap-throughs allowed within one requested step.
    snap_steps : int
        Arclength steps allowed to go around one fold.
    """

    newton: NewtonOptions = field(default_factory=NewtonOptions)
    min_step: float = 1e-6
    bifurcation_tol: float = 1e-4
    relative_correction: float = 0.25
    change_growth: float = 2.0
    stability: bool = True
    chunk: int = 10
    snaps: int = 4
    snap_steps: int = 400

    def __post_init__(self):
        if not isinstance(self.newton, NewtonOptions):
            raise TypeError(f"newton must be a NewtonOptions; got {type(self.newton).__name__}")
        if not (np.isfinite(self.relative_correction) and self.relative_correction > 0):
            raise ValueError(
                f"relative_correction must be positive and finite; got {self.relative_correction}"
            )
        if not (np.isfinite(self.change_growth) and self.change_growth >= 1):
            raise ValueError(f"change_growth must be finite and >= 1; got {self.change_growth}")
        if not 0 < self.min_step < self.bifurcation_tol < 1:
            raise ValueError(
                "need 0 < min_step < bifurcation_tol < 1; got "
                f"min_step={self.min_step}, bifurcation_tol={self.bifurcation_tol}"
            )
        for name in ("chunk", "snaps", "snap_steps"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"{name} must be a positive integer; got {value!r}")


@dataclass
class PathPoint:
    """A converged equilibrium on the path.

    Attributes
    ----------
    u : ndarray, shape (size,)
    scale : float
    error : float
        The model's convergence measure (<= 1).
    stability : float
        The model's cheap stability indicator (> 0 stable).
    lin : Linearization or None
        The linearization at the state (stacked, one member), with its tangent (None for the
        inner states of a batch-corrected chunk, which the path does not continue from).
    rate : ndarray or None
        ``du/dscale`` along the path (None where the tangent is singular).
    residual : ndarray or None
        ``R(u, scale)``, shape (size,).
    """

    u: np.ndarray
    scale: float
    error: float
    stability: float
    lin: Linearization
    rate: np.ndarray | None = None
    residual: np.ndarray | None = None


@dataclass
class PathRun:
    """What :func:`follow_load` returns.

    Attributes
    ----------
    points : list of PathPoint
        One per requested scale, in order.
    iterations : ndarray of int
        Newton iterations spent reaching each requested scale from the previous one.
    events : list of dict
        Bifurcations and snap-throughs (see :mod:`coilrod.path.events`).
    start : PathPoint
        The start state.
    steps, cuts : int
        Accepted load sub-steps and rejected attempts (Newton failed, a jump, a change of
        stability being located).
    """

    points: list
    iterations: np.ndarray
    events: list
    start: PathPoint
    steps: int = 0
    cuts: int = 0


def touchdown_secant(s0: float, h: float, s1: float, force: float, landed, tol: float) -> float:
    """The next trial step from ``s0`` after the trial step ``h`` to ``s1`` ended with a newly
    touching contact point carrying ``force`` > ``tol`` (its normal force per length, the
    model's ``touchdown_tol``): aimed just past the touch (a quarter of ``tol``) that the
    secant through the last such trial ``landed`` = (s, force) predicts -- the normal force
    grows linearly from 0 at the touch -- where that lies strictly between ``s0`` and ``s1``,
    else half the step.  The load stepping (:meth:`_Tracker.touchdown_step`) and
    :func:`coilrod.insert`'s steps use it."""
    if landed is not None and landed[1] != force and landed[0] != s1:
        slope = (force - landed[1]) / (s1 - landed[0])
        aim = s1 - (force - 0.25 * tol) / slope
        if (aim - s0) * h > 0 and abs(aim - s0) < abs(s1 - s0):
            return aim - s0
    return h / 2.0


class _Tracker:
    """State of one run (the current and previous points, the counters)."""

    def __init__(self, problem: PathProblem, opts: PathOptions, name: str):
        self.P = as_batched(problem)
        self.native = problem.batched
        self.model = problem
        self.opts = opts
        self.name = name
        self.events: list = []
        self.steps = 0
        self.cuts = 0
        self.last_change = None  # change of the state in the last accepted step
        self.event = None  # (point, step) of a trial step ended at a contact event
        self.crossing = None  # the start of a trial step predicted across contact events
        # distances already measured, reused by identity: (cur, guess, predicted change) of
        # the last trial step and (cur, u, change) of the last smoothness test
        self.predicted = None
        self.moved = None
        #: Corrections below this (1e-3 of the model's max_correction) never signal a jump.
        limit = self.P.max_correction
        self.negligible = 1e-3 * limit if np.isfinite(limit) else 0.0
        #: Normal force a newly touching point may carry (friction; :meth:`touchdown_force`).
        self.touchdown_tol = float(getattr(problem, "touchdown_tol", np.inf))

    # -- small helpers ------------------------------------------------------------------------
    def point(self, u, scale, error, lin, stab=None, rate=None) -> PathPoint:
        if stab is None:
            stab = float(self.P.stability(lin)[0]) if self.opts.stability else 1.0
        if rate is None:
            rate = self.rate(lin)
        return PathPoint(u, float(scale), float(error), stab, lin, rate, np.array(lin.residual[0]))

    def rate(self, lin: Linearization):
        """du/dscale = -J^-1 dR/dscale at a converged state (None if J is singular); a
        model's corrector may have computed it already (``lin.path_rate``, (k, size))."""
        known = getattr(lin, "path_rate", None)
        if known is not None:
            r = known[0]
        else:
            with np.errstate(all="ignore"):
                r = -self.P.solve(lin, self.P.d_residual_d_scale(lin))[0]
        return r if np.isfinite(r).all() else None

    def predict(self, cur: PathPoint, prev: PathPoint | None, s1: float) -> np.ndarray:
        ds = s1 - cur.scale
        if cur.rate is None:
            return cur.u.copy()
        guess = cur.u + ds * cur.rate
        if prev is not None:
            h = cur.scale - prev.scale
            if h != 0 and abs(ds) <= 4 * abs(h):
                curv = (prev.u - cur.u + cur.rate * h) / (h * h)
                guess = guess + curv * ds * ds
        return guess

    def stable(self, value: float) -> bool:
        return bool(value > 0)

    def continuous(self, cur: PathPoint, guess: np.ndarray, u: np.ndarray) -> bool:
        """The converged ``u`` continues the path from ``cur``: its distance from the
        prediction ``guess`` is within the model's ``max_correction`` and, where the path
        tangent is known, within ``relative_correction`` of the predicted change."""
        if cur.rate is None:
            return float(self.P.distance((u - guess)[None])[0]) <= self.P.max_correction
        known = self.predicted
        if known is not None and known[0] is cur and known[1] is guess:  # measured by _trial
            correction, change = float(self.P.distance((u - guess)[None])[0]), known[2]
        else:  # (np.array of equal-shape rows: np.stack's values, at a quarter of its overhead)
            correction, change = map(float, self.P.distance(np.array([u - guess, guess - cur.u])))
        if correction > self.P.max_correction:
            return False
        return correction <= self.opts.relative_correction * change + self.negligible

    def smooth(self, cur: PathPoint, u: np.ndarray, rate, h: float) -> bool:
        """The step from ``cur`` to ``u`` (rate ``rate``) over ``h`` follows one smooth path:
        the change agrees with the trapezoidal rule of the two path rates,
        ``u - cur.u = h (cur.rate + rate) / 2`` up to ``relative_correction`` of the change (a
        third-order error on a smooth path).  A state on another branch -- reached over a
        fold, where the two rates differ in sign or size -- fails it even when it lies close
        to the prediction and is as stable as ``cur``."""
        if cur.rate is None or rate is None or self.crossing is cur:
            return True
        change = u - cur.u
        gap, size, moved = map(  # (one call of the model's distance for the three)
            float,
            self.P.distance(
                np.array([change - 0.5 * h * (cur.rate + rate), np.abs(cur.u) + np.abs(u), change])
            ),
        )
        self.moved = (cur, u, moved)  # (the change again for accepted())
        # rounding of the states themselves (a step far below their resolution)
        rounding = 64 * _EPS * size
        tol = self.opts.relative_correction * moved
        return gap <= tol + self.negligible + rounding

    def change_limit(self) -> float:
        """Largest predicted change of the state in the next step: twice the last accepted
        step's change (so the stepping creeps into a fold or the knee of an imperfect
        bifurcation, where the path tangent blows up, instead of leaping across), at least a
        tenth and at most all of the model's ``max_step_change``."""
        cap = self.P.max_step_change
        if self.last_change is None or not math.isfinite(cap):
            return cap
        return min(cap, max(self.opts.change_growth * self.last_change, 0.1 * cap))

    def trial(self, cur: PathPoint, prev, h: float, target: float):
        """The next trial step from ``cur`` toward ``target``: ``(h, s1, guess)``.

        ``h`` is shortened so that the whole predicted change of the state -- the Hermite
        curvature term included, which near a fold can carry the prediction across it -- is
        within :meth:`change_limit` (first by the linear part ``|rate| h``, then by shortening
        until the prediction itself complies); a step reaching ``target`` ends exactly there.
        A model with contact (an ``event_fraction(U, dU)`` method) predicts a step whose
        contact set changes by its ``piecewise_prediction(u, scale, ds)`` (the linearised
        complementarity problem; the trapezoid test of :meth:`smooth` does not apply across
        the change), else ends the step where the set first changes and resumes the step's
        length after it (:mod:`coilrod.rod.contact_predictor`); the step after a change
        predicts without the Hermite term (``prev`` lies on the other side of the kink).
        """
        event, self.event = self.event, None
        crossed, self.crossing = self.crossing, None
        if event is not None and event[0] is prev and abs(event[1]) > abs(h):
            h = float(np.copysign(abs(event[1]), h))  # the step ended at an event: resume
        if prev is not None and (crossed is prev or (event is not None and event[0] is prev)):
            prev = None  # the last step met a change of the contact set: no Hermite term
        h1, s1, guess = self._trial(cur, prev, h, target)
        hook = getattr(self.model, "event_fraction", None)
        if hook is None:
            return h1, s1, guess
        across = getattr(self.model, "piecewise_prediction", None)
        if across is not None and cur.rate is not None:
            frac = float(hook(cur.u[None], (guess - cur.u)[None])[0])
            if not frac < 1.0:  # no event ahead (the loop below would measure it again)
                return h1, s1, guess
            crossed = across(cur.u, cur.scale, h1)
            limit = self.change_limit()
            if crossed is not None and float(
                self.P.distance((crossed - cur.u)[None])[0]
            ) <= limit * (1.0 + 1e-9):
                self.crossing = cur  # a step across contact events: not smooth
                return h1, s1, crossed
        start = h1
        for _ in range(4):  # the Hermite term makes the prediction nonlinear in the step
            frac = float(hook(cur.u[None], (guess - cur.u)[None])[0])
            if not frac < 1.0:
                break
            h1 *= max(frac, 1e-3)
            s1 = cur.scale + h1
            guess = self.predict(cur, prev, s1)
        if h1 != start:
            self.event = (cur, h)
        return h1, s1, guess

    def polish(self, res) -> None:
        """One more Newton iteration on a converged requested state of a model with contact
        (an ``event_fraction`` method) whose error is not well below the tolerance: its
        piecewise-linear complementarity rows let Newton stop just under it, and the
        requested states are what the caller reports (forces that balance to round-off)."""
        if getattr(self.model, "event_fraction", None) is None or not res.ok[0]:
            return
        if res.error[0] <= 1e-3 or res.lin is None or res.lin.tangent is None:
            return
        with np.errstate(all="ignore"):
            du = self.P.solve(res.lin, -np.asarray(res.lin.residual))
            u = res.u + du
            lin = self.P.linearize(u, np.asarray(res.lin.scale))
            err = np.asarray(self.P.error(lin, du), float)
        if np.all(np.isfinite(err)) and bool(np.all(lin.ok)) and err[0] < res.error[0]:
            res.u, res.lin, res.error = u, lin, err
            res.iterations = res.iterations + 1

    def _trial(self, cur: PathPoint, prev, h: float, target: float):
        """:meth:`trial` without the contact events."""
        limit = self.change_limit()
        bounded = cur.rate is not None and math.isfinite(limit)
        if bounded:
            per_unit = float(self.P.distance(cur.rate[None])[0])
            if per_unit * abs(h) > limit:
                h = math.copysign(limit / per_unit, h)
        remaining = target - cur.scale
        if abs(h) >= abs(remaining):
            h, s1 = remaining, target
        else:
            s1 = cur.scale + h
        guess = self.predict(cur, prev, s1)
        if not bounded:
            return h, s1, guess
        for _ in range(60):
            change = float(self.P.distance((guess - cur.u)[None])[0])
            if change <= limit * (1.0 + 1e-9):
                self.predicted = (cur, guess, change)
                break
            h *= min(0.5, max(0.1, 0.9 * limit / change))
            s1 = cur.scale + h
            guess = self.predict(cur, prev, s1)
        return h, s1, guess

    def accepted(self, old: PathPoint, new: PathPoint) -> None:
        """Record the change of an accepted step (for :meth:`change_limit`) and tell a
        path-dependent model (:meth:`commit`)."""
        known = self.moved
        if known is not None and known[0] is old and known[1] is new.u:  # measured by smooth
            self.last_change = known[2]
        else:
            self.last_change = float(self.P.distance((new.u - old.u)[None])[0])
        self.commit(new)

    def commit(self, p: PathPoint) -> None:
        """Tell the model that ``p`` is accepted (its ``accept_state(u)`` hook, if it has one:
        friction measures slip from the last accepted state)."""
        hook = getattr(self.model, "accept_state", None)
        if hook is not None:
            hook(p.u)

    def touchdown_force(self, cur: PathPoint, u: np.ndarray) -> float:
        """Normal force of the points that touch in the step from ``cur`` to ``u``, for a
        path-dependent model (friction) with a ``touchdown_force(u_old, u_new)`` method
        (0 otherwise): above the model's ``touchdown_tol`` their slip would be measured
        from where they were before the step, not from where they touched, so the step is
        cut until it ends at the touch (:meth:`touchdown_step`)."""
        hook = getattr(self.model, "touchdown_force", None)
        if hook is None or not getattr(self.model, "path_dependent", False):
            return 0.0
        return float(hook(cur.u, u))

    def touchdown_step(self, cur: PathPoint, h: float, s1: float, force: float, landed):
        """The next trial step after the trial at ``s1`` touched with ``force`` (> the
        model's ``touchdown_tol``): :func:`touchdown_secant`."""
        return touchdown_secant(cur.scale, h, s1, force, landed, self.touchdown_tol)

    def near_fold(self, cur: PathPoint) -> bool:
        """The model says ``cur`` is close to a limit point (failing steps then mean a fold)."""
        hook = getattr(self.model, "near_fold", None)
        return bool(hook(cur.lin)) if hook is not None else False

    def fail(self, k, target, cur, residual, why="") -> ConvergenceError:
        hint = getattr(self.model, "fold_hint", None)
        extra = hint(cur.lin) if hint is not None else ""
        reason = getattr(self.model, "last_failure", "")
        if not why:
            why = (
                f"error {residual:.3g} of the tolerance"
                if np.isfinite(residual)
                else (reason or "the model could not be evaluated at the trial states")
            )
        return ConvergenceError(
            f"{self.name} could not reach scale {target:g} (index {k}); it reached scale "
            f"{cur.scale:g} ({why}){extra}",
            reached=cur.scale,
            target=float(target),
            residual=float(residual),
        )

    # -- one requested step ----------------------------------------------------------------------
    def advance(self, cur: PathPoint, prev, target: float, k: int, first_of: float):
        """Continue from ``cur`` to ``target``; returns (cur, prev, iterations)."""
        opts = self.opts
        full = target - cur.scale
        if full == 0:
            return cur, prev, 0
        h = full
        iters = 0
        snaps = 0
        failures = 0
        locating = False  # a change of stability lies ahead: bisect, do not grow the step
        seen_at = None  # the trial scale where the change was seen
        residual = np.inf
        touch = None  # (scale, force) of the last trial cut for touching too hard
        resume = None  # the step's length before such cuts (resumed once the points touched)
        while True:
            remaining = target - cur.scale
            if remaining == 0:
                return cur, prev, iters
            h, s1, guess = self.trial(cur, prev, h, target)
            res = newton(self.P, guess[None], np.array([s1]), opts.newton)
            if s1 == target:
                self.polish(res)
            iters += int(res.iterations[0])
            ok = bool(res.ok[0])
            residual = float(res.error[0])
            stab = 1.0
            rate = None
            u = res.u[0]
            if ok:
                ok = self.continuous(cur, guess, u)
            if ok:
                rate = self.rate(res.lin)
                ok = self.smooth(cur, u, rate, h)
            force = self.touchdown_force(cur, u) if ok else 0.0
            if force > self.touchdown_tol and abs(h) > opts.min_step * abs(full):
                # friction: end the step where the new contact points touch
                if resume is None:
                    resume = h
                h = self.touchdown_step(cur, h, s1, force, touch)
                touch = (s1, force)
                self.cuts += 1
                locating, seen_at = True, s1
                continue
            if ok and force > 0:
                touch = None  # (touched: the next touch-down is another one)
            if ok and opts.stability:
                stab = float(self.P.stability(res.lin)[0])
                if self.stable(stab) != self.stable(cur.stability):
                    if abs(h) > opts.bifurcation_tol * abs(full):
                        h /= 2.0  # locate the change of stability: shorten the step
                        self.cuts += 1
                        locating, seen_at = True, s1
                        continue
                    locating = False
                    self.record_bifurcation(cur, s1, stab, k, first_of, target)
            if ok:
                new = self.point(u, s1, residual, res.lin, stab, rate)
                self.accepted(cur, new)
                prev, cur = cur, new
                failures = 0
                self.steps += 1
                if locating and (s1 - seen_at) * full >= 0:
                    # passed the trial state where the change was seen without meeting it
                    # (that trial had converged to another branch): stop bisecting
                    locating = False
                taken = h
                if res.iterations[0] <= 4 and not locating:
                    h *= 2.0
                elif res.iterations[0] <= 4:
                    # bisecting toward the change: grow, but never past the scale where it
                    # was seen (a step cut for another reason must not creep on at its size)
                    h = math.copysign(min(2.0 * abs(h), abs(seen_at - s1)), h)
                if force > 0 and resume is not None:
                    # touched: back toward the step's length before the cuts (at once, the
                    # next trial often failed past the next touch: at most 64 landing steps)
                    h = math.copysign(min(abs(resume), 64.0 * abs(taken)), h)
                    resume, locating = None, False
                elif touch is not None:  # short of the touch aimed at: the same step again
                    h = taken
                continue
            h /= 2.0
            failures += 1
            self.cuts += 1
            near = failures % 4 == 0 and self.near_fold(cur)
            if near or abs(h) < opts.min_step * abs(full):
                snaps += 1
                landing = self.snap(cur, target, full) if snaps <= opts.snaps else None
                if landing is None:
                    raise self.fail(k, target, cur, residual)
                fold, landed = landing
                if fold is not None:  # the path turned at a fold and came back: a snap
                    self.events.append(
                        {
                            "kind": "snap",
                            "index": k,
                            "scale": fold,
                            "landing": landed.scale,
                            "stable": True,
                            "between": (first_of, target),
                        }
                    )
                # else the arclength passed a hard stretch of a monotone path (a vertical
                # inflection): a continuation on the same branch, not an event
                prev, cur = None, landed
                self.commit(landed)
                self.last_change = None
                full = h = target - cur.scale

    def record_bifurcation(self, cur, s1, stab, k, first_of, target):
        a, b = cur.scale, s1
        ma, mb = cur.stability, stab
        # linear interpolation of the stability measure (exact for a linear eigenvalue)
        crit = a + (b - a) * ma / (ma - mb) if ma != mb else b
        if not min(a, b) <= crit <= max(a, b):
            crit = 0.5 * (a + b)
        self.events.append(
            {
                "kind": "bifurcation",
                "index": k,
                "scale": float(crit),
                "stable": self.stable(stab),
                "between": (first_of, target),
            }
        )

    def snap(self, cur: PathPoint, target: float, full: float):
        """Follow the path by arclength from ``cur`` (where load steps toward ``target`` fail)
        until it is stable beyond ``cur.scale``.

        Returns ``(fold_scale, landing_point)`` when the path turned back at a fold (a
        snap-through), ``(None, point)`` when it went on beyond ``cur.scale`` without turning
        (a stretch the load steps could not pass, e.g. a vertical inflection), and None when
        it does not come back (the branch ends or stays unstable).  The arclength's scale unit
        is the requested step ``full`` (at least the rest of it); its steps may grow to a unit,
        the model's ``max_step_change`` bounding each step's change of the state.
        """
        direction = 1 if target > cur.scale else -1
        span = max(abs(target - cur.scale), abs(full), 1e-3 * abs(cur.scale), 1e-150)
        tracer = ArcLength(self.model, span, self.opts.newton, max_step=span)
        extreme, turned = cur.scale, False
        for u, c, err, lin in tracer.follow(cur.u, cur.scale, direction, self.opts.snap_steps):
            if not turned:
                if (c - extreme) * direction >= 0:
                    extreme = c  # still on the old branch, toward the fold
                else:
                    turned = True
            if (c - cur.scale) * direction > 0 and self.stable(
                float(self.P.branch_stability(lin)[0])
            ):
                return (float(extreme) if turned else None), self.point(u, c, err, lin)
        return None

    # -- chunks of a smooth stretch (batched models) ---------------------------------------------
    def chunk(self, cur: PathPoint, prev: PathPoint, targets: np.ndarray):
        """Correct the next ``targets`` together; returns the accepted leading run as a list of
        (point, iterations)."""
        h = cur.scale - prev.scale
        d = targets - cur.scale
        if h == 0 or cur.rate is None or (d * h <= 0).any() or ((d[1:] - d[:-1]) * h <= 0).any():
            return []
        curv = (prev.u - cur.u + cur.rate * h) / (h * h)
        preds = cur.u + d[:, None] * cur.rate + (d * d)[:, None] * curv
        steps = self.P.distance(_increments(cur.u, preds))
        limit = self.change_limit()
        m = len(targets) if np.all(steps <= limit) else int(np.argmax(steps > limit))
        if m < 2:
            return []
        targets, preds, d = targets[:m], preds[:m], d[:m]
        res = newton(self.P, preds, targets, self.opts.newton)
        dist = self.P.distance
        # each member continues the path (its correction against its predicted change from
        # ``cur``) and no member jumps (its increment from the previous member stays within
        # twice the predicted increment)
        correction = dist(res.u - preds)
        good = res.ok & (correction <= self.P.max_correction)
        tiny = self.negligible
        good &= correction <= self.opts.relative_correction * dist(preds - cur.u) + tiny
        good &= dist(_increments(cur.u, res.u)) <= 2.0 * steps[:m] + tiny
        n_good = m if good.all() else int(np.argmin(good))
        if n_good == 0:
            return []
        stab = np.asarray(self.P.stability(res.lin), float) if self.opts.stability else np.ones(m)
        flips = (stab[:n_good] > 0) != self.stable(cur.stability)
        if flips.any():  # leave the change of stability to the stepping (it locates it)
            n_good = int(np.argmax(flips))
        if n_good:
            last = res.u[n_good - 1] - (res.u[n_good - 2] if n_good > 1 else cur.u)
            self.last_change = float(self.P.distance(last[None])[0])
        run = []
        # (Python floats and ints of the members' numbers in one conversion each)
        scales, errors = targets[:n_good].tolist(), res.error[:n_good].tolist()
        stabs, iters = stab[:n_good].tolist(), res.iterations[:n_good].tolist()
        for j in range(n_good):
            lin = rate = None
            if j == n_good - 1:  # the last accepted state carries on the path
                lin = take(self.P, res.lin, np.array([j]))
                rate = self.rate(lin)
            p = PathPoint(
                res.u[j], scales[j], errors[j], stabs[j], lin, rate, np.array(res.lin.residual[j])
            )
            run.append((p, iters[j]))
        return run


def _increments(u0: np.ndarray, U: np.ndarray) -> np.ndarray:
    """The increments ``U[0] - u0, U[1] - U[0], ...`` of a stack ``U``, shape (k, size): the
    values of ``np.diff(np.vstack([u0[None], U]), axis=0)`` without its stacking copy."""
    out = np.empty_like(U)
    np.subtract(U[0], u0, out=out[0])
    np.subtract(U[1:], U[:-1], out=out[1:])
    return out


def follow_load(
    problem: PathProblem,
    u0: np.ndarray,
    scales,
    opts: PathOptions | None = None,
    *,
    start_scale: float = 0.0,
    name: str = "solve",
    progress=None,
) -> PathRun:
    """Continue the equilibrium at ``(u0, start_scale)`` through ``scales`` in order.

    Parameters
    ----------
    problem : PathProblem
    u0 : ndarray, shape (size,)
        The start state (an equilibrium at ``start_scale``, e.g. the unloaded model; it is
        corrected by Newton first).
    scales : array-like, shape (m,)
        Requested load scales.
    opts : PathOptions, optional
    start_scale : float
    name : str
        The solver's name, for error messages.
    progress : callable, optional
        Called as ``progress(k, scale)`` after each requested scale converged.

    Returns
    -------
    PathRun

    Raises
    ------
    ConvergenceError
        A requested scale could not be reached; ``reached`` is the last converged scale,
        ``points`` the converged :class:`PathPoint` of the requested scales before it and
        ``events`` the events so far.
    """
    opts = PathOptions() if opts is None else opts
    scales = np.asarray(scales, dtype=float)
    if scales.ndim != 1:
        raise ValueError(f"scales must be one-dimensional; got shape {scales.shape}")
    if not np.all(np.isfinite(scales)) or not np.isfinite(start_scale):
        raise ValueError(
            f"the load scales must be finite; got start_scale={start_scale!r}, "
            f"non-finite requested scales at indices {np.flatnonzero(~np.isfinite(scales))}"
        )
    t = _Tracker(problem, opts, name)
    res = newton(t.P, np.asarray(u0, float)[None], np.array([start_scale]), opts.newton)
    if not res.ok[0]:
        raise ConvergenceError(
            f"{name}: the start state at scale {start_scale:g} is not an equilibrium "
            f"(error {float(res.error[0]):.3g})",
            reached=float("nan"),
            target=float(scales[0]) if scales.size else float("nan"),
            residual=float(res.error[0]),
        )
    start = t.point(res.u[0], start_scale, float(res.error[0]), res.lin)
    t.commit(start)
    # a path-dependent model (friction) is stepped one scale at a time: a chunk would correct
    # all its states from one accepted state
    chunks = opts.chunk > 1 and not getattr(problem, "path_dependent", False)
    cur, prev = start, None
    points: list = []
    iterations = np.zeros(scales.size, dtype=int)
    k = 0
    try:
        while k < scales.size:
            if t.native and chunks and prev is not None and scales.size - k > 1:
                wanted = scales[k : k + opts.chunk]
                run = t.chunk(cur, prev, wanted)
                t.steps += len(run)
                for p, its in run:
                    prev, cur = cur, p
                    _append(points, p)
                    iterations[k] = its
                    if progress is not None:
                        progress(k, p.scale)
                    k += 1
                if len(run) == len(wanted) and cur.rate is not None:
                    continue  # a smooth stretch: try the next chunk; else one plain step
            if k >= scales.size:
                break
            first_of = cur.scale
            cur, prev, its = t.advance(cur, prev, float(scales[k]), k, first_of)
            iterations[k] += its
            _append(points, cur)
            if progress is not None:
                progress(k, cur.scale)
            k += 1
    except ConvergenceError as err:
        err.points = points
        err.events = t.events
        err.steps, err.cuts = t.steps, t.cuts
        raise
    return PathRun(points, iterations, t.events, start, t.steps, t.cuts)


def _append(points: list, p: PathPoint) -> None:
    """Append ``p``; the previous point no longer needs its linearization (a FEM tangent's
    factorisation is large): only the current point's is kept."""
    if points and points[-1] is not p:
        points[-1].lin = None
    points.append(p)
