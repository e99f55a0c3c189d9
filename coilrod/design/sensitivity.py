"""Exact sensitivities of a solved rod state: derivatives of the tip by the adjoint method.

At a converged state the residual vanishes, ``R(u, p) = 0``, so for any parameter ``p`` and
output ``q(u)`` (tip x, y and tip angle)

    dq/dp = -lambda^T dR/dp,        J^T lambda = dq/du,

one transposed solve with the state's own factorised Newton Jacobian ``J`` per output (three),
whatever the number of parameters.  ``dR/dp`` is never formed: the magnetic load is linear in
the node magnetization and in the field and its gradient at each node, so
``lambda^T dR/dp`` is a sum over nodes of closed-form adjoint loads
(:meth:`coilrod.rod.planar.PlanarRod.load_adjoint`) times the parameter's own change of the
node magnetization or of the field (a unit current's field, a unit field component, ...).
With Richardson extrapolation the derivative is extrapolated like the tip itself:
``(4 d_fine - d_coarse) / 3``, the exact derivative of the reported tip.

At a bifurcation or limit point ``J`` is singular and the derivative does not exist (the tip
is not a differentiable function of the parameters there): :func:`sensitivities` says so.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

import coils

from ..robot.magnetization import Magnetization
from ..rod.mesh import segment_weights

__all__ = ["sensitivities", "Sensitivities", "Derivative", "PARAMETER_GROUPS", "SingularStateError"]

#: Parameter groups, their units and what they need.
PARAMETER_GROUPS = {
    "magnitudes": "A/m",
    "angles": "rad",
    "youngs_modulus": "Pa",
    "scale": "1",
    "B": "T",
    "B0": "T",
    "gradient": "T/m",
    "currents": "A",
}
#: |smallest second-variation eigenvalue| below this fraction of the straight rod's: the
#: state is at a bifurcation or fold and the derivative does not exist.
SINGULAR = 1e-7


class SingularStateError(ValueError):
    """The state is at a bifurcation or limit point: the tip is not differentiable there."""


@dataclass(frozen=True)
class Derivative:
    """Derivatives of the tip with respect to one group of parameters.

    Attributes
    ----------
    labels : tuple of str, length p
        Parameter names, e.g. ``magnitudes[2]``.
    tip : ndarray, shape (p, 3)
        d(tip position)/d(parameter), m per unit of the parameter.
    tip_angle : ndarray, shape (p,)
        d(tip angle)/d(parameter), rad per unit of the parameter.
    unit : str
        Unit of the parameters.
    """

    labels: tuple
    tip: np.ndarray
    tip_angle: np.ndarray
    unit: str


@dataclass(frozen=True)
class Sensitivities:
    """Derivatives of the tip of state ``index`` of a result (see :func:`sensitivities`).

    Attributes
    ----------
    index : int
        The state.
    scale : float
        Its load scale.
    parameters : tuple of str, length p
        Parameter labels, grouped (``magnitudes[0]``, ..., ``youngs_modulus``, ``B[0]``...).
    groups : dict
        Group name -> slice into ``parameters``.
    units : tuple of str, length p
        Unit of each parameter.
    values : ndarray, shape (p,)
        The parameters' values at this state (SI units).
    tip : ndarray, shape (p, 3)
        d(tip position)/d(parameter), m per parameter unit.
    tip_angle : ndarray, shape (p,)
        d(tip angle)/d(parameter), rad per parameter unit.
    """

    index: int
    scale: float
    parameters: tuple
    groups: dict
    units: tuple
    values: np.ndarray
    tip: np.ndarray
    tip_angle: np.ndarray

    def __getitem__(self, group: str) -> Derivative:
        if group not in self.groups:
            raise KeyError(f"no parameter group {group!r}; this one has {sorted(self.groups)}")
        sl = self.groups[group]
        return Derivative(
            self.parameters[sl], self.tip[sl], self.tip_angle[sl], PARAMETER_GROUPS[group]
        )

    @property
    def matrix(self) -> np.ndarray:
        """The Jacobian of (tip x, tip y, tip z, tip angle) with respect to the parameters,
        shape (4, p) (m and rad per parameter unit)."""
        return np.vstack([self.tip.T, self.tip_angle[None]])

    def __repr__(self) -> str:
        rows = [f"Sensitivities of state {self.index} (scale {self.scale:g})"]
        for name, unit, d, a in zip(
            self.parameters, self.units, self.tip, self.tip_angle, strict=True
        ):
            rows.append(
                f"  {name:>16s}: dtip = ({d[0]: .4g}, {d[1]: .4g}, {d[2]: .4g}) m/{unit}, "
                f"dangle = {a: .4g} rad/{unit}"
            )
        return "\n".join(rows)


# -- parameters ---------------------------------------------------------------------------------
def _segments(magnetization: Magnetization, length: float):
    """(edges, magnitudes, angles) of a piecewise-constant profile (a constant one is a single
    segment), or None for a profile given by functions."""
    if hasattr(magnetization, "segment_edges"):
        return (
            np.asarray(magnetization.segment_edges, float),
            np.asarray(magnetization.segment_magnitudes, float),
            np.asarray(magnetization.segment_angles, float),
        )
    if magnetization.is_constant:
        s = np.array([0.0])
        return (
            np.array([0.0, length]),
            magnetization.magnitude(s)[:1].copy(),
            magnetization.angle(s)[:1].copy(),
        )
    return None


def _unit_field_groups(field) -> dict:
    """Field parameter groups of ``field``: name -> (labels, values, evaluate) with
    ``evaluate(points (N, 3)) -> (B (N, 3, p) T per unit, G (N, 3, 3, p))``."""
    groups = {}
    if isinstance(field, coils.UniformField):

        def uniform(points):
            n = points.shape[0]
            return np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3, 3, 3))

        groups["B"] = ([f"B[{i}]" for i in range(3)], field.B0.copy(), uniform)
    elif isinstance(field, coils.LinearField):
        origin = field.origin

        def offset(points):
            n = points.shape[0]
            return np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3, 3, 3))

        def gradient(points):
            d = points - origin  # B_a = G[a, b] d_b
            n = points.shape[0]
            B = np.zeros((n, 3, 3, 3))
            G = np.zeros((n, 3, 3, 3, 3))
            for a in range(3):
                B[:, a, a, :] = d
                for b in range(3):
                    G[:, a, b, a, b] = 1.0
            return B.reshape(n, 3, 9), G.reshape(n, 3, 3, 9)

        groups["B0"] = ([f"B0[{i}]" for i in range(3)], field.B0.copy(), offset)
        labels = [f"gradient[{a},{b}]" for a in range(3) for b in range(3)]
        groups["gradient"] = (labels, field.G.ravel().copy(), gradient)
    if hasattr(field, "with_current") and not hasattr(field, "unit_fields"):
        unit = field.with_current(1.0)  # a single coil or pair: one current channel

        def one_channel(points):
            B, G = unit.B_and_gradient(points)
            return B[..., None], G[..., None]

        groups["currents"] = (["currents[0]"], np.array([field.current], float), one_channel)
    if hasattr(field, "unit_fields") and hasattr(field, "currents"):
        currents = np.asarray(field.currents, float)
        groups["currents"] = (
            [f"currents[{i}]" for i in range(currents.size)],
            currents,
            field.unit_fields,
        )
    return groups


def available(result) -> list[str]:
    """The parameter groups a rod result's states have."""
    sol = _solution(result)
    out = []
    if _segments(sol.rod.magnetization, sol.rod.length) is not None:
        out += ["magnitudes", "angles"]
    out += ["youngs_modulus", "scale"]
    out += list(_unit_field_groups(sol.field))
    return out


def _solution(result):
    sol = getattr(result, "_solution", None)
    if sol is None:
        raise ValueError(
            f"sensitivities need a coilrod.RodResult from solve_rod; got {type(result).__name__}"
        )
    return sol


def _groups(wrt, have: list[str], what: str) -> list[str]:
    """The requested parameter groups (default: all the state has), validated: ValueError for
    an unknown group or one the state (described by ``what``) does not have."""
    if wrt is None:
        return list(have)
    wrt = [wrt] if isinstance(wrt, str) else list(wrt)
    if not wrt:
        raise ValueError("wrt must name at least one parameter group")
    for name in wrt:
        if name not in PARAMETER_GROUPS:
            raise ValueError(
                f"unknown parameter group {name!r}; the groups are {sorted(PARAMETER_GROUPS)}"
            )
        if name not in have:
            raise ValueError(f"this state has no parameter {name!r} ({what}); it has {have}")
    return list(dict.fromkeys(wrt))


def _check_wrt(result, wrt) -> list[str]:
    sol = _solution(result)
    what = f"rod magnetization {sol.rod.magnetization!r}, field {type(sol.field).__name__}"
    return _groups(wrt, available(result), what)


# -- the computation ----------------------------------------------------------------------------
def _magnetization_rates(rod, mesh, group: str, dim: int = 2) -> np.ndarray:
    """d(mu_i)/dp of the segment magnitudes or angles, shape (p, n, dim), in the problem's
    units (1/T per A/m, or per rad): the body vector (cos a cos e, sin a cos e, sin e) of each
    segment's angle a and elevation e (its first two components for the planar rod, whose
    magnetization has e = 0)."""
    edges, mags, angs = _segments(rod.magnetization, rod.length)
    elev = np.asarray(getattr(rod.magnetization, "segment_elevations", np.zeros_like(angs)))
    factor = rod.area * rod.length**2 / rod.bending_stiffness
    cache = mesh.__dict__.setdefault("_segment_weights", {})
    key = (tuple(edges), rod.length)
    if key not in cache:
        cache[key] = segment_weights(edges, mesh, rod.length)
    W = cache[key] * factor  # (n, p)
    ce = np.cos(elev)
    if group == "magnitudes":  # unit magnitude on segment j, its own direction
        u = np.stack([np.cos(angs) * ce, np.sin(angs) * ce, np.sin(elev)], axis=-1)
    else:  # |M_j| turned by a right angle about the binormal on segment j
        u = mags[:, None] * np.stack([-np.sin(angs) * ce, np.cos(angs) * ce, 0 * ce], axis=-1)
    return W.T[:, :, None] * u[:, None, :dim]


def _mesh_derivatives(problem, U, S, rod, groups, field_groups, lin=None):
    """d(tip x, y [units of L], angle [rad])/dp for the states U (k, size) of one mesh:
    shape (k, 3, p), parameters in the order of ``groups``."""
    if lin is None:
        lin = problem.linearize(U, S)
    lam = lin.tangent.solve_transposed(problem.tip_gradients(U))  # (3, k, size)
    if not np.all(np.isfinite(lam)):
        raise SingularStateError(
            "the Jacobian of the state is singular: it is at a bifurcation or limit point, "
            "where the tip is not differentiable"
        )
    R1 = lin.load_rate  # (k, size), dR/dscale
    lamR1 = np.einsum("qks,ks->kq", lam, R1)  # (k, 3)
    fv = getattr(lin, "field_values", None)
    B, G = fv if fv is not None else problem.field_at_states(U)
    k, n = U.shape[0], problem.n
    g_mu, g_b, g_G = problem.load_adjoint(U, lam, B, G)  # (3, k, n, ...)
    cols = []
    for group in groups:
        if group == "scale":
            cols.append(-lamR1[:, :, None])
        elif group == "youngs_modulus":  # mu ~ 1/E
            cols.append((S[:, None] / rod.youngs_modulus * lamR1)[:, :, None])
        elif group in ("magnitudes", "angles"):
            dmu = _magnetization_rates(rod, problem.mesh, group)
            d = g_mu.reshape(3 * k, -1) @ dmu.reshape(dmu.shape[0], -1).T  # (3 k, p)
            cols.append(-S[:, None, None] * d.reshape(3, k, -1).transpose(1, 0, 2))
        else:
            _, _, evaluate = field_groups[group]
            points = problem.points(problem.node_positions(U)).reshape(-1, 3)
            Bp, Gp = evaluate(points)
            Bp = np.asarray(Bp).reshape(k, n, 3, -1)[:, :, :2]
            Gp = np.asarray(Gp).reshape(k, n, 3, 3, -1)[:, :, :2, :2]
            d = _contract(g_b, Bp)
            if g_G is not None:
                d += _contract(g_G, Gp)
            elif np.any(Gp):
                raise AssertionError("a gradient parameter needs the mixed layout")
            cols.append(-S[:, None, None] * d)
    return np.concatenate(cols, axis=2)


def _pushes_out_of_plane(sol, rows, groups, field_groups) -> bool:
    """True if a field parameter of ``groups`` changes B_z or dB_z/dx, dB_z/dy at the nodes
    of the planar states ``rows`` (relative 1e-12 of the field's own size)."""
    from ..rod.model import leaves_plane

    problem, U = sol.problems[0], sol.states[0][rows]
    points = problem.points(problem.node_positions(U)).reshape(-1, 3)
    return any(
        leaves_plane(*field_groups[group][2](points), sol.rod.length)
        for group in groups
        if group in field_groups
    )


def _as_spatial(sol, rows, S, mixed=False):
    """The spatial problems on the meshes of a planar solution and the states ``rows`` (scales
    ``S``) carried over -- rotations about z by theta - theta_0, the same discrete equilibria:
    (problems, states), each state stack of shape (len(rows), size)."""
    from ..rod.model import clamp_frame
    from ..rod.solve import build_spatial_problem

    problems, states = [], []
    for problem, U in zip(sol.problems, sol.states, strict=True):
        if hasattr(problem, "rotations"):  # spatial already (to the mixed layout)
            R0, phi = problem.R0, problem.rotations(np.atleast_2d(U)[rows])
        else:
            R0 = clamp_frame(problem.theta0, None)
            th = problem.theta(np.atleast_2d(U)[rows])
            phi = np.zeros(th.shape + (3,))
            phi[..., 2] = th - problem.theta0
        sp = build_spatial_problem(
            sol.rod, sol.field, problem.mesh, problem.clamp, R0, problem.tol, mixed
        )
        states.append(np.array([sp.from_rotations(p, c) for p, c in zip(phi, S, strict=True)]))
        problems.append(sp)
    return tuple(problems), tuple(states)


def _spatial_mesh_derivatives(problem, U, S, rod, groups, field_groups, rotation=False):
    """d(tip x, y, z [units of L], azimuth [rad])/dp of spatial states U (k, size) on one
    mesh by the adjoint of the state's Jacobian: shape (k, 4, p); with ``rotation`` (k, 7, p),
    rows 4:7 the tip frame's rotation (rad, world axes; see ``SpatialRod.tip_gradients``)."""
    lin = problem.linearize(U, S)
    grads = problem.tip_gradients(U, rotation=True) if rotation else problem.tip_gradients(U)
    lam = lin.tangent.solve_transposed(grads)  # (4 or 7, k, size)
    if not np.all(np.isfinite(lam)):
        raise SingularStateError(
            "the Jacobian of the state is singular: it is at a bifurcation or limit point, "
            "where the tip is not differentiable"
        )
    lamR1 = np.einsum("qks,ks->kq", lam, lin.load_rate)  # (k, 4 or 7)
    k, n = U.shape[0], problem.n
    cols = []
    for group in groups:
        if group == "scale":
            cols.append(-lamR1[:, :, None])
        elif group == "youngs_modulus":  # mu ~ 1/E, the stiffness ratios do not change
            cols.append((S[:, None] / rod.youngs_modulus * lamR1)[:, :, None])
        else:
            if group in ("magnitudes", "angles"):
                rates = problem.load_rates(
                    U, dmu=_magnetization_rates(rod, problem.mesh, group, dim=3)
                )
            else:
                _, _, evaluate = field_groups[group]
                points = problem.points(problem.node_positions(U)).reshape(-1, 3)
                Bp, Gp = evaluate(points)
                Bp = np.asarray(Bp).reshape(k, n, 3, -1)
                Gp = np.asarray(Gp).reshape(k, n, 3, 3, -1)
                rates = problem.load_rates(U, B=Bp, G=Gp)
            d = np.einsum("qks,ksp->kqp", lam, rates)
            cols.append(-S[:, None, None] * d)
    return np.concatenate(cols, axis=2)


def _contract(g: np.ndarray, F: np.ndarray) -> np.ndarray:
    """sum over nodes and components of g (q, k, n, ...) times F (k, n, ..., p): (k, q, p)."""
    q, k = g.shape[:2]
    return np.matmul(g.reshape(q, k, -1).transpose(1, 0, 2), F.reshape(k, -1, F.shape[-1]))


def _as_mixed(problem, U):
    """The problem in the mixed layout and the states carried over (uniform fields: positions
    from the angles, zero force resultants -- the same equilibrium)."""
    from ..rod.planar import PlanarRod

    mixed = PlanarRod(
        problem.mesh,
        problem.mu,
        problem.field,
        problem.L,
        problem.clamp,
        problem.theta0,
        problem.tol,
        mixed=True,
    )
    return mixed, np.array([mixed.from_theta(problem.theta(u)) for u in np.atleast_2d(U)])


def _parameters(rod, groups, field_groups) -> tuple[list[str], list[str], np.ndarray]:
    """Labels, units and values (SI; NaN for the per-state scale) of the parameters of
    ``groups``, in order."""
    labels, units, values = [], [], []
    for group in groups:
        if group in ("magnitudes", "angles"):
            _, mags, angs = _segments(rod.magnetization, rod.length)
            val = mags if group == "magnitudes" else angs
            lab = [f"{group}[{j}]" for j in range(val.size)]
        elif group == "youngs_modulus":
            lab, val = ["youngs_modulus"], np.array([rod.youngs_modulus])
        elif group == "scale":
            lab, val = ["scale"], np.array([np.nan])  # per state; filled by sensitivities()
        else:
            lab, val, _ = field_groups[group]
        labels += list(lab)
        units += [PARAMETER_GROUPS[group]] * len(lab)
        values.append(np.asarray(val, float))
    return labels, units, np.concatenate(values)


def _tip_rotation(problems, states, a):
    """The tip tangent (k, 3) of the reported frames and its rates (k, 3, p), from the tip
    frame rotations ``a`` (one (k, 3, p) per mesh, world axes, rad) of the meshes' states.

    One mesh: t = R_N e1, dt = a x t.  Two (Richardson on SO(3), as the solve reports the
    frames): R = R_f exp(-w / 3) with w = log(R_f^T R_c), whose rotation is exactly
    ``a = a_f - R_f J_l(-w/3) J_l(w)^-1 R_f^T (a_c - a_f) / 3`` (the first-order change of
    w is J_l(w)^-1 R_f^T (a_c - a_f)); to leading order the linear (4 a_f - a_c) / 3."""
    from ..rod.so3 import expm, hat, left_jacobian, logm

    frames = [p.frames(U)[:, -1] for p, U in zip(problems, states, strict=True)]
    if len(frames) == 1:
        R, rate = frames[0], a[0]
    else:
        Rc, Rf = frames
        w = logm(np.swapaxes(Rf, -1, -2) @ Rc)  # (k, 3)
        R = Rf @ expm(-w / 3)
        P = Rf @ left_jacobian(-w / 3) @ np.linalg.inv(left_jacobian(w)) @ np.swapaxes(Rf, -1, -2)
        rate = a[1] - P @ (a[0] - a[1]) / 3
    t = R[:, :, 0]
    return t, -hat(t) @ rate


def tip_derivatives(result, rows, wrt=None, *, check: bool = True, tangent: bool = False):
    """Batched sensitivities of the states ``rows`` of a rod result (see
    :func:`sensitivities`): returns (labels, units, values, D) with D of shape (k, 4, p):
    d(tip x, y, z [m], tip angle [rad])/dp; with ``tangent``, shape (k, 7, p): rows 4:7 the
    derivatives of the unit tip tangent (the first column of ``result.frames(k)[-1]``),
    1 per parameter unit (planar states whose parameters keep the field in the plane: the
    tangent (cos theta, sin theta, 0) turned by d(tip angle))."""
    sol = _solution(result)
    groups = _check_wrt(result, wrt)
    rows = np.atleast_1d(np.asarray(rows, dtype=int))
    rod = sol.rod
    field_groups = _unit_field_groups(sol.field)
    S = np.asarray(result.scales, float)[rows]
    labels, units, values = _parameters(rod, groups, field_groups)
    if check:
        _check_regular(result, sol, rows, S)
    per_mesh = []
    spatial = getattr(result, "model", "planar") == "spatial"
    problems, all_states = sol.problems, sol.states
    gradient = "gradient" in groups and sol.problems[0].uniform
    if (not spatial and _pushes_out_of_plane(sol, rows, groups, field_groups)) or (
        spatial and gradient
    ):
        # a planar state whose parameter moves the field out of the plane: its tip leaves
        # the plane at first order -- the spatial model at the same (planar) state has it;
        # a gradient parameter needs the force unknowns (mixed layout)
        problems, all_states = _as_spatial(sol, rows, S, mixed=gradient)
        spatial = True
        rows_in = np.arange(rows.size)
    else:
        rows_in = rows
    for problem, states in zip(problems, all_states, strict=True):
        U = states[rows_in]
        if spatial:
            per_mesh.append(
                _spatial_mesh_derivatives(problem, U, S, rod, groups, field_groups, tangent)
            )
            continue
        if problem.uniform and "gradient" in groups:
            problem, U = _as_mixed(problem, U)
        per_mesh.append(_mesh_derivatives(problem, U, S, rod, groups, field_groups))
    d = per_mesh[0] if len(per_mesh) == 1 else (4 * per_mesh[1] - per_mesh[0]) / 3
    if spatial:
        D = d.copy()
        D[:, 0:3] *= rod.length  # units of L -> m
        if tangent:  # the tangent of the frames as reported (Richardson on SO(3))
            states = [U[rows_in] for U in all_states]
            _, D[:, 4:7] = _tip_rotation(problems, states, [m[:, 4:7] for m in per_mesh])
        return labels, units, values, D
    D = np.zeros((rows.size, 7 if tangent else 4, d.shape[2]))
    D[:, 0:2] = rod.length * d[:, 0:2]  # units of L -> m
    D[:, 3] = d[:, 2]
    if tangent:  # t = (cos theta, sin theta, 0)
        theta = np.asarray(result.tip_angle, float)[rows]
        D[:, 4] = -np.sin(theta)[:, None] * d[:, 2]
        D[:, 5] = np.cos(theta)[:, None] * d[:, 2]
    return labels, units, values, D


def _check_regular(result, sol, rows, S):
    """SingularStateError if a state is at a bifurcation or fold."""
    problem = sol.problems[0]
    mu = result._min_eigenvalue
    if callable(mu):
        lin = problem.linearize(sol.states[0][rows], S)
        mu = np.asarray(problem.branch_stability(lin, precise=True), float)
    else:
        mu = np.asarray(mu, float)[rows]
    bad = np.flatnonzero(np.isfinite(mu) & (np.abs(mu) < SINGULAR * problem.mu0))
    if bad.size:
        j = int(rows[bad[0]])
        raise SingularStateError(
            f"state {j} (scale {result.scales[j]:g}) is at a bifurcation or limit point "
            f"(smallest second-variation eigenvalue {mu[bad[0]]:.3g}, straight rod "
            f"{problem.mu0:.3g}): the tip is not differentiable there, the derivative does "
            "not exist"
        )


# -- FEM results ----------------------------------------------------------------------------------
FEM_GROUPS = ("scale", "youngs_modulus", "magnitudes", "angles", "B", "currents")


def _fem_available(result) -> list[str]:
    asm = result._asm
    field = asm.field
    rod = result._asm.rod
    out = ["scale", "youngs_modulus"]
    if rod.magnetization.is_planar and _segments(rod.magnetization, rod.length) is not None:
        out += ["magnitudes", "angles"]
    if isinstance(field, coils.UniformField):
        out.append("B")
    if hasattr(field, "with_current") and not hasattr(field, "unit_fields"):
        out.append("currents")
    return out


def _fem_sensitivities(result, k: int, wrt) -> Sensitivities:
    """Sensitivities of a FEM state by the direct method: one solve with the state's
    factorised tangent per parameter.

    The load enters the residual as ``scale * R1(z; M, B)``, linear in the magnetization at the
    quadrature points and in the field, so ``dR/dp = scale * R1(z; dM/dp or dB/dp)``.  The
    moduli are proportional to E at a fixed Poisson ratio, so the state depends on E and the
    scale only through scale / E: ``dq/dE = -(scale / E) dq/dscale`` (exact)."""
    import copy

    from ..fem.problem import FEMProblem

    asm = result._asm
    rod = asm.rod
    if not rod.magnetization.is_planar:  # the segment rates below are those of planar M
        asked = [wrt] if isinstance(wrt, str) else list(wrt or ())
        if "magnitudes" in asked or "angles" in asked:
            rod.magnetization.check_planar("FEM sensitivities to magnitudes and angles")
    groups = _groups(wrt, _fem_available(result), f"FEM, field {type(asm.field).__name__}")
    z, s = result._states[k], float(result.scales[k])
    problem = FEMProblem(asm, 1e-8, 1e-8)
    lin = problem.linearize(z, s)
    if not lin.ok:
        raise ValueError(f"FEM state {k} could not be evaluated")

    def rate(**swap):
        other = copy.copy(asm)
        for name, value in swap.items():
            setattr(other, name, value)
        out = np.zeros(problem.size)
        out[: asm.nfree] = other.evaluate(z, 1.0, tangent=False).load_rate
        return out

    labels, units, values, cols = [], [], [], []
    R1 = problem.d_residual_d_scale(lin)
    for g in groups:
        if g in ("scale", "youngs_modulus"):
            lab, val, col = [g], [s if g == "scale" else rod.youngs_modulus], [R1]
        elif g in ("magnitudes", "angles"):
            edges, mags, angs = _segments(rod.magnetization, rod.length)
            sq = asm.X[..., 0]
            seg = np.clip(np.searchsorted(edges, sq, side="right") - 1, 0, mags.size - 1)
            lab, val, col = [], [], []
            for j in range(mags.size):
                dM = np.zeros_like(asm.M)
                on = seg == j
                if g == "magnitudes":
                    dM[on, 0], dM[on, 1] = np.cos(angs[j]), np.sin(angs[j])
                else:
                    dM[on, 0], dM[on, 1] = -mags[j] * np.sin(angs[j]), mags[j] * np.cos(angs[j])
                lab.append(f"{g}[{j}]")
                val.append((mags if g == "magnitudes" else angs)[j])
                col.append(s * rate(M=dM))
        elif g == "B":
            lab = [f"B[{i}]" for i in range(3)]
            val = list(asm.field.B0)
            col = [s * rate(field=coils.UniformField(B=np.eye(3)[i])) for i in range(3)]
        else:  # currents of a single coil or pair
            lab, val = ["currents[0]"], [asm.field.current]
            col = [s * rate(field=asm.field.with_current(1.0))]
        labels += lab
        units += [PARAMETER_GROUPS[g]] * len(lab)
        values += list(val)
        cols += col
    dz = np.array([-problem.solve(lin, c) for c in cols])  # (p, size)
    origin = asm.tip(np.zeros(problem.size))
    tip = np.array([asm.tip(d) - origin for d in dz])
    angle = _fem_angle_rates(result, asm, z, dz)
    if "youngs_modulus" in labels:  # through scale / E: d/dE = -(scale / E) d/dscale
        i = labels.index("youngs_modulus")
        tip[i] *= -s / rod.youngs_modulus
        angle[i] *= -s / rod.youngs_modulus
    groups_sl, start = {}, 0
    for g in groups:
        n = sum(1 for lab in labels if lab == g or lab.startswith(g + "["))
        groups_sl[g] = slice(start, start + n)
        start += n
    return Sensitivities(
        index=k,
        scale=s,
        parameters=tuple(labels),
        groups=groups_sl,
        units=tuple(units),
        values=np.asarray(values, float),
        tip=tip,
        tip_angle=angle,
    )


def _fem_angle_rates(result, asm, z, dz) -> np.ndarray:
    """d(tip angle) for state increments dz (p, size): the angle of the image ``a`` of the
    end face's y axis (least-squares fit of the face, as :attr:`FEMResult.tip_angle`)."""
    X = asm.nodes
    face = np.abs(X[0] - asm.length) <= 1e-9 * asm.length
    cols = [np.ones(face.sum()), X[1, face]] + ([X[2, face]] if asm.dim == 3 else [])
    pinv = np.linalg.pinv(np.column_stack(cols))[1]  # a = pinv @ x_face
    x = (X + asm.nodal(z))[:2, face]
    a = x @ pinv
    out = np.empty(len(dz))
    for i, d in enumerate(dz):
        da = asm.nodal(d)[:2, face] @ pinv
        out[i] = (a[0] * da[1] - a[1] * da[0]) / (a @ a)
    return out


def sensitivities(result, k: int, wrt: Sequence[str] | str | None = None) -> Sensitivities:
    """Exact derivatives of the tip of state ``k`` of a rod result (adjoint method).

    Parameters
    ----------
    result : RodResult or FEMResult
        From :func:`coilrod.solve_rod` (any field, with or without Richardson) or
        :func:`coilrod.solve_fem` (groups "scale", "youngs_modulus", "magnitudes", "angles",
        "B" of a uniform field, "currents" of a single coil or pair; by the direct method, one
        solve with the state's tangent per parameter).
    k : int
        The state (index into ``result.scales``; negative counts from the end).
    wrt : str or sequence of str, optional
        Parameter groups (default: all the state has):

        * ``"magnitudes"``, ``"angles"``: |M| (A/m) and angle (rad) of each segment of a
          :meth:`Magnetization.segments` profile (a constant magnetization is one segment);
        * ``"youngs_modulus"`` (Pa);
        * ``"scale"``: the load scale (the field multiplier; the path tangent);
        * ``"B"`` of a :class:`coils.UniformField` (T, three components);
        * ``"B0"`` (T) and ``"gradient"`` (T/m, nine entries ``[i, j] = dB_i/dx_j``) of a
          :class:`coils.LinearField`;
        * ``"currents"`` (A) of a coil field with current channels (``unit_fields``).

        Derivatives with respect to field parameters are at the state's scale: the field
        acting is ``scale * field(parameters)``.

    Returns
    -------
    Sensitivities
        ``tip`` (p, 3) m per unit, ``tip_angle`` (p,) rad per unit, grouped
        (``sens["magnitudes"].tip``) and as a (4, p) Jacobian (``sens.matrix``).

    Raises
    ------
    ValueError
        An unknown group, a group the state does not have, a bad index; a rod result (or
        FEM magnitudes and angles) of a magnetization with an out-of-plane elevation.
    SingularStateError
        The state is at a bifurcation or limit point (the derivative does not exist).

    Notes
    -----
    Cost: the state's Jacobian is factorised once (as in one Newton step) and solved
    transposed for the three outputs; each parameter then costs O(n) (one evaluation of a
    unit field at the nodes for field parameters).  The derivatives are those of the discrete
    (Richardson-extrapolated) tip that :func:`solve_rod` reports, to round-off; the tests
    check them against central differences of independent solves at tolerance 1e-12.

    Examples
    --------
    >>> import coils
    >>> from coilrod import Rod, Circle, Magnetization, solve_rod, sensitivities
    >>> rod = Rod(0.04, 1e6, Circle(2e-3), Magnetization(128e3, 0.0))
    >>> lam = 1e-3  # small deflection: tip y = lambda L / 3, lambda = A M B L^2 / (E I)
    >>> res = solve_rod(rod, coils.UniformField(B=(0, rod.field_for_lambda(lam), 0)), [1.0])
    >>> d = sensitivities(res, 0, wrt="youngs_modulus")
    >>> round(float(d.tip[0, 1] / (-lam * rod.length / 3 / rod.youngs_modulus)), 3)
    1.0
    """
    from ..fem.result import FEMResult

    if isinstance(result, FEMResult):
        n_states = len(result.scales)
        if isinstance(k, bool) or not isinstance(k, int | np.integer):
            raise ValueError(f"k must be an integer state index; got {k!r}")
        if not -n_states <= k < n_states:
            raise ValueError(f"k = {k} is out of range for a result of {n_states} states")
        return _fem_sensitivities(result, int(k) % n_states, wrt)
    _solution(result)
    n_states = len(result.scales)
    if isinstance(k, bool) or not isinstance(k, int | np.integer):
        raise ValueError(f"k must be an integer state index; got {k!r}")
    if not -n_states <= k < n_states:
        raise ValueError(f"k = {k} is out of range for a result of {n_states} states")
    k = int(k) % n_states
    labels, units, values, D = tip_derivatives(result, [k], wrt)
    groups, start = {}, 0
    for group in _check_wrt(result, wrt):
        count = sum(1 for lab in labels if lab == group or lab.startswith(group + "["))
        groups[group] = slice(start, start + count)
        start += count
    if "scale" in groups:
        values[groups["scale"]] = float(result.scales[k])
    return Sensitivities(
        index=k,
        scale=float(result.scales[k]),
        parameters=tuple(labels),
        groups=groups,
        units=tuple(units),
        values=values,
        tip=D[0, 0:3].T.copy(),
        tip_angle=D[0, 3].copy(),
    )
