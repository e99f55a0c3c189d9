"""Load steps that end where the contact set changes (the spatial rod's contact predictor).

A contact state is a piecewise-smooth function of the load: between changes of the active set
(a contact point closing on the wall, or an active one whose force per length falls to zero
and releases) the path is smooth and the path tangent of the active set predicts it to second
order; across a change the tangent is wrong at first order (it lets the rod penetrate the
wall, or keeps pulling it onto the wall), and semi-smooth Newton then spends iterations
finding the new set point by point.  :func:`event_fraction` gives the fraction of a predicted
change at which the first such event happens; where it is below 1, the path engine's trial
step (:meth:`coilrod.path.stepping._Tracker.trial`) predicts with
:func:`piecewise_prediction` (the linearised complementarity problem along the step: the
active set's tangent, switched at each event), or, if that cannot be formed, ends the step
at the event -- so that every corrector starts from a prediction with the right contact set.
(A primal-dual active-set solve of the same linearised problem at the step's end was tried:
it cycles on the flat support from 64 segments.)
"""

from __future__ import annotations

import math

import numpy as np

from .mesh import _remember

__all__ = ["event_fraction", "piecewise_prediction"]

#: An active multiplier below this fraction of the largest one is taken as already released
#: (its sign change is left to Newton: ending a step there would stall the stepping).
_RELEASE_FLOOR = 1e-6

#: A converged state's prediction takes the every-rows band of the last tangent at its scale
#: where no node's rotation differs from the state's by more than this (rad): Newton's last
#: chord steps (1e-9 to 1e-5 rad in the bend state), not a fresh linearization.
_NEAR = 1e-3


def event_fraction(problem, U: np.ndarray, dU: np.ndarray) -> np.ndarray:
    """Fraction (k,) of the changes ``dU`` (k, size) of states ``U`` (k, size) at which the
    first contact event of the spatial rod ``problem`` happens, 1 if none does: an open
    contact point closing (:meth:`~coilrod.rod.spatial.SpatialRod.closing_fraction`,
    evaluated on the changed state) or an active multiplier (contact force per length)
    reaching zero (linear in ``dU``)."""
    U, dU = np.atleast_2d(U), np.atleast_2d(dU)
    k = U.shape[0]
    if not problem.nc or problem.uniform or problem.nt:
        # with friction (problem.nt tangential unknowns per point) the stick/slip rows are
        # measured from the last accepted state: the step is left to the corrector
        return np.ones(k)
    frac = problem.closing_fraction(U, dU)
    nc = problem.nc
    lam = U.reshape(k, problem.n, problem.nv)[:, 1:, 9 : 9 + nc]
    d_lam = dU.reshape(k, problem.n, problem.nv)[:, 1:, 9 : 9 + nc]
    floor = _RELEASE_FLOOR * np.abs(lam).max(axis=(1, 2), keepdims=True)
    releasing = (lam > floor) & (lam + d_lam < 0.0)
    with np.errstate(all="ignore"):
        release = np.where(releasing, lam / -d_lam, 1.0)
    return np.minimum(frac, release.min(axis=(1, 2)))


def _reach(D: np.ndarray, c: np.ndarray) -> np.ndarray:
    """A bound (m,) on how far m nodes' contact points ``x + c t`` move (units of L) under a
    change ``D`` (m, nv) of their unknowns: ``|dx| + c |dphi|`` (``c`` (m,): the offsets
    along the tangents, units of L; ``|dt| <= |dphi|`` for ``t = exp(phi) R0 e1``: the left
    Jacobian of SO(3)'s exponential map has norm 1 at most)."""
    dx, dp = D[:, 0:3], D[:, 3:6]
    return np.sqrt(np.einsum("ji,ji->j", dx, dx)) + c * np.sqrt(np.einsum("ji,ji->j", dp, dp))


def _every_rows_linearization(problem, u: np.ndarray, scale: float):
    """The linearization of ``problem`` at the state ``u`` (size,) and ``scale`` with every
    contact row the gap's (kappa times its gradient: ``SpatialRod._every_rows``, set on the
    instance for this call only); it remembers the state's surface gaps
    (``SpatialRod._state_gaps``)."""
    problem._every_rows = True
    try:
        return problem.linearize(u[None], np.array([scale]))
    finally:
        del problem._every_rows


_ENTRIES: dict = {}  # (n, nv, nc, kl + ku) -> _contact_entries (read-only arrays), bounded


def _contact_entries(problem):
    """Band-storage indices (rows, cols), each (n - 1, nc, 6 + nc), of the contact rows of the
    free nodes: their entries in the node's position, rotation and multiplier columns
    (remembered by layout: an insertion asks once per step for the same one)."""
    n, nv, nc = problem.n, problem.nv, problem.nc
    key = (n, nv, nc, problem.kl + problem.ku)
    hit = _ENTRIES.get(key)
    if hit is None:
        j = np.arange(1, n)[:, None, None]
        rows = nv * j + 9 + np.arange(nc)[None, :, None]
        offsets = np.concatenate([np.arange(6), 9 + np.arange(nc)])
        cols = nv * j + offsets[None, None, :]
        rows, cols = np.broadcast_arrays(rows, cols)
        hit = (problem.kl + problem.ku + rows - cols, np.array(cols))
        for a in hit:
            a.flags.writeable = False
        _remember(_ENTRIES, key, hit)
    return hit


def _fractions(events: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The fractions ``a / (a - b)`` (n - 1, nc) of a step at which the points ``events``
    reach zero (a quantity going from a to b), inf elsewhere, for :func:`piecewise_prediction`:
    clipped to [0, 1] (np.clip, element by element) where the least is not positive; where it
    is, unclipped (the event loop's least fraction and its tests ``<= f`` for f < 1 come out
    the same: clipping is monotone, and a value above 1 is not below such an f either way)."""
    out = np.where(events, a / (a - b), np.inf)
    if not float(out.min()) > 0.0:
        out = np.where(events, np.clip(out, 0.0, 1.0), np.inf)
    return out


class _Rates:
    """The path rates of :func:`piecewise_prediction`'s active sets, all at one tangent
    matrix: ``base`` (band storage, this prediction's own: its contact rows are overwritten)
    with every contact row the gap's, its ``load_rate`` (size,), and ``factors`` (the active
    set, LU factors and pivots of Newton's kept tangent, or None).  A call gives the rate
    (size,) of an active set, or None where its tangent is singular or the rate not finite;
    after the first, each call switches the points ``flipped`` only, restarting the band LU
    (and, compiled, the solve's forward sweep) from their first column: bitwise the
    factorisation from column 0."""

    def __init__(self, problem, base, load_rate, factors):
        from . import _compiled

        # the band kernels, looked up once per prediction (not per event)
        self._lu, self._solve = _compiled.band_lu, _compiled.band_solve
        self._rate_solve, self._rate_step = _compiled.rate_solve, _compiled.rate_step
        events_pay = _compiled.events_pay

        nc = problem.nc
        self.bi, self.ci = _contact_entries(problem)
        self.active_rows = base[self.bi, self.ci]  # (n-1, nc, 6 + nc)
        self.inactive_rows = np.zeros_like(self.active_rows)
        self.inactive_rows[..., 6:] = np.eye(nc)
        self.rhs = -np.asarray(load_rate, float).reshape(-1, 1)  # (size, 1)
        self.kl, self.ku = problem.kl, problem.ku
        # the rates' band, unfactorised: the last rate's contact rows
        self.band = np.asfortranarray(base)
        self.factors = factors
        self.last = None  # the last rate's factors and pivots
        self.x = np.empty_like(self.rhs)  # each rate's solve (used before the next)
        self.fast = events_pay()  # the event loop compiled (its ski rental): for the whole loop
        self.keep = np.empty((2, self.rhs.shape[0]))  # the last solve's forward sweep
        w = 6 + nc  # the flat views of the contact rows' entries: one row of w per point
        self.bf, self.cf = self.bi.reshape(-1, w), self.ci.reshape(-1, w)
        self.rows = np.stack(  # (2, n-1 nc, w): inactive, active
            [self.inactive_rows.reshape(-1, w), self.active_rows.reshape(-1, w)]
        )

    def __call__(self, active, flat, flipped=None):
        """The rate (size,) of the active set ``active`` (n - 1, nc) (``flat``: the same
        array, (n - 1) nc), the points ``flipped`` (flat indices, ascending) switched since
        the last call; None where singular or not finite."""
        band_lu, band_solve, rate_solve, rate_step = (
            self._lu,
            self._solve,
            self._rate_solve,
            self._rate_step,
        )
        band, kl, ku = self.band, self.kl, self.ku
        if self.last is not None and self.fast:  # an event's steps compiled (solve restarted)
            ab, ipiv = self.last
            self.last = None
            if rate_step(band, ab, ipiv, self.bf, self.cf, self.rows, flat, flipped,
                         flipped.size, kl, ku, self.rhs, self.x, self.keep):  # fmt: skip
                return None  # (a zero pivot, or not finite)
            self.last = ab, ipiv
            return self.x.reshape(-1)
        if self.last is None:
            band[self.bi, self.ci] = np.where(
                active[..., None], self.active_rows, self.inactive_rows
            )
            factors = self.factors
            if factors is not None and np.array_equal(active, factors[0]):
                # the band of the kept tangent (the same blocks and contact rows): its
                # factors, Newton's (band_lu from column 0 gives them, bitwise)
                ab, ipiv = factors[1].copy(order="F"), factors[2].copy()
                start = band.shape[1]
            else:
                ab, ipiv, start = band.copy(order="F"), np.empty(band.shape[1], np.int64), 0
        else:
            # an event switches a few contact rows: the factors' columns before the first
            # column of those rows' entries (the first flipped point's node's first unknown)
            # are the last rate's, kept (band_lu restarts there, bitwise the factorisation
            # from column 0); the others the new band's
            ab, ipiv = self.last
            bf, cf = self.bf, self.cf
            band[bf[flipped], cf[flipped]] = self.rows[
                active.reshape(-1)[flipped].view(np.int8), flipped
            ]
            start = int(cf[flipped[0], 0]) if flipped.size else band.shape[1]
            ab[:, start:] = band[:, start:]
        self.last = None
        if band_lu(ab, kl, ku, ipiv, start) > 0:  # an exactly zero pivot: singular
            return None
        self.last = ab, ipiv
        if self.fast:  # (its forward sweep kept for the restarts)
            singular = rate_solve(ab, kl, ku, ipiv, self.rhs, self.x, 0, self.keep)
            return None if singular else self.x.reshape(-1)
        np.copyto(self.x, self.rhs)
        band_solve(ab, kl, ku, ipiv, self.x)
        r = self.x.reshape(-1)
        return r if math.isfinite(r.sum()) else None  # (a NaN or inf anywhere: not finite)


def piecewise_prediction(problem, u: np.ndarray, scale: float, ds: float, max_events=None):
    """Prediction of the state at ``scale + ds`` from the converged state ``u`` (size,) of the
    spatial rod ``problem``, following the path tangent of the active contact set and
    switching the set where a point closes or an active one releases (the linearised
    complementarity problem along the step: a piecewise-linear path, one new tangent per
    event, all at the tangent matrix of ``u``).  Returns the predicted state (size,), or None
    when it cannot be formed (a singular tangent, more than ``max_events`` switches)."""
    from ._compiled import event_step, events_charge

    n, nv, nc = problem.n, problem.nv, problem.nc
    if max_events is None:
        max_events = 2 * (n - 1) * nc + 4
    # One linearization at u with every contact row active (the gradient of kappa g): the
    # force and moment rows depend on the multipliers alone (not on which rows are active),
    # and each rate below overwrites all the contact rows by the active set's, so this one
    # tangent serves every switch.
    # the converged step's blocks, if at u or within a chord step of it (the prediction's
    # tangent: the path rate's own is that one)
    kept = problem._every_active_band(u, scale, near=_NEAR)
    factors = None if kept is None else problem._kept_factors()
    if kept is None:
        every = _every_rows_linearization(problem, u, scale)
        if not bool(every.ok[0]):
            return None
        kept = every.tangent.parts, every.load_rate
    g = problem._state_gaps(u[None])[0]
    rates = _Rates(problem, *kept, factors)
    lam0 = u.reshape(n, nv)[1:, 9 : 9 + nc]
    npts = (n - 1) * nc
    flat = (problem.kappa * g[1:] < lam0).reshape(-1)  # the active set, by point
    active = flat.reshape(n - 1, nc)  # (a view: the event steps switch points in place)
    x, left = u.copy(), 1.0
    switched = set()
    flipped = None  # the points switched at the last event (flat indices in (n-1, nc))
    g0 = g[1:].reshape(-1).copy()  # the gaps at the segment's start (the last event)
    g1, xd = np.empty(npts), np.empty_like(x)
    f_rel, f_close, at = np.empty(npts), np.empty(npts), np.empty(npts, np.int64)
    w = 6 + nc
    lin = np.ascontiguousarray(rates.active_rows.reshape(npts, w))
    cols = rates.ci.reshape(npts, w)
    end_gaps = _end_gaps(problem)
    # a round section's surface gap is 1-Lipschitz in its contact point p = x + c t (a
    # signed distance, units of L), and |dt| <= |d phi| (t = exp(phi) R0 e1): a release
    # before any open point can reach the wall needs no gaps at the segment's end
    c = problem._contact_geometry()[0][1:] if problem._round else np.empty(0)
    kappa = problem.kappa
    with np.errstate(all="ignore"):  # (one context for the loop: its entry costs as an op)
        for _ in range(max_events):
            r = rates(active, flat, flipped)
            if r is None:
                return None
            if not rates.fast:
                events_charge()
            step = event_step if rates.fast else _event_step
            args = (x, r, left * ds, flat, g0, g1, xd, lin, cols, c, nv, nc, kappa, f_rel,
                    f_close, at)  # fmt: skip
            code, f, count = step(False, *args)
            if code == 1:  # the gaps at the segment's end decide
                np.copyto(g1, end_gaps(xd).reshape(-1))
                code, f, count = step(True, *args)
            if code == 0:
                return xd.copy()
            left *= 1.0 - f
            where = round(left, 12)
            flipped = at[:count].copy()
            for p in flipped.tolist():
                key = (p, where)
                if key in switched:  # back and forth at one scale: degenerate, give up
                    return None
                switched.add(key)
    return None


def _event_step(gaps, x, r, scale, active, g0, g1, xd, lin, cols, c, nv, nc, kappa, f_rel,
                f_close, flipped):  # fmt: skip
    """One segment of :func:`piecewise_prediction`'s event loop (the numpy twin of the
    compiled :func:`coilrod.rod._compiled.event_step`): the segment from the state ``x``
    (size,) along ``scale`` times the rate ``r`` (size,) ends at its first contact event,
    found in two calls.

    ``gaps`` False: the fractions of the releases (an active point's multiplier reaching
    zero, linear) into ``f_rel`` (npts,) (inf where none).  If the least, f, is below 1 and
    no open point can reach the wall before it (a round section: ``c`` (n - 1,) its points'
    offsets along the tangents, units of L, else empty; the gaps ``g0`` (npts,) at the
    segment's start against f times :func:`_reach`), the event is applied with the gaps at
    it from their linearization (``lin`` (npts, w): kappa times each point's gap gradient in
    the state's entries ``cols`` (npts, w)): returns ``(2, f, count)``.  Else the segment's
    end ``x + scale r`` is written into ``xd``: returns ``(1, f, 0)``.

    ``gaps`` True (after ``(1, ...)``; ``g1`` (npts,): the gaps at ``xd``): the fractions of
    the closings (an open point's gap reaching zero, interpolated between g0 and g1) into
    ``f_close``; no event before the end: returns ``(0, f, 0)``; else the gaps at the event
    (interpolated) into g0 and the event applied: ``(2, f, count)``.

    An event at the fraction f moves x there, switches the points whose fractions are f in
    ``active`` (npts,) (their flat indices into ``flipped[:count]``, ascending) and zeroes the
    released points' multipliers.  Fractions where the least is not positive are clipped to
    [0, 1] (:func:`_fractions`)."""
    n = x.shape[0] // nv
    d = scale * r
    X, D = x.reshape(n, nv)[1:], d.reshape(n, nv)[1:]
    closings = gaps
    if not gaps:
        l0 = X[:, 9 : 9 + nc].reshape(-1)
        l1 = l0 + D[:, 9 : 9 + nc].reshape(-1)
        f_rel[:] = _fractions(active & (l1 < 0.0) & (l1 < l0), l0, l1)
        f = float(f_rel.min())
        if f < 1.0 and c.shape[0] and _clear(g0.reshape(-1, nc), active.reshape(-1, nc), D, c, f):
            g0 += f * np.einsum("pw,pw->p", lin, d[cols]) / kappa
        else:
            np.add(x, d, out=xd)
            return 1, f, 0
    else:
        f_close[:] = _fractions(~active & (g1 < 0.0) & (g1 < g0), g0, g1)
        f = min(float(f_close.min()), float(f_rel.min()))
        if not f < 1.0:
            return 0, f, 0
        g0 += f * (g1 - g0)  # the gaps at the event, to the order of the prediction
    x += f * d
    released = f_rel <= f
    at = (f_close <= f) | released if closings else released
    count = int(np.count_nonzero(at))
    flipped[:count] = np.flatnonzero(at)
    active ^= at
    X[:, 9 : 9 + nc][released.reshape(-1, nc)] = 0.0
    return 2, f, count


def _clear(g0: np.ndarray, active: np.ndarray, D: np.ndarray, c: np.ndarray, f: float) -> bool:
    """Whether no open contact point of a round section can reach the wall within the
    fraction ``f`` of a segment that changes the free nodes' unknowns by ``D`` (n - 1, nv):
    each inactive point's gap ``g0`` (n - 1, nc) (units of L) above ``f`` times the bound
    :func:`_reach` on its displacement (``c`` (n - 1,): the points' offsets along the
    tangents, units of L)."""
    return not bool(np.any((g0 <= f * _reach(D, c)[:, None]) & ~active))


def _end_gaps(problem):
    """The surface gaps (n - 1, nc) of the free nodes' contact points of a state (size,) of
    ``problem``: :meth:`SpatialRod._state_gaps`' numbers, not remembered (a prediction's
    segment ends are not asked for again)."""
    if not problem._round:
        return lambda v: problem._state_gaps(v[None])[0, 1:]
    return lambda v: problem._round_state_gaps(
        problem.rotations(v[None]), problem.node_positions(v[None])
    )[0, 1:]


def active_set_start(problem, u: np.ndarray, scale: float = 1.0, max_rounds: int = 16):
    """A start for the contact Newton method of the spatial rod ``problem`` from a state
    ``u`` (size,) that is not converged (an insertion step's carried shape): the solution
    of its linearised complementarity problem, found by a primal-dual active-set iteration
    on one linearization (a band factorisation per round).  The first guess takes a contact
    point as active where it carries force on the wall (lam > 0, kappa g < lam / 100); each
    round's step sets the active points' linearised gaps and the others' multipliers to
    zero, and the next set keeps the active points whose multiplier stayed positive and adds
    the inactive ones whose linearised gap went negative.  Returns the state after the step
    of a consistent set, or None (no consistent set within ``max_rounds``, a set seen
    before, a singular or non-finite step, a step turning a node by more than the rod's
    :attr:`max_rotation`, friction: its stick/slip rows are left to the corrector).

    The start is second order in the change it follows (an insertion's length step), the
    carried shape first order: a tip sliding on a curved wall or a point contact passing
    from one corner to the next is placed at once, where Newton's first
    Fischer-Burmeister steps mix those points' gap and multiplier rows and take several
    damped iterations (an insertion through a bend: 99 Newton iterations instead of 330)."""
    from .planar import RodTangent

    n, nv, nc = problem.n, problem.nv, problem.nc
    if not nc or problem.uniform or problem.nt:
        return None
    u = np.asarray(u, float)  # (the state's gaps below are the linearization's, remembered)
    lin = _every_rows_linearization(problem, u, scale)
    if not bool(lin.ok[0]):
        return None
    kappa = problem.kappa
    kg = kappa * problem._state_gaps(u[None])[0, 1:]  # (n - 1, nc): the linearization's own
    lam = u.reshape(n, nv)[1:, 9 : 9 + nc]
    active = (lam > 0.0) & (kg < 1e-2 * lam)
    bi, ci = _contact_entries(problem)
    base = lin.tangent.parts
    active_rows = base[bi, ci]  # (n-1, nc, 6 + nc): the rows of kappa g
    inactive_rows = np.zeros_like(active_rows)
    inactive_rows[..., 6:] = np.eye(nc)
    R = np.array(lin.residual[0]).reshape(n, nv)
    tried = set()
    for _ in range(max_rounds):
        key = active.tobytes()
        if key in tried:
            return None
        tried.add(key)
        ab = base.copy(order="F")
        ab[bi, ci] = np.where(active[..., None], active_rows, inactive_rows)
        R[1:, 9 : 9 + nc] = np.where(active, kg, lam)
        with np.errstate(all="ignore"):
            du = RodTangent(1, problem.size, False, ab, None, problem.kl, problem.ku).solve(
                -R.reshape(1, -1)
            )[0]
        if not np.all(np.isfinite(du)):
            return None
        lam1 = lam + du.reshape(n, nv)[1:, 9 : 9 + nc]
        kg1 = kg + np.einsum("joc,joc->jo", active_rows, du[ci])
        new = np.where(active, lam1 > 0.0, kg1 < 0.0)
        if np.array_equal(new, active):
            if float(problem.step_limit(u[None], du[None])[0]) < 1.0:
                return None
            return u + du
        active = new
    return None
