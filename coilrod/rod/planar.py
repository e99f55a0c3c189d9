"""The planar discrete hard-magnetic elastica as a :class:`~coilrod.path.PathProblem`.

Everything here is non-dimensional: lengths in units of L, moments in EI/L, forces in EI/L^2.
Nodes ``s_0 = 0 < ... < s_N = 1`` (:class:`~coilrod.rod.mesh.RodMesh`), segment lengths
``h_i``, trapezoid weights ``w_i``.  The discrete energy is

    E = sum_i (theta_{i+1} - theta_i)^2 / (2 h_i) - c sum_i w_i m_i(theta_i) . b(x_i),
    x_{i+1} = x_i + h_i (t(theta_i) + t(theta_{i+1})) / 2,   t = (cos, sin),

with ``c`` the load scale, ``m_i = R(theta_i) mu_i``, ``mu_i = A L^2 |M| / (EI)`` the body-frame
node magnetization (:func:`~coilrod.rod.mesh.node_magnetization`) and ``b`` the in-plane field.
Its gradient ``g_i = dE/dtheta_i`` is the discrete seed eq. (5):

    g_i = (theta_i - theta_{i-1}) / h_{i-1} + (theta_i - theta_{i+1}) / h_i - c w_i tau_i
          - t_perp_i . (w_i F_i + c (h_{i-1} / 2) w_i f_i),

``tau = m x b``, ``f = G^T m``, ``F_i = c sum_{j > i} w_j f_j`` the force resultant beyond node i.
The scheme is symmetric (trapezoid), so the error expands in even powers of h and Richardson
extrapolation of two meshes gives fourth order.

Two unknown layouts:

* uniform fields: ``theta`` only; the Jacobian (= Hessian of E) is tridiagonal.
* otherwise a mixed layout with positions and force resultants as unknowns, five per node
  ``(x_i, y_i, theta_i, Fx_i, Fy_i)`` and equations ``(position, g_i, force)`` in the same
  order: the Jacobian is banded (5 below, 5 above the diagonal -- the order within a node is
  chosen for the narrowest band), so a Newton step costs O(N).
  Eliminating positions and forces gives back the (dense, symmetric) Hessian of E.

Both layouts evaluate stacks of states at once (``batched``): the k Jacobians of a stack form
one block-diagonal banded matrix, factorised by one LAPACK call (``gttrf``/``gbtrf``) whose
factors serve every solve at that state (Newton step, path tangent, stability).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import eigvalsh_tridiagonal
from scipy.linalg.lapack import dgttrf, dgttrs
from scipy.linalg.lapack import dstebz as _stebz

from ..path.protocol import Linearization
from ._spectrum import closest_to_zero
from ._spectrum import lowest_from_inverse as _lowest_from_inverse
from .discrete import _EPS, _FLOOR, DiscreteRod
from .mesh import _remember

__all__ = ["PlanarRod", "RodTangent"]

_NV = 5  # unknowns per node in the mixed layout: (x, y, theta, Fx, Fy)
_TH = 2  # position of theta in a node's unknowns (and of the moment equation in its rows)
_KL, _KU = 5, 5  # bandwidths of the mixed Jacobian
_DIAG = _KL + _KU  # row of the diagonal in LAPACK's factorisation band storage
#: Free nodes up to which the second variation of the mixed layout is formed densely.
_DENSE_STABILITY = 96


def _rot(theta: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """m = R(theta) mu for body vectors mu (n, 2) and angles (..., n): shape (..., n, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * mu[:, 0] - s * mu[:, 1], s * mu[:, 0] + c * mu[:, 1]], axis=-1)


class RodTangent:
    """Jacobian of a stack of k states, factorised on first use.

    Uniform layout: tridiagonal ``(dl, d, du)`` of the stacked (k n) system; mixed layout:
    LAPACK band storage ``ab`` of the stacked (k 5n) system.  ``bad`` flags members whose
    Jacobian is singular or not finite (their solves return NaN).
    """

    def __init__(
        self,
        k: int,
        size: int,
        uniform: bool,
        parts,
        load_rate: np.ndarray,
        kl: int = _KL,
        ku: int = _KU,
    ):
        self.k, self.size, self.uniform = k, size, uniform
        self.kl, self.ku = kl, ku  # bandwidths of a band layout
        #: Arrays with one row per member that travel with the tangent (sliced by
        #: :func:`_take_tangent`), e.g. the spatial rod's symmetric blocks for the inertia.
        self.blocks: tuple = ()
        self.parts = parts
        self.load_rate = load_rate  # dR/dscale, (k, size)
        self.bad = np.zeros(k, dtype=bool)
        #: Sign of each member's det J when already known (the compiled corrector), else None.
        self.signs = None
        self._lu = None
        self._per_member = False

    def factor(self):
        if self._lu is None:
            self._lu = self._factor_tri() if self.uniform else self._factor_band()
        return self._lu

    def _factor_tri(self):
        d, (dl, du) = self.parts
        d = d.ravel()
        n = self.size
        while True:
            if not np.isfinite(d).all():
                self.bad |= ~np.isfinite(d.reshape(self.k, n)).all(axis=1)
            if self.bad.any():
                d, dl, du = d.copy(), dl.copy(), du.copy()
                for j in np.flatnonzero(self.bad):  # replace by identity blocks
                    d[j * n : (j + 1) * n] = 1.0
                    dl[j * n : (j + 1) * n - 1] = 0.0
                    du[j * n : (j + 1) * n - 1] = 0.0
            dl2, d2, du2, dw, ipiv, info = dgttrf(dl, d, du)
            if info == 0:
                return dl2, d2, du2, dw, ipiv
            self.bad[(info - 1) // n] = True  # a zero pivot: that member is singular

    def _factor_band(self):
        """LU of the stacked band, in place (the band storage becomes the factors).  A member
        that is flagged bad (inadmissible) is replaced by an identity block first; a member
        found singular (an exactly zero pivot; LAPACK completes the factorisation) is flagged,
        and :meth:`solve` then solves member by member so that it cannot spoil the others."""
        # Fortran order, as assembled (a copy only of a C-ordered band): one compiled
        # version of band_lu and band_solve, not one per layout
        ab, n = np.asfortranarray(self.parts), self.size
        diag = self.kl + self.ku
        if np.count_nonzero(self.bad):  # (cheaper than .any() on a few members)
            for j in np.flatnonzero(self.bad):
                ab[:, j * n : (j + 1) * n] = 0.0
                ab[diag, j * n : (j + 1) * n] = 1.0
        ipiv = np.empty(ab.shape[1], dtype=np.int64)
        # LAPACK's gbtf2, compiled: no per-column calls
        info = (_PC or _compiled()).band_lu(ab, self.kl, self.ku, ipiv, 0)
        lu = ab
        self.parts = None  # factorised in place: the band storage now holds the factors
        if info > 0:
            pivots = lu[diag].reshape(self.k, n)
            self.bad |= np.any(pivots == 0.0, axis=1)
            self._per_member = True
        return lu, ipiv

    def take(self, rows) -> RodTangent:
        """Members ``rows`` of this stacked tangent (factors sliced: the blocks are
        independent)."""
        return _take_tangent(self, rows)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve with every member's Jacobian: rhs (k, size) -> (k, size) (NaN rows for
        singular members)."""
        lu = self._lu if self._lu is not None else self.factor()
        if self._per_member:  # a singular member: solve the others one by one
            out = np.full((self.k, self.size), np.nan)
            for j in np.flatnonzero(~self.bad):
                out[j] = _take_tangent(self, [j]).solve(rhs[j : j + 1])[0]
            return out
        bad = self.bad
        any_bad = np.count_nonzero(bad)  # (cheaper than .any() on a few members)
        if self.uniform:
            b = np.ascontiguousarray(rhs, dtype=float)
            if any_bad:  # (a NaN right-hand side of one would spread to the others)
                b = b.copy()
                b[bad] = 0.0
            x, info = dgttrs(*lu, b.reshape(-1))
            if info != 0:
                raise np.linalg.LinAlgError(f"LAPACK solve failed (info {info})")
        else:
            x = np.array(rhs, dtype=float).reshape(-1, 1)
            (_PC or _compiled()).band_solve(lu[0], self.kl, self.ku, lu[1], x)
        x = x.reshape(self.k, self.size)
        if any_bad:
            x[bad] = np.nan
        return x

    def solve_transposed(self, rhs: np.ndarray) -> np.ndarray:
        """Solve with every member's transposed Jacobian (the adjoint of a state): rhs
        (k, size), or (q, k, size) for q right-hand sides per member solved together ->
        the same shape (NaN rows for singular members)."""
        rhs = np.asarray(rhs, dtype=float)
        many = rhs.ndim == 3
        R = rhs if many else rhs[None]
        q = R.shape[0]
        lu = self.factor()
        if self._per_member:
            out = np.full(R.shape, np.nan)
            for j in np.flatnonzero(~self.bad):
                out[:, j] = _take_tangent(self, [j]).solve_transposed(R[:, j : j + 1])[:, 0]
            return out if many else out[0]
        b = np.ascontiguousarray(R.reshape(q, -1).T)  # (k size, q)
        if self.uniform:
            x, info = dgttrs(*lu, b, trans="T")
            if info != 0:
                raise np.linalg.LinAlgError(f"LAPACK solve failed (info {info})")
        else:
            from ._compiled import band_solve_transposed

            x = b
            band_solve_transposed(lu[0], self.kl, self.ku, lu[1], x)
        x = x.T.reshape(q, self.k, self.size)
        x[:, self.bad] = np.nan
        return x if many else x[0]

    def det_signs(self) -> np.ndarray:
        """Sign of each member's Jacobian determinant, shape (k,) (+-1; 0 where singular)."""
        if self.signs is not None:
            return self.signs.copy()
        lu = self.factor()
        n = self.size
        # scipy returns gttrf's pivots 1-based and gbtrf's 0-based
        if self.uniform:
            diag, ipiv, base = lu[1], lu[4], 1
        else:
            diag, ipiv, base = lu[0][self.kl + self.ku], lu[1], 0
        neg = np.count_nonzero((diag < 0).reshape(self.k, n), axis=1)
        moved = ipiv != np.arange(base, ipiv.size + base)
        swaps = np.count_nonzero(moved.reshape(self.k, n), axis=1)
        out = np.where((neg + swaps) % 2 == 0, 1.0, -1.0)
        out[self.bad] = 0.0
        return out


#: The mesh-only constants of :class:`PlanarRod` already computed, keyed on the mesh's h and w
#: by value (every problem gets its own copies); at most ``mesh._CACHE_SIZE`` entries, oldest
#: dropped first (``mesh._remember``).
_MESH_CONSTANTS: dict = {}


def _mesh_constants(h: np.ndarray, w: np.ndarray) -> tuple:
    """1/h, 1/w, h_{i-1}/2 (with 0 first), the bending diagonal 1/h_{i-1} + 1/h_i, its
    round-off scale per w and floor, and the in-plane stability's off-diagonal (all as
    :class:`PlanarRod` uses them), copies of cached arrays."""
    key = (h.tobytes(), w.tobytes())
    cached = _MESH_CONSTANTS.get(key)
    if cached is None:
        n = w.size
        inv_h = 1.0 / h
        inv_w = 1.0 / w
        c = np.concatenate([[0.0], h / 2])  # h_{i-1} / 2
        # round-off scale of each equation row's terms, per unit state magnitude
        bend = np.zeros(n)
        bend[1:] += inv_h
        bend[:-1] += inv_h
        bend_scale = bend * inv_w
        floor_bend = _FLOOR * _EPS * bend_scale[1:]
        stab_e = -inv_h[1:] / np.sqrt(w[1:-1] * w[2:])
        cached = _remember(
            _MESH_CONSTANTS, key, (inv_h, inv_w, c, bend, bend_scale, floor_bend, stab_e)
        )
    return tuple(a.copy() for a in cached)


class PlanarRod(DiscreteRod):
    """The discrete problem for one rod, field and mesh (non-dimensional).

    Parameters
    ----------
    mesh : RodMesh
    mu : ndarray, shape (n, 2)
        Node magnetization in the body frame times A L^2 / (EI), 1/T.
    field : coils.Field
        The applied field (SI) at scale 1.
    length : float
        L in m.
    clamp_position : ndarray, shape (3,)
        Clamp position, m.
    clamp_angle : float
        Clamp tangent angle, rad.
    tol : float
        Newton tolerance on the scaled residual (non-dimensional): a state is converged when
        every equation, scaled to a point value (moment per length in EI/L^2, position mismatch
        per length, force per length in EI/L^3), is below ``tol`` plus its round-off floor.
    mixed : bool
        Use the mixed layout even in a uniform field (sensitivities to a field gradient).
    clamp_field : array-like, shape (3,), optional
        ``field.B(clamp_position)`` in T when the caller has it already (a uniform field is
        then not evaluated again).
    """

    batched = True
    #: Largest change of any node angle between the predicted and converged state of a step.
    max_correction = 0.25
    #: Largest predicted change of any node angle in one load step, rad (the engine also keeps
    #: it within twice the last step's change).
    max_step_change = 0.5
    #: Largest change of any node angle in one Newton step, rad.
    max_rotation = 0.5

    def __init__(
        self, mesh, mu, field, length, clamp_position, clamp_angle, tol=1e-9, mixed=False, *,
        clamp_field=None,
    ):  # fmt: skip
        self.mesh = mesh
        self.mu = np.asarray(mu, float)
        self.field = field
        self.L = float(length)
        self.clamp = np.asarray(clamp_position, float)
        self.theta0 = float(clamp_angle)
        self.tol = float(tol)
        self.uniform = bool(field.uniform) and not mixed
        self.linear = bool(field.linear or field.uniform)
        self.cheap_tangent = self.uniform  # tridiagonal: a tangent costs a residual
        self.n = n = mesh.n
        self.size = n if self.uniform else _NV * n
        h, w = mesh.h, mesh.w
        (
            self._inv_h, self._inv_w, self._c, bend, self._bend_scale, self._floor_bend,
            self._stab_e,
        ) = _mesh_constants(h, w)  # fmt: skip
        self._mu0 = None
        self._tri_cache: dict = {}
        self._no_h = np.zeros((1, 3, 3, 3))  # placeholder hessian of a linear field
        self.last_failure = ""
        #: The field at the clamp (3,), T (uniform layout: the field everywhere), else None.
        self.clamp_field = None
        if self.uniform:
            if clamp_field is None:
                clamp_field = field.B(self.clamp)[0]
            self.clamp_field = np.array(clamp_field, dtype=float)
            bx, by = self.clamp_field[:2].tolist()  # (plain floats: the same products)
            mt, mn = w * self.mu[:, 0], w * self.mu[:, 1]
            self._P1 = mt * by - mn * bx  # w (m x b) and w m.b at theta = 0, scale 1
            self._Q1 = mt * bx + mn * by
            self._k_diag = bend  # 1/h_{i-1} + 1/h_i on the diagonal
            self._k_low = -self._inv_h  # J[i + 1, i] (a new array)
            self._k_up = -self._inv_h  # J[i, i + 1]
            self._k_up[0] = 0.0  # row 0 is the clamp condition

    # -- states -----------------------------------------------------------------------------------
    def straight(self) -> np.ndarray:
        """The straight unloaded state along the clamp tangent, shape (size,)."""
        return self.from_theta(np.full(self.n, self.theta0))

    def from_theta(self, theta: np.ndarray, scale: float = 0.0) -> np.ndarray:
        """Unknowns (size,) with positions and force resultants consistent with ``theta``."""
        theta = np.asarray(theta, float)
        if self.uniform:
            return theta.copy()
        x = self.positions(theta)
        u = np.zeros((self.n, _NV))
        u[:, _TH] = theta
        u[:, 0:2] = x
        if scale != 0.0:
            _, G, _ = self._field(x[None], False)
            m = _rot(theta, self.mu)
            f = (scale * self.L) * np.einsum("nij,ni->nj", G[:, :2, :2], m)
            wf = self.mesh.w[:, None] * f
            u[:-1, 3:5] = np.cumsum(wf[::-1], axis=0)[::-1][1:]
        return u.ravel()

    def theta(self, u: np.ndarray) -> np.ndarray:
        """Node angles of a state (size,) or stack (k, size): shape (n,) or (k, n), rad."""
        return u if self.uniform else u[..., _TH::_NV]

    def positions(self, theta: np.ndarray) -> np.ndarray:
        """Trapezoid centreline relative to the clamp, theta (..., n): (..., n, 2), units of L."""
        t = np.empty(np.shape(theta) + (2,))  # (np.stack's values, without its overhead)
        t[..., 0], t[..., 1] = np.cos(theta), np.sin(theta)
        seg = self.mesh.h[:, None] * (t[..., :-1, :] + t[..., 1:, :]) / 2
        out = np.zeros(t.shape)
        np.cumsum(seg, axis=-2, out=out[..., 1:, :])
        return out

    def points(self, x: np.ndarray) -> np.ndarray:
        """Physical points (..., n, 3) in m from non-dimensional positions (..., n, 2)."""
        pts = np.empty(x.shape[:-1] + (3,))
        pts[..., :2] = self.clamp[:2] + self.L * x
        pts[..., 2] = self.clamp[2]
        return pts

    def interpolate_to(self, fine: PlanarRod, u: np.ndarray) -> np.ndarray:
        """States of this (coarse) mesh on its refinement ``fine`` (every segment halved), by
        linear interpolation: the coarse nodes carry over, the midpoints take the mean of their
        neighbours; u (size,) or (k, size)."""
        if fine.n != 2 * self.n - 1:
            raise ValueError("fine must be the refinement of this mesh (every segment halved)")
        nv = 1 if self.uniform else _NV
        v = np.atleast_2d(u).reshape(-1, self.n, nv)
        out = np.empty((v.shape[0], fine.n, nv))
        out[:, ::2] = v
        out[:, 1::2] = 0.5 * (v[:, :-1] + v[:, 1:])
        out = out.reshape(v.shape[0], -1)
        return out[0] if np.ndim(u) == 1 else out

    # -- adjoint ---------------------------------------------------------------------------------
    def node_positions(self, U: np.ndarray) -> np.ndarray:
        """Node positions of a stack of states (k, size): shape (k, n, 2), units of L."""
        U = np.atleast_2d(U)
        if self.uniform:
            return self.positions(U)
        return U.reshape(U.shape[0], self.n, _NV)[:, :, 0:2]

    def tip_gradients(self, U: np.ndarray) -> np.ndarray:
        """Derivatives of the tip (x_N, y_N in units of L; theta_N in rad) with respect to the
        unknowns of each state of a stack (k, size): shape (3, k, size)."""
        U = np.atleast_2d(U)
        out = np.zeros((3, U.shape[0], self.size))
        if self.uniform:  # x_N = sum_i w_i cos(theta_i), y_N = sum_i w_i sin(theta_i)
            th = U
            out[0] = -self.mesh.w * np.sin(th)
            out[1] = self.mesh.w * np.cos(th)
            out[2, :, -1] = 1.0
        else:
            last = _NV * (self.n - 1)
            out[0, :, last] = 1.0
            out[1, :, last + 1] = 1.0
            out[2, :, last + _TH] = 1.0
        return out

    def field_at_states(self, U: np.ndarray):
        """B (k, n, 3) T and gradient (k, n, 3, 3) T/m of the field at scale 1 at the nodes of
        a stack of states (k, size) (the clamp's field everywhere in the uniform layout)."""
        U = np.atleast_2d(U)
        k = U.shape[0]
        if self.uniform:
            B = np.broadcast_to(self.clamp_field, (k, self.n, 3))
            return B, np.zeros((k, self.n, 3, 3))
        B, G, _ = self._field(self.node_positions(U), False)
        return B.reshape(k, self.n, 3), G.reshape(k, self.n, 3, 3)

    def load_adjoint(self, U: np.ndarray, lam: np.ndarray, B=None, G=None):
        """Derivatives of ``lam . R1`` (R1 = dR/dscale, the magnetic load per unit scale) with
        respect to the node magnetization and the field at the nodes, for a stack of states.

        ``R1`` is linear in the body magnetization ``mu_i`` and in the in-plane field ``b_i``
        and gradient ``G_i`` at each node, and each enters only node i's moment row and node
        i - 1's force rows, so the derivatives are local (closed form, O(n)).

        Parameters
        ----------
        U : ndarray, shape (k, size)
            States.
        lam : ndarray, shape (q, k, size)
            Adjoint vectors (q per state).
        B, G : ndarray, optional
            The field at the nodes (:meth:`field_at_states`), if already evaluated.

        Returns
        -------
        g_mu : ndarray, shape (q, k, n, 2)
            d(lam . R1)/d mu_i (mu in the problem's units, 1/T).
        g_b : ndarray, shape (q, k, n, 2)
            d(lam . R1)/d b_i (in-plane field components, per T).
        g_G : ndarray, shape (q, k, n, 2, 2) or None
            d(lam . R1)/d G_i[c, a] (in-plane gradient, per T/m), ``[c, a]`` = dB_c/dx_a;
            None in the uniform layout (which has no force unknowns; use ``mixed=True``).
        """
        U = np.atleast_2d(U)
        k, n = U.shape[0], self.n
        lam = np.asarray(lam, float).reshape(-1, k, self.size)
        q = lam.shape[0]
        if B is None:
            B, G = self.field_at_states(U)
        th = self.theta(U)
        c, s = np.cos(th), np.sin(th)
        m = _rot(th, self.mu)  # (k, n, 2)
        w = self.mesh.w
        if self.uniform:
            lam_m = lam.copy()
        else:
            v5 = lam.reshape(q, k, n, _NV)
            lam_m = v5[..., _TH].copy()
            lam_F = np.zeros((q, k, n, 2))
            lam_F[:, :, 1:] = v5[:, :, :-1, 3:5]  # node i's force enters node i - 1's rows
        lam_m[..., 0] = 0.0  # row 0 is the clamp condition
        lw = (lam_m * w)[..., None]
        m_perp = np.empty_like(m)
        m_perp[..., 0], m_perp[..., 1] = -m[..., 1], m[..., 0]
        g_b = -lw * m_perp
        b_rot = np.empty(B.shape[:-1] + (2,))
        b_rot[..., 0], b_rot[..., 1] = B[..., 1], -B[..., 0]
        d_m = -lw * b_rot  # d/dm of -lam w (m_perp . b)
        g_G = None
        if not self.uniform:
            t_perp = np.empty((k, n, 2))
            t_perp[..., 0], t_perp[..., 1] = -s, c
            v = -(lam_m * (self._c * w))[..., None] * t_perp - w[:, None] * lam_F
            d_m += self.L * (G[..., :2, :2] @ v[..., None])[..., 0]
            g_G = self.L * m[..., :, None] * v[..., None, :]
        g_mu = np.empty_like(d_m)  # R(theta)^T d_m
        g_mu[..., 0] = c * d_m[..., 0] + s * d_m[..., 1]
        g_mu[..., 1] = c * d_m[..., 1] - s * d_m[..., 0]
        return g_mu, g_b, g_G

    # -- field ---------------------------------------------------------------------------------
    def _field(self, x: np.ndarray, hessian: bool):
        """:meth:`DiscreteRod._field` through the field's prepared evaluator
        (:meth:`coils.field.Field.evaluator`, bound once per problem): the points are made
        here, checked finite once, and evaluated without the public methods' validation and
        dispatch -- the same numbers.  Points that are not finite take the validated path
        (its ValueError)."""
        fields = self._fields
        if fields is None:
            make = getattr(self.field, "evaluator", None)
            if make is None:
                return super()._field(x, hessian)
            fields = self._fields = make()
        pts = np.empty((x.size // 2, 3))
        xy = pts[:, :2]
        np.multiply(x.reshape(-1, 2), self.L, out=xy)  # (the sum below commutes exactly)
        xy += self.clamp[:2]
        pts[:, 2] = self.clamp[2]
        if not math.isfinite(pts.sum()):  # (a sum of finite points may overflow: checked again)
            return super()._field(x, hessian)
        return fields(pts, hessian and not self.linear)

    _fields = None  # the field's prepared evaluator, bound on first use

    def _hessian_by_member(self, x: np.ndarray) -> np.ndarray:
        """The field's hessian alone (k n, 3, 3, 3) T/m^2 at positions x (k, n, 2) (units of
        L; :meth:`coils.field.Field.hessian`), NaN for members where it cannot be evaluated
        (as :meth:`_field_by_member`; the field's message kept in ``last_failure``)."""
        try:
            with np.errstate(all="ignore"):
                return self.field.hessian(self.points(x).reshape(-1, 3))
        except ValueError as exc:
            self.last_failure = f"the field could not be evaluated at the trial states ({exc})"
        k, n = x.shape[0], self.n
        H = np.full((k, n, 3, 3, 3), np.nan)
        for j in range(k):
            try:
                with np.errstate(all="ignore"):
                    H[j] = self.field.hessian(self.points(x[j]))
            except ValueError as exc:
                self.last_failure = f"the field could not be evaluated at the trial states ({exc})"
        return H.reshape(-1, 3, 3, 3)

    # -- the protocol -----------------------------------------------------------------------------
    def linearize(self, u, scale, tangent: bool = True) -> Linearization:
        """Residual (k, size), admissibility (k,) and the tangent of a stack of states."""
        U, S = self._stack(u, scale)
        if self.uniform:
            with np.errstate(all="ignore"):
                R, R1, parts = self._uniform(U, S, tangent)
                ok = np.isfinite(R).all(axis=1)
            field_values = None
        else:  # (the compiled pass and its numpy twin raise no floating-point warnings)
            R, R1, parts, field_values, ok = self._mixed(U, S, tangent)
        tan = RodTangent(U.shape[0], self.size, self.uniform, parts, R1) if tangent else None
        if tan is not None:
            tan.bad |= ~ok
        lin = Linearization(u=U, scale=S, residual=R, ok=ok, tangent=tan)
        lin.load_rate = R1
        # mixed layout: B (k, n, 3), G (k, n, 3, 3) at the nodes; the hessian (k n, 3, 3, 3)
        # or None (a linear field, or no tangent) for the out-of-plane block
        lin.field_values = None if field_values is None else field_values[:2]
        lin.field_hessian = None if field_values is None else field_values[2]
        return lin

    def compiled_newton(self, U: np.ndarray, S: np.ndarray, opts, tangent: bool = True):
        """Newton's method for the stack ``U`` (k, size) (float, C order: iterated in place)
        at scales ``S`` (k,) by a compiled corrector -- the uniform layout's
        (:mod:`coilrod.rod._planar_newton`) or the mixed layout's in coaxial coils' fields
        (:mod:`coilrod.rod._mixed_newton`): the states of
        :func:`~coilrod.path.corrector.newton`, in one call.  Returns ``(U, err, iters,
        lin)`` (``lin`` the linearization at ``U``, with its tangent), or None where it does
        not apply (the mixed layout in another field) or does not pay yet (ski rental; the
        caller then runs the numpy corrector and reports its iterations to
        :meth:`compiled_newton_rent`).
        ``tangent`` False (the caller needs the states and residuals only): the out-of-plane
        Cholesky test that :meth:`negative_counts` could reuse is skipped."""
        if not self.uniform:
            return self._compiled_newton_mixed(U, S, opts, tangent)
        pn = _planar_newton()
        if not pn.compiled_pays():
            return None
        U, F, M = pn.newton_uniform(self, U, S, opts, tangent)
        k = U.shape[0]
        R, R1 = F[0], F[1]
        ok = M[:, 3] != 0.0
        tan = RodTangent(k, self.size, True, (F[2], self._off_diagonals(k)), R1)
        tan.bad = ~ok
        tan.signs = M[:, 1]
        lin = Linearization(u=U, scale=S, residual=R, ok=ok, tangent=tan)
        lin.load_rate = R1
        lin.field_values = None
        lin.field_hessian = None
        lin.path_rate = F[3]  # read by the path engine (coilrod.path.stepping)
        if tangent and self.out_of_plane is not None:  # read by OutOfPlane.odd_count
            lin.odd_definite = M[:, 2] != 0.0
        err, iters = M[:, 0], M[:, 4].astype(int)
        return U, err, iters, lin

    def _compiled_newton_mixed(self, U: np.ndarray, S: np.ndarray, opts, tangent: bool):
        """:meth:`compiled_newton` of the mixed layout in coaxial coils' fields
        (:mod:`coilrod.rod._mixed_newton`), None where it does not apply or pay yet."""
        mn = _mixed_newton()
        if mn._constants(self) is None:  # (another field: cached on the problem)
            return None
        if not (mn.cx._rental.ready and mn.compiled_pays()):  # (the coils' pass compiled)
            return None
        out = mn.newton_mixed(self, U, S, opts, tangent)
        if out is None:
            return None
        k, n, M = U.shape[0], self.n, out["M"]
        R, R1 = out["R"], out["R1"]
        ok = M[:, 2] != 0.0
        lin = Linearization(u=U, scale=S, residual=R, ok=ok)
        lin.load_rate = R1
        lin.field_values = lin.field_hessian = None
        if tangent:
            tan = RodTangent(k, self.size, False, None, out["RT1"])
            tan._lu = (out["ab"], out["ipiv"])
            tan.bad = M[:, 4] != 0.0
            tan.signs = M[:, 3].copy()
            lin.tangent = tan
            lin.field_values = (out["B"].reshape(k, n, 3), out["G"].reshape(k, n, 3, 3))
            if (M[:, 5] != 0.0).all():
                lin.field_hessian = out["H"].reshape(k * n, 3, 3, 3)
            lin.path_rate = out["rate"]  # read by the path engine (coilrod.path.stepping)
            if self.out_of_plane is not None:  # the 3D count (negative_counts), done there
                even = _even_count(tan.signs * self.det_reference())
                odd = M[:, 6].astype(int)
                total = np.where((odd >= 0) & (even >= 0), odd + even, -1)
                lin._counts_3d = (total, odd)
        return U, M[:, 0].copy(), M[:, 1].astype(int), lin

    def compiled_newton_rent(self, iters) -> None:
        """Charge a numpy corrector call of ``iters`` iterations (per member) to the ski rental
        of :meth:`compiled_newton`."""
        if self.uniform:
            _planar_newton().charge(iters)
        elif _mixed_newton()._constants(self) is not None:
            _mixed_newton().charge(iters)

    def dense_jacobian(self, u: np.ndarray, scale: float) -> np.ndarray:
        """The Jacobian of one state as a dense (size, size) array (tests, small problems)."""
        tan = self.linearize(u, scale).tangent
        N = self.size
        J = np.zeros((N, N))
        if self.uniform:
            d, (dl, du) = tan.parts
            return np.diag(d[0]) + np.diag(dl, -1) + np.diag(du, 1)
        ab = tan.parts
        for off in range(-_KL, _KU + 1):  # off = column - row
            diag = ab[_DIAG - off, max(off, 0) : N + min(off, 0)]
            J += np.diag(diag, off)
        return J

    def error(self, lin: Linearization, du) -> np.ndarray:
        """max over equations of |scaled residual| / (tol + its round-off floor), shape (k,)."""
        R, U = lin.residual, lin.u
        k = R.shape[0]
        if self.uniform:
            with np.errstate(all="ignore"):
                size_th = 1.0 + np.abs(U).max(axis=1, keepdims=True)
                scaled = np.abs(R[:, 1:]) * self._inv_w[1:]
                return (scaled / (self.tol + size_th * self._floor_bend)).max(axis=1)
        out = np.empty(k)
        _compiled().mixed_error(
            R, U, self._inv_w, self._inv_h, self._bend_scale, self.tol, _FLOOR * _EPS, out
        )
        return out

    def residual_norm(self, residual) -> np.ndarray:
        """Max-norm of the scaled residual (non-dimensional), shape (k,), of residuals (k, size)
        (or of a linearization's)."""
        R = residual.residual if isinstance(residual, Linearization) else residual
        if self.uniform:
            return np.max(np.abs(R[:, 1:] * self._inv_w[1:]), axis=1)
        v = R.reshape(R.shape[0], self.n, _NV)
        return np.maximum(
            np.max(np.abs(v[:, 1:, _TH]) * self._inv_w[1:], axis=1),
            np.maximum(
                np.max(np.abs(v[:, 1:, 0:2]) * self._inv_h[None, :, None], axis=(1, 2)),
                np.max(np.abs(v[:, :-1, 3:5]) * self._inv_w[None, 1:, None], axis=(1, 2)),
            ),
        )

    def step_limit(self, u, du):
        """No node angle turns by more than :attr:`max_rotation` in one Newton step."""
        du = np.asarray(du)
        du = du if du.ndim == 2 else du[None]
        rot = np.abs(self.theta(du)).max(axis=1)
        out = np.ones(rot.shape)
        turns = rot > 0  # (NaN: 1, as the line search then rejects the step)
        if turns.any():
            out[turns] = np.minimum(1.0, self.max_rotation / rot[turns])
        return out

    def distance(self, du):
        """Largest change of a node angle, rad, shape (k,)."""
        du = np.asarray(du)
        if du.ndim != 2:
            du = du[None]
        return np.abs(du if self.uniform else du[:, _TH::_NV]).max(axis=1)

    def arclength_weights(self) -> np.ndarray:
        w = np.zeros(self.size)
        w[np.arange(self.n) * (self.size // self.n) + (0 if self.uniform else _TH)] = 1 / self.n
        return w

    #: The out-of-plane block (:class:`~coilrod.rod.out_of_plane.OutOfPlane`) of the spatial
    #: rod's second variation that gives the 3D stability of the planar states; None:
    #: in-plane stability only.
    out_of_plane = None

    def with_out_of_plane(self, stiffness) -> PlanarRod:
        """This problem with 3D stability: :meth:`stability` then counts the out-of-plane
        modes too (``stiffness`` = (GJ, EI_y, EI_z) / EI_z); returns self."""
        from .out_of_plane import OutOfPlane

        self.out_of_plane = OutOfPlane(self, stiffness)
        self.__dict__.pop("_newton_constants", None)  # (the compiled corrector's, now stale)
        return self

    def stability(self, lin: Linearization, precise: bool = False) -> np.ndarray:
        """Stability of the states of ``lin`` in 3D when the problem has an
        :attr:`out_of_plane` block, else in the plane (:meth:`stability_in_plane`).

        3D: the cheap indicator is +1 for a stable state and minus the number of negative
        eigenvalues of the spatial second variation otherwise (0 where it cannot be
        evaluated); ``precise``: its smallest eigenvalue (EI_z / L^3 units, the in-plane
        figure's normalisation).  ``lin`` may carry ``uniform_fields`` (k, 3) T, one uniform
        field per member (a fan of field directions)."""
        if self.out_of_plane is None or (not precise and _odd_definite(lin)):
            # (no out-of-plane negatives: the 3D indicator is the in-plane sign of det J)
            return self.stability_in_plane(lin, precise)
        total, odd_count = self.negative_counts(lin)
        signs = np.negative(total, dtype=float)  # (+1 stable, -count, 0 not finite)
        signs[total == 0] = 1.0
        signs[total < 0] = 0.0
        if not precise:
            return signs
        odd = self.out_of_plane.lowest(lin, getattr(lin, "uniform_fields", None), odd_count)
        out = np.fmin(self.stability_in_plane(lin, precise=True), odd)
        out[total < 0] = np.nan
        return out

    def negative_counts(self, lin: Linearization):
        """Negative eigenvalues of the 3D second variation at the states of ``lin``: (in all,
        out of the plane), two int arrays (k,) (-1 where not finite); cached on ``lin``.

        The in-plane count is the parity of the planar determinant's sign (the planar rod's
        eigenvalues are simple); the out-of-plane one is exact (block LDL^T of the odd block
        of the spatial rod's second variation,
        :meth:`~coilrod.rod.out_of_plane.OutOfPlane.odd_count`): reflection through the
        plane decouples the two exactly.  Needs :attr:`out_of_plane`."""
        cached = getattr(lin, "_counts_3d", None)
        if cached is not None:
            return cached
        even = _even_count(lin.tangent.det_signs() * self.det_reference())
        if _odd_definite(lin):  # no out-of-plane negatives
            lin._counts_3d = (even, np.zeros_like(even))
            return lin._counts_3d
        odd = self.out_of_plane.odd_count(lin, getattr(lin, "uniform_fields", None))
        total = np.where((odd >= 0) & (even >= 0), odd + even, -1)
        lin._counts_3d = (total, odd)
        return lin._counts_3d

    def branch_stability(self, lin: Linearization, precise: bool = False) -> np.ndarray:
        """Stability among the states the model can follow (in the plane): the engine's
        folds and snap landings are those of the planar branch."""
        return self.stability_in_plane(lin, precise)

    def stability_in_plane(self, lin: Linearization, precise: bool = False) -> np.ndarray:
        """Smallest eigenvalue mu of the in-plane second variation ``H z = mu W z``
        (W = diag(w)).

        H is the Hessian of the discrete energy in the free angles theta_1..theta_N
        (positions and forces eliminated); mu approximates the smallest eigenvalue of the
        continuous second variation per unit length (non-dimensional, EI/L^3 units): the
        equilibrium is stable iff mu > 0.  The cheap indicator is the sign of det J relative
        to the straight unloaded rod (+-1: the parity of the number of negative eigenvalues;
        the planar rod's eigenvalues are simple), read off the factors already at hand.
        ``precise``: uniform fields, an O(N) bisection of the tridiagonal H; otherwise power
        iteration on ``W^1/2 H^-1 W^1/2`` with the banded factors (dense spectrum or ARPACK
        for unstable states).
        """
        signs = lin.tangent.det_signs() * self.det_reference()
        if not precise:
            return signs
        if self.uniform:
            return self._stability_tridiagonal(lin)
        return self._stability_mixed(lin, signs)

    def det_reference(self) -> float:
        """Sign of det J of the straight unloaded rod, whose second variation is positive: +1
        in both layouts (det J = det H, the clamp rows and the position and force equations
        contributing unit triangular factors; asserted by the tests against a dense
        determinant)."""
        return 1.0

    # -- uniform layout ---------------------------------------------------------------------------
    def _uniform(self, th: np.ndarray, S: np.ndarray, tangent: bool, P1=None, Q1=None):
        """Uniform layout of a stack th (k, n); ``P1``, ``Q1`` (k, n) replace the field terms
        ``w (m x b)`` and ``w m.b`` at theta = 0 (one field direction per member)."""
        P1 = self._P1 if P1 is None else P1
        Q1 = self._Q1 if Q1 is None else Q1
        c, s = np.cos(th), np.sin(th)
        R1 = s * Q1 - c * P1  # -w tau per unit scale
        R1[:, 0] = 0.0
        dth = (th[:, 1:] - th[:, :-1]) * self._inv_h
        Sc = S[:, None]
        R = Sc * R1
        R[:, 1:] += dth
        R[:, :-1] -= dth
        R[:, 0] = th[:, 0] - self.theta0
        if not tangent:
            return R, R1, None
        d = Sc * (c * Q1 + s * P1)  # w m.b
        d += self._k_diag  # bending; row 0 is the clamp condition
        d[:, 0] = 1.0
        return R, R1, (d, self._off_diagonals(th.shape[0]))

    def _off_diagonals(self, k: int):
        """Sub- and super-diagonals of k stacked tridiagonal Jacobians (constant: bending)."""
        cached = self._tri_cache.get(("tri", k))
        if cached is None:
            dl = np.zeros((k, self.n))
            du = np.zeros((k, self.n))
            dl[:, :-1] = self._k_low
            du[:, :-1] = self._k_up
            cached = self._tri_cache[("tri", k)] = (dl.ravel()[:-1], du.ravel()[:-1])
        return cached

    def _stability_tridiagonal(self, lin: Linearization) -> np.ndarray:
        d_all = lin.tangent.parts[0]
        out = np.empty(lin.tangent.k)
        e = self._stab_e
        for j in range(lin.tangent.k):
            d = d_all[j, 1:] * self._inv_w[1:]
            if not np.all(np.isfinite(d)):
                out[j] = np.nan
                continue
            m, ev, _, _, info = _stebz(d, e, 3, 0.0, 0.0, 1, 1, 0.0, "E")
            out[j] = (
                ev[0]
                if info == 0 and m >= 1
                else eigvalsh_tridiagonal(d, e, select="i", select_range=(0, 0))[0]
            )
        return out

    # -- mixed layout -----------------------------------------------------------------------------
    def _mixed(self, U: np.ndarray, S: np.ndarray, tangent: bool):
        """Residual, load derivative, band Jacobian, the field at the nodes (B (k, n, 3),
        G (k, n, 3, 3), kept for the adjoint) and which members are finite (k,) (their
        residual rows are, the others' are NaN) of a stack, by the compiled pass of
        :mod:`coilrod.rod._compiled` (the equations are in the module docstring)."""
        mixed_assembly = _compiled().mixed_assembly
        k, n = U.shape[0], self.n
        B, G, H = self._field_by_member(U.reshape(k, n, _NV)[:, :, 0:2], tangent)
        R = np.empty((k, self.size))
        R1 = np.empty((k, self.size))
        # (2, 2) when unused: a (1, 1) array is C- and F-contiguous alike, numba types it as C
        # and would compile a second specialisation of the kernel (~2 s CPU on a cold cache)
        shape = (2 * _KL + _KU + 1, k * self.size) if tangent else (2, 2)
        ab = np.zeros(shape, order="F")  # Fortran order: LAPACK factorises it in place
        finite = np.empty(k, dtype=np.bool_)
        has_h = H is not None
        mixed_assembly(
            U,
            S,
            B,
            G,
            H if has_h else self._no_h,
            has_h,
            self.L,
            self.mu,
            self.mesh.h,
            self.mesh.w,
            self.theta0,
            tangent,
            R,
            R1,
            ab,
            finite,
        )
        if not finite.all():
            R[~finite] = np.nan
        fields = (B.reshape(k, n, 3), G.reshape(k, n, 3, 3), H)
        return R, R1, (ab if tangent else None), fields, finite

    def _stability_mixed(self, lin: Linearization, signs: np.ndarray) -> np.ndarray:
        """Smallest second-variation eigenvalue of each member (see :meth:`stability`).

        ``S = W^1/2 H^-1 W^1/2`` has eigenvalues ``sigma = 1 / mu``; each product with it is
        one solve with the banded factors already at hand, batched over the members.  Where
        det H has the sign of the unloaded rod's (an even number of negative eigenvalues --
        none on a path from the unloaded rod: the planar rod's eigenvalues are simple), the
        lowest ``mu`` is ``1 / sigma_max``, the dominant eigenvalue of S, by power iteration
        with Rayleigh quotients (error ~ (mu_1 / mu_2)^(2 k) after k products).  The other
        members (unstable) take the dense spectrum of S (or ARPACK beyond
        ``_DENSE_STABILITY`` free nodes).
        """
        k = lin.tangent.k
        out = np.full(k, np.nan)
        rows = _NV * np.arange(1, self.n) + _TH
        sq = np.sqrt(self.mesh.w[1:])
        even = signs > 0
        members = np.flatnonzero(even)
        if members.size:
            tan = lin.tangent if members.size == k else _take_tangent(lin.tangent, members)
            sigma = _dominant_batched(tan, rows, sq)
            good = np.isfinite(sigma) & (sigma > 0)
            out[members[good]] = 1.0 / sigma[good]
            even[members[~good]] = False
        for j in np.flatnonzero(~even & (signs != 0)):
            one = _take_tangent(lin.tangent, [j])
            if self.n - 1 > _DENSE_STABILITY:
                out[j] = self._stability_sparse(one, signs[j])
                continue
            rhs = np.zeros((self.n - 1, self.size))
            rhs[np.arange(self.n - 1), rows] = 1.0
            Hinv = np.stack([one.solve(r[None])[0, rows] for r in rhs], axis=1)
            S = sq[:, None] * Hinv * sq[None, :]
            S = 0.5 * (S + S.T)
            if np.all(np.isfinite(S)):
                out[j] = _lowest_from_inverse(S)
        return out

    def _stability_sparse(self, tan: RodTangent, sign: float) -> float:
        """Eigenvalue of H z = mu W z closest to zero, by ARPACK on W^1/2 H^-1 W^1/2 (each
        product one banded solve), with the sign of det H (the parity of the number of
        negative eigenvalues) guarding against an unstable state whose closest-to-zero
        eigenvalue is positive."""
        idx = _NV * np.arange(1, self.n) + _TH
        sq = np.sqrt(self.mesh.w[1:])
        rhs = np.zeros((1, self.size))

        def matvec(v):
            rhs[:] = 0.0
            rhs[0, idx] = sq * np.ravel(v)
            return sq * tan.solve(rhs)[0, idx]

        return closest_to_zero(matvec, self.n - 1, sign)


def _even_count(signs: np.ndarray) -> np.ndarray:
    """Negative in-plane eigenvalues (mod 2) from the signs of det J relative to the unloaded
    rod (k,): 0 for +1, 1 for -1, -1 (unknown) for 0."""
    return np.where(signs > 0, 0, np.where(signs < 0, 1, -1))


def _odd_definite(lin: Linearization) -> bool:
    """The compiled corrector proved the out-of-plane block of every member of ``lin``
    positive definite (its Cholesky test, ``lin.odd_definite``; not for a fan of fields)."""
    known = getattr(lin, "odd_definite", None)
    return known is not None and getattr(lin, "uniform_fields", None) is None and known.all()


def _planar_newton():
    """The compiled corrector's module (:mod:`coilrod.rod._planar_newton`), imported on first
    use (it imports numba) and kept: the import statement's lookup is a measurable part of a
    small corrector call."""
    global _PN
    if _PN is None:
        from . import _planar_newton as pn

        _PN = pn
    return _PN


_PN = None


def _mixed_newton():
    """:mod:`coilrod.rod._mixed_newton`, imported on first use (it imports numba) and kept (as
    :func:`_planar_newton`)."""
    global _MN
    if _MN is None:
        from . import _mixed_newton as mn

        _MN = mn
    return _MN


_MN = None


def _compiled():
    """:mod:`coilrod.rod._compiled`, imported on first use (it imports numba) and kept (as
    :func:`_planar_newton`)."""
    global _PC
    if _PC is None:
        from . import _compiled as pc

        _PC = pc
    return _PC


_PC = None


def _take_tangent(tan: RodTangent, rows) -> RodTangent:
    """Members ``rows`` of a stacked tangent (factors sliced: the blocks are independent)."""
    rows = np.asarray(rows, dtype=int)
    out = _take_members(tan, rows)
    out.blocks = tuple(b[rows] for b in tan.blocks)
    return out


def _take_members(tan: RodTangent, rows: np.ndarray) -> RodTangent:
    n = tan.size
    cols = (rows[:, None] * n + np.arange(n)[None, :]).ravel()
    if tan.uniform:
        d, (dl, du) = tan.parts
        off = (dl[: rows.size * n - 1], du[: rows.size * n - 1])  # the same for every member
        out = RodTangent(rows.size, n, True, (d[rows], off), tan.load_rate[rows], tan.kl, tan.ku)
        out.bad = tan.bad[rows].copy()
        return out  # refactorised on use (tridiagonal: O(n), cheaper than slicing pivots)
    out = RodTangent(rows.size, n, False, None, tan.load_rate[rows], tan.kl, tan.ku)
    out.bad = tan.bad[rows].copy()
    if tan._lu is not None:
        lu, ipiv = tan._lu
        shift = np.repeat(rows * n - np.arange(rows.size) * n, n)
        out._lu = (np.asfortranarray(lu[:, cols]), ipiv[cols] - shift)
    else:
        out.parts = np.asfortranarray(tan.parts[:, cols])
    return out


def _dominant_batched(tan: RodTangent, rows, sq, rtol: float = 1e-13, max_iter: int = 300):
    """Dominant eigenvalue of ``S_j = W^1/2 H_j^-1 W^1/2`` for every member j of ``tan``,
    by power iteration with Rayleigh quotients, one batched banded solve per product."""
    k, nf = tan.k, rows.size
    x = np.full((k, nf), 1.0 / np.sqrt(nf))
    sigma = np.zeros(k)
    rhs = np.zeros((k, tan.size))
    for _ in range(max_iter):
        rhs[:, rows] = sq * x
        with np.errstate(all="ignore"):
            y = tan.solve(rhs)[:, rows] * sq
            new = np.einsum("ki,ki->k", x, y)
            norm = np.linalg.norm(y, axis=1)
            x = y / norm[:, None]
        done = np.abs(new - sigma) <= rtol * np.abs(new)
        sigma = new
        if np.all(done | ~np.isfinite(new)):
            break
    return sigma
