"""Discrete hard-magnetic elastica: energy, residual, banded Jacobian and second variation.

Everything here is non-dimensional: lengths in units of L, moments in EI/L, forces in EI/L^2.
Nodes ``s_0 = 0 < ... < s_N = 1`` (piecewise uniform, with a node at every magnetization
breakpoint), segment lengths ``h_i``, trapezoid weights ``w_i``.  The discrete energy is

    E = sum_i (theta_{i+1} - theta_i)^2 / (2 h_i) - sum_i w_i m_i(theta_i) . b(x_i),
    x_{i+1} = x_i + h_i (t(theta_i) + t(theta_{i+1})) / 2,   t = (cos, sin),

with ``m_i = R(theta_i) mu_i``, ``mu_i = A L^2 |M| / (EI)`` the body-frame magnetization (the
trapezoid average of its one-sided limits at a node, so jumps are integrated exactly) and ``b``
the in-plane field.  Its gradient ``g_i = dE/dtheta_i`` is the discrete seed eq. (5):

    g_i = (theta_i - theta_{i-1}) / h_{i-1} + (theta_i - theta_{i+1}) / h_i - w_i tau_i
          - t_perp_i . (w_i F_i + (h_{i-1} / 2) w_i f_i),

``tau = m x b``, ``f = G^T m``, ``F_i = sum_{j > i} w_j f_j`` the force resultant beyond node i.
Both schemes are symmetric (trapezoid), so the error expands in even powers of h and
Richardson extrapolation of two meshes gives fourth order.

Two unknown layouts:

* uniform fields: ``theta`` only; the Jacobian (= Hessian of E) is tridiagonal.
* otherwise a mixed layout with positions and force resultants as unknowns, five per node
  ``(theta_i, x_i, y_i, Fx_i, Fy_i)`` and equations ``(g_i, position, force)`` in the same
  order: the Jacobian is banded (7 below, 6 above the diagonal), so a Newton step costs
  O(N).  Eliminating positions and forces gives back the (dense, symmetric) Hessian of E.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import eigh, eigvalsh_tridiagonal, solve_banded
from scipy.linalg.lapack import dgtsv as _gtsv
from scipy.linalg.lapack import dstebz as _stebz

from .mesh import RodMesh

__all__ = ["RodMesh", "DiscreteRod"]  # RodMesh re-exported from coilrod.rod_mesh

_NV = 5  # unknowns per node in the mixed layout
_LOW, _UP = 7, 6  # bandwidths of the mixed Jacobian
#: Free nodes up to which the second variation of the mixed layout is formed densely.
_DENSE_STABILITY = 96


def _rot(theta: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """m = R(theta) mu for body vectors mu (n, 2): shape (n, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * mu[:, 0] - s * mu[:, 1], s * mu[:, 0] + c * mu[:, 1]], axis=-1)


class DiscreteRod:
    """The discrete problem for one rod, field and mesh (non-dimensional).

    Parameters
    ----------
    mesh : RodMesh
    mu : ndarray, shape (n, 2)
        Node magnetization in the body frame times A L^2 / (EI), 1/T.
    field : coils.Field
        The applied field (SI).
    length : float
        L in m.
    clamp_position : ndarray, shape (3,)
        Clamp position, m.
    clamp_angle : float
        Clamp tangent angle, rad.
    """

    def __init__(self, mesh, mu, field, length, clamp_position, clamp_angle):
        self.mesh = mesh
        self.mu = mu
        self.field = field
        self.L = float(length)
        self.clamp = np.asarray(clamp_position, float)
        self.theta0 = float(clamp_angle)
        self.uniform = bool(field.uniform)
        self.linear = bool(field.linear or field.uniform)
        self.n = mesh.n
        self.size = self.n if self.uniform else _NV * self.n
        self._cache = None  # field at the last evaluated centreline (residual then Jacobian)
        #: Round-off floor of the scaled residual (differences of angles over h, divided by w).
        self.tol_floor = 64 * np.finfo(float).eps * self.n**2
        self._mu0 = None
        #: Reuse the field's second derivatives in the Jacobian while the centreline stays
        #: within this distance (units of L) of where they were evaluated (0: always exact).
        self.hessian_lag = 0.0
        self._hessian_last = None
        if self.uniform:
            self._b_uniform = field.B(self.clamp)[0, :2].copy()
            h = mesh.h
            self._inv_h = 1.0 / h
            self._wmu = mesh.w[:, None] * mu
            self._inv_w = 1.0 / mesh.w[1:]
            bx, by = self._b_uniform
            mt, mn = self._wmu[:, 0], self._wmu[:, 1]
            self._P1 = mt * by - mn * bx  # w (m x b) and w m.b at theta = 0, scale 1
            self._Q1 = mt * bx + mn * by
            # off-diagonal of W^(-1/2) H W^(-1/2) (constant: bending only)
            self._stab_e = -self._inv_h[1:] / np.sqrt(mesh.w[1:-1] * mesh.w[2:])
            self._k_diag = np.zeros(self.n)
            self._k_diag[1:] += self._inv_h
            self._k_diag[:-1] += self._inv_h
            self._k_low = -self._inv_h.copy()  # J[i + 1, i]
            self._k_up = -self._inv_h.copy()  # J[i, i + 1]
            self._k_up[0] = 0.0  # row 0 is the clamp condition

    @property
    def mu0(self) -> float:
        """Smallest second-variation eigenvalue of the unloaded straight rod (~ pi^2 / 4)."""
        if self._mu0 is None:
            self._mu0 = self.min_eigenvalue(self.straight(), 0.0)
        return self._mu0

    # -- state helpers --------------------------------------------------------------------------
    def straight(self) -> np.ndarray:
        """The straight state along the clamp tangent, unknown vector shape (size,)."""
        theta = np.full(self.n, self.theta0)
        return self.from_theta(theta)

    def from_theta(self, theta: np.ndarray, scale: float = 0.0) -> np.ndarray:
        """Unknown vector with positions and forces consistent with ``theta``."""
        if self.uniform:
            return theta.copy()
        x = self.positions(theta)
        u = np.zeros((self.n, _NV))
        u[:, 0] = theta
        u[:, 1:3] = x
        if scale != 0.0:
            _, f = self._torque_force(theta, x, scale)[:2]
            wf = self.mesh.w[:, None] * f
            tail = np.cumsum(wf[::-1], axis=0)[::-1]
            u[:-1, 3:5] = tail[1:]
        return u.ravel()

    def theta(self, u: np.ndarray) -> np.ndarray:
        """Node angles, shape (n,), rad."""
        return u if self.uniform else u[0::_NV]

    def positions(self, theta: np.ndarray) -> np.ndarray:
        """Trapezoid centreline relative to the clamp, shape (n, 2), units of L."""
        t = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
        seg = self.mesh.h[:, None] * (t[:-1] + t[1:]) / 2
        return np.concatenate([np.zeros((1, 2)), np.cumsum(seg, axis=0)])

    def theta_batch(self, states: np.ndarray) -> np.ndarray:
        """Node angles of several states (k, size): shape (k, n), rad."""
        return states if self.uniform else states[:, 0::_NV]

    def positions_batch(self, theta: np.ndarray) -> np.ndarray:
        """Trapezoid centrelines of several states, theta (k, n): shape (k, n, 2), units of L."""
        t = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
        seg = self.mesh.h[None, :, None] * (t[:, :-1] + t[:, 1:]) / 2
        out = np.zeros(t.shape)
        np.cumsum(seg, axis=1, out=out[:, 1:])
        return out

    def points_batch(self, x: np.ndarray) -> np.ndarray:
        """Physical points (k, n, 3) in m from non-dimensional positions (k, n, 2)."""
        pts = np.empty(x.shape[:2] + (3,))
        pts[..., :2] = self.clamp[:2] + self.L * x
        pts[..., 2] = self.clamp[2]
        return pts

    def newton_batch(self, thetas: np.ndarray, scales: np.ndarray, opts):
        """Newton on independent uniform-field problems at once: thetas (k, n), scales (k,).

        The k tridiagonal Jacobians are solved as one block-diagonal tridiagonal system.

        Returns
        -------
        thetas : ndarray, shape (k, n)
        ok : ndarray of bool, shape (k,)
        residual : ndarray, shape (k,)
        iterations : ndarray of int, shape (k,)
        """
        if not self.uniform:
            raise ValueError("newton_batch is for uniform fields")
        k, n = thetas.shape
        tol = max(opts.tol, self.tol_floor)
        th = thetas.copy()
        sc = np.asarray(scales, dtype=float)[:, None]
        P1, Q1 = self._P1, self._Q1
        low = np.tile(np.append(self._k_low, 0.0), k)[:-1]  # no coupling between blocks
        up = np.tile(np.append(self._k_up, 0.0), k)[:-1]
        iters = np.zeros(k, dtype=int)
        active = np.ones(k, dtype=bool)
        res = np.full(k, np.inf)
        for _ in range(opts.max_iter + 1):
            c, s = np.cos(th), np.sin(th)
            r = -sc * (c * P1 - s * Q1)
            dth = np.diff(th, axis=1) * self._inv_h
            r[:, 1:] += dth
            r[:, :-1] -= dth
            r[:, 0] = th[:, 0] - self.theta0
            with np.errstate(invalid="ignore", over="ignore"):
                res = np.max(np.abs(r[:, 1:] * self._inv_w), axis=1)
            active = ~(res <= tol)
            if not active.any():
                break
            d = self._k_diag + sc * (c * Q1 + s * P1)
            d[:, 0] = 1.0
            _, _, _, du, info = _gtsv(low, d.ravel(), up, -r.ravel())
            if info != 0:
                break
            du = du.reshape(k, n)
            rot = np.max(np.abs(du), axis=1)
            step = np.minimum(1.0, opts.max_rotation / np.maximum(rot, 1e-300))
            th[active] += step[active, None] * du[active]
            iters[active] += 1
        ok = np.isfinite(res) & (res <= tol)
        return th, ok, res, iters

    def min_eigenvalue_batch(self, thetas: np.ndarray, scales: np.ndarray) -> np.ndarray:
        """:meth:`min_eigenvalue` of several uniform-field states, thetas (k, n): shape (k,)."""
        if not self.uniform:
            raise ValueError("min_eigenvalue_batch is for uniform fields")
        sc = np.asarray(scales, dtype=float)[:, None]
        c, s = np.cos(thetas[:, 1:]), np.sin(thetas[:, 1:])
        d = (self._k_diag[1:] + sc * (c * self._Q1[1:] + s * self._P1[1:])) * self._inv_w
        out = np.empty(len(d))
        for j, dj in enumerate(d):  # one O(N) bisection per state
            abstol = 1e-13 * float(np.max(np.abs(dj)))
            m, ev, _, _, info = _stebz(dj, self._stab_e, 3, 0.0, 0.0, 1, 1, abstol, "E")
            out[j] = (
                ev[0]
                if info == 0 and m >= 1
                else eigvalsh_tridiagonal(dj, self._stab_e, select="i", select_range=(0, 0))[0]
            )
        return out

    def points(self, x: np.ndarray) -> np.ndarray:
        """Physical points (n, 3) in m from non-dimensional positions (n, 2)."""
        pts = np.empty((x.shape[0], 3))
        pts[:, :2] = self.clamp[:2] + self.L * x
        pts[:, 2] = self.clamp[2]
        return pts

    def interpolate_to(self, fine: DiscreteRod, u: np.ndarray) -> np.ndarray:
        """Unknowns of this (coarse) state on the refined mesh ``fine`` (linear interpolation)."""
        if self.uniform:
            return np.interp(fine.mesh.s, self.mesh.s, u)
        v = u.reshape(self.n, _NV)
        out = np.empty((fine.n, _NV))
        for k in range(_NV):
            out[:, k] = np.interp(fine.mesh.s, self.mesh.s, v[:, k])
        return out.ravel()

    # -- field evaluation -----------------------------------------------------------------------
    def _field(self, x: np.ndarray, scale: float, hessian: bool):
        """In-plane b (n, 2) T, G (n, 2, 2) T per L, H (n, 2, 2, 2) T per L^2 (or None)."""
        if self.uniform:
            return np.broadcast_to(scale * self._b_uniform, (self.n, 2)), None, None
        pts = self.points(x)
        cache = self._cache
        if cache is None or not np.array_equal(cache["pts"], pts):
            B, G = self.field.B_and_gradient(pts)
            cache = self._cache = {
                "pts": pts,
                "B": B[:, :2].copy(),
                "G": G[:, :2, :2].copy(),
                "H": None,
            }
        b = scale * cache["B"]
        Gp = (scale * self.L) * cache["G"]
        H = None
        if hessian and not self.linear:
            if cache["H"] is None:
                last = self._hessian_last
                if (
                    self.hessian_lag > 0
                    and last is not None
                    and np.max(np.abs(last[0] - pts)) <= self.hessian_lag * self.L
                ):
                    cache["H"] = last[1]  # lagged: the centreline moved less than the lag
                else:
                    cache["H"] = self.field.hessian(pts)[:, :2, :2, :2].copy()
                    self._hessian_last = (pts, cache["H"])
            H = (scale * self.L**2) * cache["H"]
        return b, Gp, H

    def _torque_force(self, theta, x, scale, hessian=False):
        b, G, H = self._field(x, scale, hessian)
        m = _rot(theta, self.mu)
        mp = np.stack([-m[:, 1], m[:, 0]], axis=-1)  # dm/dtheta
        tau = np.einsum("ni,ni->n", mp, b)
        if G is None:
            return tau, None, m, mp, b, G, H
        f = np.einsum("nij,ni->nj", G, m)  # f_j = G_ij m_i
        return tau, f, m, mp, b, G, H

    # -- residual -------------------------------------------------------------------------------
    def residual(self, u: np.ndarray, scale: float) -> np.ndarray:
        """Residual vector, shape (size,), in the unknowns' layout (row order of the Jacobian)."""
        mesh = self.mesh
        h, w = mesh.h, mesh.w
        theta = self.theta(u)
        bend = np.zeros(self.n)
        dth = np.diff(theta) / h
        bend[1:] += dth
        bend[:-1] -= dth
        if self.uniform:
            return self._evaluate_uniform(theta, scale, False)[0]
        v = u.reshape(self.n, _NV)
        x, F = v[:, 1:3], v[:, 3:5]
        tau, f = self._torque_force(theta, x, scale)[:2]
        tp = np.stack([-np.sin(theta), np.cos(theta)], axis=-1)
        c = np.concatenate([[0.0], h / 2])
        r = np.empty((self.n, _NV))
        r[:, 0] = bend - w * tau - np.einsum("ni,ni->n", tp, w[:, None] * F + (c * w)[:, None] * f)
        r[0, 0] = theta[0] - self.theta0
        t = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
        r[0, 1:3] = x[0]
        r[1:, 1:3] = x[1:] - x[:-1] - h[:, None] * (t[:-1] + t[1:]) / 2
        r[-1, 3:5] = F[-1]
        r[:-1, 3:5] = F[:-1] - F[1:] - w[1:, None] * f[1:]
        return r.ravel()

    def load_derivative(self, u: np.ndarray, scale: float) -> np.ndarray:
        """dR/dscale at fixed unknowns (the residual is affine in the scale), shape (size,)."""
        if self.uniform:
            out = -self._uniform_parts(u, 1.0)[0]
            out[0] = 0.0
            return out
        return self.residual(u, 1.0) - self.residual(u, 0.0)

    def residual_norm(self, r: np.ndarray) -> float:
        """Max-norm of the residual with each equation scaled to a point value (non-dim)."""
        w = self.mesh.w
        if self.uniform:
            return float(np.max(np.abs(r[1:] * self._inv_w)))
        v = r.reshape(self.n, _NV)
        h = self.mesh.h
        parts = [
            np.abs(v[1:, 0] / w[1:]),
            np.abs(v[1:, 1:3] / h[:, None]).ravel(),
            np.abs(v[:-1, 3:5] / w[1:, None]).ravel(),
        ]
        return float(max(np.max(p) for p in parts))

    # -- uniform fast path ----------------------------------------------------------------------
    def _uniform_parts(self, theta: np.ndarray, scale: float):
        """w tau and w m.b at the nodes for a uniform field: with m = R(theta) mu,
        tau = cos(theta) P - sin(theta) Q and m.b = cos(theta) Q + sin(theta) P."""
        c, s = np.cos(theta), np.sin(theta)
        return scale * (c * self._P1 - s * self._Q1), scale * (c * self._Q1 + s * self._P1)

    def _evaluate_uniform(self, theta, scale, jacobian):
        wtau, wmb = self._uniform_parts(theta, scale)
        dth = np.diff(theta) * self._inv_h
        r = -wtau
        r[1:] += dth
        r[:-1] -= dth
        r[0] = theta[0] - self.theta0
        if not jacobian:
            return r, None
        d = self._k_diag + wmb
        d[0] = 1.0
        return r, (self._k_low, d, self._k_up)

    def evaluate(self, u: np.ndarray, scale: float, jacobian: bool = True):
        """Residual, shape (size,), and (if ``jacobian``) the exact Jacobian in the form
        :meth:`solve` takes: ``(sub, diag, super)`` diagonals for a uniform field, else LAPACK
        band storage ``(ab, (l, u))``.  One field evaluation serves both."""
        if self.uniform:
            return self._evaluate_uniform(u, scale, jacobian)
        return self.residual(u, scale), (self.jacobian(u, scale) if jacobian else None)

    # -- Jacobian -------------------------------------------------------------------------------
    def jacobian(self, u: np.ndarray, scale: float):
        """Exact Jacobian: tridiagonal ``(sub, diag, super)`` for a uniform field, else LAPACK
        band storage ``(ab, (l, u))`` (7 sub- and 6 super-diagonals)."""
        if self.uniform:
            return self._evaluate_uniform(u, scale, True)[1]
        rows, cols, vals = self._jacobian_triplets(u, scale)
        ab = np.zeros((_LOW + _UP + 1, self.size))
        np.add.at(ab, (_UP + rows - cols, cols), vals)
        return ab, (_LOW, _UP)

    def dense_jacobian(self, u: np.ndarray, scale: float) -> np.ndarray:
        """The Jacobian as a dense (size, size) array (for tests and small problems)."""
        if self.uniform:
            low, diag, up = self.jacobian(u, scale)
            return np.diag(diag) + np.diag(low, -1) + np.diag(up, 1)
        ab, (lo, up) = self.jacobian(u, scale)
        J = np.zeros((self.size, self.size))
        for d in range(-lo, up + 1):
            diag = ab[up - d, max(d, 0) : self.size + min(d, 0)]
            J += np.diag(diag, d)
        return J

    def _jacobian_triplets(self, u, scale):
        n, h, w = self.n, self.mesh.h, self.mesh.w
        v = u.reshape(n, _NV)
        theta, x, F = v[:, 0], v[:, 1:3], v[:, 3:5]
        tau, f, m, mp, b, G, H = self._torque_force(theta, x, scale, hessian=True)
        t = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
        tp = np.stack([-t[:, 1], t[:, 0]], axis=-1)
        c = np.concatenate([[0.0], h / 2])
        Gtmp = np.einsum("nij,ni->nj", G, mp)  # df/dtheta = G^T m_perp, also dtau/dx
        if H is None:
            dfdx = np.zeros((n, 2, 2))
        else:
            dfdx = np.einsum("nijl,ni->njl", H, m)  # df_j/dx_l
        idx = np.arange(n)
        R, C, V = [], [], []

        def add(r, cc, val):
            R.append(np.asarray(r).ravel())
            C.append(np.asarray(cc).ravel())
            V.append(np.broadcast_to(val, np.shape(r)).ravel())

        i = idx[1:]
        # moment equations g_i, i >= 1
        add(_NV * i, _NV * (i - 1), -1 / h)
        add(_NV * idx[1:-1], _NV * (idx[1:-1] + 1), -1 / h[1:])
        diag = np.zeros(n)
        diag[1:] += 1 / h
        diag[:-1] += 1 / h
        load = w[:, None] * F + (c * w)[:, None] * f
        diag += (
            w * np.einsum("ni,ni->n", m, b)
            + np.einsum("ni,ni->n", t, load)
            - c * w * np.einsum("ni,ni->n", tp, Gtmp)
        )
        add(_NV * i, _NV * i, diag[1:])
        dgdx = -w[:, None] * Gtmp - (c * w)[:, None] * np.einsum("nj,njl->nl", tp, dfdx)
        dgdF = -w[:, None] * tp
        for a in range(2):
            add(_NV * i, _NV * i + 1 + a, dgdx[1:, a])
            add(_NV * i, _NV * i + 3 + a, dgdF[1:, a])
        add(0, 0, 1.0)
        # position equations
        for a in range(2):
            add(_NV * i + 1 + a, _NV * i + 1 + a, 1.0)
            add(_NV * i + 1 + a, _NV * (i - 1) + 1 + a, -1.0)
            add(_NV * i + 1 + a, _NV * (i - 1), -h / 2 * tp[:-1, a])
            add(_NV * i + 1 + a, _NV * i, -h / 2 * tp[1:, a])
            add(1 + a, 1 + a, 1.0)
        # force equations
        j = idx[:-1]
        for a in range(2):
            add(_NV * j + 3 + a, _NV * j + 3 + a, 1.0)
            add(_NV * j + 3 + a, _NV * (j + 1) + 3 + a, -1.0)
            add(_NV * j + 3 + a, _NV * (j + 1), -w[1:] * Gtmp[1:, a])
            for b_ in range(2):
                add(_NV * j + 3 + a, _NV * (j + 1) + 1 + b_, -w[1:] * dfdx[1:, a, b_])
            add(_NV * (n - 1) + 3 + a, _NV * (n - 1) + 3 + a, 1.0)
        return np.concatenate(R), np.concatenate(C), np.concatenate(V)

    # -- linear algebra ---------------------------------------------------------------------------
    def solve(self, jac, rhs: np.ndarray) -> np.ndarray:
        """Solve J z = rhs (rhs shape (size,) or (size, k)) with the banded LU (LAPACK gtsv
        for the tridiagonal Jacobian of a uniform field, gbsv otherwise)."""
        if self.uniform:
            low, diag, up = jac
            _, _, _, z, info = _gtsv(
                low,
                diag,
                up,
                rhs,
                overwrite_dl=False,
                overwrite_d=False,
                overwrite_du=False,
                overwrite_b=False,
            )
            if info != 0:
                raise np.linalg.LinAlgError(f"singular tridiagonal Jacobian (info {info})")
            return z
        ab, lu = jac
        return solve_banded(lu, ab, rhs, check_finite=False)

    def min_eigenvalue(self, u: np.ndarray, scale: float, jac=None) -> float:
        """Smallest eigenvalue mu of the second variation, H z = mu W z (W = diag(w)).

        H is the Hessian of the discrete energy in the free angles theta_1..theta_N (positions
        and forces eliminated); mu approximates the smallest eigenvalue of the continuous
        second variation (per unit length, non-dimensional): the equilibrium is stable iff
        mu > 0.  Cost O(N) for uniform fields (tridiagonal); otherwise O(N^3) (dense) up to
        ``_DENSE_STABILITY`` free nodes and, beyond, a Lanczos iteration on H^-1 whose
        products are banded solves (O(N) each).
        """
        w = self.mesh.w[1:]
        if jac is None:
            jac = self.jacobian(u, scale)
        if self.uniform:
            d = jac[1][1:] * self._inv_w
            e = self._stab_e
            # bisection for the lowest eigenvalue only (LAPACK stebz), O(N)
            abstol = 1e-13 * float(np.max(np.abs(d)))
            m, ev, _, _, info = _stebz(d, e, 3, 0.0, 0.0, 1, 1, abstol, "E")
            if info != 0 or m < 1:
                return float(eigvalsh_tridiagonal(d, e, select="i", select_range=(0, 0))[0])
            return float(ev[0])
        if self.n - 1 > _DENSE_STABILITY:
            return self._min_eigenvalue_sparse(jac)
        rhs = np.zeros((self.size, self.n - 1))
        rhs[_NV * np.arange(1, self.n), np.arange(self.n - 1)] = 1.0
        Hinv = self.solve(jac, rhs)[_NV * np.arange(1, self.n)]
        sq = np.sqrt(w)
        S = sq[:, None] * Hinv * sq[None, :]
        S = 0.5 * (S + S.T)
        # mu = 1 / sigma, sigma the eigenvalues of S = W^(1/2) H^-1 W^(1/2)
        try:
            np.linalg.cholesky(S)
        except np.linalg.LinAlgError:
            neg = eigh(S, eigvals_only=True, subset_by_value=(-np.inf, 0.0), check_finite=False)
            if neg.size:
                return float(1.0 / np.max(neg))
        return float(1.0 / _largest_eigenvalue(S))

    def _min_eigenvalue_sparse(self, jac) -> float:
        """Eigenvalue of H z = mu W z closest to zero, by ARPACK on S = W^(1/2) H^-1 W^(1/2)
        (largest magnitude), each product one banded solve; the sign of det H (parity of the
        number of negative eigenvalues, from the banded LU) guards against an unstable state
        whose closest-to-zero eigenvalue is positive."""
        from scipy.linalg.lapack import dgbtrf
        from scipy.sparse.linalg import LinearOperator, eigsh

        idx = _NV * np.arange(1, self.n)
        sq = np.sqrt(self.mesh.w[1:])
        rhs = np.zeros(self.size)

        def matvec(x):
            rhs[:] = 0.0
            rhs[idx] = sq * np.ravel(x)
            return sq * self.solve(jac, rhs)[idx]

        op = LinearOperator((self.n - 1, self.n - 1), matvec=matvec, dtype=float)
        sigma = eigsh(op, k=1, which="LM", tol=1e-10, return_eigenvectors=False)[0]
        mu = 1.0 / sigma
        if mu > 0:  # odd number of negative eigenvalues of H <=> det J changes sign
            ab, (lo, up) = jac
            work = np.zeros((2 * lo + up + 1, self.size))
            work[lo:] = ab
            lu, piv, info = dgbtrf(work, lo, up)
            if info == 0:
                swaps = np.count_nonzero(piv != np.arange(self.size))
                sign = np.prod(np.sign(lu[lo + up])) * (-1) ** swaps
                if sign != self._det_sign_reference():
                    return -abs(mu)  # unstable: report the magnitude with the sign of H
        return float(mu)

    def _det_sign_reference(self) -> float:
        """Sign of det J for the straight unloaded rod (H positive definite there)."""
        if getattr(self, "_det_ref", None) is None:
            from scipy.linalg.lapack import dgbtrf

            ab, (lo, up) = self.jacobian(self.straight(), 0.0)
            work = np.zeros((2 * lo + up + 1, self.size))
            work[lo:] = ab
            lu, piv, _ = dgbtrf(work, lo, up)
            swaps = np.count_nonzero(piv != np.arange(self.size))
            self._det_ref = np.prod(np.sign(lu[lo + up])) * (-1) ** swaps
        return self._det_ref


def _largest_eigenvalue(S: np.ndarray, rtol: float = 1e-13, max_iter: int = 500) -> float:
    """Largest eigenvalue of a symmetric positive-definite matrix by power iteration.

    Small dense LAPACK eigensolvers are slow under BLAS thread contention; the spectrum of the
    inverse second variation is well separated (ratio mu_1 / mu_2 of the rod's lowest modes),
    so a few dozen matrix-vector products suffice.
    """
    x = np.ones(S.shape[0]) / np.sqrt(S.shape[0])
    sigma = 0.0
    for _ in range(max_iter):
        y = S @ x
        new = float(x @ y)
        norm = np.linalg.norm(y)
        if norm == 0:
            return 0.0
        x = y / norm
        if abs(new - sigma) <= rtol * abs(new):
            return new
        sigma = new
    return sigma
