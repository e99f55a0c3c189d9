"""``solve_rod``: hard-magnetic Kirchhoff rods (planar, seed eq. 5, and spatial) in any field,
load sweeps."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from coils._validate import as_vector, finite_scalar, positive
from coils.field import Field

from ..errors import ConvergenceError
from ..path.corrector import NewtonOptions, newton
from ..path.events import warn_events
from ..path.stepping import PathOptions, follow_load
from ..robot.rod import Rod
from .mesh import RodMesh, node_magnetization
from .model import clamp_azimuth, resolve_clamp_and_model
from .planar import PlanarRod
from .result import RodResult
from .so3 import expm, logm

__all__ = [
    "solve_rod",
    "DEFAULT_SEGMENTS",
    "MAX_SEGMENTS",
    "build_problem",
    "build_spatial_problem",
    "make_mesh",
]

#: Default number of segments of the coarse mesh (the fine mesh has twice as many).  With
#: Richardson extrapolation this meets a tip error of 1e-6 L against the closed-form elastica
#: for lambda in [0, 50] (see tests/test_rod_physics.py and benchmarks/bench_rod.py).
DEFAULT_SEGMENTS = 64
#: Largest number of coarse segments accepted (memory and time stay bounded).
MAX_SEGMENTS = 100_000
#: The stability eigenvalue is Richardson-extrapolated (uniform fields) when it is below this
#: fraction of the straight rod's, i.e. near a bifurcation or fold.
_EXTRAPOLATE_MU = 0.5


def _int_option(value, name: str, low: int, high: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
        raise ValueError(f"{name} must be an integer >= {low}; got {value!r}")
    if high is not None and value > high:
        raise ValueError(f"{name} must be at most {high}; got {value!r}")
    return int(value)


def check_inputs(rod, field, scales, nodes, clamp_position, clamp_angle, tol=1e-9):
    """Validate the common inputs of the rod solvers (ValueError naming the argument); returns
    (scales, nodes, clamp, angle, tol)."""
    if not isinstance(rod, Rod):
        raise ValueError(f"rod must be a coilrod.Rod; got {type(rod).__name__}")
    if not isinstance(field, Field):
        raise ValueError(f"field must be a coils.Field; got {type(field).__name__}")
    arr = np.asarray(scales, dtype=float) if not isinstance(scales, str) else None
    if arr is None or arr.ndim > 1 or arr.size == 0:
        raise ValueError(f"scales must be a non-empty 1-D sequence of numbers; got {scales!r}")
    arr = np.atleast_1d(arr)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"scales must be finite; got {arr.tolist()}")
    nodes = _int_option(DEFAULT_SEGMENTS if nodes is None else nodes, "nodes", 4, MAX_SEGMENTS)
    clamp = as_vector(clamp_position, "clamp_position")
    angle = finite_scalar(clamp_angle, "clamp_angle")
    tol = positive(tol, "tol")
    return arr, nodes, clamp, angle, tol


def make_mesh(rod: Rod, segments: int) -> RodMesh:
    """Piecewise-uniform mesh of about ``segments`` segments with nodes at the breakpoints."""
    return RodMesh(segments, np.asarray(rod.magnetization.breakpoints, dtype=float) / rod.length)


def build_problem(
    rod: Rod,
    field: Field,
    mesh: RodMesh,
    clamp_position,
    clamp_angle,
    tol: float = 1e-9,
    stability3d: bool = True,
    *,
    clamp_field=None,
) -> PlanarRod:
    """The discrete problem of ``rod`` in ``field`` on ``mesh`` (non-dimensional); with
    ``stability3d`` (default) its stability counts the out-of-plane modes too
    (:mod:`coilrod.rod.out_of_plane`); ``clamp_field``: B (3,) T at the clamp if already
    evaluated (:class:`~coilrod.rod.planar.PlanarRod`)."""
    mu = _node_moments(rod, mesh, dim=2)
    problem = PlanarRod(
        mesh, mu, field, rod.length, clamp_position, clamp_angle, tol, clamp_field=clamp_field
    )
    if stability3d:
        problem.with_out_of_plane(rod_stiffnesses(rod))
    return problem


def _node_moments(rod: Rod, mesh: RodMesh, dim: int) -> np.ndarray:
    """Body-frame node magnetization times A L^2 / EI_z (1/T), shape (n, dim): the rods'
    non-dimensional magnetic moment per unit field."""
    L = rod.length
    scale = rod.area * L**2 / rod.bending_stiffness
    return node_magnetization(rod.magnetization, mesh, L, dim=dim) * scale


def rod_stiffnesses(rod: Rod) -> np.ndarray:
    """(GJ, EI_y, EI_z) / EI_z of ``rod`` (torsion, out-of-plane and in-plane bending)."""
    return np.asarray(rod.stiffnesses, float) / rod.bending_stiffness


def build_spatial_problem(
    rod: Rod,
    field: Field,
    mesh: RodMesh,
    clamp_position,
    clamp_rotation,
    tol: float = 1e-9,
    mixed: bool = False,
    obstacles=(),
):
    """The spatial discrete problem of ``rod`` in ``field`` on ``mesh`` (non-dimensional)."""
    from .spatial import SpatialRod

    return SpatialRod(
        mesh,
        _node_moments(rod, mesh, dim=3),
        rod_stiffnesses(rod),
        field,
        rod.length,
        clamp_position,
        clamp_rotation,
        tol,
        mixed,
        obstacles,
        section=rod.section if obstacles else None,
    )


def solve_rod(
    rod: Rod,
    field: Field,
    scales,
    *,
    model: str = "auto",
    nodes: int | None = None,
    richardson: bool = True,
    clamp_position=(0.0, 0.0, 0.0),
    clamp_angle: float = 0.0,
    clamp_rotation=None,
    obstacles=None,
    tol: float = 1e-9,
    max_iter: int = 15,
    stability: bool = True,
    progress: bool = False,
) -> RodResult:
    """Equilibria of a hard-magnetic rod in ``field`` multiplied by each of ``scales``.

    Parameters
    ----------
    rod : Rod
        Geometry, modulus and magnetization.
    field : coils.Field
        Applied field; evaluated on the deformed centreline.
    scales : array-like, shape (k,)
        Field multipliers, solved in order along the load path from the straight rod at
        scale 0 (the first scale too: it is continued from the unloaded rod, not jumped to).
    model : {"auto", "planar", "spatial"}
        "planar": the rod bends in the plane z = clamp_position[2] (seed eq. 5,
        :mod:`coilrod.rod.planar`); "spatial": the 3D Kirchhoff rod with torsion
        (:mod:`coilrod.rod.spatial`); "auto" (default) takes the planar model exactly when
        nothing pushes the rod out of its plane -- a planar magnetization (no elevation), a
        clamp frame turned about z only, and a field with ``B_z = 0`` and ``dB_z/dx = dB_z/dy
        = 0`` on the plane within the rod's reach (relative 1e-12) -- and the spatial one
        otherwise.  ``result.model`` says which ran.  "planar" with an out-of-plane load
        raises ValueError instead of dropping it.
    nodes : int, optional
        Segments of the coarse mesh (default :data:`DEFAULT_SEGMENTS`, at most
        :data:`MAX_SEGMENTS`); a node is placed at every magnetization breakpoint.
    richardson : bool
        Solve on the mesh and on its halving and extrapolate (fourth order).  False: one mesh,
        second order.  With obstacles a state is extrapolated where both meshes have the
        same contact set and the extrapolated rod is admissible, else the halved mesh's
        state is returned (second order); with friction each mesh follows the load path
        itself (the answer is path dependent) and the extrapolation stays fourth order (a
        tip pressed on a rough wall: errors 5.0e-6, 3.1e-7, 1.9e-8 of the wall force at 4,
        8, 16 segments -- so two meshes' answers agree to 6-8 digits).
    clamp_position : array-like, shape (3,)
        Clamp position, m.  The rod moves in the plane z = clamp_position[2].
    clamp_angle : float
        Tangent angle at the clamp, rad from +x (a rotation of the clamp about z).
    clamp_rotation : (3, 3) array or scipy.spatial.transform.Rotation, optional
        Clamp frame in 3D (columns: tangent, normal, binormal of the unloaded rod); orthonormal
        to 1e-9 with determinant +1.  Give either this or ``clamp_angle``.
    obstacles : sequence, optional
        Rigid obstacles (:class:`coilrod.Wall`, :class:`coilrod.Vessel`, or any object with
        ``gap``, ``gap_gradient``, ``gap_hessian`` of points in m): frictionless contact at the
        nodes, solved inside Newton as the complementarity ``min(lam, g) = 0`` (semi-smooth
        Newton, exact Jacobian of the gap).  Contact runs on the spatial rod (whose planar
        states are the planar rod's); the unloaded straight rod must be admissible.  The
        result then has ``contact_force(k)``, ``obstacle_forces(k)``, ``gaps(k)`` and
        ``contact_set(k)``.
    tol : float
        Newton tolerance on the scaled residual (non-dimensional, > 0); each equation also
        has a round-off floor that follows its own segment length.
    max_iter : int
        Newton iterations per attempt (>= 1).
    stability : bool
        Compute the second variation of each state (``stable``, ``min_eigenvalue``) and cut
        load steps that change it: a change that persists at 1e-4 of the requested step is a
        bifurcation on the branch (reported, :class:`StabilityWarning`; the solver stays on
        its branch), a jump to another branch disappears as the steps resolve the path.
    progress : bool
        Show a tqdm progress bar.

    Returns
    -------
    RodResult

    Warns
    -----
    StabilityWarning
        At a change of stability and at a snap-through (the branch ends at a limit point: the
        solver follows the path around the fold by pseudo-arclength continuation until it is
        stable again beyond the fold scale, records the event in ``instabilities`` with kind
        "snap", and continues from there, as a quasi-statically loaded rod would jump).

    Raises
    ------
    ValueError
        Bad input (the message names the argument).
    coilrod.ConvergenceError
        A scale could not be reached; ``reached`` is the last scale converged, ``result`` the
        :class:`RodResult` of the requested scales before it (None if none), and the message
        says whether the state there is at a limit point.

    Notes
    -----
    Solves seed eq. (5), ``EI theta'' + A t_z - A sin(theta) int_s^L f_x + A cos(theta)
    int_s^L f_y = 0``, ``theta(0) = clamp_angle``, ``theta'(L) = 0``, with ``t = m x B``,
    ``f = (grad B)^T m``, ``m = R(theta) M``, B and grad B at ``x(s) = clamp + int_0^s (cos
    theta, sin theta, 0)``.  Discretisation: :mod:`coilrod.rod.planar` (trapezoid discrete
    energy, exact banded Newton Jacobian including the field's second derivatives; cost per
    Newton step linear in the node count).  The load path is followed by the shared engine
    :mod:`coilrod.path` (tangent predictor, Newton with line search, step cutting, stability
    bisection, arclength around folds); smooth stretches are corrected in batches.

    Accuracy: tip error about 2e-8 L at lambda = 20 and 1e-7 L at lambda = 50 with the
    defaults (64 + 128 segments, Richardson), fourth order in the segment length; a boundary
    layer of width ~ L / sqrt(lambda) forms at the clamp, so lambda >> 100 needs more nodes.

    The spatial model (:mod:`coilrod.rod.spatial`) discretises the energy of the
    inextensible, unshearable Kirchhoff rod with stiffnesses (GJ, EI_y, EI_z)
    (:attr:`coilrod.Rod.stiffnesses`), frames on SO(3) at the nodes, torque ``A m x B`` and
    force ``A (grad B)^T m`` on the deformed centreline with their exact Jacobian; a
    planar state is the planar model's discrete solution.  Its result carries
    ``frames(k)``; its ``tip_angle`` is the azimuth of the tip tangent about z, continued
    from the clamp's.

    Limitations: a fold pair narrower than a load step (a small hysteresis loop) can be
    stepped over without a report (use finer scales or :func:`~coilrod.trace_rod`).  In the
    spatial model a double eigenvalue (a circular section in a load symmetric about the
    rod's axis) crosses zero without the cheap stability sign noticing it; ``min_eigenvalue``
    (computed on access) sees it.

    Examples
    --------
    >>> import numpy as np, coils
    >>> from coilrod import Rod, Circle, Magnetization, solve_rod
    >>> rod = Rod(0.04, 1e6, Circle(2e-3), Magnetization(128e3, 0.0))
    >>> field = coils.UniformField(B=(0.0, rod.field_for_lambda(1e-3), 0.0))
    >>> res = solve_rod(rod, field, [1.0], nodes=16)
    >>> round(float(res.tip[0, 1]) / (1e-3 * rod.length / 3), 3)  # small deflection: lambda L / 3
    1.0
    """
    scales, nodes, clamp, angle, tol = check_inputs(
        rod, field, scales, nodes, clamp_position, clamp_angle, tol
    )
    max_iter = _int_option(max_iter, "max_iter", 1)
    obstacles = _check_obstacles(obstacles)
    chosen, R0, angle = resolve_clamp_and_model(model, rod, field, clamp, angle, clamp_rotation)
    if obstacles:
        if model == "planar":
            raise ValueError(
                "contact (obstacles) runs on the spatial rod: use model='auto' or 'spatial' "
                "(a planar load keeps the spatial rod's state planar)"
            )
        chosen = "spatial"
    mesh = make_mesh(rod, nodes)
    meshes = [mesh, mesh.refined()] if richardson else [mesh]
    if chosen == "planar":
        problems = [build_problem(rod, field, meshes[0], clamp, angle, tol)]
        problems += [  # (the field at the clamp evaluated once)
            build_problem(rod, field, m, clamp, angle, tol, clamp_field=problems[0].clamp_field)
            for m in meshes[1:]
        ]
        finish = _result
    else:
        problems = [
            build_spatial_problem(rod, field, m, clamp, R0, tol, obstacles=obstacles)
            for m in meshes
        ]
        if obstacles:
            _check_start(problems, obstacles)
        finish = _result_spatial
    opts = _path_options(max_iter, bool(stability), bool(obstacles))
    bar = None
    tick = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=scales.size, desc="solve_rod", unit="scale")

        def tick(k, scale):
            bar.update(1)

    try:
        run = follow_load(
            problems[0], problems[0].straight(), scales, opts, name="solve_rod", progress=tick
        )
    except ConvergenceError as err:
        err.result = None
        points = getattr(err, "points", None)
        if points:
            try:
                err.result = finish(
                    rod, problems, points, np.zeros(len(points), int), err.events, opts
                )
            except ConvergenceError:
                pass
        raise
    finally:
        if bar is not None:
            bar.close()
    result = finish(rod, problems, run.points, run.iterations, run.events, opts)
    warn_events(result.instabilities, stacklevel=3)
    return result


@functools.lru_cache(maxsize=16)
def _path_options(max_iter: int, stability: bool, contact: bool) -> PathOptions:
    """The load stepping's settings of :func:`solve_rod` (frozen: one instance per choice)."""
    newton_opts = NewtonOptions(max_iter=max_iter)
    path_kw = {}
    if contact:  # semi-smooth Newton: the error may stall while the contact set settles
        newton_opts = NewtonOptions(max_iter=max(max_iter, 40), stagnation=12)
        # the path has kinks where contacts close or open: the trapezoidal smoothness check
        # of a step would cut every step across one down to the tolerance
        path_kw["relative_correction"] = 1.0
    return PathOptions(newton=newton_opts, stability=stability, **path_kw)


@functools.lru_cache(maxsize=16)
def _chord_start(opts: NewtonOptions) -> NewtonOptions:
    """``opts`` starting in chord mode (frozen: one instance per ``opts``)."""
    return dataclasses.replace(opts, chord_start=True)


def _check_obstacles(obstacles) -> tuple:
    """The obstacles as a tuple (ValueError for an object without the gap interface)."""
    if obstacles is None:
        return ()
    if hasattr(obstacles, "gap"):
        obstacles = [obstacles]
    out = tuple(obstacles)
    for i, ob in enumerate(out):
        for name in ("gap", "gap_gradient", "gap_hessian"):
            if not callable(getattr(ob, name, None)):
                raise ValueError(
                    f"obstacles[{i}] must be an obstacle (coilrod.Wall, coilrod.Vessel or an "
                    f"object with gap, gap_gradient and gap_hessian); {type(ob).__name__} has "
                    f"no {name}()"
                )
    return out


#: Round-off accepted by the start check (units of L): a straight rod's centreline or surface
#: this far into an obstacle still starts; a clearance this small on both sides of its section
#: is none (a vessel exactly the rod's width: the contact normal at its axis is undefined).
START_TOL = 1e-12


def _check_start(problems, obstacles) -> None:
    """ValueError unless the straight unloaded rod (every mesh's nodes) is admissible: its
    centreline, and its surface with room to move (a rod thicker than the space it starts in,
    or exactly as thick, is an error); the message names the node or contact point, its arc
    length (m), the depth and the obstacle."""
    for problem in problems:
        L, s = problem.L, problem.mesh.s
        x = problem.node_positions(problem.straight()[None])[0]
        pts = problem.points(x)
        for i, ob in enumerate(obstacles):
            gap = np.asarray(ob.gap(pts), float)
            bad = np.flatnonzero(~(gap >= -START_TOL * L))
            if bad.size:
                j, deep = int(bad[0]), int(bad[np.argmin(gap[bad])])
                msg = (
                    f"{_obstacle_name(ob, i)} leaves no admissible straight start: the "
                    f"unloaded rod's node {j} (of 0..{len(pts) - 1}) at s = {s[j] * L:.4g} m, "
                    f"{_point_mm(pts[j])}, lies {1e3 * -gap[j]:.4g} mm {_inside(ob)}"
                )
                if bad.size > 1:
                    msg += (
                        f" ({bad.size} of {len(pts)} nodes are; the deepest, node {deep} at "
                        f"s = {s[deep] * L:.4g} m, by {1e3 * -gap[deep]:.4g} mm)"
                    )
                raise ValueError(msg)
        gaps = problem.contact_state(problem.straight()[None])[1][0]  # surface, units of L
        c = problem._contact_geometry()[0]
        half = problem._half * L
        section = f"section (half-extents {1e3 * half[0]:.4g} x {1e3 * half[1]:.4g} mm)"
        bad = np.argwhere(gaps < -START_TOL)
        if bad.size:
            j, i = (int(v) for v in bad[0])
            raise ValueError(
                f"{_obstacle_name(obstacles[i], i)} leaves no room for the rod's surface: the "
                f"straight rod's {section} at contact point {j} (s = {L * (s[j] + c[j]):.4g} m)"
                f" reaches {1e3 * -gaps[j, i] * L:.4g} mm into it (a rod thicker than the "
                "vessel, or a clamp too close to the wall)"
            )
        # no room to move: the section touching an obstacle on opposite sides
        p = x + c[:, None] * problem.R0[:, 0]
        for a in range(2):
            d = half[a] / L * problem.R0[:, a + 1]
            for i, ob in enumerate(obstacles):
                both = np.asarray(ob.gap(problem.points(np.concatenate([p + d, p - d]))), float)
                room = np.maximum(*both.reshape(2, -1))
                bad = np.flatnonzero(~(room > START_TOL * L))
                if bad.size:
                    j = int(bad[0])
                    raise ValueError(
                        f"{_obstacle_name(ob, i)} leaves no room for the rod: the straight "
                        f"rod's {section} at contact point {j} (s = {L * (s[j] + c[j]):.4g} m) "
                        f"touches it on both sides along its {('normal', 'binormal')[a]} "
                        f"(clearances {room[j]:.3g} m at most; more than {START_TOL:g} L = "
                        f"{START_TOL * L:.3g} m needed on one side: a vessel exactly as wide "
                        "as the rod)"
                    )


def _obstacle_name(ob, i: int) -> str:
    return f"obstacles[{i}] ({type(ob).__name__})"


def _inside(ob) -> str:
    """How an obstacle says a point is not admissible ("outside the vessel", "behind the
    wall"; "inside it" for an object with the gap interface alone)."""
    words = getattr(type(ob), "_outside", None)
    return words if isinstance(words, str) else "inside it"


def _point_mm(p) -> str:
    """A point (3,), m, as "(x, y, z) mm" (to the nm: round-off shows as 0)."""
    return "(" + ", ".join(f"{1e3 * v:.4g}" for v in np.round(p, 9) + 0.0) + ") mm"


def _refine(problems, states, scales, opts):
    """Newton on the refined mesh from the interpolated coarse states: (states, iterations,
    residual norms, convergence measures); ConvergenceError if a state cannot be reached."""
    coarse, fine = problems
    # the interpolated coarse solution is within O(h^2) of the fine one: chord iterations
    if getattr(fine, "path_dependent", False):  # friction: the path matters
        return _refine_in_order(fine, scales, opts)
    guess = coarse.interpolate_to(fine, states)
    newton_opts = _chord_start(opts.newton)
    res = newton(fine, guess, scales, newton_opts, tangent_at_end=False)
    if not np.all(res.ok):
        k = int(np.argmin(res.ok))
        raise ConvergenceError(
            f"solve_rod could not reach scale {scales[k]:g} (index {k}) on the refined "
            f"mesh from the coarse solution (error {float(res.error[k]):.3g} of tolerance)",
            reached=float(scales[k - 1]) if k else 0.0,
            target=float(scales[k]),
            residual=float(res.error[k]),
        )
    return res.u, res.iterations, fine.residual_norm(res.lin.residual), np.asarray(res.error)


def _refine_in_order(fine, scales, opts):
    """:func:`_refine` for a path-dependent model (friction): the refined mesh follows the
    load path itself from the straight rod (its own sub-steps; a state solved directly from
    another mesh's would take a different path)."""
    run = follow_load(fine, fine.straight(), scales, opts, name="solve_rod (refined mesh)")
    out = np.array([p.u for p in run.points])
    res_norm = fine.residual_norm(np.array([p.residual for p in run.points]))
    errors = np.array([p.error for p in run.points], dtype=float)
    return out, np.asarray(run.iterations), res_norm, errors


def _solved_states(problems, points, iterations, opts):
    """The coarse states of the path points (k, size), the refined mesh's (None without
    Richardson), the Newton iterations (k,) of both and the larger scaled residual (k,).

    Also the convergence measure of each state (k,): the larger of the meshes' ``error``
    (the model's test, <= 1 when converged) as Newton measured it.  Every state returned
    must have passed it: ConvergenceError otherwise, so a result never carries an
    unconverged state."""
    coarse = problems[0]
    scales = np.array([p.scale for p in points])
    states = np.array([p.u for p in points])
    iterations = np.array(iterations, dtype=int)
    residual = coarse.residual_norm(np.array([p.residual for p in points]))
    measured = np.array([p.error for p in points], dtype=float)
    fine_states = None
    if len(problems) == 2:
        fine_states, its, fine_res, fine_err = _refine(problems, states, scales, opts)
        iterations = iterations + its
        residual = np.maximum(residual, fine_res)
        measured = np.maximum(measured, fine_err)
    bad = ~(measured <= 1.0)
    if bad.any():
        k = int(np.argmax(bad))
        raise ConvergenceError(
            f"solve_rod: the state at scale {scales[k]:g} (index {k}) does not meet the "
            f"convergence test (error {measured[k]:.3g} of the tolerance)",
            reached=float(scales[k - 1]) if k else 0.0,
            target=float(scales[k]),
            residual=float(measured[k]),
        )
    return states, fine_states, iterations, residual, measured


def _result(rod, problems, points, iterations, events, opts) -> RodResult:
    """RodResult from the coarse path points: refined-mesh states, Richardson, stability."""
    coarse = problems[0]
    states, fine_states, iterations, residual, measured = _solved_states(
        problems, points, iterations, opts
    )
    thetas_c = coarse.theta(states)
    x_c = coarse.positions(thetas_c)
    if len(problems) == 2:
        th_f = problems[1].theta(fine_states)
        thetas = (4 * th_f[:, ::2] - thetas_c) / 3
        x = (4 * problems[1].positions(th_f)[:, ::2] - x_c) / 3
    else:
        thetas, x = thetas_c, x_c
    return _assemble_result(
        rod, problems, points, events, opts, states, fine_states, iterations, residual, measured,
        points_xyz=coarse.points(x), tip_angle=thetas[:, -1].copy(), _theta=thetas,
    )  # fmt: skip


def _assemble_result(
    rod, problems, points, events, opts, states, fine_states, iterations, residual, measured,
    **fields,
) -> RodResult:  # fmt: skip
    """The RodResult shared by both models: stability (the exact sign now, the eigenvalues
    on first access), refined events, the solution kept for the sensitivities; ``fields``
    adds the model's own (points_xyz, tip_angle, _theta, model, _frames, _contact)."""
    coarse = problems[0]
    scales = np.array([p.scale for p in points])
    if not opts.stability:
        mu = np.full(scales.size, np.nan)
        stable = np.ones(scales.size, dtype=bool)
    else:
        stable = np.array([p.stability > 0 for p in points], dtype=bool)
        fine = (problems[1], fine_states) if len(problems) == 2 else None
        mu = _eigenvalues_later(coarse, states, scales, fine)
    in_plane = mu_plane = None
    if getattr(coarse, "out_of_plane", None) is not None and opts.stability:
        in_plane = _in_plane_later(coarse, states, scales)
        mu_plane = _eigenvalues_later(coarse, states, scales, fine, in_plane=True)
        events = [_label_mode(e, coarse, states, scales) for e in events]
    points_xyz = fields.pop("points_xyz")
    return RodResult(
        scales=scales,
        s=coarse.mesh.s * rod.length,
        tip=points_xyz[:, -1, :].copy(),
        converged=measured <= 1.0,
        stable=stable,
        residual=residual,
        error=measured,
        _stable_in_plane=in_plane,
        _min_eigenvalue_in_plane=mu_plane,
        _min_eigenvalue=mu,
        iterations=iterations,
        segments=coarse.mesh.counts.sum(),
        _points=points_xyz,
        instabilities=[_refine_event(e, scales, mu, coarse) for e in events],
        _solution=RodSolution(
            rod,
            coarse.field,
            tuple(problems),
            (states,) + ((fine_states,) if len(problems) == 2 else ()),
        ),
        **fields,
    )


def _result_spatial(rod, problems, points, iterations, events, opts) -> RodResult:
    """RodResult of the spatial model: refined-mesh states, Richardson extrapolation of the
    positions and of the frames (on SO(3)), stability."""
    coarse = problems[0]
    states, fine_states, iterations, residual, measured = _solved_states(
        problems, points, iterations, opts
    )
    R_c = coarse.frames(states)
    x_c = coarse.positions_from_frames(R_c)
    if len(problems) == 2:
        fine = problems[1]
        R_f = fine.frames(fine_states)
        x_f = fine.positions_from_frames(R_f)[:, ::2]
        x = (4 * x_f - x_c) / 3
        R_f = R_f[:, ::2]
        # R_c = R exp(4 e), R_f = R exp(e) to leading order: R = R_f exp(-log(R_f^T R_c) / 3)
        frames = R_f @ expm(-logm(np.swapaxes(R_f, -1, -2) @ R_c) / 3)
        if getattr(coarse, "nc", 0):  # only where admissible: else the fine mesh's state
            extrapolated = _extrapolation_admissible(problems, states, fine_states, x, frames)
            x[~extrapolated], frames[~extrapolated] = x_f[~extrapolated], R_f[~extrapolated]
    else:
        x, frames = x_c, R_c
    contact = None
    if getattr(coarse, "nc", 0):
        done = extrapolated if len(problems) == 2 else None
        contact = _contact_data(problems, states, fine_states, rod, x, frames, done)
    return _assemble_result(
        rod, problems, points, events, opts, states, fine_states, iterations, residual, measured,
        points_xyz=coarse.points(x),
        tip_angle=_tip_azimuth(frames[:, -1], coarse.rotations(states)[:, -1], coarse.R0),
        _theta=None, model="spatial", _frames=frames,
        _contact=contact,
    )  # fmt: skip


def _extrapolation_admissible(problems, states, fine_states, x, frames) -> np.ndarray:
    """Whether the Richardson extrapolation (x (k, n, 3) units of L, frames (k, n, 3, 3)) of
    each state is admissible, shape (k,): both meshes have the same contact set at the
    coarse mesh's contact points (a fine corner pair in contact where the coarse corner
    is, the tips alike) and no contact point of the extrapolated rod penetrates an
    obstacle more than the fine solution's deepest point (plus 1e-10 L).  Where the sets
    differ (an obstacle between the coarse and the fine free shapes) the error does not
    expand in powers of h and the extrapolation can cross the wall."""
    coarse, fine = problems
    _, gc, ac = coarse.contact_state(states)
    _, gf, af = fine.contact_state(fine_states)
    af_pairs = af[:, 0:-1:2] | af[:, 1::2]  # fine corners 2j, 2j+1 make coarse corner j
    same = np.all(ac[:, :-1] == af_pairs, axis=(1, 2)) & np.all(ac[:, -1] == af[:, -1], axis=1)
    deepest = np.minimum(gf.min(axis=(1, 2)), 0.0)  # units of L
    return same & (coarse.surface_gaps(x, frames).min(axis=(1, 2)) >= deepest - 1e-10)


def _contact_data(problems, states, fine_states, rod, x, frames, extrapolated):
    """Contact of each state: the force per length (k, n, nc, 3) N/m and the active set
    (k, n, nc) of the finest mesh solved at every second contact point (the corner after
    each output node, the tip; arc lengths "s" (n,) m); the gaps (k, n, nc) m of the
    returned rod's contact points (positions x (k, n, 3) units of L and ``frames`` as
    returned: extrapolated or not); the total force the rod exerts on each obstacle
    (k, nc, 3) N (Richardson-extrapolated like the tip where ``extrapolated`` (k,) is)."""
    coarse, problem = problems[0], problems[-1]
    EI, L = rod.bending_stiffness, rod.length
    U = states if fine_states is None else fine_states
    force, gaps, active = problem.contact_state(U)
    s = (problem.mesh.s + problem._contact_geometry()[0]) * L
    per_length = force * (EI / L**3)  # EI_z / L^3 units -> N/m
    totals = problem.contact_totals(force)
    if fine_states is not None:  # Richardson, as the tip (where it was extrapolated)
        coarse_totals = coarse.contact_totals(coarse.contact_state(states)[0])
        done = extrapolated[:, None, None]
        totals = np.where(done, (4 * totals - coarse_totals) / 3, totals)
    totals = totals * (EI / L**2)  # N
    step = 1 if fine_states is None else 2
    gap = coarse.surface_gaps(x, frames) * L
    return {
        "s": s[::step],
        "force": per_length[:, ::step],
        "gap": gap,
        "active": active[:, ::step],
        "totals": totals,
        "min_gap": np.minimum(gaps.min(axis=1) * L, gap.min(axis=1)),
    }


def _tip_azimuth(tip_frames: np.ndarray, tip_phi: np.ndarray, R0: np.ndarray) -> np.ndarray:
    """Azimuth (rad) of the tip tangent about z, ``atan2(t_y, t_x)``, continued from the clamp
    tangent's: the branch nearest to the clamp azimuth plus the tip's rotation about z (the
    planar model's unwrapped tip angle for a planar state)."""
    t = tip_frames[:, :, 0]
    raw = np.arctan2(t[:, 1], t[:, 0])
    guess = clamp_azimuth(R0) + tip_phi[:, 2]
    return raw + 2 * np.pi * np.round((guess - raw) / (2 * np.pi))


@dataclasses.dataclass(frozen=True)
class RodSolution:
    """The discrete problems of a :class:`RodResult` and their converged states (coarse mesh,
    and the refined mesh with Richardson), kept for :func:`coilrod.sensitivities`."""

    rod: Rod
    field: Field
    problems: tuple
    states: tuple


def _eigenvalues_later(problem, states, scales, fine=None, in_plane=False):
    """A callable computing the smallest second-variation eigenvalues of ``states`` (all, or
    the given rows), batched, for :attr:`RodResult.min_eigenvalue` (``in_plane``: the
    planar rod's in-plane figure, :attr:`RodResult.min_eigenvalue_in_plane`).

    For uniform fields with a refined mesh ``fine = (problem, states)``, the eigenvalues near a
    loss of stability (below half the straight rod's) are Richardson-extrapolated, which
    locates a critical scale to fourth order."""

    def measure(p, lin):
        how = p.branch_stability if in_plane else p.stability
        return np.asarray(how(lin, precise=True), float)

    def compute(rows=None):
        sel = np.arange(len(scales)) if rows is None else np.asarray(rows)
        mu = measure(problem, problem.linearize(states[sel], scales[sel]))
        if fine is not None and problem.uniform:
            mu0 = problem.mu0 if in_plane else problem.mu0_stability
            near = np.abs(mu) < _EXTRAPOLATE_MU * mu0
            if near.any():
                fp, fstates = fine
                flin = fp.linearize(fstates[sel[near]], scales[sel[near]])
                mu_f = measure(fp, flin)
                mu[near] = (4 * mu_f - mu[near]) / 3
        return mu

    return compute


def _in_plane_later(problem, states, scales):
    """A callable giving the in-plane stability (k,) of ``states`` (the planar determinant's
    sign), for :attr:`RodResult.stable_in_plane` (computed on first access)."""

    def compute():
        signs = problem.stability_in_plane(problem.linearize(states, scales))
        return np.asarray(signs, float) > 0

    return compute


def _label_mode(event: dict, problem, states, scales) -> dict:
    """A bifurcation of a planar path labelled with its mode: "out-of-plane" where the
    out-of-plane count changed between the requested scales around it, else "in-plane"."""
    if event.get("kind") != "bifurcation":
        return event
    k = event["index"]
    if k >= len(scales):
        return event
    rows = [k - 1, k] if k > 0 else [k]
    lin = problem.linearize(states[rows], scales[rows])
    _, odd = problem.negative_counts(lin)
    before = int(odd[0]) if k > 0 else 0
    event = dict(event)
    event["mode"] = "out-of-plane" if int(odd[-1]) != before else "in-plane"
    return event


class _Bracket:
    """``mu[k - 1]`` and ``mu[k]`` of a lazily computed eigenvalue array, computed together."""

    def __init__(self, compute, problem, scales, k):
        rows = [k - 1, k] if k > 0 else [k]
        self.values = dict(zip(rows, compute(rows), strict=True))

    def __getitem__(self, i):
        return self.values[i]


def _refine_event(event: dict, scales, mu, coarse) -> dict:
    """The event with plain-float fields; a bifurcation's critical scale re-estimated by linear
    interpolation of ``min_eigenvalue`` between the requested scales around it (the
    extrapolated eigenvalue for uniform fields, fourth order in the mesh) where both are known
    and of opposite sign; otherwise the engine's location (coarse mesh, within 1e-4 of the
    step) stands."""
    e = {key: (float(v) if isinstance(v, np.floating) else v) for key, v in event.items()}
    if e["kind"] != "bifurcation":
        return e
    k = e["index"]
    if k >= len(scales):
        return e
    if callable(mu):  # only the two eigenvalues around the event are needed
        mu = _Bracket(mu, coarse, scales, k)
    a, ma = (scales[k - 1], mu[k - 1]) if k > 0 else (0.0, coarse.mu0)
    b, mb = scales[k], mu[k]
    if np.isfinite(ma) and np.isfinite(mb) and (ma > 0) != (mb > 0) and ma != mb:
        e["scale"] = float(a + (b - a) * ma / (ma - mb))
    return e
