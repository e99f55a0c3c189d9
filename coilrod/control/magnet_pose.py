"""The pose of a permanent magnet that puts the rod's tip on a target.

The control input is the magnet's pose: its centre ``c`` and its orientation.  The pose
vector ``q`` holds

* for a target (x, y) in the bending plane: ``(c_x, c_y, psi)``, the centre in the rod's
  plane and the turn ``psi`` (rad) about the plane's normal (z) of the magnet's own
  orientation -- poses that keep a magnet lying symmetric about the plane there, so the rod
  stays planar;
* for a target (x, y, z): ``(c_x, c_y, c_z, r_x, r_y, r_z)``, the centre and the rotation
  vector ``r`` (rad) of the turn ``exp([r]) `` applied to the magnet's own orientation.

Each evaluation is one forward solve of the rod in the magnet's field at that pose, followed
along the load path from the straight rod (:func:`coilrod.solve_rod`, as
:func:`coilrod.solve_currents` does), and the exact derivatives of the tip with respect to
the pose by the adjoint (:func:`coilrod.design.sensitivity.tip_derivatives`): the magnetic
load is linear in the field and its gradient at the nodes, so the tip's derivative chains the
adjoint loads with ``d(B, grad B)/dq`` at the nodes, which the magnet gives exactly --

* a translation ``dc``: ``dB = -G dc``, ``dG = -H dc`` (``H`` the magnet's hessian);
* a turn ``omega`` about the magnet's centre (``d = x - c``): ``dB = omega x B - G (omega x
  d)``, ``dG = [omega] G - G [omega] - H (omega x d)``; a rotation vector's change ``dr`` is
  the turn ``omega = J_l(r) dr`` (``J_l`` the left Jacobian of SO(3)).

The hessian is exact (closed forms) for :class:`coils.Dipole`, :class:`coils.CylinderMagnet`
(cylinder and ring) and :class:`coils.CuboidMagnet`, so the pose derivatives are exact.

The search is trust-region Gauss-Newton in the pose scaled by a tenth of the magnet's
distance from the clamp (centre) and 0.2 rad (turn).  Each step is a constrained one: the box
``bounds`` and the robot's reach (the distance of the magnet's body from the clamp >=
L + clearance, linearised at the pose from the body's geometry) are linear inequalities of
the trust-region Gauss-Newton subproblem, solved exactly over the faces of the few
constraints that can bind within the radius (:func:`_constrained_step`); a step whose face
holds the reach ends on its curved boundary (a radial move), so a search pressed against the
reach runs along it.  The search stops at a KKT point of the miss -- "optimal", the closest
pose within the bounds and off the reach, named as active -- when the constrained Gauss-Newton
step (no trust region) predicts under 1e-12 relative decrease of the squared miss.  The tip's
map is ill-conditioned (singular values ~500-1000 apart: an inextensible rod's tip moves along
its arc far more easily than across it, whatever bends it), so the step that closes the miss
across the arc moves the pose far, and there the linearisation's error -- second order in the
step, and along the arc, where the tip is sensitive -- outgrows the gain.  The trust region
alone then shrank to steps that each gained little (a target rounded to 10 um ended at the
budget).  Instead, when a step's forward solve gains less than a quarter of the predicted
decrease, one constrained least-norm Newton step with the Jacobian there moves the tip back
onto the linearisation's prediction (the target carried along the step: continuation); that
costs little pose, as the error lies where the tip is sensitive, and keeps the gain across
the arc.  A step whose corrected solve fails or does not gain a tenth of the prediction
halves the radius, and caps its regrowth below the size that failed (the first radius is half
the scale: the map is far from linear over the start's distance).  The band of tips one
magnet reaches from near the start pose is thin: a target off it (the benchmark's planar
targets rounded to 0.1 mm) may be met only at a pose far from the start, the magnet run along
the reach's boundary, or not within the budget ("max_solves").

A predictor after a corrected step is bent by that step's correction, scaled by the square
of the step's size (the linearisation's error along a curved band), when the two steps point
alike: on the long walks along the band it saves about a fifth of the solves.

**The scout.**  The walk along the band to a far pose costs the real magnet's field 25-40
solves.  For a finite magnet (``model="real"``), the search first runs in a cheap model of
it -- its point dipole (``magnet.dipole()``, a field ~5x cheaper than a cylinder's), a coarse
mesh (:data:`SCOUT_NODES`), to 1e-5 L -- and the real search starts where the scout ends:
the dipole's pose curve runs close to the finite magnet's, and the real search closes the
difference (~1e-3 L) in 3-5 solves.  The scout only chooses the start: the pose returned is
the real search's, met in the finite magnet's field (``scout_solves`` counts the scout's
solves).  If the scout neither meets the target nor ends at an optimum of its model (its
budget :data:`SCOUT_SOLVES` spent, or stalled), or the real forward solve fails at the
scout's pose, the real search starts from the given pose.

**The robot's reach** is the ball of radius L (the rod's length) about the clamp: every point
of the rod lies in it whatever the load.  A pose is refused if any point of the magnet's body
(a :class:`coils.Dipole`: its centre; a :class:`coils.CylinderMagnet`: the solid cylinder of
its outer diameter; a :class:`coils.CuboidMagnet`: the box) is closer than
``L + clearance`` to the clamp (:func:`reach_distance`).

``model="dipole"``: the usual controller's model -- the pose is found in the field of the
magnet's point dipole (``magnet.dipole()``), and the finite magnet is then placed at that pose:
``miss`` says how far its tip really lands from the target.
"""

from __future__ import annotations

import itertools
import math
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

import coils
from coils._validate import as_array, as_count, as_vector, finite_scalar, positive

from ..design.sensitivity import tip_derivatives
from ..errors import ConvergenceError
from ..path.events import StabilityWarning
from ..robot.rod import Rod
from ..rod.result import RodResult
from ..rod.solve import solve_rod

__all__ = ["solve_magnet_pose", "MagnetPoseResult", "reach_distance"]


@dataclass
class MagnetPoseResult:
    """A magnet pose for a target tip position and where the tip lands at it.

    Attributes
    ----------
    pose : ndarray, shape (3,) or (6,)
        The pose vector: (c_x, c_y, psi) for a planar target, (c_x, c_y, c_z, r_x, r_y, r_z)
        for a 3D one (m, rad; see the module docstring).
    position : ndarray, shape (3,)
        The magnet's centre, m.
    orientation : ndarray, shape (3, 3)
        The magnet's orientation (local -> global rotation), the turn of the pose applied to
        the given magnet's.
    magnet : coils.Field
        The (finite) magnet placed at the pose.
    tip : ndarray, shape (3,)
        Tip position in the magnet's field at the pose, m.
    miss : float
        Distance of that tip from the target, m (for ``model="dipole"``: of the finite
        magnet's tip from the target, the dipole controller's miss).
    target : ndarray, shape (2,) or (3,)
        Target, m.
    result : RodResult
        The forward solve of the finite magnet at the pose.
    model : str
        "real" or "dipole".
    solves : int
        Forward solves of the search (in the model's field; each Jacobian costs a fraction of
        one: a factorisation and a few transposed solves).
    history : list of float
        Position miss of every forward solve of the search, m (in the model's field).
    scout_solves : int
        Forward solves of the scout that gave the search its start (``model="real"`` with a
        finite magnet: the search in its point dipole's field on a coarse mesh, each solve
        ~1/9 of a real one's CPU time, benchmarks/results/magnet_pose.md; module docstring); 0
        without a scout.
    status : str
        "converged" (within ``tol``), "optimal" (not met: a KKT point of the miss, where the
        Gauss-Newton step within the bounds and off the reach, both linearised, predicts a
        relative decrease of the squared miss under 1e-12: the closest pose there, the reach
        (``reach_gap`` ~0) and/or the bounds (``active``) binding), "max_solves", or
        "stalled" (a genuine failure: the trust radius shrank to nothing, or three accepted
        steps in a row each gained under 1e-12 of the squared miss).
    active : list of int
        Pose components at a bound (within 1e-9 of its span).
    reach_gap : float
        Distance of the magnet's body beyond the robot's reach (and ``clearance``) at the
        pose, m: 0 to round-off where the reach is the active constraint.
    """

    pose: np.ndarray
    position: np.ndarray
    orientation: np.ndarray
    magnet: object
    tip: np.ndarray
    miss: float
    target: np.ndarray
    result: RodResult
    model: str
    solves: int
    history: list = field(default_factory=list)
    scout_solves: int = 0
    status: str = "converged"
    active: list = field(default_factory=list)
    reach_gap: float = float("nan")

    @property
    def miss_percent(self) -> float:
        """``miss`` in % of the rod's length."""
        return 100.0 * self.miss / self.result._solution.rod.length


# -- poses ----------------------------------------------------------------------------------
_MAGNETS = (coils.Dipole, coils.CylinderMagnet, coils.CuboidMagnet)


def _skew(v) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _rotation(r) -> np.ndarray:
    """exp([r]) (Rodrigues)."""
    th = float(np.linalg.norm(r))
    K = _skew(r)
    if th < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + math.sin(th) / th * K + (1.0 - math.cos(th)) / th**2 * K @ K


def _left_jacobian(r) -> np.ndarray:
    """J_l(r): the turn omega = J_l(r) dr of exp([r + dr]) exp([r])^T."""
    th = float(np.linalg.norm(r))
    K = _skew(r)
    if th < 1e-6:
        return np.eye(3) + 0.5 * K + K @ K / 6.0
    return np.eye(3) + (1.0 - math.cos(th)) / th**2 * K + (th - math.sin(th)) / th**3 * K @ K


def _orientation(magnet) -> np.ndarray:
    if isinstance(magnet, coils.Dipole):
        return np.eye(3)
    return np.asarray(magnet.rotation, float)


def _place(magnet, center, turn):
    """``magnet`` moved to ``center`` (m) and turned by ``turn`` (3, 3) about its centre."""
    if isinstance(magnet, coils.Dipole):
        return coils.Dipole(turn @ magnet.moment, center)
    if isinstance(magnet, coils.CylinderMagnet):
        return coils.CylinderMagnet(
            magnet.diameter,
            magnet.length,
            magnet.magnetization,
            center,
            inner_diameter=magnet.inner_diameter,
            orientation=turn @ magnet.rotation,
        )
    return coils.CuboidMagnet(
        magnet.size, magnet.magnetization, center, orientation=turn @ magnet.rotation
    )


def reach_distance(magnet, clamp) -> float:
    """Distance (m) from ``clamp`` (3,) to the closest point of the magnet's body: the point
    of a :class:`coils.Dipole`, the solid cylinder (its bore included) of a
    :class:`coils.CylinderMagnet`, the box of a :class:`coils.CuboidMagnet`; 0 inside it."""
    return _body_distance(magnet, magnet.center, _orientation(magnet), clamp)


def _body_distance(magnet, center, rotation, clamp) -> float:
    """:func:`reach_distance` of ``magnet``'s body placed at ``center`` (3,) with orientation
    ``rotation`` (3, 3) (the magnet itself is not built: the search calls this often)."""
    clamp = np.asarray(clamp, float)
    if isinstance(magnet, coils.Dipole):
        return float(np.linalg.norm(clamp - center))
    local = (clamp - center) @ rotation
    if isinstance(magnet, coils.CylinderMagnet):
        dr = max(math.hypot(local[0], local[1]) - magnet.radius, 0.0)
        dz = max(abs(local[2]) - 0.5 * magnet.length, 0.0)
        return math.hypot(dr, dz)
    return float(np.linalg.norm(np.maximum(np.abs(local) - 0.5 * magnet.size, 0.0)))


class _PoseField(coils.Field):
    """The field of a posed magnet with the pose as its parameter channels: ``currents`` is
    the pose vector and ``unit_fields(points)`` its exact d(B, G)/dq, the interface by which
    :func:`coilrod.design.sensitivity.tip_derivatives` chains field parameters (the group
    "currents") with the adjoint loads."""

    def __init__(self, magnet, pose, planar: bool):
        self.magnet = magnet
        self.currents = np.asarray(pose, float)
        self.planar = planar

    @property
    def length_scale(self) -> float:
        return self.magnet.length_scale

    def _B(self, pts):
        return self.magnet.B(pts)

    def _B_and_gradient(self, pts):
        return self.magnet.B_and_gradient(pts)

    def _gradient(self, pts):
        return self.magnet.gradient(pts)

    def _hessian(self, pts):
        return self.magnet.hessian(pts)

    def _B_gradient_hessian(self, pts):
        return self.magnet.B_gradient_hessian(pts)

    def unit_fields(self, points):
        """d(B, G)/dq at ``points`` (n, 3): shapes (n, 3, p) T and (n, 3, 3, p) T/m per unit
        of the pose (m, rad)."""
        pts = np.asarray(points, float)
        B, G, H = self.magnet.B_gradient_hessian(pts)
        d = pts - self.magnet.center
        dB_rot = np.empty(B.shape + (3,))
        dG_rot = np.empty(G.shape + (3,))
        for k in range(3):
            e = np.eye(3)[k]
            K = _skew(e)
            w = np.cross(e, d)  # the points' velocity relative to the turning magnet, sign -
            dB_rot[..., k] = np.cross(e, B) - np.einsum("nij,nj->ni", G, w)
            dG_rot[..., k] = K @ G - G @ K - np.einsum("nijl,nl->nij", H, w)
        dB_tr = -G  # (n, 3, 3): [i, k] = -dB_i/dx_k
        dG_tr = -H
        if self.planar:
            dB = np.concatenate([dB_tr[..., :2], dB_rot[..., 2:]], axis=-1)
            dG = np.concatenate([dG_tr[..., :2], dG_rot[..., 2:]], axis=-1)
            return dB, dG
        Jl = _left_jacobian(self.currents[3:])
        dB = np.concatenate([dB_tr, dB_rot @ Jl], axis=-1)
        dG = np.concatenate([dG_tr, dG_rot @ Jl], axis=-1)
        return dB, dG


# -- the problem ----------------------------------------------------------------------------
@dataclass
class _Problem:
    rod: Rod
    magnet: object  # the magnet of the model (the dipole of the finite one for "dipole")
    real: object  # the finite magnet
    target: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    steps: int
    opts: dict
    tol: float
    clearance: float

    @property
    def planar(self) -> bool:
        return self.target.size == 2

    @property
    def clamp(self) -> np.ndarray:
        return self.opts["clamp_position"]

    def turn(self, q) -> np.ndarray:
        if self.planar:
            c, s = math.cos(q[2]), math.sin(q[2])
            return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return _rotation(q[3:])

    def center(self, q) -> np.ndarray:
        if self.planar:
            return np.array([q[0], q[1], self.magnet.center[2]])
        return np.asarray(q[:3], float)

    def place(self, magnet, q):
        return _place(magnet, self.center(q), self.turn(q))

    def clear(self, q) -> float:
        """Distance of the finite magnet's body at pose q beyond the reach, m (< 0: inside)."""
        turn = self.turn(q) @ _orientation(self.real)
        return _body_distance(self.real, self.center(q), turn, self.clamp) - (
            self.rod.length + self.clearance
        )

    def off_reach(self, q, onto: bool = False) -> np.ndarray:
        """q with the magnet's centre moved radially away from the clamp (in the plane for a
        planar pose) until its body is just off the reach (q itself if it is); ``onto``: also
        moved radially in onto the reach's boundary if it is off it (a step along the
        linearised boundary ends a little off the curved one)."""
        gap = self.clear(q)
        if gap > 0.0 and not onto or gap == 0.0:
            return q
        c = self.center(q)
        v = c - self.clamp
        if self.planar:
            v[2] = 0.0
        lo_t, hi_t = 1.0, 1.0
        if gap < 0.0:
            hi_t = 2.0
            while self.clear(self._scaled(q, v, hi_t)) < 0.0:
                hi_t *= 2.0
        else:
            lo_t = 0.5
            while self.clear(self._scaled(q, v, lo_t)) >= 0.0:
                lo_t *= 0.5
        for _ in range(60):  # bisection to round-off: the body just off the reach
            mid = 0.5 * (lo_t + hi_t)
            lo_t, hi_t = (mid, hi_t) if self.clear(self._scaled(q, v, mid)) < 0.0 else (lo_t, mid)
        return self._scaled(q, v, hi_t)

    def _scaled(self, q, v, t) -> np.ndarray:
        out = q.copy()
        c = self.clamp + t * v
        out[:2] = c[:2]
        if not self.planar:
            out[2] = self.clamp[2] + t * v[2]
        return out

    def reach_row(self, q, sc):
        """The reach constraint ``clear >= 0`` linearised at q in the scaled pose: (g, c) with
        ``clear(q + s * sc) ~ c + g @ s`` (m; g by central differences of the body's geometry,
        :func:`reach_distance`, no forward solve)."""
        g = np.empty(q.size)
        for k in range(q.size):
            e = np.zeros(q.size)
            e[k] = 1e-6 * sc[k]
            g[k] = (self.clear(q + e) - self.clear(q - e)) / 2e-6
        return g, self.clear(q)

    def forward(self, magnet, q) -> RodResult:
        placed = _PoseField(self.place(magnet, q), q, self.planar)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", StabilityWarning)
            return solve_rod(
                self.rod,
                placed,
                np.arange(1, self.steps + 1) / self.steps,
                model="auto",
                **self.opts,
            )

    def residual(self, res: RodResult) -> np.ndarray:
        """Tip minus target, in units of L."""
        return (res.tip[-1, : self.target.size] - self.target) / self.rod.length

    def jacobian(self, res: RodResult) -> np.ndarray:
        _, _, _, D = tip_derivatives(res, [len(res) - 1], ["currents"], check=False)
        return D[0, : self.target.size] / self.rod.length


def _pose0(magnet, planar: bool) -> np.ndarray:
    c = np.asarray(magnet.center, float)
    return np.r_[c[:2], 0.0] if planar else np.r_[c, 0.0, 0.0, 0.0]


def _bounds(bounds, q0, planar: bool):
    p = q0.size
    names = "(c_x, c_y, psi)" if planar else "(c_x, c_y, c_z, r_x, r_y, r_z)"
    if bounds is None:
        return np.full(p, -np.inf), np.full(p, np.inf)
    try:
        arr = np.asarray(bounds, dtype=float)
    except (TypeError, ValueError) as err:
        raise ValueError(f"bounds must be (lower, upper), each of shape ({p},) {names}") from err
    if arr.shape != (2, p):
        raise ValueError(
            f"bounds must be (lower, upper), each of shape ({p},) {names} in m and rad; got an "
            f"array of shape {arr.shape}"
        )
    lo, hi = arr
    if np.isnan(arr).any():
        raise ValueError(f"bounds must not hold NaN; got {arr.tolist()}")
    if np.any(lo >= hi):
        j = int(np.flatnonzero(lo >= hi)[0])
        raise ValueError(
            f"bounds: lower[{j}] = {lo[j]} must be below upper[{j}] = {hi[j]} (pose {names})"
        )
    if np.any(q0 < lo) or np.any(q0 > hi):
        j = int(np.flatnonzero((q0 < lo) | (q0 > hi))[0])
        raise ValueError(
            f"bounds: the start pose {q0.tolist()} {names} (the magnet as given) is outside "
            f"them at component {j}: [{lo[j]}, {hi[j]}]"
        )
    return lo.copy(), hi.copy()


def _problem(rod, magnet, target, bounds, model, steps, clamp_position, clamp_angle, nodes, tol,
             clearance):  # fmt: skip
    if not isinstance(rod, Rod):
        raise ValueError(f"rod must be a coilrod.Rod; got {type(rod).__name__}")
    if not isinstance(magnet, _MAGNETS):
        raise ValueError(
            "magnet must be a coils.Dipole, coils.CylinderMagnet or coils.CuboidMagnet; got "
            f"{type(magnet).__name__}"
        )
    moment = magnet.moment if isinstance(magnet, coils.Dipole) else magnet.dipole().moment
    if not np.any(moment):
        raise ValueError(
            "magnet: its magnetization (dipole moment) is zero, so is its field: no pose moves "
            "the tip"
        )
    if model not in ("real", "dipole"):
        raise ValueError(f"model must be 'real' or 'dipole'; got {model!r}")
    goal = as_array(target, "target")
    if goal.shape not in ((2,), (3,)):
        raise ValueError(
            "target must have shape (2,) (x, y in the bending plane) or (3,) (x, y, z); got "
            f"{goal.shape}"
        )
    L = rod.length
    clamp = as_vector(clamp_position, "clamp_position")
    angle = finite_scalar(clamp_angle, "clamp_angle")
    far = float(np.linalg.norm(goal - clamp[: goal.size]))
    if far > L:
        raise ValueError(
            f"target {goal.tolist()} m is {far:.4g} m from the clamp, beyond the rod's length "
            f"L = {L} m: no pose reaches it"
        )
    steps = as_count(steps, "steps", 1, 10_000)
    tol = 1e-7 * L if tol is None else positive(tol, "tol")
    clearance = finite_scalar(clearance, "clearance")
    if clearance < 0:
        raise ValueError(f"clearance must be >= 0 m; got {clearance}")
    planar = goal.size == 2
    if planar:
        mz = magnet.center[2] - clamp[2]
        leak = _out_of_plane(magnet)
        if abs(mz) > 1e-12 * L or leak:
            raise ValueError(
                "magnet: a target (x, y) in the bending plane needs a magnet lying symmetric "
                "about the rod's plane z = clamp_position[2] (its centre on the plane and its "
                "magnetisation in it, a cuboid with an edge along z), so the rod stays planar"
                f"; got centre z - clamp z = {mz:.4g} m{leak} -- give a 3D target (x, y, z) "
                "for the spatial rod"
            )
    q0 = _pose0(magnet, planar)
    lo, hi = _bounds(bounds, q0, planar)
    p = _Problem(
        rod=rod,
        magnet=magnet.dipole() if model == "dipole" and hasattr(magnet, "dipole") else magnet,
        real=magnet,
        target=goal,
        lo=lo,
        hi=hi,
        steps=steps,
        opts=dict(clamp_position=clamp, clamp_angle=angle, nodes=nodes),
        tol=tol,
        clearance=clearance,
    )
    gap = p.clear(q0)
    if gap < 0:
        raise ValueError(
            f"magnet: its body comes within {reach_distance(magnet, clamp):.4g} m of the clamp "
            f"{clamp.tolist()} m, inside the robot's reach (the ball of radius L + clearance = "
            f"{L + clearance:.4g} m about the clamp that the rod can sweep): place it farther"
        )
    return p, q0


def _out_of_plane(magnet) -> str:
    """Why the magnet (its centre on the plane) is not symmetric about the plane z = const
    ("" if it is)."""
    if isinstance(magnet, coils.Dipole):
        m = magnet.moment
        return f", moment z {m[2]:.4g} A m^2" if abs(m[2]) > 1e-12 * np.linalg.norm(m) else ""
    R = magnet.rotation
    if isinstance(magnet, coils.CylinderMagnet):
        return f", axis {R[:, 2].round(12).tolist()}" if abs(R[2, 2]) > 1e-12 else ""
    M = R @ magnet.magnetization
    if abs(M[2]) > 1e-12 * np.linalg.norm(M):
        return f", magnetization z {M[2]:.4g} A/m"
    if np.max(np.abs(R[2])) < 1.0 - 1e-12:  # no box edge along z: not mirror symmetric
        return ", no edge of the box along z"
    return ""


# -- the search -----------------------------------------------------------------------------
class _Spent(Exception):
    pass


def _scout(p: _Problem, q0):
    """The scout (module docstring): the search from q0 in the field of the finite magnet's
    point dipole on a coarse mesh, to a loose tolerance.  Returns (q, solves): the pose it
    ends at (the real search's start) and its forward solves; (q0, 0) where the model has no
    cheaper stand-in (a :class:`coils.Dipole`, or ``model="dipole"``) or the scout's first
    forward solve fails; (q0, solves) if the scout neither meets the target nor ends at an
    optimum of its model."""
    if p.magnet is not p.real or isinstance(p.real, coils.Dipole):
        return q0, 0
    cheap = replace(
        p,
        magnet=p.real.dipole(),
        steps=min(p.steps, SCOUT_STEPS),
        opts=dict(p.opts, nodes=SCOUT_NODES),
        tol=SCOUT_TOL * p.rod.length,
    )
    try:
        q, _, status, solves, _ = _search(cheap, q0, SCOUT_SOLVES, _scales(p, q0))
    except ConvergenceError:
        return q0, 0
    if status not in ("converged", "optimal"):
        # the scout ran out of solves or stalled: its end is no better a guide than the
        # given pose (and may lie where the real forward solves are slow, the magnet close)
        return q0, solves
    return q, solves


#: The scout's model: the magnet's point dipole (its field is ~5x cheaper than a cylinder's),
#: a mesh of SCOUT_NODES segments (with Richardson: without it the coarse tip is off by more
#: than the thin band of tips is wide, and the scout ends on the wrong part of the pose
#: curve), SCOUT_STEPS load steps, tolerance SCOUT_TOL L (the dipole's own tip is ~1e-3 L off
#: the finite magnet's), at most SCOUT_SOLVES forward solves.  Each of its forward solves
#: costs ~1/9 of a real one (benchmarks/results/magnet_pose.md).
SCOUT_NODES = 8
SCOUT_STEPS = 3
SCOUT_TOL = 1e-5
SCOUT_SOLVES = 40
#: A predictor bends by the last corrected step's correction (scaled by the square of the
#: step's size) when the steps' directions have a cosine above this.
BEND_COS = 0.5


def _search(p: _Problem, q0, max_solves: int, sc=None):
    """Trust-region Gauss-Newton on the tip miss with the exact Jacobian, the bounds and the
    robot's reach as linear inequalities of each step (:func:`_constrained_step`), and a
    corrector after a mispredicted step, in the pose scaled by :func:`_scales` (module
    docstring).  Returns (q, result, status, solves, history)."""
    history = []

    def evaluate(q):
        if len(history) >= max_solves:
            raise _Spent
        res = p.forward(p.magnet, q)
        r = p.residual(res)
        history.append(float(np.linalg.norm(r)) * p.rod.length)
        return res, r

    def evaluate_or_none(q):
        try:
            return evaluate(q)
        except ConvergenceError:
            return None, None

    def sq(v) -> float:
        return float(v @ v)

    def feasible(q, face, reach):
        """q within the bounds and with the body off the reach -- on it if the step's face
        held the reach (the linearised constraints' round-off: a clip, and a radial move onto
        the reach's curved boundary)."""
        return p.off_reach(np.clip(q, p.lo, p.hi), onto=reach is not None and reach in face)

    sc = _scales(p, q0) if sc is None else sc
    q = q0.copy()
    res, r = evaluate(q)
    J = None  # the Jacobian at q per scaled pose unit, once needed (none at convergence)
    radius, status, crawl = RADIUS_START, "stalled", 0
    bend = None  # (step, correction) of the last corrected step, scaled pose units
    cap = RADIUS_MAX  # the radius's cap after a failed step
    try:
        while True:
            if np.linalg.norm(r) * p.rod.length <= p.tol:
                status = "converged"
                break
            if J is None:
                J = p.jacobian(res) * sc
            A, b, reach = _constraints(p, q, sc)
            # first-order optimality: the constrained Gauss-Newton step (no trust region)
            # predicts no decrease of the squared miss -- a KKT point of the miss
            best, _ = _constrained_step(J, r, np.inf, A, b)
            if sq(r) - sq(r + J @ best) <= GAIN_TOL * sq(r):
                status = "optimal"
                break
            step, face = _constrained_step(J, r, radius, A, b)
            size = float(np.linalg.norm(step))
            goal = r + J @ step  # the linearisation's miss after the step
            pred = sq(r) - sq(goal)
            if pred <= 0.0:
                break
            # predictor: the Gauss-Newton step (shortened to the radius)
            # bent by the last correction, if the step points alike: the second-order error
            # of a curved band grows with the square of the step
            bent = step
            if bend is not None:
                s_prev, c_prev = bend
                cos = float(step @ s_prev) / (size * float(np.linalg.norm(s_prev)))
                if cos > BEND_COS:
                    bent = step + c_prev * (size / float(np.linalg.norm(s_prev))) ** 2
            trial = feasible(q + bent * sc, face, reach)
            res_t, r_t = evaluate_or_none(trial)
            if res_t is not None and sq(r) - sq(r_t) >= 0.25 * pred:
                new, grow = (trial, res_t, r_t), True
                if bent is not step:
                    bend = (step, bent - step)
            elif res_t is not None:
                # corrector: one least-norm Newton step from the predictor back to the
                # linearisation's miss ``goal`` (the target moved along by the step), with the
                # Jacobian there and the constraints -- it undoes the model's second-order
                # error, which lies in the tip's stiff directions and costs little pose
                J_t = p.jacobian(res_t) * sc
                A_t, b_t, reach_t = _constraints(p, trial, sc)
                fix, face_t = _constrained_step(J_t, r_t - goal, np.inf, A_t, b_t)
                corr = feasible(trial + fix * sc, face_t, reach_t)
                res_c, r_c = evaluate_or_none(corr)
                ok = res_c is not None and sq(r) - sq(r_c) >= 0.1 * pred
                new = (corr, res_c, r_c) if ok else None
                grow = ok and sq(r) - sq(r_c) >= 0.75 * pred
                if ok:
                    bend = (step, (corr - q) / sc - step)
            else:
                new = None
            if new is None:  # no decrease: a shorter step
                cap = RADIUS_CAP * size
                radius = RADIUS_SHRINK * min(radius, size)
                if radius < 1e-10:
                    break
                continue
            gained = sq(r) - sq(new[2])
            crawl = crawl + 1 if gained < GAIN_TOL * sq(r) else 0
            q, res, r = new
            if crawl >= 3:
                break
            J = None
            if grow:
                radius = min(max(radius, 2.0 * size), cap, RADIUS_MAX)
                cap *= RADIUS_CAP_GROWTH
    except _Spent:
        status = "max_solves"
    return q, res, status, len(history), history


#: Relative decrease of the squared miss that the constrained Gauss-Newton step must predict
#: to go on (below it: a KKT point, status "optimal").
GAIN_TOL = 1e-12
#: First trust radius and largest step, in scaled pose units (:func:`_scales`): half the
#: scale on the first step (the tip's map is far from linear over the start pose's
#: distance), and the radius's factor after a step that does not decrease the miss.
RADIUS_START = 0.5
RADIUS_MAX = 5.0
RADIUS_SHRINK = 0.5
#: After a step of size s fails, the radius grows back to at most RADIUS_CAP s, the cap
#: itself growing by RADIUS_CAP_GROWTH with each step that grows the radius (without it the
#: radius doubled back to the size that failed, and failed again: up to four solves per
#: accepted step along a curved band).
RADIUS_CAP = 0.7
RADIUS_CAP_GROWTH = 1.5
#: The error message says the magnet is pressed against the robot's reach when its body is
#: within this fraction of L of it.
REACH_NEAR = 1e-6


def _at_bounds(p: _Problem, q) -> list:
    """Pose components at a bound (within 1e-9 of its span)."""
    span = np.where(np.isfinite(p.hi - p.lo), p.hi - p.lo, 1.0)
    return np.flatnonzero((q - p.lo <= 1e-9 * span) | (p.hi - q <= 1e-9 * span)).tolist()


def _constraints(p: _Problem, q, sc):
    """The constraints on a scaled step s from q as rows ``A s >= b`` (unit rows): the box
    bounds, and the robot's reach linearised (:meth:`_Problem.reach_row`); and the reach's
    row (None if its gradient vanishes)."""
    rows, rhs = [], []
    eye = np.eye(q.size)
    for k in np.flatnonzero(np.isfinite(p.lo)):
        rows.append(eye[k])
        rhs.append((p.lo[k] - q[k]) / sc[k])
    for k in np.flatnonzero(np.isfinite(p.hi)):
        rows.append(-eye[k])
        rhs.append((q[k] - p.hi[k]) / sc[k])
    g, c = p.reach_row(q, sc)
    ng = float(np.linalg.norm(g))
    reach = None
    if ng > 0.0:
        reach = len(rows)
        rows.append(g / ng)
        rhs.append(-c / ng)
    return np.array(rows).reshape(-1, q.size), np.array(rhs), reach


def _constrained_step(J, r, radius: float, A, b) -> np.ndarray:
    """argmin |r + J s| over |s| <= radius and A s >= b (unit rows; s = 0 feasible up to
    round-off), the least-norm one on its face: the smallest of the trust-region steps
    (:func:`_tr_step`) on the faces ``A_W s = b_W`` of the constraints that can bind within
    the radius that satisfy all the others -- exact for the convex subproblem (its optimum
    lies on the face of its active set), and cheap: a few constraints, 3 or 6 unknowns.
    Returns (s, face): the step and the rows held with equality."""
    n = J.shape[1]
    tol = 1e-10 * (1.0 + (radius if np.isfinite(radius) else 0.0))
    near = np.flatnonzero(-b <= (radius if np.isfinite(radius) else np.inf))  # slack <= radius
    best, best_val, face = np.zeros(n), float(r @ r), ()
    for m in range(min(n, near.size) + 1):
        for W in itertools.combinations(near.tolist(), m):
            s = _face_step(J, r, radius, A[list(W)], b[list(W)])
            if s is None or np.any(A @ s < b - tol):
                continue
            val = float((r + J @ s) @ (r + J @ s))
            if val < best_val * (1.0 - 1e-14) or (
                val <= best_val * (1.0 + 1e-14) and s @ s < best @ best
            ):
                best, best_val, face = s, val, W
    return best, face


def _face_step(J, r, radius: float, AW, bW):
    """argmin |r + J s| over |s| <= radius on the face ``AW s = bW`` (None if it misses the
    ball): s = s0 + Z y with s0 the face's least-norm point and Z its orthonormal directions."""
    n = J.shape[1]
    if AW.shape[0] == 0:
        s0, Z = np.zeros(n), np.eye(n)
    else:
        U, sv, Vt = np.linalg.svd(AW)
        if sv[-1] < 1e-9 * sv[0] or AW.shape[0] > n:
            return None  # dependent rows: a smaller face holds the same points
        s0 = Vt[: AW.shape[0]].T @ ((U.T @ bW) / sv)
        Z = Vt[AW.shape[0] :].T
    room = radius**2 - float(s0 @ s0)
    if room < 0.0:
        return None
    if Z.shape[1] == 0:
        return s0
    return s0 + Z @ _tr_step(J @ Z, r + J @ s0, math.sqrt(room))


def _tr_step(J, r, radius: float) -> np.ndarray:
    """argmin |r + J s| over |s| <= radius (the least-norm one if several): the Gauss-Newton
    step, or the Levenberg-Marquardt step whose damping puts it on the radius."""
    U, sv, Vt = np.linalg.svd(J, full_matrices=False)
    if not sv.size or sv[0] == 0.0 or radius <= 0.0:
        return np.zeros(J.shape[1])
    b = -(U.T @ r)
    keep = sv > 1e-12 * sv[0]
    U, sv, Vt, b = U[:, keep], sv[keep], Vt[keep], b[keep]

    def step(mu):
        return Vt.T @ (sv * b / (sv**2 + mu))

    s = step(0.0)
    if np.linalg.norm(s) <= radius:
        return s
    lo, hi = 0.0, float(sv[0] ** 2) * max(1.0, float(np.linalg.norm(b)) / radius / sv[0])
    while np.linalg.norm(step(hi)) > radius:
        hi *= 4.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if np.linalg.norm(step(mid)) > radius else (lo, mid)
    return step(hi)


def _scales(p: _Problem, q0) -> np.ndarray:
    """Scales of the pose components for the trust region: a tenth of the magnet's distance
    from the clamp for the centre, 0.2 rad for the turn."""
    n = 2 if p.planar else 3
    dist = float(np.linalg.norm(p.center(q0) - p.clamp))
    return np.r_[np.full(n, 0.1 * dist), np.full(q0.size - n, 0.2)]


def solve_magnet_pose(
    rod: Rod,
    magnet,
    target,
    bounds=None,
    model: str = "real",
    *,
    steps: int = 10,
    clamp_position=(0.0, 0.0, 0.0),
    clamp_angle: float = 0.0,
    nodes: int | None = None,
    tol: float | None = None,
    clearance: float = 0.0,
    max_solves: int = 40,
) -> MagnetPoseResult:
    """The pose of a permanent magnet that puts the tip of ``rod`` on ``target``.

    Parameters
    ----------
    rod : Rod
    magnet : coils.Dipole, coils.CylinderMagnet or coils.CuboidMagnet
        The magnet at its start pose (its centre and orientation); the pose found turns its
        orientation and moves its centre.  For a target (x, y) it must lie symmetric about
        the rod's plane (centre on the plane, magnetisation in it, a cuboid with an edge
        along z).
    target : array-like, shape (2,) or (3,)
        Tip position, m: (x, y) in the bending plane (planar rod; pose (c_x, c_y, psi)) or
        (x, y, z) (pose (c_x, c_y, c_z, r_x, r_y, r_z); the spatial rod where the field
        leaves the plane).
    bounds : (lower, upper), each array-like of shape (3,) or (6,), optional
        Box on the pose vector (m for the centre, absolute; rad for the turn, relative to the
        magnet's own orientation); +-inf for no bound.  The start pose must lie in it.
    model : {"real", "dipole"}
        "real": the pose is found in the finite magnet's field; "dipole": in the field of its
        point dipole (``magnet.dipole()``), and the finite magnet then placed at that pose
        (``miss`` is the dipole controller's miss).
    steps : int
        Load steps of each forward solve (the field ramped from zero).
    clamp_position, clamp_angle, nodes
        As in :func:`coilrod.solve_rod` (m, rad).
    tol : float, optional
        Position tolerance, m (default 1e-7 L).
    clearance : float
        Extra distance (m, >= 0) the magnet's body keeps beyond the robot's reach.
    max_solves : int
        Most forward solves of the search in the model's field (the scout, for a finite
        magnet, has its own budget of :data:`SCOUT_SOLVES` cheap ones).

    Returns
    -------
    MagnetPoseResult

    Raises
    ------
    ValueError
        Bad input (naming the argument): NaN, wrong shapes, bounds with lower >= upper or not
        holding the start pose, a target farther than L from the clamp, a start pose that puts
        the magnet within the robot's reach (:func:`reach_distance` <= L + clearance), a
        magnet not symmetric about the plane for a planar target.
    coilrod.ConvergenceError
        ``model="real"`` and the target not met: the message gives the closest tip, its miss
        and why the search stopped ("optimal": the closest pose within the bounds and off the
        reach); ``err.result`` is the MagnetPoseResult there.

    Notes
    -----
    The pose vector, the exact pose derivatives and the search are in the module docstring
    (:mod:`coilrod.control.magnet_pose`).  A typical solve takes 3-5 forward solves after a
    scout of 3-30 cheap ones (``scout_solves``).  A target
    no pose within the bounds and off the robot's reach meets ends at the constrained optimum
    (status "optimal"), the magnet's body on the reach's boundary (``reach_gap`` 0) and/or pose
    components at their bounds (``active``).

    Examples
    --------
    >>> import numpy as np
    >>> import coils
    >>> from coilrod import presets, solve_magnet_pose, solve_rod
    >>> rod = presets.seed_rod(presets.M1())
    >>> magnet = coils.CylinderMagnet(20e-3, 20e-3, 1e6, center=(0.0, -0.06, 0.0), axis="y")
    >>> axis = (-np.sin(0.2), np.cos(0.2), 0.0)  # a known pose makes a reachable target
    >>> known = coils.CylinderMagnet(20e-3, 20e-3, 1e6, (0.01, -0.058, 0.0), axis)
    >>> coarse = dict(nodes=8)  # a quick example; the default discretisation works alike
    >>> target = solve_rod(rod, known, np.arange(1, 11) / 10, **coarse).tip[-1, :2]
    >>> out = solve_magnet_pose(rod, magnet, target, **coarse)
    >>> bool(out.miss < 1e-6 * rod.length)
    True
    """
    p, q0 = _problem(
        rod, magnet, target, bounds, model, steps, clamp_position, clamp_angle, nodes, tol,
        clearance,
    )  # fmt: skip
    max_solves = as_count(max_solves, "max_solves", 1, 10_000)
    q_start, scouted = _scout(p, q0)
    try:
        try:
            q, res, status, solves, history = _search(p, q_start, max_solves, _scales(p, q0))
        except ConvergenceError:
            if q_start is q0:
                raise
            # the real forward solve fails at the scout's pose: search from the given one
            q, res, status, solves, history = _search(p, q0, max_solves)
    except ConvergenceError as err:
        raise ConvergenceError(
            f"solve_magnet_pose: the forward solve at the start pose failed ({err})",
            reached=err.reached,
            target=err.target,
        ) from err
    if model == "dipole":
        res = p.forward(p.real, q)
    tip = res.tip[-1]
    miss = float(np.linalg.norm(tip[: p.target.size] - p.target))
    active = _at_bounds(p, q)
    out = MagnetPoseResult(
        pose=q.copy(),
        position=p.center(q),
        orientation=p.turn(q) @ _orientation(magnet),
        magnet=p.place(p.real, q),
        tip=tip.copy(),
        miss=miss,
        target=p.target.copy(),
        result=res,
        model=model,
        solves=solves,
        scout_solves=scouted,
        history=history,
        status=status,
        active=active,
        reach_gap=p.clear(q),
    )
    if model == "real" and status != "converged":
        why = {
            "optimal": "status 'optimal': the closest pose within the bounds and off the "
            "robot's reach",
            "max_solves": "status 'max_solves': the solve budget max_solves spent",
            "stalled": "status 'stalled': the steps stopped decreasing the miss",
        }[status]
        names = ["c_x", "c_y", "psi"] if p.planar else ["c_x", "c_y", "c_z", "r_x", "r_y", "r_z"]
        near = out.reach_gap <= REACH_NEAR * p.rod.length
        err = ConvergenceError(
            f"solve_magnet_pose: the target {p.target.tolist()} m is not reached ({why}"
            + (
                f"; pressed against the robot's reach: the magnet's body {out.reach_gap:.3g} m "
                "off it"
                if near
                else ""
            )
            + (
                f"; pose components {active} ({', '.join(names[k] for k in active)}) at "
                "their bounds"
                if active
                else ""
            )
            + f"); the closest tip is {tip[: p.target.size].tolist()} m, {miss:.4g} m "
            f"({miss / p.rod.length:.3g} L) away, at pose {np.round(q, 6).tolist()}",
            reached=0.0,
            target=1.0,
            residual=miss,
        )
        err.result = out
        raise err
    return out
