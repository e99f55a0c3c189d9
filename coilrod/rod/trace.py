"""``trace_rod``: pseudo-arclength continuation of rod equilibria through limit points."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from coils._validate import finite_scalar, positive

from ..errors import ConvergenceError
from ..path.arclength import ArcLength
from ..path.corrector import NewtonOptions, newton
from .model import resolve_clamp_and_model
from .solve import _tip_azimuth, build_problem, build_spatial_problem, check_inputs, make_mesh

__all__ = ["trace_rod", "RodPath"]


@dataclass
class RodPath:
    """Equilibrium path traced by :func:`trace_rod` (ordered by arc length along the path).

    Attributes
    ----------
    scale : ndarray, shape (m,)
        Field multiplier of each point.
    tip : ndarray, shape (m, 3)
        Tip positions, m.
    tip_angle : ndarray, shape (m,)
        Tip tangent angles, rad.
    stable : ndarray of bool, shape (m,)
        Positive-definite second variation, in 3D (a planar path's out-of-plane modes
        included, as in :class:`~coilrod.RodResult`).
    min_eigenvalue : ndarray, shape (m,)
        Smallest eigenvalue of the second variation (non-dimensional, see ``RodResult``), 3D.
    stable_in_plane, min_eigenvalue_in_plane : ndarray, shape (m,)
        The same among in-plane perturbations alone (planar paths; equal to the 3D figures
        for spatial ones).
    residual : ndarray, shape (m,)
        Scaled residual of each point.
    limit_points : list of dict
        Folds of the path: ``kind`` "fold" where the sampled scale passes an extremum
        (``scale`` from a parabola through the three points), "stability" where the smallest
        second-variation eigenvalue changes sign between two points (a fold too narrow to be
        resolved, or a bifurcation; ``scale`` interpolated); ``index`` (point after it) and
        ``tip_angle``.  A rod loaded past a fold snaps through to another branch.
    s : ndarray, shape (n,)
        Arc length of the nodes, m.
    model : str
        "planar" or "spatial" (see :func:`~coilrod.solve_rod`).
    """

    scale: np.ndarray
    tip: np.ndarray
    tip_angle: np.ndarray
    stable: np.ndarray
    min_eigenvalue: np.ndarray
    residual: np.ndarray
    s: np.ndarray
    _theta: np.ndarray = field(repr=False)
    _points: np.ndarray = field(repr=False)
    limit_points: list = field(default_factory=list)
    model: str = "planar"
    _frames: np.ndarray | None = field(default=None, repr=False)
    stable_in_plane: np.ndarray | None = None
    min_eigenvalue_in_plane: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.scale)

    def frames(self, k: int) -> np.ndarray:
        """Frames of point ``k`` at :attr:`s`, shape (n, 3, 3) (columns: tangent, normal,
        binormal in world coordinates)."""
        if self._frames is not None:
            return self._frames[k].copy()
        from .so3 import about_z

        return about_z(self._theta[k])

    def centerline(self, k: int) -> np.ndarray:
        """Centreline of point ``k``, shape (n, 3), m."""
        return self._points[k].copy()

    def theta(self, k: int) -> np.ndarray:
        """Tangent angles of point ``k`` at :attr:`s`, shape (n,), rad (planar paths)."""
        if self._theta is None:
            raise ValueError("theta() belongs to planar paths; this one is spatial: use frames(k)")
        return self._theta[k].copy()


def trace_rod(
    rod,
    field,
    scale_start: float,
    scale_range,
    *,
    initial=None,
    direction: int = 1,
    step: float | None = None,
    max_steps: int = 400,
    nodes: int | None = 64,
    clamp_position=(0.0, 0.0, 0.0),
    clamp_angle: float = 0.0,
    clamp_rotation=None,
    model: str = "auto",
    tol: float = 1e-9,
) -> RodPath:
    """Follow an equilibrium path in the field scale by pseudo-arclength continuation.

    Unlike :func:`~coilrod.solve_rod`, which steps the scale monotonically, the path may turn
    back at a limit point (fold); each fold is reported in ``limit_points``.

    Parameters
    ----------
    rod : Rod
    field : coils.Field
        Field multiplied by the scale.
    scale_start : float
        Scale of the first point.
    scale_range : (float, float)
        (low, high), low < high: the trace stops when the scale leaves this interval.
    initial : callable or array-like, optional
        Starting guess: planar model ``theta(s)`` (s in m, returns rad) or node angles, shape
        (n,); spatial model: node rotation vectors relative to the clamp frame (rad, world
        axes), shape (n, 3), or a callable of s returning them.  Default: the straight rod.
        The first point is the equilibrium Newton finds from it.
    direction : {1, -1}
        Initial direction of the scale.
    step : float, optional
        Initial arc-length step (> 0; scale units mixed with rms angle in rad); default 2 % of
        the scale range.
    max_steps : int
        Maximum number of path points (>= 1).
    nodes : int, optional
        Segments of the mesh (one mesh, second order, no extrapolation).
    clamp_position, clamp_angle, clamp_rotation, model, tol
        As in :func:`~coilrod.solve_rod`.

    Returns
    -------
    RodPath

    Raises
    ------
    ValueError
        Bad input (naming the argument); a magnetization with an out-of-plane elevation
        (the traced rod is planar).
    coilrod.ConvergenceError
        If the first point cannot be found.
    """
    lo, hi = _scale_range(scale_range)
    c0 = finite_scalar(scale_start, "scale_start")
    _, nodes, clamp, angle, tol = check_inputs(
        rod, field, [c0], nodes, clamp_position, clamp_angle, tol
    )
    if direction not in (1, -1) or isinstance(direction, bool):
        raise ValueError(f"direction must be 1 or -1; got {direction!r}")
    if not lo <= c0 <= hi:
        raise ValueError(f"scale_start {c0} lies outside scale_range ({lo}, {hi})")
    if isinstance(max_steps, bool) or not isinstance(max_steps, int | np.integer) or max_steps < 1:
        raise ValueError(f"max_steps must be a positive integer; got {max_steps!r}")
    span = max(hi - lo, 1e-300)
    ds = 0.02 * span if step is None else positive(step, "step")
    chosen, R0, angle = resolve_clamp_and_model(model, rod, field, clamp, angle, clamp_rotation)
    if chosen == "planar":
        problem = build_problem(rod, field, make_mesh(rod, nodes), clamp, angle, tol)
        start = problem.from_theta(_initial_theta(problem, rod, initial), c0)
    else:
        problem = build_spatial_problem(rod, field, make_mesh(rod, nodes), clamp, R0, tol)
        start = problem.from_rotations(_initial_rotations(problem, rod, initial), c0)
    first = newton(problem, start, c0, NewtonOptions())
    if not first.ok:
        raise ConvergenceError(
            f"trace_rod found no equilibrium at scale {c0:g} from the given "
            f"initial state (error {first.error:.3g} of the tolerance)",
            reached=float("nan"),
            target=c0,
            residual=first.error,
        )
    u = first.u
    tracer = ArcLength(problem, span, step=ds)
    pts_u, pts_c = [u], [c0]
    for u_new, c_new, _err, _lin in tracer.follow(u, c0, direction, max_steps - 1, first.lin):
        pts_u.append(u_new)
        pts_c.append(c_new)
        if not lo <= c_new <= hi:
            break
    return _finish(problem, rod, pts_u, pts_c)


def _scale_range(scale_range) -> tuple[float, float]:
    """(low, high) of ``scale_range`` (ValueError unless two finite numbers, low < high)."""
    try:
        values = [finite_scalar(v, "scale_range") for v in scale_range]
    except TypeError:
        raise ValueError(f"scale_range must be (low, high); got {scale_range!r}") from None
    if len(values) != 2:
        raise ValueError(f"scale_range must be (low, high); got {scale_range!r}")
    lo, hi = values
    if not lo < hi:
        raise ValueError(
            f"scale_range must be (low, high) with low < high; got ({lo:g}, {hi:g})"
            + (" (reversed: give the direction with direction=-1)" if lo > hi else "")
        )
    return lo, hi


def _initial_theta(problem, rod, initial) -> np.ndarray:
    s = problem.mesh.s * rod.length
    if initial is None:
        return np.full(problem.n, problem.theta0)
    if callable(initial):
        theta = np.asarray(initial(s), dtype=float)
    else:
        try:
            theta = np.asarray(initial, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(
                f"initial must be a callable theta(s) or node angles of shape ({problem.n},); "
                f"got {type(initial).__name__}"
            ) from None
    if theta.shape not in ((), (problem.n,)):
        raise ValueError(
            f"initial must give node angles of shape ({problem.n},) (the mesh's nodes: "
            f"nodes = {problem.n - 1} segments) or a scalar; got shape {theta.shape}"
        )
    theta = np.broadcast_to(theta, s.shape).astype(float)
    if not np.all(np.isfinite(theta)):
        raise ValueError("initial must give finite angles")
    theta = theta.copy()
    theta[0] = problem.theta0
    return theta


def _initial_rotations(problem, rod, initial) -> np.ndarray:
    s = problem.mesh.s * rod.length
    if initial is None:
        return np.zeros((problem.n, 3))
    phi = np.asarray(initial(s) if callable(initial) else initial, dtype=float)
    if phi.shape != (problem.n, 3):
        raise ValueError(
            f"initial must give node rotation vectors of shape ({problem.n}, 3) for the "
            f"spatial model; got shape {phi.shape}"
        )
    if not np.all(np.isfinite(phi)):
        raise ValueError("initial must give finite rotation vectors")
    phi = phi.copy()
    phi[0] = 0.0
    return phi


def _finish(problem, rod, pts_u, pts_c) -> RodPath:
    scale = np.array(pts_c)
    states = np.array(pts_u)
    lin = problem.linearize(states, scale)
    spatial = hasattr(problem, "frames")
    if spatial:
        frames = problem.frames(states)
        points = problem.points(problem.positions_from_frames(frames))
        tip_angle = _tip_azimuth(frames[:, -1], problem.rotations(states)[:, -1], problem.R0)
        thetas = None
    else:
        frames = None
        thetas = problem.theta(states)
        points = problem.points(problem.positions(thetas))
        tip_angle = thetas[:, -1].copy()
    mu = np.asarray(problem.stability(lin, precise=True), float)
    mu_plane = (
        np.asarray(problem.branch_stability(lin, precise=True), float)
        if getattr(problem, "out_of_plane", None) is not None
        else mu
    )
    residuals = problem.residual_norm(lin)
    path = RodPath(
        scale=scale,
        tip=points[:, -1].copy(),
        tip_angle=tip_angle,
        stable=mu > 0,
        min_eigenvalue=mu,
        residual=np.array(residuals),
        s=problem.mesh.s * rod.length,
        _theta=thetas,
        _points=points,
        model="spatial" if spatial else "planar",
        _frames=frames,
        stable_in_plane=mu_plane > 0,
        min_eigenvalue_in_plane=mu_plane,
    )
    dc = np.diff(scale)
    events = {}
    for k in range(1, len(dc)):
        if dc[k - 1] * dc[k] < 0:  # the scale turns back: a fold between k - 1 and k + 1
            # vertex of the parabola scale(tip angle) through the three points
            phi, c3 = tip_angle[k - 1 : k + 2], scale[k - 1 : k + 2]
            ext = float(c3[1])
            if len(np.unique(phi)) == 3:
                a2, a1, a0 = np.polyfit(phi - phi[1], c3, 2)
                if a2 != 0:
                    ext = float(a0 - a1 * a1 / (4 * a2))
            events[k] = {
                "index": k + 1,
                "scale": ext,
                "tip_angle": float(tip_angle[k]),
                "kind": "fold",
            }
    for k in range(1, len(mu)):
        if (mu[k - 1] > 0) != (mu[k] > 0) and not ({k - 1, k} & events.keys()):
            # a stability change between sampled points: a fold too narrow to resolve (or a
            # bifurcation); scale by linear interpolation of the smallest eigenvalue
            w = mu[k - 1] / (mu[k - 1] - mu[k])
            events[k] = {
                "index": k,
                "scale": float(scale[k - 1] + w * (scale[k] - scale[k - 1])),
                "tip_angle": float(tip_angle[k - 1] + w * (tip_angle[k] - tip_angle[k - 1])),
                "kind": "stability",
            }
    path.limit_points = [events[k] for k in sorted(events)]
    return path
