"""Newton's method with a backtracking line search, for one state or a stack of states.

The iteration is the same for every model: solve ``dR/du du = -R`` with the model's tangent,
shorten the step to the model's :meth:`~coilrod.path.protocol.PathProblem.step_limit`, and
backtrack (halving) until the model's :meth:`~coilrod.path.protocol.PathProblem.error`
decreases -- a full step may also raise it by up to ``full_step_growth`` (large rotations do).
A state is converged when its error is at most 1; an iteration that stagnates (the error falls
by less than half three times running) stops early so that the caller can shorten the load step.

Batched models (``problem.batched``) are iterated on a stack of independent states at once,
each member with its own step length, backtracking and convergence; converged members drop out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .protocol import Linearization, PathProblem

__all__ = ["NewtonOptions", "NewtonResult", "newton", "as_batched"]


@dataclass(frozen=True)
class NewtonOptions:
    """Newton settings.

    Attributes
    ----------
    max_iter : int
        Newton iterations per attempt (>= 1).
    backtracks : int
        Halvings of a step in the line search before the attempt fails.
    stagnation : int
        Consecutive iterations whose error falls by less than half before the attempt stops.
    chord : float
        Modified Newton in the quadratic regime: once an iteration has cut the error of every
        member by this factor or more, the following trials are evaluated without a new
        tangent and solved with the last factorisation, for as long as each such chord step
        keeps cutting the error by the same factor (0 disables).  The converged state then
        carries that factorisation (of an iterate within the last, small, increment).
    chord_start : bool
        Start in chord mode (the start is known to be close to the solution, e.g. a solution
        interpolated from a coarser mesh); it falls back to fresh tangents as above.
    """

    max_iter: int = 15
    backtracks: int = 6
    stagnation: int = 3
    chord: float = 0.125
    chord_start: bool = False

    def __post_init__(self):
        for name in ("max_iter", "backtracks", "stagnation"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"{name} must be a positive integer; got {value!r}")
        if not 0.0 <= self.chord < 1.0:
            raise ValueError(f"chord must lie in [0, 1); got {self.chord!r}")


_DEFAULT_OPTIONS = NewtonOptions()  # (frozen: one instance serves every call)


@dataclass
class NewtonResult:
    """Outcome of :func:`newton` (arrays over the stack for a stacked start).

    Attributes
    ----------
    u : ndarray, shape (size,) or (k, size)
        Last iterate(s).
    ok : bool or ndarray of bool
        Converged (error <= 1).
    error : float or ndarray
        The model's convergence measure at ``u`` (inf where inadmissible).
    iterations : int or ndarray of int
        Newton iterations spent.
    lin : Linearization or None
        The linearization at ``u`` (with tangent), for predictors and stability.
    """

    u: np.ndarray
    ok: bool | np.ndarray
    error: float | np.ndarray
    iterations: int | np.ndarray
    lin: Linearization | None


class _OneAtATime(PathProblem):
    """A model without batched evaluations presented through the batched interface."""

    batched = True

    def __init__(self, problem: PathProblem):
        self.problem = problem
        self.size = problem.size
        self.max_correction = problem.max_correction
        self.max_step_change = problem.max_step_change
        self.cheap_tangent = problem.cheap_tangent
        self.full_step_growth = problem.full_step_growth

    def with_tangent(self, lin, other):
        parts = [
            self.problem.with_tangent(a, b) for a, b in zip(lin.tangent, other.tangent, strict=True)
        ]
        return Linearization(lin.u, lin.scale, lin.residual, lin.ok, tangent=parts)

    def linearize(self, u, scale, tangent=True):
        parts = [self.problem.linearize(u[j], float(scale[j]), tangent) for j in range(len(u))]
        return Linearization(
            u=u,
            scale=np.asarray(scale, float),
            residual=np.stack([p.residual for p in parts]),
            ok=np.array([bool(p.ok) for p in parts]),
            tangent=parts,
        )

    def take(self, lin, rows):
        parts = [lin.tangent[j] for j in rows]
        return Linearization(
            lin.u[rows], lin.scale[rows], lin.residual[rows], lin.ok[rows], tangent=parts
        )

    def solve(self, lin, rhs):
        out = np.empty_like(rhs)
        for j, part in enumerate(lin.tangent):
            try:
                out[j] = self.problem.solve(part, rhs[j])
            except (np.linalg.LinAlgError, ValueError, FloatingPointError):
                out[j] = np.nan
        return out

    def d_residual_d_scale(self, lin):
        return np.stack([self.problem.d_residual_d_scale(p) for p in lin.tangent])

    def error(self, lin, du):
        return np.array(
            [
                self.problem.error(p, None if du is None else du[j])
                for j, p in enumerate(lin.tangent)
            ]
        )

    def stability(self, lin, precise=False):
        return np.array([self.problem.stability(p, precise) for p in lin.tangent])

    def branch_stability(self, lin, precise=False):
        return np.array([self.problem.branch_stability(p, precise) for p in lin.tangent])

    def step_limit(self, u, du):
        return np.array([self.problem.step_limit(u[j], du[j]) for j in range(len(u))])

    def distance(self, du):
        return np.array([self.problem.distance(d) for d in du])


def as_batched(problem: PathProblem) -> PathProblem:
    """``problem`` itself if it is batched, else an adapter that evaluates states one by one."""
    return problem if problem.batched else _OneAtATime(problem)


def take(problem: PathProblem, lin: Linearization, rows: np.ndarray) -> Linearization:
    """The members ``rows`` of a stacked linearization (the model's ``take`` if it has one)."""
    if hasattr(problem, "take"):
        return problem.take(lin, rows)
    return problem.linearize(lin.u[rows], np.asarray(lin.scale)[rows])


def _errors(problem, lin, du) -> np.ndarray:
    """The model's error of each member, inf where inadmissible (called inside
    :func:`newton`'s ``np.errstate(all="ignore")``)."""
    ok = lin.ok
    if not (isinstance(ok, np.ndarray) and ok.dtype == bool):
        ok = np.asarray(ok, bool)
    err = problem.error(lin, du)
    if not (isinstance(err, np.ndarray) and err.dtype == float):
        err = np.asarray(err, float)
    return np.where(ok & np.isfinite(err), err, np.inf)


def newton(
    problem: PathProblem,
    u0: np.ndarray,
    scale,
    opts: NewtonOptions | None = None,
    *,
    tangent_at_end: bool = True,
) -> NewtonResult:
    """Solve ``R(u, scale) = 0`` from ``u0`` (one state, or a stack for a batched model).

    Parameters
    ----------
    problem : PathProblem
    u0 : ndarray, shape (size,) or (k, size)
        Starting state(s); a stack needs a batched model (or is solved one by one).
    scale : float or ndarray, shape (k,)
        Load scale(s).
    opts : NewtonOptions, optional
    tangent_at_end : bool
        The returned linearization carries a tangent (for predictors and stability); False
        may return just the states and their residuals (``u``, ``scale``, ``residual``,
        ``ok``).

    Returns
    -------
    NewtonResult
        Shaped like the input (scalars for one state).
    """
    opts = _DEFAULT_OPTIONS if opts is None else opts
    single = np.ndim(u0) == 1
    U = np.array(u0, dtype=float, ndmin=2)  # (a copy: iterated in place)
    k = len(U)
    S = np.array(scale, dtype=float)  # a copy
    if S.shape != (k,):
        S = np.full(k, S[()]) if S.ndim == 0 else np.broadcast_to(S, (k,)).copy()
    fast = getattr(problem, "compiled_newton", None)
    done = None if fast is None else fast(U, S, opts, tangent_at_end)
    if done is not None:  # the model's own compiled corrector: the same iteration, one call
        U, err, iters, lin = done
        ok = (err <= 1.0) & np.isfinite(err)
        if single:
            return NewtonResult(U[0], bool(ok[0]), float(err[0]), int(iters[0]), lin)
        return NewtonResult(U, ok, err, iters, lin)
    P = as_batched(problem)
    with np.errstate(all="ignore"):
        state = (_One if k == 1 else _Iteration)(P, U, S, opts)
        for _ in range(opts.max_iter):
            if not state.step():
                break
        if k == 1:
            state.finish()
        lin = _final(P, U, S, state, tangent_at_end)
    if fast is not None:
        problem.compiled_newton_rent(state.iters)
    if k == 1 and single:  # (the one state's numbers as they are: scalars)
        e = state.e
        return NewtonResult(U[0], e <= 1.0, e, state.n_iter, _single(lin))
    err = state.err
    ok = np.isfinite(err) & (err <= 1.0)
    if single:
        return NewtonResult(U[0], bool(ok[0]), float(err[0]), int(state.iters[0]), _single(lin))
    return NewtonResult(U, ok, err, state.iters, lin)


class _Iteration:
    """The state of one (batched) Newton solve; :meth:`step` does one iteration."""

    def __init__(self, P, U, S, opts):
        k = len(U)
        self.P, self.U, self.S, self.opts = P, U, S, opts
        self.T = P.linearize(U, S)  # the linearization whose tangent the solves use
        self.err = _errors(P, self.T, None)
        self.alive = np.isfinite(self.err)  # (_errors: inf where not ok)
        self.R = np.array(self.T.residual)  # each member's current residual
        self.everyone = np.arange(k)
        self.owners = self.everyone  # T's members, in its row order (sorted)
        self.fresh = np.ones(k, dtype=bool)  # a member's current state is its state in T
        self.last, self.last_members = self.T, self.everyone  # the latest linearization
        self.current = np.ones(k, dtype=bool)  # a member's current state is its state in last
        self.iters = np.zeros(k, dtype=int)
        self.slow = np.zeros(k, dtype=int)
        # error contraction of each member's last iteration (0: trust the start)
        self.chords = opts.chord > 0 and not P.cheap_tangent
        self.ratio = np.zeros(k) if (opts.chord_start and self.chords) else np.ones(k)

    def step(self) -> bool:
        """One iteration over the unconverged members; False when none is left."""
        P, U, S, opts = self.P, self.U, self.S, self.opts
        active = self.alive & (self.err > 1.0)
        n = int(np.count_nonzero(active))
        if n == 0:
            return False
        whole = n == len(U)  # every member active: plain arrays instead of index copies
        act = self.everyone if whole else np.flatnonzero(active)
        chord = (
            self.chords and float((self.ratio if whole else self.ratio[act]).max()) <= opts.chord
        )
        if not chord and not (self.fresh if whole else self.fresh[act]).all():
            # a new tangent at the current states
            self.T, self.owners = P.linearize(U[act], S[act]), act  # (copies: U is iterated)
            rows = slice(None) if whole else act
            self.fresh[rows] = True
            self.R[rows] = self.T.residual
            self._set_last(self.T, act)
        if self.owners.size == n:  # act is T's members (they only drop out)
            dU = P.solve(self.T, -(self.R if whole else self.R[act]))
        else:  # a subset of T's members: zero right-hand sides for the others
            rows = np.searchsorted(self.owners, act)
            rhs = np.zeros((self.owners.size, P.size))
            rhs[rows] = -self.R[act]
            dU = P.solve(self.T, rhs)[rows]
        if not np.isfinite(dU).all():
            finite = np.isfinite(dU).all(axis=1)
            self.alive[act[~finite]] = False
            act, dU = act[finite], dU[finite]
            if act.size == 0:
                return False
        current = U if act is self.everyone else U[act]
        full = np.minimum(1.0, np.asarray(P.step_limit(current, dU), float))
        moved = self._line_search(act, dU, full, chord)
        if not chord and moved.size:  # the new states carry their own tangent
            if self.last_members is moved:  # accepted together in one round: its evaluation
                self.T, self.owners = self.last, moved
            else:  # accepted over several rounds: evaluate them together
                self.T, self.owners = P.linearize(U[moved], S[moved]), moved
                self._set_last(self.T, moved)
            self.fresh[slice(None) if moved is self.everyone else moved] = True
        if moved is self.everyone:
            stuck = (self.slow >= opts.stagnation) & (self.err > 1.0)
        else:
            stuck = (self.slow[moved] >= opts.stagnation) & (self.err[moved] > 1.0)
        if stuck.any():
            self.alive[moved[stuck]] = False
        return True

    def _line_search(self, act, dU, full, chord):
        """Backtrack each member's step until its error decreases (or a full step raises it
        by at most ``full_step_growth``); returns the members that moved (``last_members``
        itself where the latest linearization is theirs: every member of ``act`` accepted in
        one round)."""
        P, U, S = self.P, self.U, self.S
        growth = P.full_step_growth
        alpha = full
        pos = np.arange(act.size)  # members of act still searching
        moved = []
        rounds = 0
        for _ in range(self.opts.backtracks + 1):
            rounds += 1
            if rounds == 1:  # every member of act (pos is all of them): no index copies
                members, step = act, alpha[:, None] * dU
                whole = act is self.everyone
                trial = (U if whole else U[act]) + step
                tlin = P.linearize(trial, S if whole else S[act], tangent=not chord)
                e_new = _errors(P, tlin, step)
                e_old = self.err if whole else self.err[act]  # (read before _take writes)
            else:
                members = act[pos]
                step = alpha[:, None] * dU[pos]
                trial = U[members] + step
                tlin = P.linearize(trial, S[members], tangent=not chord)
                e_new = _errors(P, tlin, step)
                e_old = self.err[members]
            accept = (e_new < e_old) | (e_new <= 1.0)  # (then e_new is finite: _errors)
            if not accept.all():
                first = alpha == (full if rounds == 1 else full[pos])
                accept |= first & (e_new <= growth * e_old)
                accept &= np.isfinite(e_new)
            if accept.all():
                self._take(members, trial, tlin, e_new, e_old, slice(None))
                if pos.size == act.size:
                    self._set_last(tlin, members)
                moved.append(members)
                pos = pos[:0]
                break
            if accept.any():
                acc = np.flatnonzero(accept)
                self._take(members[acc], trial[acc], tlin, e_new[acc], e_old[acc], acc)
                moved.append(members[acc])
            keep = ~accept
            pos, alpha = pos[keep], 0.5 * alpha[keep]
            if pos.size == 0:
                break
        if pos.size:
            failed = act[pos]
            self.alive[failed] = False
            self.iters[failed] += 1
        if len(moved) == 1:  # (each round's members are in act's sorted order)
            return moved[0]
        return np.sort(np.concatenate(moved)) if moved else act[:0]

    def _set_last(self, lin, members):
        """``lin`` is the latest linearization, of ``members`` at their current states."""
        self.last, self.last_members = lin, members
        if members is self.everyone:
            self.current[:] = True
        else:
            self.current[:] = False
            self.current[members] = True

    def _take(self, members, trial, tlin, e_new, e_old, rows):
        """Accept the trial states of ``members`` (rows ``rows`` of ``tlin``)."""
        if members is self.everyone:
            members = slice(None)
        self.slow[members] = np.where(e_new > 0.5 * e_old, self.slow[members] + 1, 0)
        self.ratio[members] = np.where(e_old > 0, e_new / e_old, 0.0)
        self.U[members] = trial
        self.R[members] = tlin.residual[rows]
        self.err[members] = e_new
        self.iters[members] += 1
        self.fresh[members] = False
        self.current[members] = False


class _One:
    """:class:`_Iteration` for one state (k = 1): the same iterates, bitwise, with the
    member's bookkeeping (error, counters, flags) in Python scalars instead of length-1 arrays
    (most solves are of one state).  After :meth:`finish` it has the attributes
    :func:`_final` and :func:`newton` read, as arrays of one member."""

    def __init__(self, P, U, S, opts):
        self.P, self.U, self.S, self.opts = P, U, S, opts
        self.T = P.linearize(U, S)  # the linearization whose tangent the solves use
        self.e = _error_one(P, self.T, None)
        self.live = self.e < math.inf  # (_error_one: inf where not admissible)
        self.R = np.array(self.T.residual)  # the current residual
        self.everyone = self.owners = self.last_members = np.arange(1)
        self.is_fresh = True  # the current state is the state of T
        self.last = self.T  # the latest linearization
        self.is_current = True  # the current state is the state of last
        self.n_iter = 0
        self.n_slow = 0
        self.chords = opts.chord > 0 and not P.cheap_tangent
        self.r = 0.0 if (opts.chord_start and self.chords) else 1.0  # last error contraction

    def step(self) -> bool:
        """One iteration; False when the state has converged or failed."""
        P, U, S, opts = self.P, self.U, self.S, self.opts
        if not (self.live and self.e > 1.0):
            return False
        chord = self.chords and self.r <= opts.chord
        if not chord and not self.is_fresh:  # a new tangent at the current state
            self.T = self.last = P.linearize(U.copy(), S)
            self.is_fresh = self.is_current = True
            self.R[:] = self.T.residual
        dU = P.solve(self.T, -self.R)
        if not np.isfinite(dU).all():
            self.live = False
            return False
        lim = P.step_limit(U, dU)
        x = float(lim[0] if type(lim) is np.ndarray else np.asarray(lim, float).reshape(-1)[0])
        full = 1.0 if x >= 1.0 else x  # (np.minimum: NaN stays NaN)
        moved = self._line_search(dU, full, chord)
        if moved:
            if not chord:  # the accepted trial's linearization carries its tangent
                self.T = self.last
                self.is_fresh = True
            if self.n_slow >= opts.stagnation and self.e > 1.0:
                self.live = False
        return True

    def _line_search(self, dU, full, chord) -> bool:
        """:meth:`_Iteration._line_search` of the one member: True if it moved."""
        P, U, S = self.P, self.U, self.S
        growth = P.full_step_growth
        alpha = full
        for _ in range(self.opts.backtracks + 1):
            step = alpha * dU
            trial = U + step
            tlin = P.linearize(trial, S, tangent=not chord)
            e_new = _error_one(P, tlin, step)
            e_old = self.e
            accept = e_new < e_old or e_new <= 1.0  # (then e_new is finite: _error_one)
            if not accept:
                accept = alpha == full and e_new <= growth * e_old and e_new < math.inf
            if accept:
                self.n_slow = self.n_slow + 1 if e_new > 0.5 * e_old else 0
                self.r = e_new / e_old if e_old > 0 else 0.0
                U[:] = trial
                self.R[:] = tlin.residual
                self.e = e_new
                self.n_iter += 1
                self.is_fresh = False
                self.last, self.is_current = tlin, True
                return True
            alpha = 0.5 * alpha
        self.live = False
        self.n_iter += 1
        return False

    def finish(self):
        """The arrays of one member that :func:`_final` and :func:`newton` read."""
        self.err = np.array([self.e])
        self.iters = np.array([self.n_iter])
        self.fresh = np.array([self.is_fresh])
        self.current = np.array([self.is_current])
        return self


def _error_one(P, lin, du) -> float:
    """:func:`_errors` of a one-member linearization, as a float."""
    ok, err = lin.ok, P.error(lin, du)
    ok = bool((ok if isinstance(ok, np.ndarray) else np.asarray(ok)).reshape(-1)[0])
    e = float((err if isinstance(err, np.ndarray) else np.asarray(err, float)).reshape(-1)[0])
    return e if ok and math.isfinite(e) else math.inf


def _final(P, U, S, it: _Iteration, tangent: bool) -> Linearization:
    """The linearization of every member at its last state, for the caller.

    The tangent's own if it describes them all; with ``tangent``, otherwise the members'
    latest residuals paired with that tangent when it covers them all (each a chord step or
    less away), else a new evaluation; without ``tangent``, the latest residuals.
    """
    T, fresh = it.T, it.fresh
    k = len(U)
    everyone = it.owners.size == k
    if everyone and fresh.all():
        return T
    # the latest linearization, if it holds every member at its current state
    state = it.last if it.last_members.size == k and it.current.all() else None
    if not tangent:  # the residuals the iteration holds (no model-specific extras)
        if state is not None:
            return state
        return Linearization(U, S, it.R, np.isfinite(it.err))
    if not everyone:
        return P.linearize(U, S)
    if state is None:
        state = P.linearize(U, S, tangent=False)
    return P.with_tangent(state, T)


def _single(lin: Linearization) -> Linearization:
    """The one-state view of a stacked linearization of one member (the model's own object for
    a model evaluated one by one)."""
    if isinstance(lin.tangent, list):  # from _OneAtATime
        return lin.tangent[0]
    return lin
