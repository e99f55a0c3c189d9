"""Quasi-static insertion of a rod into a vessel: the clamp (an introducer at the vessel's
entry) feeds material, the free length grows, and the field is set per insertion step."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np

from coils._validate import as_array
from coils.field import Field

from ..errors import ConvergenceError
from ..path.corrector import NewtonOptions, newton
from ..path.stepping import touchdown_secant
from ..robot.rod import Rod
from ..rod.contact_predictor import active_set_start
from ._parts import StepProblems, free_part

__all__ = ["insert", "Insertion", "free_part"]

#: Largest number of halvings of an insertion step before the insertion stops.
MAX_HALVINGS = 12
#: The largest turn of a node (rad) from an insertion step's carried start
#: to its solution before the step is halved (:func:`_step`), and the halvings of an
#: insertion step after which a larger turn is accepted (a snap).
MAX_STEP_TURN = 1.0
MAX_JUMP_HALVINGS = 5
#: With friction, a sub-step in which a point first touches is cut toward the touch
#: (:func:`_touchdown_force`) while it is longer than this fraction of the insertion step.
TOUCHDOWN_MIN_STEP = 1e-6


@dataclasses.dataclass
class Insertion:
    """Shapes and wall forces along an insertion (:func:`insert`).

    Attributes
    ----------
    lengths : ndarray, shape (m,)
        Free length of each step, m.
    tip : ndarray, shape (m, 3)
        Tip positions, m.
    wall_force : ndarray, shape (m, 3)
        Total force the rod exerts on the vessel wall, N, in world axes (the normal forces
        and, with friction, the friction forces: on the wall they point the way the rod
        slides): a vector per step, so ``wall_force.max()`` is its largest *component*; the
        size of the force is :attr:`wall_force_magnitude` (``wall_force_magnitude.max()``:
        the largest total wall force along the insertion).
    max_contact_force : ndarray, shape (m,)
        Largest size of the contact force per unit length along the rod (normal force plus
        friction), N/m.
    contact_nodes : list of ndarray of bool
        Contact points in contact with the wall, per step (n_k,): the corners of the rod's
        polygon half a segment after each node, and the tip (:meth:`contact_points`).
    min_gap : ndarray, shape (m,)
        Smallest gap of a contact point to the wall, m (>= -1e-6 L: no penetration).
    stable : ndarray of bool, shape (m,)
        Positive second variation (active contacts as constraints).
    substeps : ndarray of int, shape (m,)
        Newton solves each step took (1 without step cutting).
    push_force : ndarray, shape (m,)
        The push force at the introducer, N: the axial component of the force the clamp
        exerts on the rod, ``-F_0 . t_0`` (F_0 the force the free part exerts on the clamp,
        t_0 the introducer's axis, pointing into the vessel); > 0 pushes the rod in, < 0
        pulls it back.  It balances the axial part of the wall's and the field's forces on
        the free part (a tip sliding on a flat wall parallel to the axis in a uniform field:
        ``+mu N`` on the way in, ``-mu N`` on the way out).  With friction the force depends
        on the direction of the motion: insertion then withdrawal through the same lengths
        draws a hysteresis loop; frictionless the two are one curve (the same states).
    """

    lengths: np.ndarray
    tip: np.ndarray
    wall_force: np.ndarray
    max_contact_force: np.ndarray
    contact_nodes: list
    min_gap: np.ndarray
    stable: np.ndarray
    substeps: np.ndarray
    push_force: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    _s: list = dataclasses.field(repr=False, default_factory=list)
    _shapes: list = dataclasses.field(repr=False, default_factory=list)
    _frames: list = dataclasses.field(repr=False, default_factory=list)
    _forces: list = dataclasses.field(repr=False, default_factory=list)
    vessel: object = dataclasses.field(repr=False, default=None)
    _points: list = dataclasses.field(repr=False, default_factory=list)
    _axial: list = dataclasses.field(repr=False, default_factory=list)
    _half_width: float = dataclasses.field(repr=False, default=0.0)

    def __len__(self) -> int:
        return len(self.lengths)

    @property
    def wall_force_magnitude(self) -> np.ndarray:
        """Size of the total force on the vessel wall per step, ``|wall_force|``, shape (m,),
        N."""
        return np.linalg.norm(self.wall_force, axis=1)

    def contact_points(self, k: int) -> np.ndarray:
        """Contact points of step ``k``, (n_k, 3), m: the corners of the rod's polygon (node
        j's straight piece along its tangent ends at ``x_j + (h_j/2) t_j``) and the tip.
        They are what the contact keeps inside the wall; on a concave wall the nodes
        between them may cross it by the piece's sagitta ``h^2 / (8 R)``."""
        return self._points[k].copy()

    def centerline(self, k: int) -> np.ndarray:
        """Centreline of step ``k``, shape (n_k, 3), m."""
        return self._shapes[k].copy()

    def frames(self, k: int) -> np.ndarray:
        """Frames of step ``k``, shape (n_k, 3, 3) (columns tangent, normal, binormal)."""
        return self._frames[k].copy()

    def contact_force(self, k: int) -> np.ndarray:
        """Contact force per unit length on the rod at the contact points of step ``k``
        (:meth:`contact_points`), (n_k, 3), N/m, in world axes: the wall's normal force
        plus, with friction, the friction force (on the rod: against its sliding)."""
        return self._forces[k].copy()

    def axial_force(self, k: int) -> np.ndarray:
        """Axial internal force of the segments of step ``k``, (n_k - 1,), N: ``F_j . t``
        with F_j the force the part beyond segment j exerts on the part before it and t
        the segment's chord direction; > 0 tension, < 0 compression.  Segment 0's is minus
        :attr:`push_force`'s axial force at the clamp up to the first segment's turning."""
        return self._axial[k].copy()

    def s(self, k: int) -> np.ndarray:
        """Arc length of the nodes of step ``k`` from the clamp, (n_k,), m."""
        return self._s[k].copy()

    def plot(self, steps=None, ax=None, force_range=(0.1, 0.4)):
        """Shapes of ``steps`` (default: about eight) in the x-y plane over the vessel (mm):
        the centreline and the rod's width in the plane (its surface is what touches),
        contact points in contact marked, and the total wall force per step (mN, log scale) against
        the clinical range ``force_range`` (N) in a second panel.  Returns the figure."""
        import matplotlib.pyplot as plt
        from matplotlib.ticker import FuncFormatter

        m = len(self)
        if steps is None:
            steps = np.unique(np.linspace(0, m - 1, min(8, m)).astype(int))
        else:
            raw = steps
            steps = np.atleast_1d(np.asarray(steps))
            if steps.ndim != 1 or not np.issubdtype(steps.dtype, np.integer):
                raise ValueError(f"steps must be step indices (integers); got {raw!r}")
            if np.any((steps < -m) | (steps >= m)):
                raise ValueError(f"steps must be step indices in [0, {m}); got {raw!r}")
            steps = steps % m
        try:
            lo, hi = (float(v) for v in force_range)
        except (TypeError, ValueError):
            lo = hi = np.nan
        if not 0 < lo < hi < np.inf:
            raise ValueError(f"force_range must be (low, high) N with 0 < low < high; got "
                             f"{force_range!r}")  # fmt: skip
        if ax is None:  # constrained layout: a suptitle added later keeps its own row
            fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), layout="constrained")
        else:
            axes = ax
            fig = axes[0].figure
        if self.vessel is not None and hasattr(self.vessel, "plot"):
            self.vessel.plot(ax=axes[0], color="0.6")
        cmap = plt.get_cmap("viridis")
        for i, k in enumerate(steps):
            x = self._shapes[k]
            color = cmap(i / max(len(steps) - 1, 1))
            label = f"{self.lengths[k] * 1e3:.0f} mm"
            # shorter shapes on top: follow-the-leader shapes share their proximal part, and
            # a short one drawn first would vanish under the longer ones
            axes[0].plot(x[:, 0], x[:, 1], color=color, lw=1.0, label=label, zorder=3 - i / 100)
            if self._half_width > 0:  # the rod's width in the plane: its surface meets walls
                t = self._frames[k][:, 0:2, 0]
                perp = np.c_[-t[:, 1], t[:, 0]] / np.linalg.norm(t, axis=1)[:, None]
                edge = self._half_width * perp
                outline = np.concatenate([x[:, 0:2] + edge, (x[:, 0:2] - edge)[::-1]])
                axes[0].fill(outline[:, 0], outline[:, 1], color=color, alpha=0.3, lw=0,
                             zorder=3 - i / 100)  # fmt: skip
            on = self.contact_nodes[k]
            p = self._points[k] if self._points else x
            axes[0].plot(p[on, 0], p[on, 1], "o", color="crimson", ms=3)
        mm = FuncFormatter(lambda v, _pos: f"{v * 1e3:g}")
        axes[0].xaxis.set_major_formatter(mm)
        axes[0].yaxis.set_major_formatter(mm)
        axes[0].set_aspect("equal")
        axes[0].set_xlabel("x (mm)")
        axes[0].set_ylabel("y (mm)")
        axes[0].legend(fontsize=7, title="free length")
        force = np.linalg.norm(self.wall_force, axis=1) * 1e3
        # a step without contact has no force: nothing to draw on a log axis (a floor value
        # would draw a force that is not there); such steps are marked on the axis instead
        touching = force > 0
        shown = np.where(touching, force, np.nan)
        axes[1].semilogy(self.lengths * 1e3, shown, "-o", ms=3, label="wall force")
        axes[1].axhspan(force_range[0] * 1e3, force_range[1] * 1e3, color="0.9",
                        label="clinical range")  # fmt: skip
        if not touching.all():
            axes[1].plot(self.lengths[~touching] * 1e3, np.full((~touching).sum(), 0.0), "|",
                         color="0.4", ms=8, transform=axes[1].get_xaxis_transform(),
                         label="no contact")  # fmt: skip
        axes[1].set_xlabel("free length (mm)")
        axes[1].set_ylabel("wall force (mN)")
        axes[1].legend()
        return fig


def _fields(field_schedule, m: int) -> Callable[[int, float], Field]:
    if isinstance(field_schedule, Field):
        return lambda k, length: field_schedule
    if callable(field_schedule):

        def call(k, length):
            out = field_schedule(k, length)
            if not isinstance(out, Field):
                raise ValueError(
                    f"field_schedule({k}, {length:g}) must return a coils.Field; got "
                    f"{type(out).__name__}"
                )
            return out

        return call
    if isinstance(field_schedule, Sequence):
        if len(field_schedule) != m:
            raise ValueError(
                f"field_schedule holds {len(field_schedule)} fields for {m} insertion steps"
            )
        for i, f in enumerate(field_schedule):
            if not isinstance(f, Field):
                raise ValueError(f"field_schedule[{i}] must be a coils.Field; got {f!r}")
        return lambda k, length: field_schedule[k]
    raise ValueError(
        "field_schedule must be a coils.Field, a list of fields (one per step) or a callable "
        f"(step, free length) -> Field; got {type(field_schedule).__name__}"
    )


def _default_clamp(vessel):
    """The introducer's pose: the entry of the vessel (of a network's first vessel), tangent
    along its centreline; the normal completes a right-handed frame with the binormal as
    close to +z as the tangent allows."""
    first = vessel.vessels[0] if hasattr(vessel, "vessels") else vessel
    if hasattr(first, "position") and hasattr(first, "tangent"):
        p0 = np.asarray(first.position(0.0), float).reshape(3)
        t = np.asarray(first.tangent(0.0), float).reshape(3)
    else:
        pts = np.asarray(getattr(first, "points", None), float)
        if pts.ndim != 2 or pts.shape[0] < 2:
            raise ValueError(
                "give clamp_position and clamp_rotation: the obstacle has no centreline"
            )
        p0, t = pts[0].copy(), pts[1] - pts[0]
    from .presets import _frame

    t = t / np.linalg.norm(t)
    ref = np.array([0.0, 0.0, 1.0]) if abs(t[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    t, b, n = _frame(t, ref)  # the binormal is ref made perpendicular, n = b x t
    return p0, np.column_stack([t, n, b])


def _carry(prev_problem, prev_u, problem):
    """A start for ``problem`` (a longer or shorter free length) from a solved state of
    ``prev_problem``: rotations and contact forces per length follow the arc length from
    the clamp (follow-the-leader), extended along the old tip beyond its length."""
    s_old = prev_problem.mesh.s * prev_problem.L
    s_new = problem.mesh.s * problem.L
    V = prev_u.reshape(prev_problem.n, prev_problem.nv)
    phi = np.stack([np.interp(s_new, s_old, V[:, 3 + i]) for i in range(3)], axis=1)
    # (the positions from the rotations; every force below is carried, none from the field)
    u = problem.from_rotations(phi).reshape(problem.n, problem.nv)
    # internal forces of the segments (at their start nodes, EI / L^2 units) and contact
    # forces per length (EI / L^3): the same forces in N in the new length's units
    ratio = problem.L / prev_problem.L
    for i in range(3):
        u[:, 6 + i] = np.interp(s_new, s_old, V[:, 6 + i], right=0.0) * ratio**2
    u[-1, 6:9] = 0.0
    for o in range(problem.nc + problem.nt):  # normal and friction forces per length
        u[:, 9 + o] = np.interp(s_new, s_old, V[:, 9 + o], right=0.0) * ratio**3
    # the tip's contact point follows the tip (beyond the old length the interpolation
    # would drop its force, and a shorter rod's tip would take an inner corner's)
    u[-1, 9 : 9 + problem.nc + problem.nt] = V[-1, 9 : 9 + problem.nc + problem.nt] * ratio**3
    return u.ravel()


def _carry_reference(prev_problem, prev_u, problem) -> np.ndarray | None:
    """Give ``problem`` (a free length grown or shortened by d) the friction reference of
    the solved ``prev_problem``: the material point at arc length s from the clamp was at
    s - d, so each new contact point's reference is where that material point was (on the
    old polygon, exact by linear interpolation between its corners; inside the introducer,
    on its axis behind the clamp).

    Returns the normal force per length (EI / L^3 units of ``problem``) each new contact
    point's material point carried there, (n, nc) (interpolated alike; 0 behind the clamp):
    a point at 0 was not in contact (:func:`_touchdown_force`).  None without friction."""
    if not problem.nt:
        return None
    c_old, _ = prev_problem._contact_geometry()
    c_new, _ = problem._contact_geometry()
    s_old = np.concatenate([[0.0], (prev_problem.mesh.s + c_old) * prev_problem.L])
    pts = np.concatenate([np.zeros((1, 3)), prev_problem.contact_points(prev_u[None])[0]])
    pts = pts * prev_problem.L  # m, relative to the clamp
    s_new = (problem.mesh.s + c_new) * problem.L - (problem.L - prev_problem.L)
    ref = np.stack([np.interp(s_new, s_old, pts[:, i]) for i in range(3)], axis=1)
    behind = s_new < 0.0
    ref[behind] = s_new[behind, None] * problem.R0[:, 0]
    # the friction forces per length of the material points (N/m alike: EI / L^3 units)
    tau = prev_problem.friction_forces(prev_u[None])[0].reshape(prev_problem.n, -1)
    tau = np.concatenate([np.zeros((1, tau.shape[1])), tau]) * (problem.L / prev_problem.L) ** 3
    tau = np.stack([np.interp(s_new, s_old, tau[:, i], left=0.0) for i in range(tau.shape[1])], 1)
    problem.set_reference(ref / problem.L, tau)
    V = prev_u.reshape(prev_problem.n, prev_problem.nv)
    lam = np.concatenate([np.zeros((1, problem.nc)), V[:, 9 : 9 + prev_problem.nc]])
    lam = np.maximum(lam, 0.0) * (problem.L / prev_problem.L) ** 3
    return np.stack([np.interp(s_new, s_old, lam[:, i], left=0.0) for i in range(problem.nc)], 1)


def _touchdown_force(problem, u, lam_ref, carried, feed: float = 0.0) -> float:
    """Largest normal force per length (EI / L^3) in the solved ``u`` (size,) of
    ``problem`` at the contact points on rough obstacles that touch in the step (0 if none
    does, or without friction): neither their material point (``lam_ref`` (n, nc),
    :func:`_carry_reference`) nor their place along the rod (the carried start ``carried``
    (size,), :func:`_carry`) carried a normal force in the last accepted state, and their
    motion since then is not the insertion's feed ``feed`` (m, the step's change of the
    free length) along the rod, to half of it.

    Their slip is measured from where their material point was before the step, so the
    tangential part of their approach counts as slip, and a point that should stick where it
    touches lands on the cone with a friction force set by how far past the touch the step
    went (:meth:`~coilrod.rod.spatial.SpatialRod.touchdown_force`): :func:`_step` cuts the
    step until they carry at most the problem's ``touchdown_tol``.  A point the feed carries
    along the wall -- material fed into a contact zone, a tip fed along it -- moved before
    and after it touched the way the feed goes, so it slips that way either way (its friction
    force is the same full slip; in 3D up to the direction of the approach): no cut."""
    if lam_ref is None:
        return 0.0
    n, nv, nc = problem.n, problem.nv, problem.nc
    lam = u.reshape(n, nv)[:, 9 : 9 + nc]
    was = carried.reshape(n, nv)[:, 9 : 9 + nc]
    new = (lam_ref <= 0.0) & (was <= 0.0) & (lam > 0.0) & (problem.mu_f > 0.0)
    new[0] = False  # (the clamp's point carries no contact)
    if new.any() and feed != 0.0:
        frames = problem.frames(u[None])
        moved = problem.contact_points(u[None], frames)[0] - problem._p_ref  # units of L
        off = np.linalg.norm(moved - (feed / problem.L) * frames[0, :, :, 0], axis=1)
        new &= (off > 0.5 * abs(feed) / problem.L)[:, None]
    return float(lam[new].max()) if new.any() else 0.0


def insert(
    rod: Rod,
    vessel,
    lengths,
    field_schedule,
    *,
    clamp_position=None,
    clamp_rotation=None,
    nodes: int = 64,
    tol: float = 1e-9,
    progress: bool = False,
) -> Insertion:
    """Quasi-static insertion of ``rod`` into ``vessel``.

    The clamp is an introducer at the vessel's entry; at step k the distal ``lengths[k]`` of
    the rod are out of it (:func:`free_part`) and the field is ``field_schedule`` of step k.
    Each step starts from the previous shape (follow-the-leader: the rotations and contact
    forces as functions of the arc length from the clamp, extended along the old tip),
    frictionless moved on to the solution of its linearised complementarity problem
    (:func:`~coilrod.rod.contact_predictor.active_set_start`: the contact set where the
    tip slides on a curved wall or a point contact passes from one corner to the next,
    placed at once), else (friction, or no consistent contact set) from the third step on
    the secant through the last two such shapes; it is solved by the
    contact Newton method of the spatial rod (:class:`~coilrod.rod.spatial.SpatialRod`;
    contact at the corners of the rod's polygon and its tip, Coulomb friction if the
    vessel's ``friction`` is > 0, stick or slip decided on each material point's motion
    since the previous step); a step that fails is split in halves (free length and field
    blended linearly), up to :data:`MAX_HALVINGS` times -- also a step that turns a node
    more than :data:`MAX_STEP_TURN` from its start (Newton jumped to another branch; with
    friction the state depends on the path), up to :data:`MAX_JUMP_HALVINGS` times.  With
    friction, a step (or part of one) in which a point first touches the wall, other than
    one the feed carries along it, is cut toward the touch until that point carries at most
    ``SpatialRod.touchdown_tol`` (its slip is then measured from where it touched: the
    answer does not move with the number of steps), and a failed try is repeated from the
    frictionless prediction.  The first step is loaded from the straight rod by
    :func:`~coilrod.solve_rod`.

    Parameters
    ----------
    rod : Rod
        The whole device; its distal part leaves the introducer.
    vessel : Vessel or obstacle
        The lumen (any obstacle with the gap interface; :class:`coilrod.Vessel`).
    lengths : array-like, shape (m,)
        Free lengths, m, each in (0, rod.length].
    field_schedule : coils.Field, sequence of m fields, or callable (k, length) -> Field
        The applied field at each step.
    clamp_position, clamp_rotation : optional
        The introducer's pose (default: the vessel's first centreline point, tangent along
        its first segment).
    nodes : int
        Segments of each step's mesh (one mesh, second order in the segment length).
    tol : float
        Newton tolerance (as :func:`~coilrod.solve_rod`).
    progress : bool
        Show a tqdm progress bar.

    Returns
    -------
    Insertion

    Raises
    ------
    ValueError
        Bad input, or an introducer pose outside the vessel.
    coilrod.ConvergenceError
        A step could not be reached even after :data:`MAX_HALVINGS` halvings; ``result`` holds
        the :class:`Insertion` up to the last step reached.
    """
    lengths = as_array(lengths, "lengths", ("m",))
    if lengths.size == 0 or not np.all(np.isfinite(lengths)):
        raise ValueError(f"lengths must be a non-empty sequence of finite lengths; got {lengths}")
    if np.any(lengths <= 0) or np.any(lengths > rod.length * (1 + 1e-12)):
        raise ValueError(f"lengths must lie in (0, {rod.length:g}] m (the rod's length)")
    schedule = _fields(field_schedule, lengths.size)
    clamp, R0 = _introducer(vessel, clamp_position, clamp_rotation)
    sec = rod.section  # the surface: a circle's radius, a rectangle's smaller half-side
    half = sec.diameter / 2 if hasattr(sec, "diameter") else min(sec.width, sec.thickness) / 2
    given = clamp_position is not None or clamp_rotation is not None
    _check_straight_start(vessel, clamp, R0, float(lengths[0]), float(half), given)
    rec = _Record(lengths, vessel, rod.bending_stiffness)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=lengths.size, desc="insert", unit="step")
    try:
        # step 0: load the straight free part from zero field
        field0 = schedule(0, float(lengths[0]))
        free0 = free_part(rod, float(lengths[0]))
        problem, u, stable = _first_step(free0, field0, nodes, clamp, R0, vessel, tol)
        rec.add(problem, u, stable, 1)
        if bar is not None:
            bar.update(1)
        prev = (float(lengths[0]), field0)
        # one stability count per step to come (of the free nodes' blocks): compile the
        # count at once if renting the numpy one to the end would cost more (the counts are
        # the same either way)
        from ..rod._inertia import expect_counts

        expect_counts(lengths.size - 1, problem.n - 1, problem.nv)
        layout, band_cache = (problem.size, problem.nc), problem._band_cache
        # each step's problem from the device's constants taken once (the problems of
        # free_part, make_mesh and build_spatial_problem, bitwise)
        problems = StepProblems(rod, nodes, clamp, R0, tol, [vessel])
        before = None  # the solved step before the previous one: (problem, state, length)
        for k in range(1, lengths.size):
            target = (float(lengths[k]), schedule(k, float(lengths[k])))

            def build(length, field):
                trial = problems(length, field)
                # a plain Newton from the carried (penetrating) shape: Fischer-Burmeister is
                # the more robust complementarity function there.  The min function takes
                # fewer iterations (218 against 330 for the 50 steps of bench_contact.py) but
                # cycles between contact sets, and in the navigation notebook's branch it
                # steered the tip into the main vessel instead of the branch; with friction a
                # held step's carried state sits on the stick-slip kink, which FB keeps exactly
                trial.ncp = "fb"
                if (trial.size, trial.nc) == layout:
                    trial._band_cache = band_cache  # the same layout's templates
                return trial

            last = (problem, u, prev[0])
            problem, u, stable, solves = _step(
                build, problem, u, prev, target, k, before, section=rod.section
            )
            rec.add(problem, u, stable, solves)
            before, prev = last, target
            if bar is not None:
                bar.update(1)
    except ConvergenceError as err:
        err.result = rec.result() if rec.out["tip"] else None
        raise
    finally:
        if bar is not None:
            bar.close()
    return rec.result()


def _introducer(vessel, clamp_position, clamp_rotation):
    """The introducer's pose (clamp (3,) m, rotation (3, 3)), checked inside the vessel."""
    from ..rod.model import as_rotation

    if clamp_position is None or clamp_rotation is None:
        p0, R0 = _default_clamp(vessel)
        clamp = p0 if clamp_position is None else as_array(clamp_position, "clamp_position", (3,))
        R0 = R0 if clamp_rotation is None else as_rotation(clamp_rotation)
    else:
        clamp = as_array(clamp_position, "clamp_position", (3,))
        R0 = as_rotation(clamp_rotation)
    check = getattr(vessel, "check_start", None)
    if callable(check):
        check(clamp[None], "the clamp (introducer)")
    return clamp, R0


def _check_straight_start(vessel, clamp, R0, length: float, half: float, given: bool) -> None:
    """ValueError naming ``lengths[0]`` if the first free part, straight out of the
    introducer, leaves the vessel or its surface (``half`` m from its axis) reaches into the
    wall: the insertion's first step starts from it (solve_rod's own check named neither the
    length nor the way out)."""
    gap_of = getattr(vessel, "gap", None)
    if not callable(gap_of):
        return
    s = np.linspace(0.0, length, 65)
    gap = np.asarray(gap_of(clamp + np.outer(s, R0[:, 0])), float)
    bad = np.flatnonzero(~(gap >= -1e-12 * length))
    what = "it leaves the vessel"
    if not bad.size:
        bad = np.flatnonzero(~(gap - half >= -1e-12 * length))
        if bad.size and bad[0] == 0:  # no room at the clamp: solve_rod says why (too thick)
            return
        what = f"its surface ({1e3 * half:.4g} mm from its axis) reaches into the wall"
        gap = gap - half
    if bad.size:
        k = int(bad[0])
        turn = " or turn clamp_rotation along the vessel" if given else ""
        raise ValueError(
            f"lengths[0] = {1e3 * length:.4g} mm: the first free part starts straight out of "
            f"the introducer, and straight {what} {1e3 * s[k]:.4g} mm from the clamp (by "
            f"{1e3 * -gap[bad].min():.3g} mm at most); start with a shorter first length{turn}"
        )


def _first_step(free, field, nodes, clamp, R0, vessel, tol):
    """The first free part loaded from the straight rod by solve_rod: (problem, state,
    stable)."""
    from ..rod.solve import solve_rod

    try:
        first = solve_rod(
            free, field, [1.0], nodes=nodes, richardson=False, clamp_position=clamp,
            clamp_rotation=R0, obstacles=[vessel], tol=tol, model="spatial",
        )  # fmt: skip
    except ConvergenceError as err:
        err.result = None
        raise
    return first._solution.problems[0], first._solution.states[0][0], bool(first.stable[0])


def _step(build, problem, u, prev, target, k, before=None, section=None):
    """One insertion step from the solved (problem, u) at (length, field) ``prev`` to
    ``target``, halving the step on failure: (problem, state, stable, solves).

    Frictionless, each try starts first from the solution of the linearised
    complementarity problem at the carried state
    (:func:`~coilrod.rod.contact_predictor.active_set_start`).  ``before`` (problem,
    state, length) is the step solved before ``prev``: the (next) try then starts from the
    secant through the two states (each carried to the new length, extrapolated linearly in
    the free length); a halved step starts from the carried state alone.

    With friction, a try that failed is repeated from the frictionless twin's prediction
    (:func:`_frictionless_start`; first for the rest of the step once it converged there),
    and a part of the step in which a point first touches
    (:func:`_touchdown_force`) is cut toward the touch -- a secant on that point's normal
    force (:func:`~coilrod.path.stepping.touchdown_secant`), not counted as a halving --
    until it ends where the point touches (to ``touchdown_tol``); the step then resumes its
    length."""
    # semi-smooth Newton: the error may stall for a few iterations while the contact set
    # settles (then it converges quadratically)
    opts = NewtonOptions(max_iter=40, stagnation=12)
    (prev_len, prev_field), (target_len, target_field) = prev, target
    # a reversal with friction (insertion after withdrawal or back): the first try starts
    # from the carried state with its friction turned round (_reverse_friction), the usual
    # start (the secant, which heads back to the old state) second.  Frictionless, the
    # secant is right (the states do not depend on the direction)
    reversal = bool(problem.nt) and before is not None
    reversal = reversal and (target_len - prev_len) * (prev_len - before[2]) < 0
    t, dt, solves, halvings = 0.0, 1.0, 0, 0
    cur_problem, cur_u, cur_lin = problem, u, None
    touch = None  # (t, force) of the last trial cut for touching too hard (friction)
    twin_first = False  # (friction: try the frictionless prediction before the carried start)
    resume = None  # the sub-step before such cuts (resumed once the points touched)
    while t < 1.0:
        t1 = min(1.0, t + dt)
        length = prev_len + t1 * (target_len - prev_len)
        field = target_field if t1 == 1.0 else prev_field * (1 - t1) + target_field * t1
        trial = build(length, field)
        lam_ref = _carry_reference(cur_problem, cur_u, trial)
        start = carried = _carry(cur_problem, cur_u, trial)
        starts = [_reverse_friction(trial, start)] if reversal and t == 0.0 else []
        # frictionless contact: first the solution of the linearised complementarity
        # problem at the carried shape (its contact set found by an active-set iteration);
        # then (friction, no consistent contact set, or Newton failed from there) the
        # carried shape, from the third step on the secant through the last two
        # (friction, last: the frictionless prediction with the carried friction forces)
        predicted = active_set_start(trial, start)
        tries = starts if predicted is None else [*starts, predicted]
        # (once it converged where the carried start failed -- a landing -- it goes first for
        # the rest of the step: the cuts toward the touch land again)
        last = [_frictionless_start] if trial.nt and section is not None else []
        for guess in [*tries, *last, None] if twin_first else [*tries, None, *last]:
            twin = guess is _frictionless_start
            if guess is None:
                guess = start
                if before is not None and t == 0.0 and t1 == 1.0 and before[2] != prev_len:
                    w = (target_len - prev_len) / (prev_len - before[2])
                    guess = start + w * (start - _carry(before[0], before[1], trial))
            elif twin:
                guess = _frictionless_start(trial, start, section)
                if guess is None:
                    continue
            res = newton(trial, guess, 1.0, opts)
            solves += 1
            if res.ok:
                twin_first = twin_first or twin
                break
        why = _reason(trial)
        if res.ok and dt > 2.0**-MAX_JUMP_HALVINGS:
            # a step whose solution turned a node further than MAX_STEP_TURN from the
            # carried start has not followed the path (at a coarse step Newton jumps onto a
            # folded branch of a floppy rod pushed round a bend, from which later steps
            # fail, with or without friction; with friction the state depends on the path
            # too); halve it.  At the smallest such step the jump is accepted (a snap)
            turn = float(trial.distance(res.u - carried)[0])
            if turn > MAX_STEP_TURN:
                res.ok, why = False, f"; a node turned {turn:.3g} rad in the step"
        force = 0.0
        if res.ok and lam_ref is not None:
            feed = length - (prev_len + t * (target_len - prev_len))
            force = _touchdown_force(trial, res.u, lam_ref, carried, feed)
        if force > trial.touchdown_tol and t1 - t > TOUCHDOWN_MIN_STEP:
            # friction: end the sub-step where the new contact points touch, so that their
            # slip is measured from there (not a halving: the trial converged)
            resume = dt if resume is None else resume
            dt = touchdown_secant(t, t1 - t, t1, force, touch, trial.touchdown_tol)
            touch = (t1, force)
            continue
        if res.ok:  # (its linearization carries the state's stability)
            taken = t1 - t
            t, cur_problem, cur_u, cur_lin = t1, trial, res.u, res.lin
            if force > 0.0 and resume is not None:
                # touched: back toward the sub-step before the cuts (at most 64 times the
                # landing one: a trial far past the next touch may not converge)
                dt, touch, resume = min(resume, 64.0 * taken), None, None
            elif touch is not None:  # short of the touch aimed at: the same sub-step again
                dt = taken
            else:
                dt = 2 * dt
            dt = min(1.0 - t, dt) if t < 1.0 else dt
            continue
        halvings += 1
        if halvings > MAX_HALVINGS:
            raise ConvergenceError(
                f"insert could not reach free length {target_len:.6g} m (step {k}): it "
                f"stopped at {prev_len + t * (target_len - prev_len):.6g} m, {t:.3g} of the "
                f"way from step {k - 1} in length and field, after {MAX_HALVINGS} halvings "
                f"(error {float(res.error):.3g} of the tolerance){why}",
                reached=prev_len + t * (target_len - prev_len),
                target=target_len,
                residual=float(res.error),
            )
        dt /= 2
    stable = np.ravel(cur_problem.stability(cur_lin))[0] > 0
    return cur_problem, cur_u, bool(stable), solves


def _frictionless_start(problem, u, section):
    """A start for the friction ``problem`` from its carried start ``u`` (size,): the
    frictionless twin's linearised complementarity solution
    (:func:`~coilrod.rod.contact_predictor.active_set_start`, which a problem with friction
    rows does not have) with the carried friction forces; None where it has none.  A point
    landing on the wall from a carried start without contact: plain Newton often fails there
    (a rising field at a held length: from the carried start every step with a new contact
    failed, frictionless without the prediction as well), and with friction each such step
    was halved until the halvings ran out."""
    from ..rod.spatial import SpatialRod

    twin = SpatialRod(
        problem.mesh, problem.mu, problem.K, problem.field, problem.L, problem.clamp,
        problem.R0, problem.tol, False, problem.obstacles, section=section, friction_rows=False,
    )  # fmt: skip
    twin.ncp = problem.ncp
    V = u.reshape(problem.n, problem.nv)
    predicted = active_set_start(twin, np.ascontiguousarray(V[:, : twin.nv]).ravel())
    if predicted is None:
        return None
    out = V.copy()
    out[:, : twin.nv] = predicted.reshape(twin.n, twin.nv)
    return out.ravel()


def _reverse_friction(problem, u):
    """The start ``u`` (size,) with its friction forces turned round.  At a reversal of the
    motion the carried state's friction opposes the old motion, and every carried material
    point has moved the new way (from its reference) by the step: under a high tension
    (EI / (T R^2) ~ 3e-4) Newton from there makes every point stick, which an inextensible
    rod taut between its contacts cannot take up (a straight span lengthens only at second
    order), and it diverged even for steps of 1e-5 of the length.  With the friction
    turned round the start is the sliding state of the new direction (exact where the step
    exceeds the short stick transition, which a quasi-static step does not resolve)."""
    if not problem.nt:
        return u
    u = u.reshape(problem.n, problem.nv).copy()
    u[:, 9 + problem.nc :] *= -1.0
    return u.ravel()


class _Record:
    """The per-step figures of an insertion, and the :class:`Insertion` they make."""

    def __init__(self, lengths, vessel, bending_stiffness):
        self.lengths, self.vessel = lengths, vessel
        self.EI = float(bending_stiffness)  # E I_z, N m^2 (every free part's)
        keys = ("tip", "wall", "fmax", "nodes", "gap", "stable", "sub", "s", "x", "R", "f", "p",
                "push", "axial")  # fmt: skip
        self.out = {key: [] for key in keys}
        self.half_width = 0.0

    def add(self, problem, u, stable, solves):
        out = self.out
        V = u.reshape(problem.n, problem.nv)
        frames = problem.frames(u[None])  # (once: the contact state and points use them)
        R = frames[0]
        x = problem.points(V[:, 0:3])
        force, gaps, active = problem.contact_state(u[None], frames)
        EI, L = self.EI, problem.L
        per_length = force[0].sum(axis=1) * (EI / L**3)
        out["tip"].append(x[-1].copy())
        out["wall"].append(problem.contact_totals(force)[0].sum(axis=0) * (EI / L**2))
        out["fmax"].append(float(np.max(np.linalg.norm(per_length, axis=1))))
        out["nodes"].append(active[0].any(axis=1))
        out["gap"].append(float(gaps.min() * L))
        out["stable"].append(bool(stable))
        out["sub"].append(int(solves))
        out["s"].append(problem.mesh.s * L)
        out["x"].append(x)
        out["R"].append(R)
        out["f"].append(per_length)
        out["p"].append(problem.points(problem.contact_points(u[None], frames)[0]))
        # (0.0 - x: no "-0" in the tables of a step without contact)
        out["push"].append((0.0 - float(V[0, 6:9] @ problem.R0[:, 0])) * (EI / L**2))
        chord = np.diff(V[:, 0:3], axis=0)
        chord /= np.linalg.norm(chord, axis=1, keepdims=True)
        out["axial"].append(np.einsum("ji,ji->j", V[:-1, 6:9], chord) * (EI / L**2))
        self.half_width = float(problem._half[0] * L)  # in-plane (normal) half-extent, m

    def result(self) -> Insertion:
        out = self.out
        return Insertion(
            lengths=self.lengths[: len(out["tip"])].copy(),
            tip=np.array(out["tip"]).reshape(-1, 3),
            wall_force=np.array(out["wall"]).reshape(-1, 3),
            max_contact_force=np.array(out["fmax"]),
            contact_nodes=out["nodes"],
            min_gap=np.array(out["gap"]),
            stable=np.array(out["stable"], dtype=bool),
            substeps=np.array(out["sub"], dtype=int),
            push_force=np.array(out["push"]),
            _s=out["s"],
            _shapes=out["x"],
            _frames=out["R"],
            _forces=out["f"],
            vessel=self.vessel,
            _points=out["p"],
            _axial=out["axial"],
            _half_width=self.half_width,
        )


def _reason(problem) -> str:
    why = getattr(problem, "last_failure", "")
    return f"; {why}" if why else ""
