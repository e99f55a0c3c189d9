"""Coil currents that put the rod's tip on a target, in the real field or as an ideal-field
controller would choose them.

``model="real"``: Gauss-Newton on the currents.  Each iteration is one forward solve of the
rod in the system's real (Biot-Savart) field, followed along the load path from the straight
rod (:func:`coilrod.solve_rod`), and the exact derivatives of the tip with respect to the
currents (:func:`coilrod.sensitivities`, adjoint).  With more channels than constraints the
step is the minimum-power one: ``I_new = argmin sum_j R_j I_j^2`` subject to the linearised
target ``J (I_new - I) = target - tip`` and the current limits (the least-distance program of
:func:`coils.currents.minimum_power`), whose fixed point satisfies the first-order conditions
of the minimum-power currents that reach the target.  The start is the ideal-field answer:
the in-plane uniform field that puts the tip on the target (a cheap two-unknown Newton
iteration with uniform-field solves), made by the system's minimum-power currents at its
centre.

``model="ideal"``: the usual controller -- the same iteration with the field over the robot
replaced by the system's field and gradient at its centre (``system.with_currents(I).ideal()``
for every current vector, exact in the currents); the currents are then applied to the real
field and ``miss`` says how far the tip really lands from the target.

A 3D target (x, y, z) is the same iteration with the tip's z among the controlled outputs
(the forward solves then run on the spatial rod); a target tip direction d adds the tip
tangent's two misses off d (its stereographic projection, :meth:`_Problem.turn`) with their
exact derivatives (:func:`~coilrod.design.sensitivity.tip_derivatives` with ``tangent``).
The system is any multi-channel source under current control: air coils
(:class:`coils.CoilSystem`) or a calibrated eMNS model (:class:`coils.MPEM`).

The search, one function per stage: :func:`_problem` validates the input and sets up the
problem (:class:`_Problem`: the weighted misses r(I) of the controlled outputs and their exact
Jacobian); :func:`_start` gives the start currents; :func:`_approach` takes the Gauss-Newton /
minimum-power steps with their step control; :func:`_damped` goes on, off the target, by
Levenberg-Marquardt within the limits to a local least-squares optimum; :func:`_search` runs
the two and says how the search ended; :func:`solve_currents` restarts a warm start that led
astray (a plain loop over the starts); :func:`_finish` and :func:`_report` make the result and
tell an unreachable target's reason (the limits, or the robot's reachable set).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

import coils
from coils._validate import as_array, as_count, as_limits, as_vector, finite_scalar, positive
from coils.currents import minimum_power

from ..design.sensitivity import tip_derivatives
from ..design.workspace import workspace
from ..errors import ConvergenceError
from ..path.events import StabilityWarning
from ..robot.rod import Rod
from ..rod.result import RodResult
from ..rod.solve import solve_rod

__all__ = ["solve_currents", "ControlResult", "ControlWarning"]


@dataclass
class ControlResult:
    """Currents for a target tip pose and where the tip lands in the real field.

    Attributes
    ----------
    currents : ndarray, shape (m,)
        Channel currents, A.
    tip : ndarray, shape (3,)
        Tip position in the real field with these currents, m.
    tip_angle : float
        Tip angle in the real field, rad.
    miss : float
        Distance of the real tip from the target position, m (with a target angle: the
        position miss; ``angle_miss`` holds the angle's).
    angle_miss : float or None
        |tip angle - target angle|, rad (None without a target angle).
    power : float
        Copper power of the currents, W (NaN if a channel has no resistance).
    result : RodResult
        The forward solve in the real field (load path from the straight rod to the currents).
    model : str
        "real" or "ideal".
    target : ndarray, shape (2,) or (3,)
        Target (x, y) in the bending plane, or (x, y, z), m.
    solves : int
        Forward solves used (real or ideal field; the start's uniform-field solves counted
        separately in ``start_solves``).
    start_solves : int
        Uniform-field solves of the start.
    history : list of float
        Miss after each iteration, m (in the model's own field).
    status : str
        "converged" (the target met within ``tol``), "optimal" (not met, but a local
        least-squares optimum of the weighted misses within the current limits: no bounded
        Gauss-Newton step predicts a relative decrease of their squares above ``GAIN_TOL`` =
        1e-6), or, for a result that is neither, why the search stopped: "max_solves" (the
        solve budget spent), "stalled" (no step decreased the misses any more, or the steps
        crept towards the edge of the rod's branch without reaching an optimum), or
        "branch_edge" (the search stopped where the rod's branch ends: trial steps of the
        currents along one direction, small enough that their linearisation predicts a
        small change, sent the rod to another branch ``EDGE_JUMPS`` times -- see
        :class:`_EdgeWatch`; ``message`` names the direction, the miss reached and the
        solves spent).
    optimal : bool
        ``status`` is "converged" or "optimal".  A result that is not is returned with a
        :class:`ControlWarning` (or, for an unreachable position target, said in the error).
    active : list of int
        Channels at their current limit in ``currents`` (within ``LIMIT_RTOL`` of it).
    tip_direction : ndarray, shape (3,)
        Unit tangent at the tip in the real field (the first column of
        ``result.frames(-1)[-1]``).
    direction_miss : float or None
        Angle between the real tip tangent and the target direction, rad (None without a
        target direction).
    message : str
        How the search ended when the target is not met in the model's own field (the
        status, the closest miss there, the solves spent, and at a branch edge its
        direction); "" when it is met.
    """

    currents: np.ndarray
    tip: np.ndarray
    tip_angle: float
    miss: float
    angle_miss: float | None
    power: float
    result: RodResult
    model: str
    target: np.ndarray
    solves: int
    start_solves: int
    history: list = field(default_factory=list)
    status: str = "converged"
    optimal: bool = True
    active: list = field(default_factory=list)
    tip_direction: np.ndarray | None = None
    direction_miss: float | None = None
    message: str = ""


class ControlWarning(RuntimeWarning):
    """:func:`solve_currents` returns a compromise that is not a (local) least-squares optimum
    within the current limits (``ControlResult.optimal`` is False)."""


def _channels_at_center(system):
    """B (3, m) T/A and gradient (3, 3, m) T/(A m) per unit current at the system centre."""
    B, G = system.unit_fields(np.asarray(system.center, float)[None])
    return B[0], G[0]


def _forward(rod, field, steps, opts):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StabilityWarning)
        return solve_rod(rod, field, np.arange(1, steps + 1) / steps, **opts)


def _outputs(res: RodResult, with_angle: bool, with_z: bool = False) -> np.ndarray:
    """The controlled outputs of the last state: tip x, y (and z), (and the tip angle)."""
    tip = res.tip[-1, : 3 if with_z else 2]
    return np.r_[tip, res.tip_angle[-1]] if with_angle else tip.copy()


def _weights_for(with_angle: bool, length: float, with_z: bool = False) -> np.ndarray:
    """Scales of the outputs in the least-squares sense: positions in L, the angle in rad."""
    pos = np.full(3 if with_z else 2, 1.0 / length)
    return np.r_[pos, 1.0] if with_angle else pos


def _leaves_plane(system, clamp: np.ndarray, length: float) -> bool:
    """True if some channel of ``system`` makes B_z (or dB_z/dx, dB_z/dy) on the rod's plane
    within its reach: the tip can then leave the plane and z is controlled too."""
    from ..rod.model import leaves_plane, reach_fields

    B, G = reach_fields(system.unit_fields, clamp, length, radii=9, angles=24)
    return leaves_plane(B, G, length)


def _uniform_start(rod, goal, with_angle, steps, opts, b_cap, tol: float = 0.0):
    """The in-plane uniform field (2,) T whose tip meets ``goal`` (least squares), and the
    solves used: scipy's trust-region least squares with the exact Jacobian (the tip's
    sensitivity to the field is nearly singular along the rod's own direction, so plain
    Newton steps overshoot), from the weakest state of a coarse workspace grid near the
    target (the best point the least squares met is returned).  No field (and no solve)
    where the unloaded rod's tip already meets ``goal`` within ``tol`` (m; its angle within
    ``tol / L`` rad): the least power is none (the grid has no zero field, and the least
    squares would find a field along the rod, e.g. antiparallel just below buckling)."""
    from scipy.optimize import least_squares

    L = rod.length
    wts = _weights_for(with_angle, L)
    clamp = np.asarray(opts["clamp_position"], float)
    ang = opts["clamp_angle"]
    if not b_cap > 0.0:  # limits too small for any field in some direction (rounded to 0)
        return np.zeros(2), 0
    if tol > 0.0:
        straight = clamp[:2] + L * np.array([math.cos(ang), math.sin(ang)])
        miss = np.r_[straight, ang][: goal.size] - goal
        if np.hypot(*miss[:2]) <= tol and (goal.size == 2 or abs(miss[2]) <= tol / L):
            return np.zeros(2), 0
    # the closest stable state of a coarse (direction, magnitude) grid up to b_cap (all
    # directions followed together, coilrod.workspace): a start on the regular branch, not
    # on a buckled one of a nearly antiparallel field
    grid = workspace(
        rod,
        b_cap,
        directions=36,
        magnitudes=8,
        nodes=16,
        richardson=False,
        refine=0,
        clamp_position=clamp,
        clamp_angle=ang,
    )
    dist = np.linalg.norm(grid.tips[:, 1:, :2] - goal[:2], axis=2)
    dist = np.where(grid.stable[:, 1:], dist, np.inf)
    # among the grid states near the closest one (within 3 % of L: the grid's resolution),
    # the weakest field: the minimum-power answer is sought, and a strong field reaching the
    # same tip (a rod curled further) is a different, costlier solution.  Not within a
    # multiple of the closest distance: for a target out of reach that takes in the straight
    # rod of a weak field, far from the closest tips
    near = dist <= dist.min() + 0.03 * L
    field = np.broadcast_to(grid.magnitudes[1:], dist.shape)
    d, j = np.unravel_index(np.argmin(np.where(near, field + 1e-9 * dist, np.inf)), dist.shape)
    b0 = grid.magnitudes[j + 1]
    x0 = np.array([math.cos(grid.directions[d]), math.sin(grid.directions[d])])  # units b0
    cache = {}

    def solve(x):
        key = tuple(x)
        if key not in cache:
            B = b0 * np.array([x[0], x[1], 0.0])
            try:
                cache[key] = _forward(rod, coils.UniformField(B=B), steps, opts)
            except ConvergenceError:
                cache[key] = None
        return cache[key]

    best = [np.inf, x0]

    def fun(x):
        res = solve(x)
        if res is None:
            return np.full(goal.size, 1e3)
        r = (_outputs(res, with_angle) - goal) * wts
        if np.linalg.norm(r) < best[0]:
            best[:] = [float(np.linalg.norm(r)), np.array(x, float)]
        return r

    def jac(x):
        res = solve(x)
        if res is None:
            return np.eye(goal.size, 2)
        _, _, _, D = tip_derivatives(res, [len(res) - 1], ["B"], check=False)
        J = np.vstack([D[0, 0:2, 0:2], D[0, 3:4, 0:2]])[: goal.size]
        return J * wts[:, None] * b0

    least_squares(fun, x0, jac=jac, xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=30, x_scale="jac")
    return best[1] * b0, len(cache) + 1


def _centre_currents(system, B, weights, limits, Bu, B_fixed):
    """The currents (m,) A that make the field ``B`` (3,) T at the system's centre with least
    ``sum w I^2`` within the limits: ``system.currents_for`` (the shared
    :func:`coils.currents.currents_for_target`: the current-free field -- an MPEM's offset --
    is subtracted first); beyond the limits, the unlimited answer clipped to them."""
    try:
        return system.currents_for(B=B, weights=weights)
    except ValueError:  # beyond the limits: a start all the same
        sol = minimum_power(Bu, B - B_fixed, weights, limits)
        return np.clip(sol.unlimited, -limits, limits)


def _start(
    rod, goal, with_angle, steps, opts, Bu, weights, limits, system=None, B_fixed=None, tol=0.0
):
    """Start currents: the uniform-field answer (within the largest centre field the limits
    allow in every direction; none where the unloaded tip meets the goal within ``tol``, m),
    made at the centre with minimum power (by ``system``'s ``currents_for`` when given, its
    current-free field subtracted); and the solves used."""
    from coils.currents import largest_fraction

    phis = np.linspace(0.0, 2 * np.pi, 36, endpoint=False)
    b_big = rod.field_for_lambda(30.0)  # beyond any useful field: lambda = 30
    caps = [
        largest_fraction(Bu[:2], b_big * np.array([math.cos(a), math.sin(a)]), limits)[0]
        for a in phis
    ]
    b_cap = b_big * float(min(caps))  # the largest centre field (T) in every direction
    b, solves = _uniform_start(rod, goal, with_angle, steps, opts, b_cap, tol)
    B = np.array([b[0], b[1], 0.0])
    if system is not None:
        return _centre_currents(system, B, weights, limits, Bu, B_fixed), solves
    start = minimum_power(Bu, B, weights, limits)
    I = start.currents if start.currents is not None else np.clip(start.unlimited, -limits, limits)
    return I, solves


@dataclass
class _Problem:
    """One control problem, validated: the rod, the channels and their limits, the target and
    how its misses are weighed.

    The controlled outputs of a state are the tip x, y (and z, held on the rod's plane when a
    channel can push the rod out of it), the tip angle with a target angle, and the tip
    tangent's two misses off a target direction (:meth:`turn`); ``goal`` holds
    their targets and ``scales`` their weights in the least-squares sense (positions in L, the
    angle in rad).  ``residual`` is the weighted miss vector r of a forward solve, ``jacobian``
    its exact derivative dr/dI (adjoint, :func:`coilrod.design.sensitivity.tip_derivatives`).
    """

    rod: Rod
    system: object
    model: str
    target: np.ndarray  # (2,) tip x, y in the bending plane, or (3,) x, y, z, m
    angle: float | None  # target tip angle, rad
    direction: np.ndarray | None  # (3,) target unit tip tangent (3D targets)
    limits: np.ndarray  # (m,) current limits, A
    resistance: np.ndarray  # (m,) weights of the power sum R I^2 (ones without resistances)
    steps: int  # load steps of a forward solve
    opts: dict  # clamp_position, clamp_angle, nodes of solve_rod
    tol: float  # position tolerance, m
    with_z: bool  # z held on the plane too
    Bu: np.ndarray  # (3, m) centre field per ampere, T/A
    Gu: np.ndarray  # (3, 3, m) centre gradient per ampere, T/(A m)
    B_fixed: np.ndarray  # (3,) current-free centre field, T
    G_fixed: np.ndarray  # (3, 3) current-free centre gradient, T/m

    @property
    def with_angle(self) -> bool:
        return self.angle is not None

    @property
    def oriented(self) -> bool:
        """A target tip angle (plane) or tip direction (3D) besides the position."""
        return self.angle is not None or self.direction is not None

    @property
    def across(self) -> np.ndarray:
        """(2, 3) orthonormal basis of the plane normal to the target direction d."""
        d = self.direction
        e = np.eye(3)[int(np.argmin(np.abs(d)))]
        e1 = np.cross(d, e)
        e1 /= np.linalg.norm(e1)
        return np.array([e1, np.cross(d, e1)])

    def turn(self, res: RodResult):
        """The direction's misses (2,) and their derivative by the tip tangent t (2, 3): the
        stereographic projection of t from -d onto the plane normal to d, ``s = 2 E t /
        (1 + d . t)`` (E = :attr:`across`): zero only on d, ``|s| = 2 tan(alpha / 2)`` for
        the angle alpha between t and d (the angle to first order), rank 2 on the tangent's
        own changes (normal to t)."""
        t = res.frames(len(res) - 1)[-1, :, 0]
        E, d = self.across, self.direction
        den = 1.0 + float(d @ t)
        return 2.0 * (E @ t) / den, 2.0 * E / den - 2.0 * np.outer(E @ t, d) / den**2

    @property
    def length(self) -> float:
        return self.rod.length

    @property
    def npos(self) -> int:
        """Number of position outputs (2 or 3)."""
        return 3 if self.with_z else 2

    @property
    def spatial(self) -> bool:
        """A 3D target (x, y, z)."""
        return self.target.size == 3

    @property
    def planar_goal(self) -> np.ndarray:
        """(x, y) or (x, y, angle): the uniform-field start's target."""
        return np.r_[self.target, self.angle] if self.with_angle else self.target

    @property
    def goal(self) -> np.ndarray:
        """Targets of the controlled outputs."""
        z = [self.opts["clamp_position"][2]] if self.with_z and not self.spatial else []
        d = [0.0, 0.0] if self.direction is not None else []
        return np.r_[self.target, z, [self.angle] if self.with_angle else [], d]

    @property
    def scales(self) -> np.ndarray:
        w = _weights_for(self.with_angle, self.length, self.with_z)
        return np.r_[w, 1.0, 1.0] if self.direction is not None else w

    def field_of(self, I):
        """The field the model steers with at currents ``I`` (A): the real one, or the linear
        field of the centre field and gradient (the limits checked as for the real field)."""
        real = self.system.with_currents(I)
        if self.model == "real":
            return real
        return coils.LinearField(
            self.Bu @ I + self.B_fixed, self.Gu @ I + self.G_fixed, self.system.center
        )

    def residual(self, res: RodResult) -> np.ndarray:
        """Weighted misses r of the last state of ``res``."""
        out = _outputs(res, self.with_angle, self.with_z)
        if self.direction is not None:
            out = np.r_[out, self.turn(res)[0]]
        return (out - self.goal) * self.scales

    def jacobian(self, res: RodResult) -> np.ndarray:
        """dr/dI of the last state of ``res``, shape (outputs, m)."""
        k = len(res) - 1
        tangent = self.direction is not None
        if self.model == "real":
            _, _, _, D = tip_derivatives(res, [k], ["currents"], check=False, tangent=tangent)
            J = D[0]
        else:  # chain rule through the centre field and gradient, linear in I
            wrt = ["B0", "gradient"]
            _, _, _, D = tip_derivatives(res, [k], wrt, check=False, tangent=tangent)
            J = D[0, :, :3] @ self.Bu + D[0, :, 3:] @ self.Gu.reshape(9, -1)
        rows = ([0, 1, 2] if self.with_z else [0, 1]) + ([3] if self.with_angle else [])
        if tangent:  # the direction's misses through the tip tangent
            return np.vstack([J[rows], self.turn(res)[1] @ J[4:7]]) * self.scales[:, None]
        return J[rows] * self.scales[:, None]

    def position_miss(self, r) -> float:
        """Distance of the tip from the target position, m, from the weighted misses."""
        return float(np.linalg.norm(r[: self.npos])) * self.length

    def met(self, r) -> bool:
        """The target met: position (and angle or direction) within the tolerance (an angle
        of tol / L, rad)."""
        on_angle = not self.with_angle or abs(r[-1]) <= self.tol / self.length
        if self.direction is not None:  # |s| = 2 tan(alpha / 2) >= alpha
            on_angle = float(np.linalg.norm(r[-2:])) <= self.tol / self.length
        return self.position_miss(r) <= self.tol and on_angle


class _BudgetSpent(Exception):
    """The search has spent its forward solves (``max_solves``)."""


#: A trial state is on another branch of the rod when its weighted misses moved by more than
#: ``JUMP_RATIO`` times the change the linearisation predicted for the step, and by more than
#: ``JUMP_MIN`` (in L, rad), away from the target: the step was small enough for the
#: linearisation, the rod was not.
JUMP_RATIO = 100.0
JUMP_MIN = 0.01
#: A branch edge: ``EDGE_JUMPS`` such jumps along the same direction of the currents (unit
#: steps with |cos| >= ``EDGE_COS``), the misses not halved from the first jump's state to the
#: last's (a search that still halves them between jumps is still closing in).
EDGE_JUMPS = 2
EDGE_COS = 0.9


class _BranchEdge(Exception):
    """The search reached an edge of the rod's branch (:class:`_EdgeWatch`):
    ``direction`` (m,) the unit step of the currents that leaves it, ``jumps`` how often,
    ``moved`` and ``predicted`` the largest jump of |r| and the change its step predicted;
    ``unstable``: the steps reached the end of the branch's stable part (they gained, but
    the rod lost its stability there) rather than jumped."""

    def __init__(self, direction, jumps, moved, predicted, unstable=False):
        super().__init__("branch edge")
        self.direction, self.jumps = direction, jumps
        self.moved, self.predicted, self.unstable = moved, predicted, unstable


@dataclass
class _EdgeWatch:
    """The trial steps of a search (:func:`_approach`, :func:`_damped`) that sent the rod to
    another branch.

    A jump: the misses moved ``JUMP_RATIO`` times further than the step's linearisation
    predicted, and by more than ``JUMP_MIN``, and grew (a snap to another stable state, the
    tip ~L away, where the step predicted a fraction of a per cent).  One jump is a step
    too long;
    ``EDGE_JUMPS`` along the same direction of the currents, with the misses not halved
    between the first's state and the last's, are the edge of the branch the search is on:
    the remaining miss lies across it, and the steps would alternate a jump with a tiny gain
    until the budget is spent.  Then :meth:`check` raises :class:`_BranchEdge`.

    A warm start's search that a fresh one follows also watches the end of the branch's
    stable part (:meth:`lost`): ``EDGE_JUMPS`` trial steps of :func:`_damped` along one
    direction that gain but leave the rod unstable, the misses not halved between them, raise
    :class:`_BranchEdge` as well (the steps accepted after them would creep to the stability
    boundary, a solve each)."""

    jumps: list = field(default_factory=list)  # (unit step, moved, predicted, |r|) per jump
    losses: list = field(default_factory=list)  # the same per step that lost stability

    def check(self, r, r_t, predicted, step) -> None:
        """Record the trial (misses ``r_t`` after ``step`` from ``r``; ``predicted`` = J step)
        if it jumped, and raise :class:`_BranchEdge` at the edge."""
        moved = float(np.linalg.norm(r_t - r))
        change = float(np.linalg.norm(predicted))
        if moved <= max(JUMP_RATIO * change, JUMP_MIN) or r_t @ r_t <= r @ r:
            return  # no jump, or one closer to the target (a snap-through that helps)
        self._record(self.jumps, r, step, moved, change, False)

    def lost(self, r, r_t, predicted, step) -> None:
        """Record a trial (as :meth:`check`) that gained but left the stable rod unstable,
        and raise :class:`_BranchEdge` (``unstable``) at the end of the stable part."""
        moved = float(np.linalg.norm(r_t - r))
        self._record(self.losses, r, step, moved, float(np.linalg.norm(predicted)), True)

    @staticmethod
    def _record(events, r, step, moved, change, unstable) -> None:
        u, here = step / np.linalg.norm(step), float(np.linalg.norm(r))
        events.append((u, moved, change, here))
        same = [j for j in events if abs(float(j[0] @ u)) >= EDGE_COS and here > 0.5 * j[3]]
        if len(same) >= EDGE_JUMPS:
            worst = max(same, key=lambda j: j[1])
            raise _BranchEdge(u, len(same), worst[1], worst[2], unstable)


@dataclass
class _Search:
    """The forward solves of one search: the budget, the misses met and the closest state.

    ``best`` is (key, currents, result, r) of the closest state found, stable states first (an
    unstable state is not where the tip stays), then by |r|; ``edge`` watches the trial steps
    for jumps to another branch of the rod (:class:`_EdgeWatch`)."""

    problem: _Problem
    max_solves: int
    solves: int = 0
    history: list = field(default_factory=list)
    best: tuple | None = None
    edge: _EdgeWatch = field(default_factory=_EdgeWatch)

    def evaluate(self, I, base=None):
        """Forward solve at currents ``I``: (result, weighted misses r, position miss m).
        ``base`` (I0, r0, J0): the state the trial ``I`` steps from, its misses and their
        Jacobian (the step's jump to another branch is checked, :class:`_EdgeWatch`).

        Raises _BudgetSpent once ``max_solves`` solves are spent, ConvergenceError (naming
        the currents) if the forward solve fails, and _BranchEdge at an edge of the branch."""
        p = self.problem
        if self.solves >= self.max_solves:
            raise _BudgetSpent
        try:
            res = _forward(p.rod, p.field_of(I), p.steps, p.opts)
        except ConvergenceError as err:
            raise ConvergenceError(
                f"solve_currents: the forward solve failed at currents {np.round(I, 6).tolist()} A"
                f" ({err})",
                reached=err.reached,
                target=err.target,
            ) from err
        self.solves += 1
        r = p.residual(res)
        miss = p.position_miss(r)
        self.history.append(miss)
        key = (not bool(res.stable[-1]), float(np.linalg.norm(r)))
        if self.best is None or key < self.best[0]:
            self.best = (key, I.copy(), res, r)
        if base is not None and np.any(I != base[0]):
            I0, r0, J0 = base
            self.edge.check(r0, r, J0 @ (I - I0), I - I0)
        return res, r, miss


#: Beyond this miss (in L) the iteration takes restoring steps, towards the target first.
FAR = 1e-3


#: Singular values of the weighted Jacobian below this fraction of the largest are taken as
#: zero by the Gauss-Newton steps: such an output combination needs a million times the
#: currents of the best one to move it.  (An axially, uniformly magnetised rod feels only the
#: field at its tip -- its magnetic energy is the field's potential there -- so its tip
#: position and direction, five outputs, move with three current combinations; the other two
#: singular values are round-off, ~1e-10 of the largest, and inverted they send the step to
#: the current limits.)
STEP_RCOND = 1e-6


def _moved(J, r, rcond=STEP_RCOND):
    """The linearised misses on the output combinations the currents move: (U_k^T J,
    U_k^T r), U_k the left singular vectors of ``J`` (outputs, m) with singular values above
    ``rcond`` of the largest.  Their solutions are the least-squares ones of J s = -r
    (the misses the currents cannot move are left as they are).  ``J`` and ``r`` themselves
    where none is dropped."""
    U, sv, _ = np.linalg.svd(J, full_matrices=False)
    k = int(np.sum(sv > rcond * sv[0])) if sv.size and sv[0] > 0.0 else 0
    if k == sv.size:
        return J, r
    return U[:, :k].T @ J, U[:, :k].T @ r


def _restoring_step(J, r, I, p: _Problem, rcond=STEP_RCOND):
    """The least correction towards the linearised target, in the power metric:
    ``argmin sum R s^2`` over the least-squares solutions of ``J s = -r`` (on the misses the
    currents move, :func:`_moved`)."""
    root = np.sqrt(p.resistance)
    J, r = _moved(J, r, rcond)
    return (np.linalg.pinv(J / root) @ -r) / root


def _least_power_step(J, r, I, p: _Problem, rcond=STEP_RCOND):
    """The step to the minimum-power currents of the linearised target:
    ``argmin sum R I_new^2`` subject to ``J (I_new - I) = -r`` and the limits (or, out of
    reach within the limits, the least-squares currents within them; also where the
    least-distance program of :func:`coils.currents.minimum_power` fails, as its NNLS solver
    can on an ill-conditioned J).  The linearised target is that of the misses the currents
    move (:func:`_moved`)."""
    J, r = _moved(J, r, rcond)
    try:
        sol = minimum_power(J, J @ I - r, p.resistance, p.limits)
    except RuntimeError:  # the NNLS failure: the least-squares step within the limits
        sol = None
    if sol is not None and sol.currents is not None:
        return sol.currents - I
    from scipy.optimize import lsq_linear

    return lsq_linear(J, J @ I - r, bounds=(-p.limits, p.limits)).x - I


def _within_limits(step, J, r, I, limits):
    """``step`` and the largest fraction t <= 1 of it within the limits; when a channel at
    its limit blocks it (t < 0.1), the least-squares step of the linearisation within the
    limits instead."""
    t = _room(I, step, limits)
    if t < 0.1:
        from scipy.optimize import lsq_linear

        lo, hi = -limits - I, limits - I
        step = lsq_linear(J, -r, bounds=(np.minimum(lo, 0.0), np.maximum(hi, 0.0))).x
        t = _room(I, step, limits)
    return step, t


def _approach(p: _Problem, search: _Search, I, max_iter: int) -> None:
    """Gauss-Newton steps towards the target from the currents ``I`` (the states met are kept
    by ``search``).

    Each iteration, at the currents I with misses r and exact Jacobian J:

    1. the step: near the target (position miss <= FAR L), the minimum-power step
       (:func:`_least_power_step`: its fixed point is the minimum-power solution), and if that
       fails the restoring step (:func:`_restoring_step`); far from the target, the restoring
       step only.  Once a minimum-power step has left the tip further off (with spare
       channels it moves far along the target's null space, where the linearisation is poor,
       and alternating would cycle), only restoring steps follow: the currents are then those
       of the last minimum-power step, corrected onto the target.  Both steps leave out the
       output combinations the currents barely move (:func:`_moved`, ``STEP_RCOND``) until an
       accepted step near the target fails to halve |r|; from then on they use every one
       (a coarse rod's discretisation makes such a combination small but real);
    2. step control: the step is cut to the current limits (:func:`_within_limits`), a
       minimum-power step to the trust fraction ``trust`` (doubled after a success, set to the
       last fraction tried after a failure), and halved up to three times until the miss
       decreases (or, near the target, stays within FAR L) -- also when the forward solve at
       the trial currents fails (a load path that cannot be followed there);
    3. the iteration ends on the target, after ``max_iter`` iterations, or when no step is
       accepted -- or, raising :class:`_BranchEdge` from ``search.evaluate``, at an edge of
       the rod's branch (trial steps along one direction jumping to another branch,
       :class:`_EdgeWatch`).
    """
    res, r, miss, I = _first_state(search, I)
    far = FAR * p.length
    restore_next, trust, rcond = False, 1.0, STEP_RCOND
    for _ in range(max_iter):
        if p.met(r):
            return
        J = p.jacobian(res)
        near = miss <= far and not restore_next
        kinds = [_least_power_step, _restoring_step] if near else [_restoring_step]
        moved = False
        for kind in kinds:
            least_power = kind is _least_power_step
            step, t = _within_limits(kind(J, r, I, p, rcond), J, r, I, p.limits)
            if not np.any(step) or t <= 0.0:
                continue
            if least_power:
                t = min(t, trust)
            for _trial in range(4):  # backtracking
                trial = np.clip(I + t * step, -p.limits, p.limits)
                try:
                    res_t, r_t, miss_t = search.evaluate(trial, (I, r, J))
                except ConvergenceError:  # no equilibrium followed there: a shorter step
                    t /= 2
                    continue
                if miss_t < miss or (near and miss_t <= far):
                    restore_next = restore_next or (least_power and miss_t > miss)
                    if least_power:
                        trust = min(1.0, 2.0 * t)
                    if near and np.linalg.norm(r_t) > 0.5 * np.linalg.norm(r):
                        rcond = 0.0  # slow near the target: every output combination
                    I, res, r, miss, moved = trial, res_t, r_t, miss_t, True
                    break
                t /= 2
            else:
                if least_power:
                    trust = t
            if moved:
                break
        if not moved:
            return


#: Fractions of the start currents tried, in turn, when the forward solve at the start fails.
START_BACKOFF = (0.5, 0.25, 0.125)


def _first_state(search: _Search, I):
    """The forward solve at the start currents ``I``: (result, misses, position miss, the
    currents).  Where its load path cannot be followed (a fold on the way, e.g. a start
    field nearly antiparallel to the rod), the start moved towards zero current
    (:data:`START_BACKOFF`; the unloaded rod is always an equilibrium) so the search has a
    state to report; the first failure is raised if none of them can be followed either."""
    try:
        return (*search.evaluate(I), I)
    except ConvergenceError as first:
        for f in START_BACKOFF:
            try:
                return (*search.evaluate(f * I), f * I)
            except ConvergenceError:
                continue
        raise first from first.__cause__


def _search(p: _Problem, I, max_iter: int, max_solves: int, fresh_next: bool = False):
    """One search from the start currents ``I``: Gauss-Newton steps towards the target
    (:func:`_approach`), then, if the target is not met, Levenberg-Marquardt within the limits
    from the closest state to a local least-squares optimum (:func:`_damped`).  With
    ``fresh_next`` (a warm start whose every result off the target is dropped for a fresh
    start) the damped steps stop at the end of the branch's stable part
    (:meth:`_EdgeWatch.lost`).

    Returns the search (solves, history), the closest currents and their forward solve, the
    status (see :class:`ControlResult`) and the :class:`_BranchEdge` met (or None)."""
    search = _Search(p, max_solves)
    bounds = (-p.limits, p.limits.copy())  # the currents' range (narrowed by _damped)
    edge = None
    try:
        _approach(p, search, I, max_iter)
        if not p.met(search.best[3]):
            _, I, res, r = search.best
            watch = search.edge if fresh_next else None
            bounds = _damped(I, res, r, p.jacobian, search.evaluate, p.met, bounds, watch)
    except _BudgetSpent:  # the closest tip found is reported
        stopped = "max_solves"
    except _BranchEdge as err:  # the closest state on the branch is reported
        stopped, edge = "branch_edge", err
    else:
        stopped = "stalled"
    _, I, res, r = search.best
    if p.met(r):
        status = "converged"
    elif _optimal(p.jacobian(res), r, I, _within(bounds, I), (-p.limits, p.limits)):
        status = "optimal"
    else:
        status = stopped
    return search, I, res, status, edge


def _target(target, angle, direction):
    """The validated target (2,) or (3,) in m, tip angle (rad or None) and unit tip direction
    ((3,) or None) of :func:`solve_currents`."""
    goal = as_array(target, "target")
    if goal.shape not in ((2,), (3,)):
        raise ValueError(
            "target must have shape (2,) (x, y in the bending plane) or (3,) (x, y, z); got "
            f"{goal.shape}"
        )
    spatial = goal.size == 3
    angle = None if angle is None else finite_scalar(angle, "angle")
    if spatial and angle is not None:
        raise ValueError(
            "angle: a target tip angle is only for a target (x, y) in the bending plane; got a "
            "3D target (give a tip direction instead)"
        )
    if direction is not None:
        if not spatial:
            raise ValueError(
                "direction: a target tip direction is only for a 3D target (x, y, z); for a "
                "target (x, y) in the bending plane give angle"
            )
        direction = as_vector(direction, "direction")
        norm = float(np.linalg.norm(direction))
        if abs(norm - 1.0) > 1e-6:
            raise ValueError(f"direction must be a unit vector; got |direction| = {norm:.6g}")
        direction = direction / norm
    return goal, angle, direction


def _problem(
    rod,
    system,
    target,
    max_current,
    model,
    angle,
    steps,
    clamp_position,
    clamp_angle,
    nodes,
    tol,
    direction=None,
) -> _Problem:
    """Validate the arguments of :func:`solve_currents` and set up the problem."""
    if not isinstance(rod, Rod):
        raise ValueError(f"rod must be a coilrod.Rod; got {type(rod).__name__}")
    protocol = ("channels", "currents", "max_current", "with_currents", "with_limits")
    if not all(hasattr(system, a) for a in (*protocol, "unit_fields", "fixed_field", "center")):
        raise ValueError(
            "system must be a multi-channel source under current control (a "
            "coils.CoilSystem or a calibrated coils.MPEM: channels, currents, max_current, "
            f"with_currents, with_limits, unit_fields, fixed_field, center); got "
            f"{type(system).__name__}"
        )
    if model not in ("real", "ideal"):
        raise ValueError(f"model must be 'real' or 'ideal'; got {model!r}")
    goal, angle, direction = _target(target, angle, direction)
    spatial = goal.size == 3
    m = system.currents.size
    if max_current is None:
        limits = np.asarray(system.max_current, float)
    else:
        limits = as_limits(max_current, "max_current", m)
        system = system.with_limits(limits)
    L = rod.length
    tol = 1e-7 * L if tol is None else positive(tol, "tol")
    steps = as_count(steps, "steps", 1, 10_000)
    clamp = as_vector(clamp_position, "clamp_position")
    opts = dict(
        clamp_position=clamp, clamp_angle=finite_scalar(clamp_angle, "clamp_angle"), nodes=nodes
    )
    Bu, Gu = _channels_at_center(system)
    rank_tol = 1e-12 * max(np.abs(Bu).max(), 1e-300)
    if np.linalg.matrix_rank(Bu[:2], tol=rank_tol) < 2:
        raise ValueError(
            "the system's channels cannot make every in-plane field (B_x, B_y) at its centre: "
            f"the centre field per ampere has rank {np.linalg.matrix_rank(Bu[:2])} in the plane"
        )
    if spatial and np.linalg.matrix_rank(Bu, tol=rank_tol) < 3:
        raise ValueError(
            "target: a 3D target needs a system whose channels make every field (B_x, B_y, "
            f"B_z) at its centre; its centre field per ampere has rank "
            f"{np.linalg.matrix_rank(Bu, tol=rank_tol)}"
        )
    distance = float(np.linalg.norm(goal - clamp[: goal.size]))
    if distance > L * (1 + 1e-12):
        units = " (target is in m: was it given in mm?)" if distance > 100 * L else ""
        raise ConvergenceError(
            f"the target {goal.tolist()} m is {distance:.4g} m from the clamp, beyond the "
            f"rod's length {L:g} m: unreachable{units}",
            reached=0.0,
            target=1.0,
        )
    resistance = _resistances(system, m)
    B_fixed, G_fixed = _fixed(system)
    return _Problem(
        rod=rod,
        system=system,
        model=model,
        target=goal,
        angle=angle,
        direction=direction,
        limits=limits,
        resistance=resistance,
        steps=steps,
        opts=opts,
        tol=tol,
        # a system that can push the rod out of its plane: the tip is held on the plane too
        with_z=spatial or _leaves_plane(system, clamp, L),
        Bu=Bu,
        Gu=Gu,
        B_fixed=B_fixed,
        G_fixed=G_fixed,
    )


def solve_currents(
    rod: Rod,
    system,
    target,
    max_current=None,
    model: str = "real",
    *,
    angle: float | None = None,
    steps: int = 10,
    clamp_position=(0.0, 0.0, 0.0),
    clamp_angle: float = 0.0,
    nodes: int | None = None,
    tol: float | None = None,
    max_iter: int = 15,
    initial=None,
    max_solves: int = 40,
    direction=None,
) -> ControlResult:
    """Currents of ``system`` that put the tip of ``rod`` on ``target``.

    Parameters
    ----------
    rod : Rod
    system : coils.CoilSystem or coils.MPEM
        A multi-channel source under current control (``channels``, ``currents``,
        ``max_current``, ``with_currents``, ``with_limits``, ``unit_fields``,
        ``fixed_field``, ``center``): air coils, e.g.
        ``coils.presets.three_axis_helmholtz()``, or a calibrated eMNS model, e.g.
        ``coils.presets.cardiomag()``.  Minimum power weighs the channels by their
        resistances, or equally (least ``sum I^2``) for a system without them (an MPEM).
    target : array-like, shape (2,) or (3,)
        Tip position, m: (x, y) in the bending plane, or (x, y, z) for the spatial rod (the
        system's channels must make every field direction at its centre; the start is the
        planar answer turned about the clamp tangent into the target's plane, fitted to a
        target direction's tip angle in that plane too, see :func:`_start_3d`).
    max_current : float or array-like, shape (m,), optional
        Current limits, A (> 0); default the system's own (``system.max_current``).
    model : {"real", "ideal"}
        "real": the currents are found in the real field; "ideal": as the usual controller
        does, from the system's field and gradient at its centre (see the module docstring).
    angle : float, optional
        Target tip angle, rad, for a target (x, y) only (then three conditions; with fewer
        independent channels the result is the least-squares compromise of the misses --
        positions in L, the angle in rad -- within the current limits, and the misses say
        so).  When the first steps stop improving, the search goes on by Levenberg-Marquardt
        steps within the limits until a local optimum; ``ControlResult.status`` says whether
        one was reached.
    direction : array-like, shape (3,), optional
        Target unit tip tangent, for a 3D target only (|direction| = 1 within 1e-6).  A
        weighted target, not a hard constraint: two more conditions (the tangent's
        stereographic projection from -direction, ``2 tan(alpha / 2)`` for the angle alpha off
        it, about alpha in rad, weighed against the position misses in L); with enough
        independent channels (five conditions: e.g. CardioMag's eight) both are met to
        ``tol``, with fewer the result is the least-squares compromise within the limits (as
        for ``angle``; ``direction_miss`` says how far off it is, a ControlWarning if it is not
        a local optimum).
    steps : int
        Load steps of each forward solve (the currents ramped from zero: the path matters at
        snap-throughs).
    clamp_position, clamp_angle, nodes
        As in :func:`coilrod.solve_rod` (m, rad).
    tol : float, optional
        Position tolerance, m (default 1e-7 L).
    max_iter : int
        Gauss-Newton iterations.
    max_solves : int
        Most forward solves of the iteration (its start excluded): a target that is not met
        by then is reported unreachable with the closest tip found.
    initial : array-like, shape (m,), optional
        Start currents, A (e.g. the previous target's along a tip path): the uniform-field
        start is skipped (and taken after all if the warm start does not reach the target).

    Returns
    -------
    ControlResult

    Raises
    ------
    ValueError
        Bad input (naming the argument), a system that cannot make an in-plane field (or,
        for a 3D target, every field direction), or a magnetization with an out-of-plane
        elevation (the start is found on the planar rod).
    coilrod.ConvergenceError
        The target position is not reachable: the message gives the closest stable tip found
        and its distance, and why: the current limits (naming the channels at their limit),
        or, with no limit active at a local optimum of the miss, a target outside the robot's
        reachable set; ``err.result`` is the ControlResult there.

    Warns
    -----
    ControlWarning
        The currents returned are neither on the target nor a local least-squares optimum
        (``status`` "max_solves", "stalled" or "branch_edge"; ``optimal`` False;
        ``message`` says how the search ended).

    Notes
    -----
    The search, for the model's field (see the module docstring):

    1. start: ``initial``, or the in-plane uniform field that puts the tip on the target
       made at the centre with minimum power (:func:`_start`; for a 3D target turned about
       the clamp tangent, :func:`_start_3d`);
    2. Gauss-Newton steps on the weighted misses r(I) with the exact Jacobian, minimum-power
       steps near the target (:func:`_approach`);
    3. off the target: Levenberg-Marquardt within the limits to a local least-squares
       optimum (:func:`_damped`); steps 2 and 3 stop early at an edge of the rod's branch
       (status "branch_edge": small steps along one direction of the currents land the rod
       on another branch, again and again; the closest state on the branch is returned);
    4. a warm start (``initial``) that does not reach the target in the real field is followed
       by a fresh one from the uniform-field start (both searches' solves counted); for a
       position target its step 3 also stops where steps that gain leave the rod unstable
       (the end of the stable part of its branch), where a fresh search creeps on to the
       stability boundary;
    5. the report (:func:`_finish`): the real-field tip of the currents, and an error or a
       warning when the target is not met.

    Examples
    --------
    >>> import coils
    >>> from coilrod import presets, solve_currents
    >>> rod = presets.seed_rod(presets.M1())
    >>> system = coils.presets.three_axis_helmholtz()
    >>> out = solve_currents(rod, system, target=(0.029, 0.025))
    >>> bool(out.miss < 1e-6 * rod.length)
    True
    """
    p = _problem(
        rod,
        system,
        target,
        max_current,
        model,
        angle,
        steps,
        clamp_position,
        clamp_angle,
        nodes,
        tol,
        direction,
    )
    max_solves = as_count(max_solves, "max_solves", 1, 10_000)
    max_iter = as_count(max_iter, "max_iter", 1, 10_000)
    starts = ["fresh"]
    if initial is not None:
        warm = as_array(initial, "initial", (p.limits.size,)).copy()
        if np.any(np.abs(warm) > p.limits):
            raise ValueError(
                f"initial currents {warm.tolist()} A exceed the limits {p.limits.tolist()}"
            )
        starts = ["warm", "fresh"]
    solves, history = 0, []
    for start in starts:
        if start == "warm":
            I, start_solves = warm, 0
        elif p.spatial:
            I, start_solves = _start_3d(p)
        else:
            I, start_solves = _start(
                p.rod,
                p.planar_goal,
                p.with_angle,
                p.steps,
                p.opts,
                p.Bu,
                p.resistance,
                p.limits,
                p.system,
                p.B_fixed,
                p.tol,
            )
        fresh_next = start == "warm" and p.model == "real" and not p.oriented
        search, I, res, status, edge = _search(p, I, max_iter, max_solves, fresh_next)
        solves, history = solves + search.solves, history + search.history
        # a warm start led astray (e.g. across a snap-through): start afresh
        astray = min(search.history) > p.tol and (not p.oriented or status != "optimal")
        if not (start == "warm" and p.model == "real" and astray):
            break
    return _finish(p, I, res, solves, start_solves, history, status, edge)


#: Largest relative decrease of the squared weighted misses a bounded Gauss-Newton step may
#: predict at a state called a local least-squares optimum (|P r| <= 0.1 % of |r|, P the
#: projection on the range of the Jacobian).
GAIN_TOL = 1e-6


def _within(bounds, I):
    """The bounds (lo, hi) widened to hold ``I`` (a returned state found before they were
    narrowed)."""
    return np.minimum(bounds[0], I), np.maximum(bounds[1], I)


def _gain(J, r, I, bounds) -> float:
    """Relative decrease of |r|^2 that the best step within ``bounds`` (lo, hi) of the
    currents predicts for the linearisation ``r + J s``: 0 at a (bounded) local least-squares
    optimum."""
    from scipy.optimize import lsq_linear

    rr = float(r @ r)
    if rr == 0.0:
        return 0.0
    lo, hi = bounds
    s = lsq_linear(J, -r, bounds=(lo - I, hi - I + 1e-300 * (hi <= I))).x
    after = r + J @ s
    return max(0.0, (rr - float(after @ after)) / rr)


def _optimal(J, r, I, bounds, limits) -> bool:
    """(I, r) is a local least-squares optimum: no step within ``bounds`` (the limits as
    narrowed by :func:`_damped`) gains, and -- where a channel is on a narrowed bound
    (:func:`_pinned`) -- no step within the ``limits`` either (that bound is no limit: a
    state held against it is not an optimum within the limits)."""
    if _gain(J, r, I, bounds) > GAIN_TOL:
        return False
    return not _pinned(I, bounds, limits).any() or _gain(J, r, I, limits) <= GAIN_TOL


def _damped(I, res, r, jacobian, evaluate, met, bounds, edge=None):
    """Levenberg-Marquardt within the current limits from the state (I, res, r): steps
    ``argmin |r + J s|^2 + mu |D s|^2`` over ``|I + s| <= limits`` (D the column norms of J),
    a step accepted when the misses decrease (and the state stays stable if it was), ``mu``
    raised after a failed step and lowered after a good one.  Ends at a local optimum (see
    :func:`_gain`), when ``mu`` grows beyond any useful step or three accepted steps in a row
    gain almost nothing, or when ``evaluate`` spends the solve budget or finds the edge of the
    rod's branch (:class:`_EdgeWatch`: its steps along one direction jump to another branch,
    the remaining miss lies across the edge) -- or, with ``edge`` (an :class:`_EdgeWatch`),
    where steps that gain leave the rod unstable (:meth:`_EdgeWatch.lost`); the states met
    are kept by ``evaluate``.

    A channel whose change of sign sent the rod to another branch (a step that raised the
    misses, e.g. the small current that decides to which side a rod in a nearly antiparallel
    field buckles) is kept on its side of zero, at least as far from it as now: the bounds
    (lo, hi) of the currents are narrowed so, and returned (the optimum is sought, and
    checked, within them).  Such a bound holds where it was set: when the iteration ends
    with a channel on one (not on its limit) and a step within the limits still promises a
    gain, the bounds are widened back to the limits and the iteration goes on (up to
    ``RELAX`` times) -- the optimum met against such a bound is an artefact of the
    narrowing, not of the rod or the limits."""
    from scipy.optimize import lsq_linear

    lo, hi = (np.array(b, float) for b in bounds)
    J = jacobian(res)
    d = np.linalg.norm(J, axis=0)
    mu, crawl, relaxed = 1e-3, 0, 0
    while not met(r):
        if not (_gain(J, r, I, (lo, hi)) > GAIN_TOL and mu < 1e10 and crawl < 3):
            held = relaxed < RELAX and _pinned(I, (lo, hi), bounds).any()
            if not held or _gain(J, r, I, bounds) <= GAIN_TOL:
                break
            lo, hi = (np.array(b, float) for b in bounds)  # widened back to the limits
            mu, crawl, relaxed = 1e-3, 0, relaxed + 1
        d = np.maximum(d, 1e-6 * max(d.max(), 1e-300))
        A = np.vstack([J, np.sqrt(mu) * np.diag(d)])
        b = np.r_[-r, np.zeros(I.size)]
        step = lsq_linear(A, b, bounds=(lo - I, hi - I + 1e-300 * (hi <= I))).x
        pred = float(r @ r) - float((r + J @ step) @ (r + J @ step))
        if pred <= 0.0 or not np.any(step):
            mu *= 4.0
            continue
        trial = np.clip(I + step, lo, hi)
        try:
            res_t, r_t, _ = evaluate(trial, (I, r, J))
        except ConvergenceError:
            mu *= 4.0
            continue
        rho = (float(r @ r) - float(r_t @ r_t)) / pred
        flipped = (np.sign(trial) != np.sign(I)) & (I != 0.0)
        if rho < 0.0 and np.any(flipped):  # another branch: keep those channels on their side
            lo = np.where(flipped & (I > 0), I, lo)
            hi = np.where(flipped & (I < 0), I, hi)
            continue
        if rho > 1e-3 and (bool(res_t.stable[-1]) or not bool(res.stable[-1])):
            # steps that each gain < 1e-6 of |r|^2 while the linearisation promises more:
            # the misses creep towards an edge of the branch (e.g. a bifurcation the load
            # path turns away from), not towards an optimum
            crawl = crawl + 1 if float(r @ r) - float(r_t @ r_t) < 1e-6 * float(r @ r) else 0
            I, res, r = trial, res_t, r_t
            J = jacobian(res)
            d = np.maximum(d, np.linalg.norm(J, axis=0))
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
        else:
            if edge is not None and rho > 1e-3:  # gained, but the stable rod is unstable there
                edge.lost(r, r_t, J @ (trial - I), trial - I)
            mu *= 4.0
    return lo, hi


#: How often :func:`_damped` widens bounds it narrowed back to the limits.
RELAX = 2


def _pinned(I, bounds, limits) -> np.ndarray:
    """Channels (bool, (m,)) on a bound of ``bounds`` (lo, hi) that is narrower than
    ``limits`` (lo, hi): kept on their side of zero by :func:`_damped`, not at a limit."""
    (lo, hi), (lo0, hi0) = bounds, limits
    scale = np.maximum(np.maximum(np.abs(lo0), np.abs(hi0)), 1e-300)
    low = (lo > lo0) & (I <= lo + 1e-9 * scale)
    high = (hi < hi0) & (I >= hi - 1e-9 * scale)
    return low | high


def _start_3d(p: _Problem):
    """Start currents for a 3D target: the bending plane turned about the clamp tangent t by
    the angle phi that brings it through the target, the in-plane uniform-field answer
    (:func:`_uniform_start`) for the target turned into the plane, and that field turned back
    (exact for a rod symmetric about its axis, e.g. an axial magnetization on a round section;
    a start otherwise), made at the centre with minimum power.  With a target direction d,
    the planar answer fits the tip angle of d's projection on the turned plane too (the
    least-squares blend of the position's and the direction's bending, positions in L, the
    angle in rad; the angle taken on the branch nearest twice the chord's, the tip angle of a
    uniformly bent rod).  Returns (currents, solves)."""
    from coils.currents import largest_fraction

    clamp, a = p.opts["clamp_position"], p.opts["clamp_angle"]
    t = np.array([math.cos(a), math.sin(a), 0.0])
    n = np.array([-math.sin(a), math.cos(a), 0.0])
    v = p.target - clamp
    phi = math.atan2(v[2], v @ n)
    n_phi = math.cos(phi) * n + math.sin(phi) * np.array([0.0, 0.0, 1.0])
    planar = clamp[:2] + (v @ t) * t[:2] + math.hypot(v @ n, v[2]) * n[:2]
    d = p.direction
    with_angle = d is not None and math.hypot(d @ t, d @ n_phi) > 1e-6  # d not across the plane
    if with_angle:  # d's tip angle in the turned plane, relative to the clamp tangent
        turn = math.atan2(d @ n_phi, d @ t)
        bent = 2.0 * math.atan2(math.hypot(v @ n, v[2]), v @ t)  # uniform bending's
        turn += 2 * math.pi * round((bent - turn) / (2 * math.pi))
        planar = np.r_[planar, a + turn]
    b_big = p.rod.field_for_lambda(30.0)  # beyond any useful field: lambda = 30
    caps = [
        largest_fraction(p.Bu, b_big * (math.cos(al) * t + math.sin(al) * n_phi), p.limits)[0]
        for al in np.linspace(0.0, 2 * np.pi, 36, endpoint=False)
    ]
    b_cap = b_big * float(min(caps))  # the largest centre field (T) in every direction of it
    b, solves = _uniform_start(p.rod, planar, with_angle, p.steps, p.opts, b_cap)
    B = (b @ t[:2]) * t + (b @ n[:2]) * n_phi
    return _centre_currents(p.system, B, p.resistance, p.limits, p.Bu, p.B_fixed), solves


def _room(I, step, limits) -> float:
    """Largest t <= 1 with |I + t step| <= limits."""
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(step != 0, (limits - np.sign(step) * I) / np.abs(step), np.inf)
    return float(max(0.0, min(1.0, np.min(room))))


def _resistances(system, m: int) -> np.ndarray:
    """The weights (m,) of the power sum: the channels' resistances (ohm), or ones for a
    system without them (a calibrated :class:`coils.MPEM`, or coils of unknown copper): the
    least ``sum I^2``."""
    try:
        resistance = getattr(system, "resistance", None)
    except ValueError:  # a CoilSystem with a coil of unknown resistance
        resistance = None
    if resistance is None:
        return np.ones(m)
    return np.asarray(resistance, float)


def _fixed(system):
    """Field and gradient of the system's fixed (current-free) parts at its centre."""
    B, G = system.fixed_field(np.asarray(system.center, float)[None])
    return B[0], G[0]


def _ending(p: _Problem, res, solves, status, edge) -> str:
    """How the search ended, for ``ControlResult.message``: "" on the target; else the status,
    the closest position miss in the model's own field (``res`` its forward solve at the
    returned currents), the solves spent and, at a branch edge (``edge``, a
    :class:`_BranchEdge`), the direction of the currents that leaves the branch."""
    if status == "converged":
        return ""
    miss = p.position_miss(p.residual(res))
    own = "the real field" if p.model == "real" else "the ideal (centre-field) model"
    reached = f"the closest tip in {own} is {miss:.4g} m ({miss / p.length:.3g} L) from the target"
    if edge is None:
        return f"{status} after {solves} solves: {reached}"
    if edge.unstable:
        return (
            f"branch_edge after {solves} solves: the search stopped at the end of the stable "
            f"part of the rod's branch -- {edge.jumps} small steps of the currents along "
            f"{np.round(edge.direction, 3).tolist()} gained but left the rod unstable; "
            f"{reached}, the remaining miss lies across the edge"
        )
    return (
        f"branch_edge after {solves} solves: the search stopped at an edge of the rod's branch "
        f"-- {edge.jumps} small steps of the currents along {np.round(edge.direction, 3).tolist()}"
        f" sent the rod to another branch (its misses moved {edge.moved:.3g} where the step's "
        f"linearisation predicted {edge.predicted:.3g}; positions in L); {reached}, the "
        "remaining miss lies across the edge"
    )


def _finish(p: _Problem, I, res, solves, start_solves, history, status, edge=None) -> ControlResult:
    """The result at currents ``I`` (``res`` the model's forward solve there), with the tip in
    the real field; raises for an unreachable position target and warns for a result that is
    not a local optimum (:func:`_report`)."""
    real = res if p.model == "real" else _forward(p.rod, p.system.with_currents(I), p.steps, p.opts)
    tip = real.tip[-1]
    tangent = real.frames(len(real) - 1)[-1, :, 0].copy()
    goal_pos = p.goal[: p.npos]  # (x, y) or (x, y, z) held, m
    miss = float(np.linalg.norm(tip[: goal_pos.size] - goal_pos))
    try:
        power = float(p.system.power(I)) if hasattr(p.system, "power") else float("nan")
    except ValueError:
        power = float("nan")
    out = ControlResult(
        currents=I,
        tip=tip.copy(),
        tip_angle=float(real.tip_angle[-1]),
        miss=miss,
        angle_miss=abs(float(real.tip_angle[-1]) - p.angle) if p.with_angle else None,
        power=power,
        result=real,
        model=p.model,
        target=p.target.copy(),
        solves=solves,
        start_solves=start_solves,
        history=history,
        status=status,
        optimal=status in ("converged", "optimal"),
        active=np.flatnonzero(np.abs(I) >= p.limits * (1.0 - LIMIT_RTOL)).tolist(),
        tip_direction=tangent,
        direction_miss=(
            float(np.arctan2(np.linalg.norm(np.cross(tangent, p.direction)), tangent @ p.direction))
            if p.direction is not None
            else None
        ),
        message=_ending(p, res, solves, status, edge),
    )
    _report(p, out, history)
    return out


#: A channel within this fraction of its limit is reported at its limit (``active``): the
#: bounded least-squares steps end a few 1e-10 of the limit short of it (-9.999999996 A of a
#: 10 A limit was reported as "no current limit is active").
LIMIT_RTOL = 1e-6


#: A closest state whose tip is within this fraction of L of the straight rod's is "nearly
#: straight" in the report of a stalled search.
NEAR_STRAIGHT = 0.05


def _stalled_where(p: _Problem, out: ControlResult) -> str:
    """What a stalled search (status "stalled") ran into, for the error: the steps stopped
    decreasing the miss, no current limit active, and -- when the closest rod is nearly
    straight -- why (the tip's axial position moves at second order only in the field
    there: a target the straight rod's tip cannot approach is likely out of reach)."""
    a = p.opts["clamp_angle"]
    straight = p.opts["clamp_position"] + p.length * np.array([math.cos(a), math.sin(a), 0.0])
    off = float(np.linalg.norm(out.tip - straight)) / p.length
    text = (
        " (status 'stalled': the Gauss-Newton and damped steps stopped decreasing the miss "
        "short of a local optimum; no current limit is active)"
    )
    if off <= NEAR_STRAIGHT:
        text += (
            f"; the closest rod is nearly straight (its tip {off:.3g} L from the straight "
            "rod's), where the tip moves towards the clamp only at second order in the field: "
            "the target is probably outside the robot's reachable set"
        )
    return text


def _held_by_limits(p: _Problem, out: ControlResult) -> bool:
    """A local optimum within the limits with no channel at its limit, where a step beyond
    them would still gain at least half of the squared misses: limits so tight that no
    step within them moves the tip (e.g. 1e-12 A), not a target out of the robot's reach
    (there the misses' gradient vanishes, and no step gains, whatever its size: the misses
    lie off the combinations the currents move)."""
    r = p.residual(out.result)
    # the misses on the output combinations the currents move (singular values above
    # STEP_RCOND of the largest, not round-off ones): an unbounded step removes them all
    _, moved = _moved(p.jacobian(out.result), r)
    return float(moved @ moved) > 0.5 * float(r @ r)


def _report(p: _Problem, out: ControlResult, history) -> None:
    """Raise ConvergenceError for a position target the real controller did not reach --
    telling the current limits (naming the channels at theirs) from a target outside the
    robot's reachable set -- or warn (ControlWarning) for a result that is not a local
    least-squares optimum."""
    I, tip, miss = out.currents, out.tip, out.miss
    if p.model == "real" and min(history) > p.tol and not p.oriented:
        if out.active:
            why = (
                "beyond the current limits: not reachable within them (channels "
                f"{', '.join(map(str, out.active))} at their limit)"
            )
        elif out.optimal and _held_by_limits(p, out):
            why = (
                "beyond the current limits: within them the currents barely move the tip (the "
                "best step within the limits gains almost nothing, one beyond them much)"
            )
        elif out.optimal:
            why = (
                "outside the robot's reachable set (no current limit is active at the closest "
                "tip, a local optimum of the miss)"
            )
        elif out.status == "branch_edge":
            why = f"not reached: the search stopped at an edge of the rod's branch ({out.message})"
        elif out.status == "max_solves":
            why = (
                "not reached: the search stopped (the solve budget max_solves spent) before a "
                "local optimum of the miss; no current limit is active"
            )
        else:
            why = "not reached: the search stalled" + _stalled_where(p, out)
        closest = (
            "the closest stable tip found"
            if out.result.stable[-1]
            else "the closest tip found (an unstable equilibrium: no stable one was found)"
        )
        err = ConvergenceError(
            f"solve_currents: the target {p.target.tolist()} m is {why}; {closest} is "
            f"{tip[: p.target.size].tolist()} m, {miss:.4g} m ({miss / p.length:.3g} L) away, with "
            f"currents {np.round(I, 4).tolist()} A",
            reached=0.0,
            target=1.0,
            residual=history[-1] if history else miss,
        )
        err.result = out
        raise err
    if out.status == "branch_edge":
        warnings.warn(
            f"solve_currents: the currents {np.round(I, 4).tolist()} A do not meet the target "
            f"({out.message}; in the real field the tip is {miss:.4g} m from it); "
            "ControlResult.optimal is False",
            ControlWarning,
            stacklevel=4,
        )
    elif not out.optimal:
        warnings.warn(
            f"solve_currents: the currents {np.round(I, 4).tolist()} A are not a local "
            f"least-squares optimum of the misses ({out.status}: miss {miss:.4g} m"
            + (f", angle miss {out.angle_miss:.4g} rad" if p.with_angle else "")
            + (f", direction miss {out.direction_miss:.4g} rad" if p.direction is not None else "")
            + "); ControlResult.optimal is False",
            ControlWarning,
            stacklevel=4,
        )
