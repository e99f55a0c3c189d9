"""``solve_rod``: planar hard-magnetic Kirchhoff rod (seed eq. 5) in any field, load sweeps."""

from __future__ import annotations

import warnings

import numpy as np

from coils._validate import as_vector, finite_scalar
from coils.field import Field

from ..errors import ConvergenceError
from ..path.events import StabilityWarning
from ..path.newton import NewtonOptions, _near_fold, newton, step_to
from ..robot.rod import Rod
from .mesh import RodMesh
from .planar import DiscreteRod
from .result import RodResult

__all__ = ["solve_rod", "DEFAULT_SEGMENTS"]

#: Default number of segments of the coarse mesh (the fine mesh has twice as many).  With
#: Richardson extrapolation this meets a tip error of 1e-6 L against the closed-form elastica
#: for lambda in [0, 50] (see tests/test_rod_physics.py and benchmarks/bench_rod.py).
DEFAULT_SEGMENTS = 64
#: Sub-steps retried when a load step lands on an unstable state from a stable one.
_RETRY_SUBSTEPS = 16
#: Scales predicted and corrected together on smooth stretches of a uniform-field sweep.
_CHUNK = 10
#: The stability eigenvalue is Richardson-extrapolated (uniform fields) when it is below this
#: fraction of the straight rod's, i.e. near a bifurcation or fold.
_EXTRAPOLATE_MU = 0.5
#: Pseudo-arclength steps allowed to go around one fold, and folds allowed per load step.
_SNAP_STEPS = 400
_MAX_SNAPS = 4


def _check_inputs(rod, field, scales, nodes, clamp_position, clamp_angle):
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
    if nodes is None:
        nodes = DEFAULT_SEGMENTS
    if isinstance(nodes, bool) or not isinstance(nodes, int | np.integer) or nodes < 4:
        raise ValueError(f"nodes must be an integer >= 4; got {nodes!r}")
    clamp = as_vector(clamp_position, "clamp_position")
    angle = finite_scalar(clamp_angle, "clamp_angle")
    return arr, int(nodes), clamp, angle


def node_magnetization(rod: Rod, mesh: RodMesh) -> np.ndarray:
    """Trapezoid node magnetization times A L^2 / (EI), body frame, shape (n, 2), 1/T.

    At a node the one-sided limits are weighted by the adjacent half-segments, so a
    magnetization jump at a node is integrated exactly by the trapezoid rule.
    """
    L = rod.length
    s = mesh.s * L
    left = rod.magnetization.vector(np.nextafter(s, -np.inf).clip(0.0, L))
    right = rod.magnetization.vector(np.nextafter(s, np.inf).clip(0.0, L))
    hl = np.concatenate([[0.0], mesh.h]) / 2
    hr = np.concatenate([mesh.h, [0.0]]) / 2
    avg = (hl[:, None] * left + hr[:, None] * right) / mesh.w[:, None]
    return avg * (rod.area * L**2 / rod.bending_stiffness)


def build_problem(
    rod: Rod, field: Field, mesh: RodMesh, clamp_position, clamp_angle
) -> DiscreteRod:
    """The discrete problem of ``rod`` in ``field`` on ``mesh`` (non-dimensional)."""
    return DiscreteRod(
        mesh,
        node_magnetization(rod, mesh),
        field,
        rod.length,
        np.asarray(clamp_position, float),
        float(clamp_angle),
    )


def make_mesh(rod: Rod, segments: int) -> RodMesh:
    """Piecewise-uniform mesh of about ``segments`` segments with nodes at the breakpoints."""
    L = rod.length
    br = np.asarray(rod.magnetization.breakpoints, dtype=float) / L
    br = br[(br > 1e-12) & (br < 1 - 1e-12)]
    return RodMesh(segments, br)


def solve_rod(
    rod: Rod,
    field: Field,
    scales,
    *,
    nodes: int | None = None,
    richardson: bool = True,
    clamp_position=(0.0, 0.0, 0.0),
    clamp_angle: float = 0.0,
    tol: float = 1e-9,
    max_iter: int = 15,
    stability: bool = True,
    progress: bool = False,
    hessian_lag: float = 0.0,
) -> RodResult:
    """Equilibria of a hard-magnetic rod in ``field`` multiplied by each of ``scales``.

    Parameters
    ----------
    rod : Rod
        Geometry, modulus and magnetization.
    field : coils.Field
        Applied field; evaluated on the deformed centreline.  Only the in-plane (x, y)
        components of B and of its gradient act (planar model).
    scales : array-like, shape (k,)
        Field multipliers, solved in order, each continued from the previous state (the first
        from the straight rod at scale 0).  Failed steps are sub-divided automatically.
    nodes : int, optional
        Segments of the coarse mesh (default :data:`DEFAULT_SEGMENTS`); a node is placed at
        every magnetization breakpoint.
    richardson : bool
        Solve on the mesh and on its halving and extrapolate (fourth order).  False: one mesh,
        second order.
    clamp_position : array-like, shape (3,)
        Clamp position, m.  The rod moves in the plane z = clamp_position[2].
    clamp_angle : float
        Tangent angle at the clamp, rad from +x.
    tol : float
        Newton tolerance on the scaled residual (non-dimensional).
    max_iter : int
        Newton iterations per attempt.
    stability : bool
        Compute the second variation of each state (``stable``, ``min_eigenvalue``).  A change
        of stability issues a :class:`StabilityWarning`; the solver stays on its branch (a
        symmetric bifurcation is not crossed silently: perturb, e.g. tilt the field, to pick a
        branch).  A load step that lands on an unstable state from a stable one is first
        retried in small sub-steps (a long step may jump onto another branch).
    progress : bool
        Show a tqdm progress bar.
    hessian_lag : float
        Quasi-Newton option for fields with a non-constant gradient: reuse the field's second
        derivatives (``field.hessian``, closed form for coils, about the cost of one gradient
        evaluation) in the Jacobian while the centreline stays within ``hessian_lag * L`` of
        where they were evaluated.  0 (default): exact Jacobian at every iterate.  The converged
        states do not depend on it (only the Jacobian does); ``1e-3`` saves about 10% of a
        coil-field solve.

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
        A scale could not be reached; ``reached`` is the last scale converged, and the message
        says whether the state there is at a limit point.

    Notes
    -----
    Solves seed eq. (5), ``EI theta'' + A t_z - A sin(theta) int_s^L f_x + A cos(theta)
    int_s^L f_y = 0``, ``theta(0) = clamp_angle``, ``theta'(L) = 0``, with ``t = m x B``,
    ``f = (grad B)^T m``, ``m = R(theta) M``, B and grad B at ``x(s) = clamp + int_0^s (cos
    theta, sin theta, 0)``.  Discretisation: :mod:`coilrod.rod_discrete` (trapezoid discrete
    energy, exact banded Newton Jacobian including the field's second derivatives from
    ``field.hessian``; cost per Newton step linear in the node count).  Uniform fields take a
    tridiagonal fast path with no force unknowns, and their refined-mesh solves are batched.

    Accuracy: tip error about 2e-8 L at lambda = 20 and 1e-7 L at lambda = 50 with the
    defaults (64 + 128 segments, Richardson), fourth order in the segment length; a boundary
    layer of width ~ L / sqrt(lambda) forms at the clamp, so lambda >> 100 needs more nodes.

    Limitations: the continuation follows one branch with finite load steps; a fold pair
    narrower than a load step (a small hysteresis loop) can be stepped over without a report
    (use finer scales or :func:`~coilrod.trace_rod`).  Out-of-plane components of B, of the
    torque and of the force are ignored (planar model).

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
    scales, nodes, clamp, angle = _check_inputs(
        rod, field, scales, nodes, clamp_position, clamp_angle
    )
    opts = NewtonOptions(tol=finite_scalar(tol, "tol"), max_iter=int(max_iter))
    mesh = make_mesh(rod, nodes)
    meshes = [mesh, mesh.refined()] if richardson else [mesh]
    problems = [build_problem(rod, field, m, clamp, angle) for m in meshes]
    lag = finite_scalar(hessian_lag, "hessian_lag")
    if lag < 0:
        raise ValueError(f"hessian_lag must be >= 0; got {lag}")
    for problem in problems:
        problem.hessian_lag = lag
    coarse = problems[0]
    k_total = scales.size
    coarse_states = np.empty((k_total, coarse.size))
    residual = np.empty(k_total)
    mu_coarse = np.full(k_total, np.nan)
    iterations = np.zeros(k_total, dtype=int)
    u, tangent, previous, history = coarse.straight(), None, 0.0, None
    snap_events: list = []
    prev_stable = True  # the straight rod at scale 0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=k_total, desc="solve_rod", unit="scale")
    k = 0
    while k < k_total:
        if coarse.uniform and history is not None and tangent is not None and k_total - k > 1:
            # smooth stretches of a uniform-field sweep: predict a chunk of scales from the
            # branch and correct them together (one batched tridiagonal Newton)
            run = _chunk(
                coarse,
                u,
                previous,
                history,
                tangent,
                scales[k : k + _CHUNK],
                opts,
                stability,
                prev_stable,
            )
            for u_j, res_j, its_j, mu_j in run:
                coarse_states[k], residual[k], iterations[k] = u_j, res_j, its_j
                mu_coarse[k] = mu_j
                history, u, previous = (u, previous), u_j, float(scales[k])
                prev_stable = mu_j > 0 if stability else True
                k += 1
            if bar is not None:
                bar.update(len(run))
            if run:
                tangent = _tangent_at(coarse, u, previous)
                if tangent is None or k >= k_total:
                    continue
                if len(run) == min(_CHUNK, k_total - (k - len(run))):
                    continue
        if k >= k_total:
            break
        # one load step (sub-stepped, snap-through and stability retries as needed)
        target = float(scales[k])
        snaps: list = []
        step = _advance(
            coarse, u, previous, target, opts, tangent, k, events=snaps, history=history
        )
        iterations[k] += step.iterations
        if stability:
            mu = coarse.min_eigenvalue(step.u, target, jac=step.jac)
            if mu <= 0 and prev_stable and target != previous:
                # a long step may land on another (unstable) branch: follow the path closely
                try:
                    retry = _advance(
                        coarse, u, previous, target, opts, tangent, k, substeps=_RETRY_SUBSTEPS
                    )
                except ConvergenceError:
                    retry = None
                if retry is not None:
                    iterations[k] += retry.iterations
                    mu_retry = coarse.min_eigenvalue(retry.u, target)
                    if mu_retry > 0:
                        step, mu = retry, mu_retry
            mu_coarse[k] = mu
            prev_stable = mu > 0
        history = (u, previous) if not snaps else None
        u, tangent = step.u, step.tangent
        coarse_states[k] = u
        residual[k] = (
            step.residual
            if np.isfinite(step.residual)
            else coarse.residual_norm(coarse.residual(u, target))
        )
        for fold, landing in snaps:
            snap_events.append(
                {
                    "index": k,
                    "scale": float(fold),
                    "landing": float(landing),
                    "stable": True,
                    "kind": "snap",
                }
            )
            warnings.warn(
                f"snap-through: the equilibrium branch ends at a limit point at scale {fold:.6g} "
                f"(between scales {previous:g} and {target:g}); the rod jumps to another stable "
                f"branch (continued from scale {landing:.6g})",
                StabilityWarning,
                stacklevel=2,
            )
        previous = target
        k += 1
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    if richardson:
        fine_states = _solve_fine(problems, coarse_states, scales, opts, residual, iterations)
        all_states = [coarse_states, fine_states]
    else:
        all_states = [coarse_states]
    thetas, points = _extrapolate(problems, all_states)
    min_eig = mu_coarse
    if stability and richardson and coarse.uniform:
        # near a loss of stability sharpen the estimate (it locates the critical scale)
        near = np.abs(mu_coarse) < _EXTRAPOLATE_MU * coarse.mu0
        for k in np.flatnonzero(near):
            mu_fine = problems[1].min_eigenvalue(fine_states[k], float(scales[k]))
            min_eig[k] = (4 * mu_fine - mu_coarse[k]) / 3
    stable = min_eig > 0 if stability else np.ones(k_total, dtype=bool)
    result = RodResult(
        scales=scales.copy(),
        s=mesh.s * rod.length,
        tip=points[:, -1, :].copy(),
        tip_angle=thetas[:, -1].copy(),
        converged=residual <= max(opts.tol, problems[-1].tol_floor),
        stable=stable,
        residual=residual,
        min_eigenvalue=min_eig,
        iterations=iterations,
        segments=nodes,
        _theta=thetas,
        _points=points,
    )
    if stability:
        _report_instabilities(result)
    result.instabilities = sorted(
        result.instabilities + snap_events, key=lambda e: (e["index"], e["scale"])
    )
    return result


def _chunk(problem, u, previous, history, tangent, chunk, opts, stability, prev_stable):
    """Batch-continue a uniform-field branch over ``chunk`` (scales after ``previous``).

    Predictions: the quadratic (Hermite) extrapolation through the last two states with the
    tangent at the last.  A scale is accepted if Newton converged there with a correction of
    at most ``opts.max_correction`` (no jump to another branch) and, with ``stability``, if it
    does not lose stability; the leading run of accepted scales is returned as a list of
    ``(u, residual, iterations, mu)``.  The rest is left to the sequential load stepping.
    """
    h = previous - history[1]
    d = np.asarray(chunk, dtype=float) - previous
    if h == 0 or np.any(d * h <= 0) or np.any(np.diff(d) * h <= 0):
        return []  # only monotone continuations of the current direction
    curv = (history[0] - u + tangent * h) / (h * h)
    preds = u + d[:, None] * tangent + (d * d)[:, None] * curv
    th, ok, res, its = problem.newton_batch(preds, chunk, opts)
    good = ok & (np.max(np.abs(th - preds), axis=1) <= opts.max_correction)
    n_good = len(chunk) if good.all() else int(np.argmin(good))
    if stability and n_good:
        mus = problem.min_eigenvalue_batch(th[:n_good], np.asarray(chunk[:n_good], float))
    run = []
    for j in range(n_good):
        mu = mus[j] if stability else np.nan
        if stability and mu <= 0 and prev_stable:
            break  # leave the loss of stability to the sequential path (retry and report)
        prev_stable = mu > 0 if stability else True
        run.append((th[j], float(res[j]), int(its[j]), mu))
    return run


def _tangent_at(problem, u, scale):
    """du/dscale at a converged state (None if the Jacobian is singular)."""
    from ..path.newton import _tangent

    return _tangent(problem, u, scale)


def _solve_fine(problems, coarse_states, scales, opts, residual, iterations):
    """Fine-mesh states for every scale, each by Newton from its interpolated coarse state
    (independent problems: batched in one tridiagonal system for a uniform field)."""
    coarse, fine = problems
    k_total = len(scales)
    guesses = np.array([coarse.interpolate_to(fine, u) for u in coarse_states])
    out = np.empty_like(guesses)
    todo = np.arange(k_total)
    if fine.uniform:
        out, ok, res, its = fine.newton_batch(guesses, scales, opts)
        iterations += its
        residual[ok] = np.maximum(residual[ok], res[ok])
        todo = np.flatnonzero(~ok)
    for k in todo:
        target = float(scales[k])
        u_new, ok_k, res_k, it, _ = newton(fine, guesses[k], target, opts)
        iterations[k] += it
        if not ok_k:
            raise ConvergenceError(
                f"solve_rod could not reach scale {target:g} (index {k}) on the refined mesh "
                f"from the coarse solution (residual {res_k:.3g})",
                reached=float(scales[k - 1]) if k else 0.0,
                target=target,
                residual=res_k,
            )
        out[k] = u_new
        residual[k] = max(residual[k], res_k)
    return out


def _extrapolate(problems, states):
    """Node angles (k, n) and points (k, n, 3) on the coarse nodes, Richardson-extrapolated
    if two meshes; ``states`` holds the unknowns of each mesh, shape (k, size)."""
    coarse = problems[0]
    th_c = coarse.theta_batch(states[0])
    x_c = coarse.positions_batch(th_c)
    if len(problems) == 1:
        return th_c, coarse.points_batch(x_c)
    fine = problems[1]
    th_f = fine.theta_batch(states[1])
    x_f = fine.positions_batch(th_f)
    theta = (4 * th_f[:, ::2] - th_c) / 3
    x = (4 * x_f[:, ::2] - x_c) / 3
    return theta, coarse.points_batch(x)


def _advance(problem, u, previous, target, opts, tangent, k, substeps=1, events=None, history=None):
    """Continue ``u`` from ``previous`` to ``target`` (in ``substeps`` equal steps).

    A step that stops at a limit point (smallest second-variation eigenvalue near zero) is
    continued by pseudo-arclength around the fold until the path comes back, stable, beyond
    the fold scale: the snap-through of a quasi-static load.  Each snap is appended to
    ``events`` as ``(fold_scale, landing_scale)``.
    """
    total = 0
    subs = [target] if substeps == 1 else np.linspace(previous, target, substeps + 1)[1:]
    for sub in subs:
        sub = float(sub)
        for _ in range(_MAX_SNAPS + 1):
            step = step_to(problem, u, previous, sub, opts, tangent=tangent, previous=history)
            total += step.iterations
            if step.ok:
                break
            landing = _snap(problem, step, sub, opts)
            if landing is None:
                why = (
                    f"residual {step.residual:.3g}"
                    if np.isfinite(step.residual)
                    else "the field could not be evaluated at the trial states"
                )
                raise ConvergenceError(
                    f"solve_rod could not reach scale {target:g} (index {k}); it reached scale "
                    f"{step.reached:g} ({why}){_fold_hint(problem, step)}",
                    reached=step.reached,
                    target=target,
                    residual=step.residual,
                )
            if events is not None:
                events.append((step.reached, landing[1]))
            u, previous, tangent, history = landing[0], landing[1], None, None
        else:
            raise ConvergenceError(
                f"solve_rod could not reach scale {target:g} (index {k}): more than "
                f"{_MAX_SNAPS} snap-throughs in one step",
                reached=previous,
                target=target,
                residual=step.residual,
            )
        history = (u, previous)
        u, previous, tangent = step.u, sub, step.tangent
    step.iterations = total
    return step


def _snap(problem, step, target, opts):
    """From a state stuck at a fold, follow the path around it until it is stable again at a
    scale beyond the fold; ``(u, scale)`` or None (not a fold, or the path does not return)."""
    from ..path.arclength import ArcLength

    if not _near_fold(problem, step.u, step.reached):
        return None
    direction = 1 if target > step.reached else -1
    span = max(abs(target - step.reached), 1e-3 * abs(step.reached), 1e-300)
    tracer = ArcLength(problem, span, opts)
    for u, c, _ in tracer.follow(step.u, step.reached, direction, _SNAP_STEPS):
        beyond = (c - step.reached) * direction > 0
        if beyond and problem.min_eigenvalue(u, c) > 0:
            return u, c
    return None


def _fold_hint(problem, step) -> str:
    """Say whether the last converged state is close to a limit point (snap-through)."""
    try:
        mu = problem.min_eigenvalue(step.u, step.reached)
    except (ValueError, np.linalg.LinAlgError):
        return ""
    if mu < 0.05 * problem.mu0:
        return (
            f"; the smallest eigenvalue of the second variation there is {mu:.3g}: "
            "a limit point (fold), the rod snaps through beyond it -- trace it with "
            "coilrod.trace_rod"
        )
    return f"; smallest second-variation eigenvalue there {mu:.3g}"


def _report_instabilities(result: RodResult) -> None:
    mu = result.min_eigenvalue
    for k in range(1, len(mu)):
        if result.stable[k] == result.stable[k - 1]:
            continue
        a, b = result.scales[k - 1], result.scales[k]
        crit = a + (b - a) * mu[k - 1] / (mu[k - 1] - mu[k]) if mu[k - 1] != mu[k] else b
        result.instabilities.append(
            {"index": k, "scale": float(crit), "stable": bool(result.stable[k])}
        )
        what = "regained" if result.stable[k] else "lost"
        warnings.warn(
            f"the equilibrium branch {what} stability between scales {a:g} and {b:g} "
            f"(estimated critical scale {crit:.6g}): a bifurcation or limit point",
            StabilityWarning,
            stacklevel=3,
        )
