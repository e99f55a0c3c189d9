"""Independent high-precision reference for static 3D Kirchhoff rods with magnetic loads.

A test helper, not part of the package: it shares no code with coilrod's rod solvers (only the
field objects of ``coils`` are used) and solves the boundary-value problem with
:func:`scipy.integrate.solve_bvp`, so a spatial rod solver can be checked against it.

Model (SI units).  An inextensible, unshearable rod of length ``L``, arc length ``s`` in
``[0, L]``, centreline ``x(s)`` and body frame ``R(s)`` in SO(3) whose columns are the tangent
``d_t``, the normal ``d_n`` and the binormal ``d_b`` (the unloaded rod lies along ``R0 e1`` with
``R = R0``, the clamp rotation; identity by default, i.e. tangent +x, normal +y, binormal +z)::

    x' = R e1,   R' = R [kappa]_x,   m = R K kappa,   K = diag(GJ, EI_y, EI_z),
    n' + f = 0,  m' + x' x n + tau = 0,
    mw = R M_body(s),  tau = A mw x B(x),  f = A G(x)^T mw,  G[i, j] = dB_i/dx_j,
    x(0) = x0,  R(0) = R0,  n(L) = 0,  m(L) = 0.

``n`` and ``m`` are the world-frame internal force and moment exerted by the part ``(s, L]``
on the part ``[0, s]``; ``B`` and ``G`` are the field and its gradient multiplied by the load
``scale`` and evaluated on the *deformed* centreline.

Numerics.  The unknowns are ``(x, q, n, m)`` (13 components) with the frame carried by a unit
quaternion ``q = (w, v)`` (scalar first), ``q' = q (x) (0, kappa) / 2``, which preserves
``|q|``; the rotation is evaluated as ``R(q / |q|)`` so it is orthogonal even where collocation
lets ``|q|`` drift by O(tol).  The problem is non-dimensionalised with ``L`` and
``k = EI_z``: ``sigma = s / L``, ``xi = (x - x0) / L``, ``nu = n L^2 / k``, ``mu = m L / k``;
for each solve ``nu`` and ``mu`` are further divided by their largest magnitude in the initial
guess, so that every unknown is O(1).  solve_bvp gets the exact Jacobian (the field's hessian
enters the force's dependence on position).  Large loads are reached by natural-parameter
continuation in ``scale`` from the straight rod: a secant predictor, a loose solve (tol 1e-6),
acceptance only if the frames moved less than :data:`MAX_FRAME_CHANGE` rad from the prediction
(so the path cannot jump branches), step halving on failure; each requested scale is then
refined to ``tol`` (collocation residual and boundary residual of solve_bvp, both on the scaled
non-dimensional equations).

Accuracy.  ``tol`` bounds the relative collocation residual (fourth-order collocation); the
error of the positions is far below it in the tests: against closed forms (elastica, torsion,
out-of-plane rotation, rigid motion) ``|tip - exact| ~ 1e-14 L`` at ``tol = 1e-10``, and
solutions at tol 1e-8, 1e-10 and 1e-11 agree to ``1e-12 L``.  ``estimate_error=True`` re-solves
at ``tol / 10`` (at ``10 tol`` if that would pass :data:`TOL_FLOOR`, giving an upper bound) and
reports the differences.  Tolerances below :data:`TOL_FLOOR` = 1e-11 are not reachable in double
precision: the rounding of solve_bvp's residual estimate (about eps |y| / h) then exceeds tol,
and refinement adds nodes until ``max_nodes`` (slowly) and fails.

Limitations.  ``magnetization`` must be smooth in ``s`` (solve_bvp's collocation converges at
fourth order only for smooth right-hand sides; a jump costs accuracy and nodes: split such
problems into pieces elsewhere).  Natural-parameter continuation stops at folds (limit points)
in ``scale``: beyond a fold the continuation fails with :class:`RuntimeError`.  Symmetric
solutions are followed as they are (e.g. a straight twisted rod), also past the load where they
become unstable: the reference finds *an* equilibrium, not necessarily a stable one.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence

import numpy as np
from scipy.integrate import solve_bvp

__all__ = [
    "MAX_FRAME_CHANGE",
    "TOL_FLOOR",
    "ReferenceSolution",
    "evaluate",
    "quaternion_from_rotation",
    "rotation_from_quaternion",
    "spatial_reference",
    "twisted_case",
    "TWISTED_TIP",
    "TWISTED_TIP_FRAME",
]

#: Largest rotation (rad) of any node's frame away from the predictor in one continuation step.
MAX_FRAME_CHANGE = 0.25
#: Tightest tol solve_bvp reliably reaches in double precision: below it the rounding of the
#: residual estimate (about eps |y| / h) exceeds tol on the meshes needed, and refinement diverges.
TOL_FLOOR = 1e-11
#: Collocation tolerance of the continuation steps (the requested scales are refined to tol).
_STEP_TOL = 1e-6
#: Smallest continuation step relative to the largest |scale| requested.
_MIN_STEP = 1e-6


# -- rotations --------------------------------------------------------------------------------
def rotation_from_quaternion(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of quaternions (scalar first), normalised on the fly.

    Parameters
    ----------
    q : ndarray, shape (4, n)
        Quaternions ``(w, x, y, z)``; need not be unit.

    Returns
    -------
    ndarray, shape (n, 3, 3)
        ``R(q / |q|)``.
    """
    w, a, b, c = q
    n2 = w * w + a * a + b * b + c * c
    R = np.empty((q.shape[1], 3, 3))
    R[:, 0, 0] = w * w + a * a - b * b - c * c
    R[:, 0, 1] = 2 * (a * b - w * c)
    R[:, 0, 2] = 2 * (a * c + w * b)
    R[:, 1, 0] = 2 * (a * b + w * c)
    R[:, 1, 1] = w * w - a * a + b * b - c * c
    R[:, 1, 2] = 2 * (b * c - w * a)
    R[:, 2, 0] = 2 * (a * c - w * b)
    R[:, 2, 1] = 2 * (b * c + w * a)
    R[:, 2, 2] = w * w - a * a - b * b + c * c
    return R / n2[:, None, None]


def quaternion_from_rotation(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (scalar first, ``w >= 0``) of a rotation matrix (Shepperd's method).

    Parameters
    ----------
    R : array-like, shape (3, 3)
        Proper rotation matrix.

    Returns
    -------
    ndarray, shape (4,)
    """
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    d = np.array([tr, R[0, 0], R[1, 1], R[2, 2]])
    k = int(np.argmax(d))
    if k == 0:
        w = 0.5 * math.sqrt(1 + tr)
        q = [w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w)]
        q.append((R[1, 0] - R[0, 1]) / (4 * w))
    else:
        i, j, l = k - 1, k % 3, (k + 1) % 3
        v = np.empty(3)
        v[i] = 0.5 * math.sqrt(1 + 2 * R[i, i] - tr)
        v[j] = (R[j, i] + R[i, j]) / (4 * v[i])
        v[l] = (R[l, i] + R[i, l]) / (4 * v[i])
        w = (R[l, j] - R[j, l]) / (4 * v[i])
        q = [w, *v]
    q = np.array(q)
    return q if q[0] >= 0 else -q


def _as_rotation(R) -> np.ndarray:
    if R is None:
        return np.eye(3)
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ValueError(f"clamp_rotation must be a finite 3x3 matrix; got shape {R.shape}")
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-12) or np.linalg.det(R) <= 0:
        raise ValueError("clamp_rotation must be a proper rotation (R^T R = I, det R = +1)")
    return R


def _rotation_unnormalized(q):
    """The quadratic form Rtilde(q) with R(q) = Rtilde(q) / |q|^2, shape (3, 3)."""
    w, a, b, c = q
    return np.array(
        [
            [w * w + a * a - b * b - c * c, 2 * (a * b - w * c), 2 * (a * c + w * b)],
            [2 * (a * b + w * c), w * w - a * a + b * b - c * c, 2 * (b * c - w * a)],
            [2 * (a * c - w * b), 2 * (b * c + w * a), w * w - a * a - b * b + c * c],
        ]
    )


def _quadratic_coefficients():
    """C[i, j, a, b], symmetric in (a, b), with Rtilde_ij(q) = C_ijab q_a q_b (polarisation)."""
    e = np.eye(4)
    C = np.empty((3, 3, 4, 4))
    for a in range(4):
        for b in range(4):
            C[:, :, a, b] = 0.5 * (
                _rotation_unnormalized(e[a] + e[b])
                - _rotation_unnormalized(e[a])
                - _rotation_unnormalized(e[b])
            )
        C[:, :, a, a] = _rotation_unnormalized(e[a])
    return C


_C = _quadratic_coefficients()
#: Constant Jacobians of the boundary conditions: x(0), q(0) at the clamp, n(L), m(L) at the tip.
_BC_A = np.zeros((13, 13))
_BC_A[0:7, 0:7] = np.eye(7)
_BC_B = np.zeros((13, 13))
_BC_B[7:13, 7:13] = np.eye(6)


def _cross(a, b):
    """Cross products of column vectors, shapes (3, n) -> (3, n)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def _skew(v):
    """Cross-product matrices [v]_x of row vectors, shape (n, 3) -> (n, 3, 3)."""
    S = np.zeros((v.shape[0], 3, 3))
    S[:, 0, 1], S[:, 0, 2] = -v[:, 2], v[:, 1]
    S[:, 1, 0], S[:, 1, 2] = v[:, 2], -v[:, 0]
    S[:, 2, 0], S[:, 2, 1] = -v[:, 1], v[:, 0]
    return S


# -- the non-dimensional problem ----------------------------------------------------------------
class _Problem:
    """Right-hand side and boundary conditions of the non-dimensional BVP."""

    def __init__(self, length, stiffnesses, area, magnetization, field, x0, R0):
        self.L = float(length)
        K = np.asarray(stiffnesses, dtype=float)
        if K.shape != (3,) or not np.all(K > 0) or not np.all(np.isfinite(K)):
            raise ValueError(f"stiffnesses must be three positive numbers; got {stiffnesses}")
        if not (self.L > 0 and math.isfinite(self.L)):
            raise ValueError(f"length must be positive; got {length}")
        if not (area > 0 and math.isfinite(area)):
            raise ValueError(f"area must be positive; got {area}")
        self.k = K[2]  # reference stiffness EI_z, N m^2
        self.K = K
        self.compliance = self.k / K  # L kappa = compliance * (R^T mu)
        self.c_tau = area * self.L**2 / self.k  # torque per length -> d mu / d sigma, per (A/m T)
        self.c_f = area * self.L**3 / self.k  # force per length -> d nu / d sigma
        self.magnetization = magnetization
        self.field = field
        self.uniform = bool(getattr(field, "uniform", False))
        self.x0 = x0
        self.q0 = quaternion_from_rotation(R0)
        self.scale = 0.0

    def body_magnetization(self, sigma):
        Mb = np.asarray(self.magnetization(self.L * sigma), dtype=float)
        if Mb.shape != (sigma.size, 3):
            raise ValueError(
                f"magnetization(s) must return shape (n, 3) = {(sigma.size, 3)}; got {Mb.shape}"
            )
        return Mb

    def _field(self, pts, hessian):
        """Scaled B (n,3) T, G (n,3,3) T/m (None if uniform), H (n,3,3,3) T/m^2 (None if
        uniform or linear, or not requested)."""
        f = self.field
        if self.uniform:
            return self.scale * np.asarray(f.B(pts), dtype=float), None, None
        H = None
        if hessian and not getattr(f, "linear", False):
            if hasattr(f, "B_gradient_hessian"):
                B, G, H = f.B_gradient_hessian(pts)
            else:
                B, G = f.B(pts), f.gradient(pts)
                H = self._hessian_fd(pts)
            H = self.scale * np.asarray(H, dtype=float)
        elif hasattr(f, "B_and_gradient"):
            B, G = f.B_and_gradient(pts)
        else:
            B, G = f.B(pts), f.gradient(pts)
        return self.scale * np.asarray(B, dtype=float), self.scale * np.asarray(G, dtype=float), H

    def _hessian_fd(self, pts):
        """Central differences of the gradient (fields without ``hessian``; Jacobian only)."""
        h = 1e-6 * self.L
        H = np.empty((pts.shape[0], 3, 3, 3))
        for l in range(3):
            e = np.zeros(3)
            e[l] = h
            H[:, :, :, l] = (self.field.gradient(pts + e) - self.field.gradient(pts - e)) / (2 * h)
        return H

    def _common(self, sigma, y, hessian=False):
        q = y[3:7]
        R = rotation_from_quaternion(q)
        Mb = self.body_magnetization(sigma)
        mw = np.einsum("kij,kj->ki", R, Mb)
        pts = self.x0 + self.L * y[0:3].T
        B, G, H = self._field(pts, hessian)
        return R, Mb, mw, B, G, H

    def rhs(self, sigma, y):
        R, _, mw, B, G, _ = self._common(sigma, y)
        q, nu, mu = y[3:7], y[7:10], y[10:13]
        kap = self.compliance[:, None] * np.einsum("kji,jk->ik", R, mu)  # L kappa, body frame
        w, v = q[0], q[1:4]
        dq = 0.5 * np.vstack([-(v * kap).sum(0), w * kap + _cross(v, kap)])
        t = R[:, :, 0].T
        dmu = -_cross(t, nu) - self.c_tau * _cross(mw.T, B.T)
        if G is None:
            dnu = np.zeros_like(nu)
        else:
            dnu = -self.c_f * np.einsum("kij,ki->jk", G, mw)
        return np.vstack([t, dq, dnu, dmu])

    def jac(self, sigma, y):
        """Exact Jacobian d rhs / d y, shape (13, 13, n)."""
        R, Mb, mw, B, G, H = self._common(sigma, y, hessian=True)
        q, nu, mu = y[3:7], y[7:10], y[10:13]
        n = sigma.size
        n2 = (q * q).sum(0)
        # dR/dq_a = (dRtilde/dq_a) / |q|^2 - R 2 q_a / |q|^2, Rtilde quadratic in q
        dR = 2 * np.einsum("ijab,bk->kija", _C, q) / n2[:, None, None, None]
        dR -= 2 * R[..., None] * (q.T / n2[:, None])[:, None, None, :]
        J = np.zeros((n, 13, 13))
        dt = dR[:, :, 0, :]  # (n, 3, 4)
        J[:, 0:3, 3:7] = dt
        # quaternion kinematics: dq = q (x) (0, kap) / 2
        kap = self.compliance[None, :] * np.einsum("kji,jk->ki", R, mu)  # (n, 3)
        dkap_dq = self.compliance[None, :, None] * np.einsum("kjia,jk->kia", dR, mu)
        dkap_dmu = self.compliance[None, :, None] * R.transpose(0, 2, 1)
        right = np.zeros((n, 4, 4))  # q (x) p = right(p) q for p = (0, kap)
        right[:, 0, 1:] = -kap
        right[:, 1:, 0] = kap
        right[:, 1:, 1:] = -_skew(kap)
        left = np.zeros((n, 4, 3))  # d(q (x) (0, kap)) / d kap
        left[:, 0, :] = -q[1:4].T
        left[:, 1:, :] = q[0][:, None, None] * np.eye(3) + _skew(q[1:4].T)
        J[:, 3:7, 3:7] = 0.5 * (right + left @ dkap_dq)
        J[:, 3:7, 10:13] = 0.5 * left @ dkap_dmu
        # moment balance: dmu = -t x nu - c_tau mw x B
        dmw = np.einsum("kija,kj->kia", dR, Mb)  # (n, 3, 4)
        J[:, 10:13, 3:7] = _skew(nu.T) @ dt + self.c_tau * _skew(B) @ dmw
        J[:, 10:13, 7:10] = -_skew(R[:, :, 0])
        if G is not None:
            J[:, 10:13, 0:3] = -self.c_tau * self.L * _skew(mw) @ G
            # force balance: dnu = -c_f G^T mw
            J[:, 7:10, 3:7] = -self.c_f * G.transpose(0, 2, 1) @ dmw
            if H is not None:
                J[:, 7:10, 0:3] = -self.c_f * self.L * np.einsum("kijl,ki->kjl", H, mw)
        return J.transpose(1, 2, 0)

    def bc(self, ya, yb):
        return np.concatenate([ya[0:3], ya[3:7] - self.q0, yb[7:10], yb[10:13]])

    def bc_jac(self, ya, yb):
        return _BC_A, _BC_B

    def straight(self, sigma):
        y = np.zeros((13, sigma.size))
        y[0:3] = rotation_from_quaternion(self.q0[:, None])[0][:, 0:1] * sigma
        y[3:7] = self.q0[:, None]
        return y

    def solve(self, scale, sigma, y, tol, max_nodes):
        """solve_bvp at ``scale`` from the guess ``y`` (13, len(sigma)); None on failure.

        The unknowns are rescaled so that every group is O(1): ``n`` and ``m`` (non-dimensional)
        are divided by their largest magnitude in the guess (at least 1).  Otherwise large
        internal loads put the rounding floor of solve_bvp's residual estimate (eps |y| / h)
        above tol ~ 1e-11, and mesh refinement then diverges.
        """
        self.scale = float(scale)
        c = np.ones(13)
        c[7:10] = max(1.0, float(np.max(np.abs(y[7:10]))))
        c[10:13] = max(1.0, float(np.max(np.abs(y[10:13]))))
        cc = c[:, None]

        def fun(sig, z):
            return self.rhs(sig, cc * z) / cc

        def jac(sig, z):
            return self.jac(sig, cc * z) * (c[None, :, None] / c[:, None, None])

        def bc(za, zb):
            return self.bc(c * za, c * zb) / c

        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            try:
                raw = solve_bvp(
                    fun,
                    bc,
                    sigma,
                    y / cc,
                    fun_jac=jac,
                    bc_jac=self.bc_jac,
                    tol=tol,
                    bc_tol=tol,
                    max_nodes=max_nodes,
                )
            except (ValueError, np.linalg.LinAlgError, FloatingPointError, MemoryError):
                return None
        if raw.status != 0 or not np.all(np.isfinite(raw.y)):
            return None
        return _Solved(raw, c)


class _Solved:
    """A solve_bvp result with the unknowns' scaling undone: ``y`` and ``sol`` are the
    non-dimensional ``(xi, q, nu, mu)``; ``raw.y = y / yscale``."""

    def __init__(self, raw, yscale):
        self.raw = raw
        self.yscale = yscale
        self.x = raw.x
        self.y = raw.y * yscale[:, None]
        self.status = raw.status
        self.niter = raw.niter
        self.rms_residuals = raw.rms_residuals

    def sol(self, sigma):
        return self.raw.sol(sigma) * self.yscale[:, None]


def _frame_change(y_new, y_ref):
    """Largest rotation angle (rad) between the frames of two node sets of quaternions."""
    qa = y_new[3:7] / np.linalg.norm(y_new[3:7], axis=0)
    qb = y_ref[3:7] / np.linalg.norm(y_ref[3:7], axis=0)
    dot = np.clip(np.abs((qa * qb).sum(0)), 0.0, 1.0)
    return float(np.max(2 * np.arccos(dot)))


# -- results -------------------------------------------------------------------------------------
class ReferenceSolution:
    """A converged solve_bvp solution in SI units.

    Attributes
    ----------
    raw : scipy.optimize.OptimizeResult
        solve_bvp's result on the non-dimensional problem (``raw.x`` = s / L, ``raw.y`` the
        non-dimensional ``(xi, q, nu, mu)`` divided row-wise by ``yscale``).
    yscale : ndarray, shape (13,)
        Scaling of the unknowns in ``raw``.
    length, k, x0 : float, float, ndarray (3,)
        Scales: L in m, reference stiffness EI_z in N m^2, clamp position in m.
    """

    def __init__(self, solved, length, k, x0):
        self.raw = solved.raw
        self.yscale = solved.yscale
        self._solved = solved
        self.length = length
        self.k = k
        self.x0 = x0
        self.status = solved.status
        self.niter = solved.niter
        self.rms_residuals = solved.rms_residuals

    @property
    def x(self) -> np.ndarray:
        """Mesh nodes as arc length, shape (n,), m."""
        return self.length * self.raw.x

    def sol(self, s) -> np.ndarray:
        """Dimensional state at arc lengths ``s`` (m, shape (p,)).

        Returns
        -------
        ndarray, shape (13, p)
            Rows: x (m, 3), quaternion (4, scalar first), n (N, 3), m (N m, 3), world frame.
        """
        s = np.atleast_1d(np.asarray(s, dtype=float))
        y = self._solved.sol(s / self.length)
        out = np.empty_like(y)
        out[0:3] = self.x0[:, None] + self.length * y[0:3]
        out[3:7] = y[3:7] / np.linalg.norm(y[3:7], axis=0)
        out[7:10] = y[7:10] * self.k / self.length**2
        out[10:13] = y[10:13] * self.k / self.length
        return out


def evaluate(result: dict, s) -> dict:
    """Centreline, frames and internal loads of one reference state at arbitrary arc lengths.

    Parameters
    ----------
    result : dict
        One entry of :func:`spatial_reference`'s list.
    s : array-like, shape (p,)
        Arc lengths in [0, L], m.

    Returns
    -------
    dict
        ``x`` (p, 3) m, ``R`` (p, 3, 3), ``n`` (p, 3) N, ``m`` (p, 3) N m.
    """
    y = result["sol"].sol(s)
    return {
        "x": y[0:3].T.copy(),
        "R": rotation_from_quaternion(y[3:7]),
        "n": y[7:10].T.copy(),
        "m": y[10:13].T.copy(),
    }


def _package(problem, raw, scale, extra=None):
    ref = ReferenceSolution(raw, problem.L, problem.k, problem.x0)
    s = ref.x
    y = ref.sol(s)
    out = {
        "scale": float(scale),
        "s": s,
        "x": y[0:3].T.copy(),
        "R": rotation_from_quaternion(y[3:7]),
        "n": y[7:10].T.copy(),
        "m": y[10:13].T.copy(),
        "tip": y[0:3, -1].copy(),
        "sol": ref,
        "max_rms_residual": float(np.max(raw.rms_residuals)),
        "bc_residual": float(np.max(np.abs(problem.bc(raw.y[:, 0], raw.y[:, -1])))),
        "nodes": int(raw.x.size),
    }
    if extra:
        out.update(extra)
    return out


def spatial_reference(
    length: float,
    stiffnesses: Sequence[float],
    area: float,
    magnetization: Callable[[np.ndarray], np.ndarray],
    field,
    scales: Sequence[float],
    *,
    clamp_position=(0.0, 0.0, 0.0),
    clamp_rotation=None,
    tol: float = 1e-10,
    max_nodes: int = 20_000,
    estimate_error: bool = False,
) -> list[dict]:
    """Static equilibria of a magnetic Kirchhoff rod, continued in the load ``scale``.

    Parameters
    ----------
    length : float
        Rod length L, m.
    stiffnesses : sequence of 3 floats
        ``(GJ, EI_y, EI_z)`` in N m^2: torsion, bending about the normal ``d_n``, bending about
        the binormal ``d_b``.
    area : float
        Cross-section area A, m^2.
    magnetization : callable
        ``magnetization(s)`` with ``s`` an ndarray (n,) of arc lengths in m returns the
        body-frame magnetization ``(M_t, M_n, M_b)``, shape (n, 3), A/m.  Must be smooth in s.
    field : coils field
        Any object with ``B(points) -> (n, 3)`` T and ``gradient(points) -> (n, 3, 3)`` T/m
        (``G[k, i, j] = dB_i/dx_j``); ``uniform = True`` skips the gradient.
    scales : sequence of float
        Load factors multiplying the field, continued in the given order from the straight rod
        at scale 0.
    clamp_position : array-like, shape (3,)
        x(0), m.
    clamp_rotation : None or array-like, shape (3, 3)
        R(0) (columns: tangent, normal, binormal); None is the identity.
    tol : float
        solve_bvp ``tol`` and ``bc_tol`` of the final solve at each requested scale (relative
        collocation residual of the non-dimensional equations).
    max_nodes : int
        solve_bvp's node limit of the final solves.
    estimate_error : bool
        If True, re-solve every state at ``error_tol = tol / 10`` (``10 tol`` if
        ``tol / 10 < TOL_FLOOR``) and report ``tip_error`` (m), the tip difference, and
        ``max_error`` (m), the largest centreline difference at the nodes.

    Returns
    -------
    list of dict, one per scale
        ``scale``; ``s`` (n,) mesh nodes, m; ``x`` (n, 3) m; ``R`` (n, 3, 3); ``n`` (n, 3) N;
        ``m`` (n, 3) N m (world frame internal force and moment); ``tip`` (3,) m; ``sol``, a
        :class:`ReferenceSolution` whose ``sol(s)`` (s in m) gives the dimensional state
        (13, p) and ``raw`` is solve_bvp's object (scaled, see there); ``max_rms_residual``,
        ``bc_residual`` and ``nodes`` of the final solve; with ``estimate_error`` also
        ``error_tol``, ``tip_error``, ``max_error``.

    Raises
    ------
    RuntimeError
        If a scale cannot be reached (a fold, or too hard a load); the message says the last
        scale reached.
    """
    x0 = np.asarray(clamp_position, dtype=float).reshape(3)
    R0 = _as_rotation(clamp_rotation)
    problem = _Problem(length, stiffnesses, area, magnetization, field, x0, R0)
    scales = [float(v) for v in scales]
    if not scales or not all(math.isfinite(v) for v in scales):
        raise ValueError(f"scales must be a non-empty list of finite numbers; got {scales}")
    min_step = _MIN_STEP * max(max(abs(v) for v in scales), 1e-300)

    sigma = np.linspace(0.0, 1.0, 41)
    problem.body_magnetization(sigma)  # validates the shape before any solve
    current = (0.0, sigma, problem.straight(sigma))  # scale, mesh, nodal values
    previous = None  # the accepted state before `current`, for the secant predictor
    results = []
    step = None
    for target in scales:
        while current[0] != target:
            s_c, sig_c, y_c = current
            if step is None or abs(step) > abs(target - s_c) or step * (target - s_c) < 0:
                step = target - s_c
            trial = target if abs(target - (s_c + step)) < 1e-12 * abs(target) else s_c + step
            guess = y_c
            if previous is not None and previous[0] != s_c:
                y_p = previous[1].sol(sig_c)
                guess = y_c + (trial - s_c) / (s_c - previous[0]) * (y_c - y_p)
            raw = problem.solve(trial, sig_c, guess, _STEP_TOL, max(2000, 4 * sig_c.size))
            ok = raw is not None and _frame_change(raw.sol(sig_c), guess) < MAX_FRAME_CHANGE
            if ok:
                previous = (s_c, _Interp(sig_c, y_c))
                current = (trial, raw.x, raw.y)
                step *= 1.5
            else:
                step *= 0.5
                if abs(step) < min_step:
                    raise RuntimeError(
                        f"continuation stalled at scale {s_c!r} on the way to {target!r} "
                        "(a fold or a load too hard for natural-parameter continuation)"
                    )
        raw = problem.solve(target, current[1], current[2], tol, max_nodes)
        if raw is None:
            raise RuntimeError(f"refinement to tol={tol} failed at scale {target!r}")
        extra = None
        if estimate_error:
            # a tighter tol if the rounding floor allows it, else a looser one (an upper bound)
            error_tol = tol / 10 if tol / 10 >= TOL_FLOOR else tol * 10
            start = (raw.x, raw.y) if error_tol < tol else (current[1], current[2])
            other = problem.solve(target, *start, error_tol, max_nodes)
            if other is None:
                raise RuntimeError(f"the error estimate's solve failed at scale {target!r}")
            xa = raw.sol(other.x)[0:3]
            extra = {
                "error_tol": error_tol,
                "tip_error": float(problem.L * np.linalg.norm(raw.y[0:3, -1] - other.y[0:3, -1])),
                "max_error": float(problem.L * np.max(np.linalg.norm(xa - other.y[0:3], axis=0))),
            }
        results.append(_package(problem, raw, target, extra))
    return results


class _Interp:
    """Piecewise-linear interpolant of nodal values (the predictor's previous state)."""

    def __init__(self, sigma, y):
        self.sigma, self.y = sigma, y

    def sol(self, sigma):
        return np.array([np.interp(sigma, self.sigma, row) for row in self.y])


# -- a genuinely 3D, twisted case for comparisons ------------------------------------------------
def twisted_case() -> dict:
    """A twisted, out-of-plane benchmark: elevated magnetization, oblique field, anisotropic K.

    Rod: L = 40 mm, E = 1 MPa, rectangular section of thickness t = 1 mm along the normal
    (the soft bending plane, as in ``coilrod.Rectangle``) and width w = 2 mm along the binormal:
    EI_z = E w t^3 / 12, EI_y = E t w^3 / 12 = 4 EI_z, GJ = 0.6 EI_z (chosen), A = w t.
    Magnetization uniform, |M| = 128 kA/m with body direction
    (cos 0.3 cos 0.4, sin 0.3 cos 0.4, sin 0.4).  Field uniform, B = b (0.3, 1, 0.5) with b
    such that lambda = |M| b A L^2 / EI_z = 5 at scale 1 (|B| = 1.1576 b).

    Returns
    -------
    dict
        Keyword arguments of :func:`spatial_reference` except ``scales`` (use ``[1.0]``), plus
        ``lam`` = 5 and ``youngs_modulus``, ``width``, ``thickness``, ``magnitude``,
        ``theta_m``, ``psi_m``, ``B`` (T, at scale 1) for building the same robot elsewhere.
    """
    import coils

    L, E, w, t, Mmag = 0.04, 1e6, 2e-3, 1e-3, 128e3
    EIz = E * w * t**3 / 12
    A = w * t
    lam = 5.0
    b = lam * EIz / (Mmag * A * L**2)
    theta_m, psi_m = 0.3, 0.4
    direction = np.array(
        [math.cos(theta_m) * math.cos(psi_m), math.sin(theta_m) * math.cos(psi_m), math.sin(psi_m)]
    )
    B = b * np.array([0.3, 1.0, 0.5])

    def magnetization(s):
        return np.broadcast_to(Mmag * direction, (np.size(s), 3)).copy()

    return {
        "length": L,
        "stiffnesses": (0.6 * EIz, 4 * EIz, EIz),
        "area": A,
        "magnetization": magnetization,
        "field": coils.UniformField(B=B),
        "lam": lam,
        "youngs_modulus": E,
        "width": w,
        "thickness": t,
        "magnitude": Mmag,
        "theta_m": theta_m,
        "psi_m": psi_m,
        "B": B,
    }


#: Tip (m) of :func:`twisted_case` at scale 1, clamp at the origin, identity clamp rotation,
#: solved at tol 1e-11; tol 1e-8, 1e-10 and 1e-11 agree to 1e-13 L (tests/test_spatial_reference).
TWISTED_TIP = np.array([0.0343867286900568, 0.018823369743911886, 0.0014195143282931628])
#: Tip frame R(L) of the same state (columns: tangent, normal, binormal).
TWISTED_TIP_FRAME = np.array(
    [
        [0.7657490148198184, -0.6244920809071761, -0.15374682821672178],
        [0.6416982604456989, 0.757875578510664, 0.1176773131835108],
        [0.04303241619339158, -0.18877035885263066, 0.9810779595807905],
    ]
)
