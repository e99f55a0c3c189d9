"""The spatial discrete hard-magnetic Kirchhoff rod as a :class:`~coilrod.path.PathProblem`.

Non-dimensional like :mod:`coilrod.rod.planar`: lengths in L, moments in EI_z/L, forces in
EI_z/L^2 (EI_z the in-plane bending stiffness, :attr:`coilrod.Rod.bending_stiffness`).  Nodes
``s_0 = 0 < ... < s_N = 1`` with segment lengths ``h_i`` and trapezoid weights ``w_i``; each
node carries a cross-section frame ``R_i`` in SO(3) (columns: tangent, normal, binormal).

Discretisation (inextensible, unshearable).  The discrete energy is

    E = sum_i psi_i^T K psi_i / (2 h_i) - c sum_i w_i m_i . b(x_i),
    psi_i = log(R_i^T R_{i+1}),   m_i = R_i mu_i,
    x_{i+1} = x_i + h_i (t_i + t_{i+1}) / 2,   t_i = R_i e_1,

with ``K = diag(GJ, EI_y, EI_z) / EI_z`` (torsion, bending about the normal, bending about the
binormal), ``mu_i`` the body-frame node magnetization times ``A L^2 / EI_z`` (1/T) and ``b``
the field (T) at scale 1, ``c`` the load scale.  ``psi_i / h_i`` is the body-frame Darboux
vector of segment i (exact for a helix between the nodes); for a planar state (rotations about
z) the energy is exactly that of :mod:`coilrod.rod.planar`, so the two solvers share their
discrete solutions.  The scheme is symmetric: the error expands in even powers of h (second
order; fourth with the Richardson extrapolation of :func:`~coilrod.solve_rod`).

Unknowns.  The frames are ``R_i = exp(hat(phi_i)) R_0`` with ``phi_i`` the rotation vector (rad,
world frame) relative to the clamp frame ``R_0``: a vector chart, so the engine's predictors and
secants apply unchanged; it is singular only where a node has turned a full 2 pi relative to
the clamp (:attr:`SpatialRod.max_turn` guards it).  The equations are the moment balances in the
world frame (the derivative of E with respect to a small world rotation of each node); their
Jacobian with respect to ``phi`` is exact: the second derivative in world rotations, minus
``hat(r_i) / 2`` on the diagonal (the rotations do not commute), times ``J_l(phi)``.

* uniform fields: ``phi`` only (3 unknowns per node): block-tridiagonal Jacobian (band 5, 5).
* otherwise a mixed layout with positions and the position constraints' multipliers (the
  internal force of each segment) as unknowns, nine per node ``(x_i, phi_i, F_i)``, equations
  (position, moment, force) in the same order: band (11, 11); a Newton step costs O(N).

Both layouts evaluate stacks of states at once; the k Jacobians of a stack form one block
diagonal band matrix factorised by one pass (:class:`~coilrod.rod.planar.RodTangent`).
"""

from __future__ import annotations

import numpy as np

from ..path.protocol import Linearization
from .discrete import _EPS, _FLOOR, DiscreteRod
from .mesh import _remember
from .planar import RodTangent, _lowest_from_inverse, _take_tangent, closest_to_zero
from .so3 import cross, expm, hat, inv_right_jacobian_coefficients, left_jacobian, logm

__all__ = ["SpatialRod"]

#: Free rotational unknowns up to which the second variation is formed densely.
_DENSE_STABILITY = 600

#: Band layouts of recent problems (SpatialRod._band_layout), by their sizes and slots.
_LAYOUTS: dict = {}


#: ``a.max(axis)`` without the method's Python wrapper (the same reduction).
_max = np.maximum.reduce

#: The band storage argument of the per-node pass where it does not write one (Fortran
#: order, as the real one: one compiled version of the pass).
_NO_BAND = np.zeros((2, 2), order="F")
#: The gap hessians' argument of the compiled contact terms without the tangent.
_NO_HESS = np.zeros((1, 1, 1, 3, 3))
#: The second variation's outputs of the compiled contact terms without the tangent.
_NO_VAR, _NO_TURN = np.zeros((1, 1, 3, 3, 3)), np.zeros((1, 1, 1, 3))
#: The member statistics argument of the per-node pass where none are asked for.
_NO_STATS = np.zeros((0, 3))

_CS = None  # the module coilrod.rod._compiled_spatial once imported (it imports numba)


def _spatial_module():
    """:mod:`coilrod.rod._compiled_spatial`, imported on first use (not at import time)."""
    global _CS
    if _CS is None:
        from . import _compiled_spatial

        _CS = _compiled_spatial
    return _CS


_CC = None  # the module coilrod.rod._compiled_contact once imported (it imports numba)


def _contact_module():
    """:mod:`coilrod.rod._compiled_contact`, imported on first use (not at import time)."""
    global _CC
    if _CC is None:
        from . import _compiled_contact

        _CC = _compiled_contact
    return _CC


def _compiled_core():
    """The compiled per-node pass if this process uses it already (its ski rental is over),
    else None: :meth:`SpatialRod._assemble` then calls it directly."""
    return _CS.spatial_core if _CS is not None and _CS._rental.ready else None


def _matvec(A, v):
    return np.einsum("...ij,...j->...i", A, v)


def _outer(a, b):
    return a[..., :, None] * b[..., None, :]


#: Rounding of a rectangle's section for contact (relative to its half-extents): the support
#: of the section along a contact normal n is ``sum_a half_a f(n . d_a)`` with ``f(x) =
#: sqrt((1 - e^2) x^2 + e^2) - e (1 - x^2)`` (e this number: convex, the support of a thin
#: ellipsoid per axis, shifted), not ``|x|``: smooth where a face is parallel to the wall, so
#: a face contact's force moves continuously across the face (``|x|``'s corner flipped under
#: a tilt of 1e-12 rad and Newton did not converge).  Exact for faces along and across the
#: normal (x = 0, +-1), within ``e half_a`` otherwise.
FACE_ROUNDING = 3e-8


def _face_support(x: np.ndarray, order: int = 1) -> tuple:
    """``f(x)`` of :data:`FACE_ROUNDING` and its derivatives up to ``order`` (1 or 2), of the
    cosines x (...) of a contact normal with a section axis."""
    e = FACE_ROUNDING
    a = 1.0 - e * e
    r = np.sqrt(a * x * x + e * e)
    out = (r - e * (1.0 - x * x), a * x / r + 2.0 * e * x)
    return out if order < 2 else (*out, a * e * e / r**3 + 2.0 * e)


#: The small-angle series of :func:`_tangents`, rows sin(t)/t and (1 - cos t)/t^2 side by
#: side: ``C0 - t^2/C3 (1 - t^2/C2 (1 - t^2/C1))`` (so3's, term by term).
_SERIES_C0 = np.array([[1.0], [0.5]])
_SERIES_C1 = np.array([[42.0], [56.0]])
_SERIES_C2 = np.array([[20.0], [30.0]])
_SERIES_C3 = np.array([[6.0], [24.0]])


def _cross_matrix(r: np.ndarray) -> np.ndarray:
    """M (3, 3) with ``v @ M = v x r`` (the rows the unit vectors' cross products with r)."""
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def _tangents(phi: np.ndarray, R0: np.ndarray, M: np.ndarray | None = None) -> np.ndarray:
    """Node tangents ``expm(phi) R0 e_1`` (..., 3) of rotation vectors phi (..., 3) by
    Rodrigues' formula on the vector, ``cos(t) r + sin(t)/t phi x r + (1 - cos t)/t^2
    (phi . r) phi`` with ``r = R0 e_1`` and ``t = |phi|`` (the frames' first column without
    the whole frames; the same to rounding; so3's series below 0.05 rad).  ``M``:
    ``_cross_matrix(r)`` if at hand."""
    r = R0[:, 0]
    t2 = np.einsum("...i,...i->...", phi, phi)
    theta = np.sqrt(t2)
    small = theta < 0.05
    ts = np.where(small, 1.0, theta)
    # cos t, sin(t)/t and (1 - cos t)/t^2 as the rows of one array (the series' nodes then
    # written in one scatter; each entry by the same operations, the same roundings)
    q = np.empty((3,) + t2.shape)
    cos, a, b = q
    np.cos(ts, out=cos)
    np.sin(ts, out=a)
    a /= ts
    np.subtract(1.0, cos, out=b)
    b /= ts * ts
    idx = np.flatnonzero(small)  # (the clamp's node at least)
    if idx.size <= 4:  # a few: in Python floats (IEEE arithmetic: numpy's roundings)
        af, bf, cf, tf = a.reshape(-1), b.reshape(-1), cos.reshape(-1), t2.reshape(-1)
        for i in idx.tolist():
            s2 = float(tf[i])
            bs = 0.5 - s2 / 24 * (1 - s2 / 30 * (1 - s2 / 56))
            af[i] = 1 - s2 / 6 * (1 - s2 / 20 * (1 - s2 / 42))
            bf[i] = bs
            cf[i] = 1.0 - bs * s2
    else:
        s2 = t2.reshape(-1)[idx]
        ser = np.empty((3, idx.size))
        ser[1:] = _SERIES_C0 - s2 / _SERIES_C3 * (1 - s2 / _SERIES_C2 * (1 - s2 / _SERIES_C1))
        np.multiply(ser[2], s2, out=ser[0])
        np.subtract(1.0, ser[0], out=ser[0])
        q.reshape(3, -1)[:, idx] = ser
    if M is None:
        M = _cross_matrix(r)
    out = cos[..., None] * r
    out += a[..., None] * (phi @ M)
    b *= phi @ r
    out += b[..., None] * phi
    return out


def _sym_term(a, b):
    """Hessian of ``b . (exp(hat(d)) a)`` in the world rotation d at 0: (a b^T + b a^T) / 2
    - (a . b) I."""
    out = 0.5 * (_outer(a, b) + _outer(b, a))
    d = np.einsum("...i,...i->...", a, b)
    out[..., 0, 0] -= d
    out[..., 1, 1] -= d
    out[..., 2, 2] -= d
    return out


#: The mesh- and stiffness-only constants of :class:`SpatialRod` already computed, keyed on
#: the mesh's h and w, the stiffnesses, the layout and the unknowns per node by value (a
#: changed input is a new key, never a stale hit); read-only arrays shared by the problems
#: built from them; at most ``mesh._CACHE_SIZE`` entries, oldest dropped first.
_MESH_CONSTANTS: dict = {}


def _mesh_constants(h, w, K, uniform: bool, nv: int) -> tuple:
    """1/h, 1/w, the bending round-off scale per node (n,), its maximum, the same as a
    column (n, 1), the scaled residual's row multipliers (n, 3 or nv) and the last two side
    by side (n, 3 or nv + 1: the compiled pass's error constants), as :class:`SpatialRod`
    uses them (read-only: computed once per mesh, stiffness and layout)."""
    key = (h.tobytes(), w.tobytes(), K.tobytes(), uniform, nv)
    out = _MESH_CONSTANTS.get(key)
    if out is None:
        n = w.size
        inv_h = 1.0 / h
        inv_w = 1.0 / w
        bend = np.zeros(n)
        bend[1:] += inv_h
        bend[:-1] += inv_h
        bend_scale = bend * inv_w * float(np.max(K))
        bend_max = float(np.max(bend_scale))
        bend_column = bend_scale[:, None].copy()
        # multipliers of the scaled residual (_scaled): moments and forces per length,
        # position mismatch per length (the clamp rows and the tip force row zeroed there)
        row_scale = np.ones((n, 3 if uniform else nv))
        if uniform:
            row_scale[:] = inv_w[:, None]
        else:
            row_scale[:, 3:6] = inv_w[:, None]
            row_scale[1:, 0:3] = inv_h[:, None]
            row_scale[:-1, 6:9] = inv_w[1:, None]
        econ = np.concatenate((row_scale, bend_column), axis=1)
        arrays = (inv_h, inv_w, bend_scale, bend_column, row_scale, econ)
        for a in arrays:
            a.flags.writeable = False
        out = _remember(
            _MESH_CONSTANTS,
            key,
            (inv_h, inv_w, bend_scale, bend_max, bend_column, row_scale, econ),
        )
    return out


class SpatialRod(DiscreteRod):
    """The discrete spatial rod for one rod, field and mesh (non-dimensional).

    Parameters
    ----------
    mesh : RodMesh
    mu : ndarray, shape (n, 3)
        Node magnetization in the body frame (tangent, normal, binormal) times A L^2 / EI_z, 1/T.
    stiffness : array-like, shape (3,)
        (GJ, EI_y, EI_z) / EI_z, non-dimensional.
    field : coils.Field
        The applied field (SI) at scale 1.
    length : float
        L in m.
    clamp_position : ndarray, shape (3,)
        m.
    clamp_rotation : ndarray, shape (3, 3)
        Frame of the clamp (columns: tangent, normal, binormal), orthonormal, det +1.
    tol : float
        Newton tolerance on the scaled residual (as :class:`~coilrod.rod.planar.PlanarRod`).
    mixed : bool
        Use the mixed layout even in a uniform field (sensitivities to a field gradient).
    obstacles : sequence
        Rigid obstacles (the gap interface of :mod:`coilrod.contact.obstacle`).
    section : Circle or Rectangle, optional
        The cross-section (m): contact is with the rod's surface, the gap of a contact point
        minus the section's half-extent along the contact normal (a circle's radius; a
        rectangle's ``(thickness |n . d_2| + width |n . d_3|) / 2`` with d_2, d_3 the
        section's axes, its faces rounded by :data:`FACE_ROUNDING`), the force applied at
        the section's touching point (a corner; on a face parallel to the wall a point
        across the face).  None: the centreline.
    friction_rows : bool, optional
        Carry the friction unknowns and rows (:meth:`_friction_rows`); default (None): if an
        obstacle's ``friction`` is > 0.  True with every ``friction`` 0 gives the frictionless
        solutions (to round-off; tests).

    Notes
    -----
    Coulomb friction (an obstacle's ``friction`` mu > 0) is quasi-static and incremental:
    each contact point p_j carries a tangential force per length tau_j in the obstacle's
    tangent plane, stick (``|tau| <= mu lam``) or slip (``|tau| = mu lam`` opposite to the
    slip) decided on the tangential displacement of p_j since the last accepted state
    (:meth:`accept_state`; the path engine calls it at each accepted load step, insertion
    at each insertion step).  Stick is exact (no regularisation: a held load does not
    creep).  The friction force acts at the centreline's contact point (the rolling of the
    section on the wall is not resolved).  The solution therefore depends on the load path:
    the engine does not correct several load scales together for such a model
    (:attr:`path_dependent`).
    """

    batched = True
    max_correction = 0.25
    max_step_change = 0.5
    #: Largest rotation of any node in one Newton step, rad.
    max_rotation = 0.5
    #: Largest rotation of a node relative to the clamp accepted (rad): the chart
    #: ``exp(hat(phi)) R_0`` is singular at 2 pi.
    max_turn = 1.9 * np.pi

    def __init__(
        self,
        mesh,
        mu,
        stiffness,
        field,
        length,
        clamp_position,
        clamp_rotation,
        tol=1e-9,
        mixed=False,
        obstacles=(),
        section=None,
        friction_rows=None,
    ):
        self.mesh = mesh
        self.mu = np.asarray(mu, float)
        self.K = np.asarray(stiffness, float)
        self.field = field
        self.L = float(length)
        self.clamp = np.asarray(clamp_position, float)
        self.R0 = np.asarray(clamp_rotation, float)
        self.tol = float(tol)
        self.obstacles = tuple(obstacles)
        # the section's half-extents along (normal, binormal), units of L; round: a circle
        self._half, self._round = np.zeros(2), True
        if section is not None:
            if hasattr(section, "diameter"):
                self._half = np.full(2, 0.5 * float(section.diameter) / float(length))
            else:
                self._half = 0.5 * np.array([section.thickness, section.width]) / float(length)
                self._round = False
        self.nc = len(self.obstacles)  # contact multipliers per node, one per obstacle
        self.mu_f = np.zeros(0)  # friction coefficient per obstacle
        if self.obstacles:
            from ..contact.obstacle import as_friction

            self.mu_f = np.array(
                [
                    as_friction(getattr(ob, "friction", 0.0), f"obstacles[{i}].friction")
                    for i, ob in enumerate(self.obstacles)
                ]  # fmt: skip
            ).reshape(-1)
        if friction_rows is None:
            friction_rows = bool(self.nc and np.any(self.mu_f > 0))
        #: Friction unknowns per node (3 per obstacle: tau in the world frame), 0 without.
        self.nt = 3 * self.nc if friction_rows else 0
        if self.nc:  # semi-smooth Newton: a step that switches contacts may raise the residual
            self.full_step_growth = 1e3
            # gap scale of the complementarity: a contact force per length lam against the
            # local bending stiffness of a wave of the mesh's length, ~ 1/h^4 (times h^2:
            # tested robust from 4/h^2 to 1e3/h^2 in insertions through curved walls)
            self.kappa = 100.0 / float(np.min(mesh.h)) ** 2
        self.uniform = bool(field.uniform) and not mixed and not self.obstacles
        self.linear = bool(field.linear or field.uniform)
        self.cheap_tangent = False
        self.n = n = mesh.n
        self.nv = 3 if self.uniform else 9 + self.nc + self.nt
        self.size = self.nv * n
        (
            self._inv_h, self._inv_w, self._bend_scale, self._bend_max, self._bend_column,
            self._row_scale, self._econ,
        ) = _mesh_constants(mesh.h, mesh.w, self.K, self.uniform, self.nv)  # fmt: skip
        self._band_cache: dict = {}
        self._work: dict = {}  # per-call arrays of _assemble (_workspace)
        self._mu0 = None
        self.last_failure = ""
        if self.uniform:
            self._b_uniform = np.asarray(field.B(self.clamp)[0], float)
        self.kl, self.ku, self._index = self._band_layout()
        self._p_ref = self._tau_ref = None
        # the blocks of the last one-state contact tangent (:meth:`_every_active_band`)
        self._kept = None
        self._kept_tangent = None  # (_kept, its tangent) where its rows are min's (_kept_factors)
        self._gaps_memo: dict = {}  # state -> surface gaps (_state_gaps)
        if self.nt:  # the reference of the friction: the straight rod until a state is accepted
            self._p_ref = self.contact_points(self.straight()[None])[0]
            self._tau_ref = np.zeros((self.n, self.nc, 3))

    @property
    def path_dependent(self) -> bool:
        """True with friction: a state depends on the load path (the path engine then
        steps one load scale at a time and calls :meth:`accept_state`)."""
        return bool(self.nt)

    def accept_state(self, u: np.ndarray) -> None:
        """Make the contact points of the accepted state ``u`` (size,) the friction's
        reference: stick or slip at the next solve is decided on the tangential
        displacement from them.  No-op without friction."""
        if self.nt:
            u = np.asarray(u, float)
            self._p_ref = self.contact_points(u[None])[0].copy()
            self._tau_ref = self.friction_forces(u[None])[0]

    #: Largest normal force per length (EI_z / L^3) a contact point may carry in the accepted
    #: state in which it first touches, with friction (:meth:`touchdown_force`): the path
    #: engine cuts a load step that lands a point harder, so that its slip is measured from
    #: where it touched.
    touchdown_tol = 1e-6

    def touchdown_force(self, u_old: np.ndarray, u_new: np.ndarray) -> float:
        """Largest normal force per length (EI_z / L^3) in state ``u_new`` (size,) of the
        contact points not in contact in the accepted state ``u_old`` (size,), on obstacles
        with friction (0 without).

        The friction rows measure a point's slip from its place in the last accepted state
        (:meth:`accept_state`), so the tangential motion of a point that touches within a
        step -- its approach before it touched included -- counts as slip, and it lands on
        the cone with ``|tau| = mu lam``: a friction force set by how far past the touch the
        step went, i.e. by the sub-steps (and the mesh).  The path engine therefore cuts a
        step whose newly touching points carry more than :attr:`touchdown_tol` until it
        ends where they touch (:mod:`coilrod.path.stepping`)."""
        if not self.nt:
            return 0.0
        lam_old = np.asarray(u_old, float).reshape(self.n, self.nv)[:, 9 : 9 + self.nc]
        lam_new = np.asarray(u_new, float).reshape(self.n, self.nv)[:, 9 : 9 + self.nc]
        new = (lam_old <= 0) & (lam_new > 0) & (self.mu_f > 0)  # (touching a rough obstacle)
        return float(lam_new[new].max()) if new.any() else 0.0

    def set_reference(self, points: np.ndarray, tau: np.ndarray | None = None) -> None:
        """Set the friction's reference: contact points (n, 3) (units of L relative to the
        clamp) and friction forces per length (n, nc, 3) (EI_z / L^3 units; None: zero) of
        the last accepted state (:func:`~coilrod.contact.insert` carries them along the
        material).  Stick and slip are decided on the points alone (the forces are kept for
        the record: the stick rows are exact, :meth:`_friction_rows`)."""
        points = np.asarray(points, float)
        if points.shape != (self.n, 3):
            raise ValueError(f"points must have shape ({self.n}, 3); got {points.shape}")
        self._p_ref = points.copy()
        shape = (self.n, self.nc, 3)
        self._tau_ref = np.zeros(shape) if tau is None else np.array(tau, float).reshape(shape)

    def friction_forces(self, U: np.ndarray) -> np.ndarray:
        """Tangential (friction) force per length on the rod at the contact points of states
        (k, size), (k, n, nc, 3) in EI_z / L^3 units (zeros without friction)."""
        U = np.atleast_2d(U)
        out = np.zeros((U.shape[0], self.n, self.nc, 3))
        if self.nt:
            V = U.reshape(U.shape[0], self.n, self.nv)
            out[:] = V[:, :, 9 + self.nc :].reshape(out.shape)
            out[:, 0] = 0.0
        return out

    # -- layout -----------------------------------------------------------------------------
    def _slots(self):
        """Offsets of (x, phi, F) within a node's unknowns (None where absent); the contact
        multipliers (one per obstacle) follow from offset 9."""
        return (None, 0, None) if self.uniform else (0, 3, 6)

    def rotations(self, u: np.ndarray) -> np.ndarray:
        """Rotation vectors phi (rad) of a state (size,) or stack (k, size): (..., n, 3)."""
        v = u.reshape(u.shape[:-1] + (self.n, self.nv))
        return v[..., 0:3] if self.uniform else v[..., 3:6]

    def frames(self, u: np.ndarray) -> np.ndarray:
        """Node frames R_i (..., n, 3, 3) (columns: tangent, normal, binormal, world)."""
        return expm(self.rotations(u)) @ self.R0

    def positions_from_frames(self, R: np.ndarray) -> np.ndarray:
        """Trapezoid centreline relative to the clamp from frames (..., n, 3, 3): (..., n, 3),
        units of L."""
        t = R[..., :, 0]
        seg = self.mesh.h[:, None] * (t[..., :-1, :] + t[..., 1:, :]) / 2
        out = np.zeros(t.shape)
        np.cumsum(seg, axis=-2, out=out[..., 1:, :])
        return out

    def node_positions(self, U: np.ndarray) -> np.ndarray:
        """Node positions (k, n, 3) relative to the clamp, units of L."""
        U = np.atleast_2d(U)
        if self.uniform:
            return self.positions_from_frames(self.frames(U))
        return U.reshape(U.shape[0], self.n, self.nv)[:, :, 0:3]

    def points(self, x: np.ndarray) -> np.ndarray:
        """Physical points (..., 3) in m from positions relative to the clamp in units of L."""
        return self.clamp + self.L * x

    def straight(self) -> np.ndarray:
        """The straight unloaded state along the clamp tangent, shape (size,)."""
        u = np.zeros((self.n, self.nv))
        if not self.uniform:
            u[:, 0:3] = self.mesh.s[:, None] * self.R0[:, 0]
        return u.ravel()

    def from_rotations(self, phi: np.ndarray, scale: float = 0.0) -> np.ndarray:
        """Unknowns (size,) with positions and forces consistent with rotations phi (n, 3)."""
        phi = np.asarray(phi, float)
        if self.uniform:
            return phi.ravel().copy()
        R = expm(phi) @ self.R0
        x = self.positions_from_frames(R)
        u = np.zeros((self.n, self.nv))
        u[:, 0:3], u[:, 3:6] = x, phi
        if scale != 0.0:
            _, G, _ = self._field(x[None], False)
            m = _matvec(R, self.mu)
            f = (scale * self.L) * np.einsum("nij,ni->nj", G, m)
            wf = self.mesh.w[:, None] * f
            u[:-1, 6:9] = np.cumsum(wf[::-1], axis=0)[::-1][1:]
        return u.ravel()

    def interpolate_to(self, fine: SpatialRod, u: np.ndarray) -> np.ndarray:
        """States of this mesh on its refinement (every segment halved), linear interpolation
        of every unknown; u (size,) or (k, size)."""
        if fine.n != 2 * self.n - 1:
            raise ValueError("fine must be the refinement of this mesh (every segment halved)")
        v = np.atleast_2d(u).reshape(-1, self.n, self.nv)
        out = np.empty((v.shape[0], fine.n, self.nv))
        out[:, ::2] = v
        out[:, 1::2] = 0.5 * (v[:, :-1] + v[:, 1:])
        if self.nc:
            # contact force per length: a distributed contact keeps it, a point contact keeps
            # the node's force (w lam) -- the mean of the two is a start Newton corrects fast
            ratio = self._contact_geometry()[1] / fine._contact_geometry()[1][::2]
            ratio[0] = 1.0
            out[:, ::2, 9:] *= (0.5 * (1.0 + ratio))[None, :, None]
        out = out.reshape(v.shape[0], -1)
        return out[0] if np.ndim(u) == 1 else out

    # -- field ------------------------------------------------------------------------------
    # -- the protocol -------------------------------------------------------------------------
    def linearize(self, u, scale, tangent: bool = True) -> Linearization:
        """Residual (k, size), admissibility (k,) and the tangent of a stack of states."""
        if (
            type(u) is np.ndarray and u.ndim == 2 and u.dtype == float
            and type(scale) is np.ndarray and scale.shape == (u.shape[0],) and scale.dtype == float
        ):  # fmt: skip
            U, S = u, scale  # (the engine's stacks: no conversion)
        else:
            U, S = self._stack(u, scale)
        kept = self._kept  # (a one-state contact tangent below keeps its blocks anew)
        if self.nc or _compiled_core() is None:  # numpy passes and contact terms may warn
            with np.errstate(all="ignore"):
                R, R1, ab, sym = self._assemble(U, S, tangent)
        else:  # the compiled pass (numpy's error model, silent) and band gathers only
            R, R1, ab, sym = self._assemble(U, S, tangent)
        stats = self._stats  # (the compiled pass's: finiteness, largest rotation component)
        if stats is None:
            ok = np.logical_and.reduce(np.isfinite(R), axis=1)
            phi = U if self.uniform else self.rotations(U)  # (every unknown a rotation)
            big = _max(np.abs(phi), axis=None)
        else:
            ok = stats[:, 2] > 0.0
            big = stats[0, 1] if U.shape[0] == 1 else _max(stats[:, 1])
        # |phi| <= sqrt(3) max|phi_a|: the norms only where that bound exceeds the limit
        if not big <= self._turn_bound:
            phi = self.rotations(U)
            with np.errstate(all="ignore"):
                turned = np.sqrt(np.einsum("kni,kni->kn", phi, phi)).max(axis=1)
            bad_turn = turned > self.max_turn
            if bad_turn.any():
                ok &= ~bad_turn
                self.last_failure = (
                    f"a node turned {float(turned.max()):.3g} rad relative to the clamp "
                    f"(the rotation chart of the spatial rod is limited to "
                    f"{self.max_turn:.3g} rad)"
                )
        tan = None
        if tangent:
            tan = RodTangent(U.shape[0], self.size, False, ab, R1, self.kl, self.ku)
            tan.bad = ~ok  # (a new tangent: no member flagged yet)
            tan.blocks = sym  # (diagonal, upper) blocks of the second variation
            if self.nc and U.shape[0] == 1:  # the kept blocks' tangent (_kept_factors)
                plain = self.ncp == "min" and not self._every_rows and self._kept is not kept
                self._kept_tangent = (self._kept, tan) if plain else None
        lin = Linearization(u=U, scale=S, residual=R, ok=ok, tangent=tan)
        lin.load_rate = R1
        lin.pair = (self._pair, R, R1, stats)  # (R and R1 views of it: error, _error_one)
        return lin

    def solve(self, lin: Linearization, rhs: np.ndarray) -> np.ndarray:
        """:meth:`DiscreteRod.solve` without its ``np.atleast_2d`` where ``rhs`` is a stack
        (k, size) already (the engine's: the same array)."""
        if not (type(rhs) is np.ndarray and rhs.ndim == 2):
            rhs = np.atleast_2d(rhs)
        return lin.tangent.solve(rhs)

    @property
    def _turn_bound(self) -> float:
        """A bound on the largest rotation-vector component below which no node has turned
        more than :attr:`max_turn` (0.999 max_turn / sqrt(3): clear of round-off)."""
        return 0.999 * self.max_turn / 1.7320508075688772  # sqrt(3)

    def dense_jacobian(self, u: np.ndarray, scale: float) -> np.ndarray:
        """The Jacobian of one state as a dense (size, size) array (tests, small problems)."""
        ab = self.linearize(u, scale).tangent.parts
        N, kl, ku = self.size, self.kl, self.ku
        J = np.zeros((N, N))
        for off in range(-kl, ku + 1):
            J += np.diag(ab[kl + ku - off, max(off, 0) : N + min(off, 0)], off)
        return J

    def _scaled(self, R: np.ndarray) -> np.ndarray:
        """Residuals scaled to point values (k, n, nv): moments per length, position mismatch
        per length, forces per length (zero: the clamp's rows and the tip's force row)."""
        v = R.reshape(R.shape[0], self.n, self.nv)
        out = v * self._row_scale
        out[:, 0, : 3 if self.uniform else 6] = 0.0
        if not self.uniform:
            out[:, -1, 6:9] = 0.0
        return out

    def _scaled_max(self, R: np.ndarray) -> np.ndarray:
        """max over each node's equations of |scaled residual| (k, n) (:meth:`_scaled`; in
        the uniform layout each node's rows share one scale: the maximum first)."""
        if not self.uniform:
            return _max(np.abs(self._scaled(R)), axis=2)
        out = _max(np.abs(R.reshape(R.shape[0], self.n, 3)), axis=2)
        out *= self._inv_w
        out[:, 0] = 0.0
        return out

    def error(self, lin: Linearization, du) -> np.ndarray:
        """max over equations of |scaled residual| / (tol + its round-off floor), shape (k,)."""
        # the largest |scaled residual| of each node, divided by the node's tolerance (the
        # same maximum as dividing every equation: a positive divisor keeps the order)
        pair = getattr(lin, "pair", None)
        if (
            pair is not None and pair[3] is not None
            and pair[1] is lin.residual and pair[2] is lin.load_rate
        ):  # fmt: skip
            return pair[3][:, 0].copy()  # the compiled pass's (the same numbers)
        if lin.residual.shape[0] == 1:
            return self._error_one(lin)
        scaled = self._scaled_max(lin.residual)  # (k, n)
        with np.errstate(all="ignore"):
            size = _max(np.abs(lin.u), axis=1)  # rotations, positions, forces
            size += 1.0
            load = _max(self._scaled_max(lin.load_rate), axis=1)
            load *= np.abs(lin.scale)
            # tol + _FLOOR eps (size bend_scale + load), in place
            div = size[:, None] * self._bend_scale
            div += load[:, None]
            div *= _FLOOR * _EPS
            div += self.tol
            scaled /= div
            out = _max(scaled, axis=1)
            if not out.sum() < np.inf:  # (one sum: NaN or inf if any member is not finite)
                out[~np.isfinite(out)] = np.inf
        return out

    def _error_one(self, lin: Linearization) -> np.ndarray:
        """:meth:`error` of one member: the member-wide numbers as Python floats, and each
        equation divided by its node's divisor before one maximum over all (the same numbers:
        for d > 0, max_a(x_a) / d = max_a(x_a / d) and max_a(|x_a|) s = max_a(|x_a| s), as
        rounding is monotone; a maximum over a node's few equations is a slow numpy
        reduction)."""
        pair = getattr(lin, "pair", None)
        if pair is not None and pair[1] is lin.residual and pair[2] is lin.load_rate:
            both = np.abs(pair[0])  # (2, 1, n, nv): |R| and |R1| (linearize)
        else:
            both = np.abs(np.concatenate((lin.residual, lin.load_rate)))
            both = both.reshape(2, 1, self.n, self.nv)
        both *= self._row_scale  # the scaled residual and load rate (_scaled)
        scaled = both[0]
        scaled[:, 0, : 3 if self.uniform else 6] = 0.0  # the clamp's rows
        if not self.uniform:
            scaled[:, -1, 6:9] = 0.0  # the tip's force row
        # (the rows _scaled zeroes are zero in R1: the clamp's and the tip force's rows)
        load = float(_max(both[1], axis=None))
        scale = lin.scale
        load *= abs(float(scale[0] if isinstance(scale, np.ndarray) else scale))
        size = 1.0 + float(_max(np.abs(lin.u), axis=None))
        # no floating-point warning can arise where the divisors are finite (>= tol) and the
        # quotients below 1e300: then without np.errstate's cost
        if (
            size * self._bend_max < 1e300
            and load < 1e300
            and float(_max(scaled, axis=None)) < 1e300 * self.tol
        ):
            out = self._divided_max(scaled, size, load)
        else:
            with np.errstate(all="ignore"):
                out = self._divided_max(scaled, size, load)
        return np.array([out if out < np.inf else np.inf])

    def _divided_max(self, scaled: np.ndarray, size: float, load: float) -> float:
        """max of ``scaled / (tol + _FLOOR eps (size bend_scale + load))`` (scaled: (1, n,
        nv), divided in place by its node's divisor)."""
        div = self._bend_column * size  # (n, 1)
        div += load
        div *= _FLOOR * _EPS
        div += self.tol
        scaled /= div
        return float(_max(scaled, axis=None))

    def residual_norm(self, residual) -> np.ndarray:
        """Max-norm of the scaled residual (non-dimensional), shape (k,)."""
        R = residual.residual if isinstance(residual, Linearization) else residual
        return np.abs(self._scaled(R)).max(axis=(1, 2))

    def step_limit(self, u, du):
        """No node rotates by more than :attr:`max_rotation` in one Newton step."""
        rot = self._largest_rotation(du)
        if rot.shape == (1,):  # one member: in scalars (the same IEEE operations)
            r = float(rot[0])
            lim = np.array([min(self.max_rotation / r, 1.0) if r > 0.0 else 1.0])
        else:
            lim = np.ones(rot.shape)
            np.divide(self.max_rotation, rot, out=lim, where=rot > 0)
            np.minimum(lim, 1.0, out=lim)
        if self.nc and not self.uniform and self.close_first:
            lim = np.minimum(lim, self.closing_fraction(np.atleast_2d(u), np.atleast_2d(du)))
        if self.nc and not self._round:
            lim = np.minimum(lim, self.face_fraction(np.atleast_2d(u), np.atleast_2d(du)))
        return lim

    def face_fraction(self, U, dU):
        """Fraction (k,) of each change dU (k, size) of states U (k, size) at which the first
        pressed face of a rectangle turns parallel to its wall, 1 if none does: a cosine
        ``n . d_a`` of a point with a positive multiplier that would change sign, from beyond
        100 :data:`FACE_ROUNDING` to beyond it on the other side.  A Newton step from a
        corner's linearization (the rounding's curvature ~0 there) overshoots the face's
        equilibrium by the whole twist the corner's moment makes; limited to it, the step
        ends where the next one sees the rounding (the rectangle on a nearly parallel wall)."""
        k = U.shape[0]
        cos = []
        for W in (U, U + dU):
            V = W.reshape(k, self.n, self.nv)
            frames = self.frames(W)
            c, _ = self._contact_geometry()
            pts = self.points(V[:, :, 0:3] + c[:, None] * frames[..., :, 0]).reshape(-1, 3)
            normals = np.stack(
                [np.asarray(self._evaluate_at(o, pts, 1)[1], float) for o in range(self.nc)], 1
            ).reshape(k, self.n, self.nc, 3)
            cos.append(np.einsum("knoi,knia->knoa", normals, frames[..., :, 1:3]))
        d0, d1 = cos
        e = FACE_ROUNDING
        pressed = (U.reshape(k, self.n, self.nv)[:, :, 9 : 9 + self.nc] > 0)[..., None]
        turning = pressed & (np.abs(d0) > 100 * e) & (d0 * d1 < 0) & (np.abs(d1) > e)
        with np.errstate(all="ignore"):
            frac = np.where(turning, d0 / (d0 - d1), 1.0)
        return frac.min(axis=(1, 2, 3))

    #: Newton steps end where the first open contact point would close (see
    #: :meth:`closing_fraction`).  Off by default: the load stepping already predicts across
    #: contact events (:meth:`event_fraction`, :meth:`piecewise_prediction`), and it costs two
    #: gap evaluations per Newton step (an insertion through a bend was slower with it).
    close_first = False

    def closing_fraction(self, U, dU):
        """Fraction (k,) of each change dU (k, size) of states U (k, size) at which the first
        open contact point (surface gap > 1e-6 L) reaches the wall, 1 if none does.  A Newton
        step limited to it (:attr:`close_first`) ends on the wall instead of overshooting
        it, and the next one sees the contact; the load stepping's contact events
        (:meth:`event_fraction`) use it for the closing points."""
        g0 = self._state_gaps(U)
        g1 = self._state_gaps(U + dU)
        closing = (g0 > 1e-6) & (g1 < 0.0)
        with np.errstate(all="ignore"):
            frac = np.where(closing, g0 / (g0 - g1), 1.0)
        return frac.min(axis=(1, 2))

    def event_fraction(self, U, dU):
        """Fraction (k,) of each change dU (k, size) of states U (k, size) at which the
        contact set first changes (a point closes or an active one releases), 1 if it does
        not: the path engine ends a load step's prediction there
        (:mod:`coilrod.rod.contact_predictor`)."""
        if not self.nc or self.uniform or self.nt:  # no contact events to find (as there)
            return np.ones(np.shape(U)[0] if np.ndim(U) == 2 else 1)
        from .contact_predictor import event_fraction

        return event_fraction(self, U, dU)

    def _every_active_band(self, u: np.ndarray, scale: float, near: float = 0.0):
        """The band storage and load rate (1, size) of the linearization at the state ``u``
        (size,) and ``scale`` with every contact row the gap's (kappa times its gradient), from
        the kept blocks of this problem's last one-state tangent if it was at that state
        (a converged load step's: the prediction that follows starts there), else None.  The
        force and moment rows depend on the multipliers alone, not on the complementarity
        function, so the band is the one a linearization with every row active would build,
        bitwise; None too where that linearization was not admissible.  ``near`` (rad): the
        kept tangent of another state at the same scale is taken too where no node's rotation
        differs from ``u``'s by more (a Newton solve that ends with chord steps keeps the
        tangent of an iterate a chord step before its last: the band and load rate are
        then that iterate's)."""
        kept = self._kept
        if kept is None:
            return None
        key, skey, blocks, every, R1, R = kept
        c_x, c_phi = every if blocks is not None else (every, None)
        if skey != np.array([scale], float).tobytes():
            return None
        if key != np.asarray(u, float)[None].tobytes():
            at = np.frombuffer(key)
            if not (near > 0 and at.shape == np.shape(u)
                    and self.distance((at - u)[None])[0] <= near):  # fmt: skip
                return None
            u = at
        phi = self.rotations(np.asarray(u, float))
        turned = np.sqrt(np.einsum("ni,ni->n", phi, phi)).max()
        if not (np.isfinite(R).all() and turned <= self.max_turn):  # (linearize's ok)
            return None
        if blocks is None:  # the compiled kernel's inputs (_compiled_contact): run it again
            terms, frames, phi, blk = c_x
            scratch = np.zeros((1, self.n, self.nv))
            return self._contact_band(terms, frames, phi, blk, scratch, True, every=True)[0], R1
        c_lam = np.zeros_like(blocks["c_lam"])
        every = {**blocks, "c_x": c_x, "c_phi": c_phi, "c_lam": c_lam}
        return self._scatter(1, every), R1

    def _kept_factors(self):
        """``(active, ab, ipiv)``: the LU factors (band storage, pivots) of the one-state
        tangent whose blocks :meth:`_every_active_band` keeps, and its active contact set
        (n - 1, nc) (its contact rows: kappa times the gap's gradient where active, the
        multiplier's identity elsewhere: :meth:`_ncp`'s "min"), once that tangent is
        factorised (a Newton solve's); None otherwise (not factorised, a singular or flagged
        member, another complementarity function, friction).  The factors are the tangent's
        own: copy before changing them."""
        pair, kept = self._kept_tangent, self._kept
        if pair is None or kept is None or pair[0] is not kept:
            return None
        tan = pair[1]
        lu = tan._lu
        if lu is None or tan._per_member or np.count_nonzero(tan.bad):
            return None
        blocks, every = kept[2], kept[3]
        if blocks is None:  # the compiled kernel's inputs: (lam, gaps, normals, hess), ...
            lam, gaps = every[0][0], every[0][1]
            active = (self.kappa * gaps < lam)[0, 1:]
        else:  # the numpy blocks: the multipliers' own entries are 0 where active
            active = np.diagonal(blocks["c_lam"][0], axis1=-2, axis2=-1) == 0.0
        return active, lu[0], lu[1]

    def piecewise_prediction(self, u, scale, ds):
        """Prediction (size,) of the state at ``scale + ds`` from the converged state ``u``
        (size,) across changes of the contact set, or None
        (:func:`coilrod.rod.contact_predictor.piecewise_prediction`)."""
        from .contact_predictor import piecewise_prediction

        return piecewise_prediction(self, u, scale, ds)

    def distance(self, du):
        """Largest change of a node rotation vector, rad, shape (k,)."""
        return self._largest_rotation(du)

    def _largest_rotation(self, du):
        if not (type(du) is np.ndarray and du.dtype == float):
            du = np.asarray(du, float)
        k = du.shape[0] if du.ndim == 2 else 1
        d = du.reshape(k, self.n, 3) if self.uniform else self.rotations(du.reshape(k, -1))
        out = _max(np.einsum("kni,kni->kn", d, d), axis=1)
        return np.sqrt(out, out=out)

    def arclength_weights(self) -> np.ndarray:
        w = np.zeros((self.n, self.nv))
        w[:, self._slots()[1] : self._slots()[1] + 3] = 1.0 / self.n
        return w.ravel()

    #: Scale of the gap against the contact force per length in the complementarity
    #: function of (lam, kappa g) (non-dimensional; any positive value has the same solutions;
    #: a contact problem sets 100 / h_min^2).
    kappa = 1.0

    #: Proximal weight of the friction's stick rows in the Newton step only
    #: (:meth:`_friction_rows`), non-dimensional: the rows themselves are exact.  At 1e-6 a
    #: Newton step that made a taut span's points stick together gave them tangential forces
    #: 1e3 times the cone (the inextensible span cannot take up their displacement), and the
    #: iteration cycled between stick and slip: a re-insertion after a withdrawal at
    #: EI / (T R^2) ~ 1e-4 failed even at 5 um steps; at 1e-3 it converges (the capstan
    #: test's sweep, benchmarks/bench_friction.py)
    stick_slack = 1e-3

    #: Complementarity function: "min" (min(lam, kappa g); the default: a Newton step drops a
    #: point whose multiplier went negative at once, where Fischer-Burmeister mixes the two
    #: rows and releases it over several iterations) or "fb" (Fischer-Burmeister).
    ncp = "min"

    #: Every contact row the gap's (a linearization for the contact predictor,
    #: :mod:`coilrod.rod.contact_predictor`, sets it on the instance): :meth:`_ncp`'s
    #: partials are 0 in lam and 1 in kappa g at every point (its value, min(lam, g), unused).
    _every_rows = False

    def _ncp(self, lam: np.ndarray, gaps: np.ndarray):
        """Complementarity function of (lam, kappa g) and its partial derivatives in lam and
        in kappa g (semismooth; zero iff lam >= 0, g >= 0, lam g = 0); with
        :attr:`_every_rows` the gap's rows at every point."""
        if self._every_rows:
            return np.minimum(lam, gaps), np.zeros_like(lam), np.ones_like(lam)
        a, b = lam, self.kappa * gaps
        if self.ncp == "min":
            pick = b < a
            return np.minimum(a, b), np.where(pick, 0.0, 1.0), np.where(pick, 1.0, 0.0)
        r = np.hypot(a, b)
        safe = np.where(r > 0, r, 1.0)
        da = np.where(r > 0, 1.0 - a / safe, 1.0 - 2**-0.5)
        db = np.where(r > 0, 1.0 - b / safe, 1.0 - 2**-0.5)
        return a + b - r, da, db

    def _contact_geometry(self):
        """Offsets c (n,) of the contact points along the node tangents and their weights
        omega (n,) (units of L): the corners of the rod's polygon ``p_j = x_j + (h_j/2) t_j``
        (j < N; node j's straight piece ends there) and the tip ``p_N = x_N``; weights
        ``omega_j = h_j``, the last corner's and the tip's ``h_{N-1}/2`` (node 0's corner is
        held by the clamp and carries no multiplier).  Read-only, formed once (the mesh is
        the problem's)."""
        out = self.__dict__.get("_geometry")
        if out is None:
            h, n = self.mesh.h, self.n
            c = np.zeros(n)
            c[:-1] = 0.5 * h
            om = np.zeros(n)
            om[:-1] = h
            om[-2] = om[-1] = 0.5 * h[-1]
            c.flags.writeable = om.flags.writeable = False
            out = self.__dict__["_geometry"] = (c, om)
        return out

    def contact_points(self, U: np.ndarray, frames: np.ndarray | None = None) -> np.ndarray:
        """Contact points of states (k, size): the polygon's corners and the tip (k, n, 3),
        units of L relative to the clamp (see :meth:`_contact_geometry`).  ``frames``: the
        states' node frames (k, n, 3, 3) if already at hand (:meth:`frames`)."""
        U = np.atleast_2d(U)
        c, _ = self._contact_geometry()
        t = (self.frames(U) if frames is None else frames)[..., :, 0]
        return self.node_positions(U) + c[:, None] * t

    def _contact_terms(self, V: np.ndarray, x: np.ndarray, frames: np.ndarray, hessian: bool):
        """Contact multipliers lam (k, n, nc) (force per length, EI_z / L^3 units), gaps of
        the rod's surface (k, n, nc) (units of L), unit normals (k, n, nc, 3), gap hessians
        (k, n, nc, 3, 3) (1/m, times L: per unit of L) at the contact points
        ``x_j + c_j t_j`` (node positions x, frames (k, n, 3, 3)), and the offset of a
        rectangle's touching point from the contact point, ``-arm`` (k, n, nc, 3) in units
        of L (a corner, or a point across a face nearly parallel to the wall:
        :data:`FACE_ROUNDING`; None for a round section: it touches along the normal)."""
        k, n = V.shape[0], self.n
        c, _ = self._contact_geometry()
        pts = self.points(x + c[:, None] * frames[..., :, 0]).reshape(-1, 3)
        lam = V[:, :, 9 : 9 + self.nc]
        gaps = np.empty((k, n, self.nc))
        normals = np.empty((k, n, self.nc, 3))
        hess = np.zeros((k, n, self.nc, 3, 3)) if hessian else None
        for o in range(self.nc):
            g, grad, hs = self._evaluate_at(o, pts, 2 if hessian else 1)
            gaps[:, :, o] = np.asarray(g, float).reshape(k, n) / self.L
            normals[:, :, o] = np.asarray(grad, float).reshape(k, n, 3)
            if hessian:
                hess[:, :, o] = np.asarray(hs, float).reshape(k, n, 3, 3)
        arm = None
        if self._round:
            gaps -= self._half[0]
        else:  # support of the rectangle along the normal: arm = sum_a half_a f'(n.d_a) d_a
            d = np.einsum("knoi,knia->knoa", normals, frames[..., :, 1:3])  # (k, n, nc, 2)
            f, df = _face_support(d)  # (|n.d_a| and sign(n.d_a), rounded: FACE_ROUNDING)
            gaps -= f @ self._half
            arm = np.einsum("knoa,knia->knoi", df * self._half, frames[..., :, 1:3])
        return lam, gaps, normals, hess, arm

    def surface_gaps(self, x: np.ndarray, frames: np.ndarray) -> np.ndarray:
        """Gaps of the rod's surface at the contact points of a rod given by its node
        positions x (k, n, 3) (units of L relative to the clamp) and frames (k, n, 3, 3)
        (e.g. a Richardson extrapolation): (k, n, nc), units of L."""
        if not self._round:  # a rectangle's support along the normal: the normals too
            V = np.zeros(x.shape[:2] + (self.nv,))
            return self._contact_terms(V, x, frames, False)[1]
        return self._round_gaps(x, frames[..., :, 0])

    def _round_gaps(self, x: np.ndarray, t: np.ndarray) -> np.ndarray:
        """:meth:`surface_gaps` of a round section from the node tangents t (k, n, 3): the
        gaps alone (no normals), the same numbers as :meth:`_contact_terms`'."""
        k, n = x.shape[:2]
        c, _ = self._contact_geometry()
        return self._gaps_at(self.points(x + c[:, None] * t).reshape(-1, 3), k, n)

    def _gaps_at(self, pts: np.ndarray, k: int, n: int) -> np.ndarray:
        """Gaps (k, n, nc) of a round section's surface, units of L, at its contact points
        pts (k n, 3), m."""
        if self.nc == 1:  # (one obstacle: its gaps as they come, the same roundings)
            g = self._evaluate_at(0, pts, 0)[0]
            return (np.asarray(g, float).reshape(k, n, 1) / self.L) - self._half[0]
        gaps = np.empty((k, n, self.nc))
        for o in range(self.nc):
            g = self._evaluate_at(o, pts, 0)[0]
            gaps[:, :, o] = np.asarray(g, float).reshape(k, n) / self.L
        gaps -= self._half[0]
        return gaps

    def _evaluate_at(self, o: int, pts: np.ndarray, order: int):
        """(gap, gradient or None, hessian or None) of obstacle ``o`` at the contact points
        ``pts`` (n, 3), m, up to ``order``: an :class:`~coilrod.contact.Obstacle`'s own
        ``_evaluate`` where the points are finite (what its ``evaluate`` validates: the
        same numbers without the checks), else its public methods (which raise on
        non-finite points, as before)."""
        ob = self.obstacles[o]
        direct = self.__dict__.get("_direct")
        if direct is None:
            from ..contact.obstacle import Obstacle

            direct = self.__dict__["_direct"] = [isinstance(b, Obstacle) for b in self.obstacles]
        if direct[o] and len(pts) and np.isfinite(pts).all():
            return ob._evaluate(pts, order)
        if hasattr(ob, "evaluate"):  # one nearest-point search for all three
            return ob.evaluate(pts, order=order)
        return (
            ob.gap(pts),
            ob.gap_gradient(pts) if order >= 1 else None,
            ob.gap_hessian(pts) if order >= 2 else None,
        )

    def _state_gaps(self, U: np.ndarray) -> np.ndarray:
        """Surface gaps of states (k, size): :meth:`surface_gaps` at their node positions and
        frames, (k, n, nc), units of L; the last few stacks remembered (a load step's event
        test and its prediction ask for the converged state's), read-only."""
        U = np.atleast_2d(U)
        key = (U.shape, U.tobytes())
        hit = self._gaps_memo.get(key)
        if hit is None:
            if self._round:  # the tangents alone (Rodrigues on R0's first column)
                hit = self._round_state_gaps(self.rotations(U), self.node_positions(U))
            else:
                hit = self.surface_gaps(self.node_positions(U), self.frames(U))
        return self._remember_gaps(U, hit, key)

    def _round_state_gaps(self, phi: np.ndarray, x: np.ndarray) -> np.ndarray:
        """:meth:`_round_gaps` of states given by their rotation vectors phi and node
        positions x (k, n, 3): the tangents and contact points by the compiled
        :func:`~coilrod.rod._compiled_contact.round_points` once compiling pays (the numpy
        operations whose roundings numpy owns stay numpy's: the same numbers), else by
        :func:`_tangents`; (k, n, nc), units of L."""
        cached = self.__dict__.get("_cross_R0")
        if cached is None:
            r = np.ascontiguousarray(self.R0[:, 0])
            cached = self.__dict__["_cross_R0"] = (_cross_matrix(r), r)
        M, r = cached
        k, n = x.shape[:2]
        if not _contact_module().points_pay(k * n):
            return self._round_gaps(x, _tangents(phi, self.R0, M))
        # _tangents' numpy operations, the same calls on the same arrays
        t2 = np.einsum("...i,...i->...", phi, phi)
        theta = np.sqrt(t2)
        small = theta < 0.05
        ts = np.where(small, 1.0, theta)
        cos, sin = np.cos(ts), np.sin(ts)
        pm, pr = phi @ M, phi @ r
        c, _ = self._contact_geometry()
        pts = np.empty((k * n, 3))
        _contact_module().round_points(
            np.ascontiguousarray(phi).reshape(-1, 3), np.ascontiguousarray(x).reshape(-1, 3),
            t2.reshape(-1), ts.reshape(-1), cos.reshape(-1), sin.reshape(-1),
            np.ascontiguousarray(pm).reshape(-1, 3), pr.reshape(-1), small.reshape(-1), r, c,
            self._clamp_point(), float(self.L), pts,
        )  # fmt: skip
        return self._gaps_at(pts, k, n)

    def _clamp_point(self) -> np.ndarray:
        """The clamp's position (3,) as a C-contiguous float array (the compiled points')."""
        out = self.__dict__.get("_clamp_c")
        if out is None:
            out = self.__dict__["_clamp_c"] = np.ascontiguousarray(self.clamp, dtype=float)
        return out

    def _remember_gaps(self, U: np.ndarray, gaps: np.ndarray, key=None) -> np.ndarray:
        """Remember the surface gaps (k, n, nc) of states U (k, size) for
        :meth:`_state_gaps` (the last four stacks; a linearization's too: a converged
        state's event test then needs no search), read-only; returns them.  ``key``: U's
        memory key ``(U.shape, U.tobytes())`` if at hand."""
        gaps.flags.writeable = False
        key = (U.shape, U.tobytes()) if key is None else key
        return _remember(self._gaps_memo, key, gaps, size=4)

    def contact_state(self, U: np.ndarray, frames: np.ndarray | None = None):
        """Contact of states (k, size) at the contact points (:meth:`contact_points`): force
        per length on the rod (k, n, nc, 3) in EI_z / L^3 units (times the weights omega_j:
        the point forces; the normal force plus friction), gaps (k, n, nc) in units of L, and
        the active set (k, n, nc) (points where the gap is closed and the wall pushes).
        ``frames``: the states' node frames (k, n, 3, 3) if already at hand."""
        U = np.atleast_2d(U)
        V = U.reshape(U.shape[0], self.n, self.nv)
        frames = self.frames(U) if frames is None else frames
        lam, gaps, normals, _, _ = self._contact_terms(V, V[:, :, 0:3], frames, False)
        force = lam[..., None] * normals + self.friction_forces(U)
        force[:, 0] = 0.0
        active = self.kappa * gaps < lam
        active[:, 0] = False
        return force, gaps, active

    def contact_totals(self, force: np.ndarray) -> np.ndarray:
        """Total force the rod exerts on each obstacle, (k, nc, 3) in EI_z / L^2 units, from
        the contact force per length on the rod (k, n, nc, 3) of :meth:`contact_state` (minus
        its integral with the contact points' weights)."""
        return -np.einsum("n,knoi->koi", self._contact_geometry()[1], force)

    # -- derivatives of the tip (sensitivities) --------------------------------------------------
    def tip_gradients(self, U: np.ndarray, rotation: bool = False) -> np.ndarray:
        """Derivatives of the tip (x_N, y_N, z_N in units of L relative to the clamp; the tip
        azimuth atan2(t_y, t_x) in rad) with respect to the unknowns of each state of a stack
        (k, size): shape (4, k, size).  With ``rotation``, shape (7, k, size): rows 4:7 the
        tip frame's rotation a (rad, world axes: dR_N = hat(a) R_N, a = J_l(phi_N) dphi_N;
        the tip tangent moves by a x t)."""
        U = np.atleast_2d(U)
        k, n, nv = U.shape[0], self.n, self.nv
        out = np.zeros((7 if rotation else 4, k, n, nv))
        phi = self.rotations(U)
        op = self._slots()[1]
        if self.uniform:  # x_N = sum_j w_j t_j, dt_j = -hat(t_j) J_l(phi_j) dphi_j
            R = self.frames(U)
            dt = -hat(R[..., :, 0]) @ left_jacobian(phi)  # (k, n, 3, 3)
            out[0:3, :, :, op : op + 3] = np.moveaxis(self.mesh.w[:, None, None] * dt, 2, 0)
        else:
            out[0:3, :, -1, 0:3] = np.eye(3)[:, None, :]
        t = expm(phi[:, -1]) @ self.R0[:, 0]  # (k, 3) tip tangent
        dt = -hat(t) @ left_jacobian(phi[:, -1])  # (k, 3, 3)
        rho2 = t[:, 0] ** 2 + t[:, 1] ** 2
        out[3, :, -1, op : op + 3] = (t[:, 0, None] * dt[:, 1] - t[:, 1, None] * dt[:, 0]) / rho2[
            :, None
        ]
        if rotation:
            out[4:7, :, -1, op : op + 3] = np.moveaxis(left_jacobian(phi[:, -1]), 1, 0)
        return out.reshape(out.shape[0], k, -1)

    def load_rates(self, U: np.ndarray, dmu=None, B=None, G=None) -> np.ndarray:
        """dR/dscale of the states (k, size) for other loads, linear in them: the body
        magnetization ``dmu`` (p, n, 3) in the problem's units in the field of the problem,
        or the field ``B`` (k, n, 3, p) T and gradient ``G`` (k, n, 3, 3, p) T/m at the nodes
        with the problem's magnetization.  Shape (k, size, p)."""
        U = np.atleast_2d(U)
        k, n, nv = U.shape[0], self.n, self.nv
        R = self.frames(U)  # (k, n, 3, 3)
        w = self.mesh.w
        if dmu is not None:
            m = np.einsum("knij,pnj->knip", R, dmu)  # (k, n, 3, p)
            if self.uniform:
                b = np.broadcast_to(self._b_uniform, (k, n, 3))
                Gf = None
            else:
                Bf, Gf, _ = self._field(self.node_positions(U), False)
                b, Gf = Bf.reshape(k, n, 3), Gf.reshape(k, n, 3, 3)
            tau = cross(np.moveaxis(m, -1, 0), b[None])  # (p, k, n, 3)
            f = None if Gf is None else np.einsum("knij,knip->knjp", Gf, m)
        else:
            m = np.einsum("knij,nj->kni", R, self.mu)
            tau = cross(m[None], np.moveaxis(B, -1, 0))
            f = np.einsum("knijp,kni->knjp", G, m)
        p = tau.shape[0]
        out = np.zeros((k, n, nv, p))
        op = self._slots()[1]
        out[:, :, op : op + 3] = np.moveaxis(-w[:, None] * tau, 0, -1)
        out[:, 0, op : op + 3] = 0.0
        if f is not None and not self.uniform:
            out[:, :-1, 6:9] = -(w[1:, None, None] * self.L) * f[:, 1:]
        return out.reshape(k, -1, p)

    # -- assembly -----------------------------------------------------------------------------
    def _band_layout(self):
        """(kl, ku, index): the band widths and every block's (band row, column) entries,
        state-independent: shared by the problems of one layout (an insertion builds one per
        step), the last few layouts cached (read-only arrays)."""
        key = (self.n, self.nv, self.nc, self.nt, self.uniform, self._slots())
        out = _LAYOUTS.get(key)
        if out is None:
            entries = self._block_entries()
            diff = np.concatenate([(r - c).ravel() for r, c in entries.values()])
            kl, ku = int(max(diff.max(), 1)), int(max(-diff.min(), 1))
            index = {name: (kl + ku + r - c, c) for name, (r, c) in entries.items()}
            for rows, cols in index.values():
                rows.flags.writeable = cols.flags.writeable = False
            out = _remember(_LAYOUTS, key, (kl, ku, index), size=8)
        return out

    def _block_entries(self):
        """Rows and columns (member 0) of every Jacobian block's entries, by block kind:
        arrays (nblocks, rows, cols)."""
        n, nv, nc = self.n, self.nv, self.nc
        ox, op, of = self._slots()
        ol = 9  # contact multipliers
        ot, nt = 9 + nc, self.nt  # friction forces

        def block(rnodes, roff, cnodes, coff, nr=3, ncol=3):
            ii, jj = np.meshgrid(np.arange(nr), np.arange(ncol), indexing="ij")
            r = (nv * np.asarray(rnodes) + roff)[:, None, None] + ii
            c = (nv * np.asarray(cnodes) + coff)[:, None, None] + jj
            return r, c

        j = np.arange(1, n)  # free nodes
        idx = {
            "clamp_phi": block([0], op, [0], op),
            "m_prev": block(j, op, j - 1, op),  # moment j wrt phi_{j-1}
            "m_diag": block(j, op, j, op),
            "m_next": block(j[:-1], op, j[:-1] + 1, op),
        }
        if not self.uniform:
            idx.update(
                {
                    "clamp_x": block([0], ox, [0], ox),
                    "p_x": block(j, ox, j, ox),
                    "p_xprev": block(j, ox, j - 1, ox),
                    "p_phiprev": block(j, ox, j - 1, op),
                    "p_phi": block(j, ox, j, op),
                    "m_x": block(j, op, j, ox),
                    "m_Fprev": block(j, op, j - 1, of),
                    "m_F": block(j[:-1], op, j[:-1], of),
                    "f_F": block(np.arange(n), of, np.arange(n), of),
                    "f_Fnext": block(j - 1, of, j, of),
                    "f_xnext": block(j - 1, of, j, ox),
                    "f_phinext": block(j - 1, of, j, op),
                }
            )
        if nc:
            idx.update(
                {
                    "clamp_lam": block([0], ol, [0], ol, nc, nc),
                    "f_lamnext": block(j - 1, of, j, ol, 3, nc),
                    "m_lam": block(j, op, j, ol, 3, nc),
                    "c_x": block(j, ol, j, ox, nc, 3),
                    "c_phi": block(j, ol, j, op, nc, 3),
                    "c_lam": block(j, ol, j, ol, nc, nc),
                }
            )
        if nt:
            idx.update(
                {
                    "clamp_tau": block([0], ot, [0], ot, nt, nt),
                    "f_taunext": block(j - 1, of, j, ot, 3, nt),
                    "m_tau": block(j, op, j, ot, 3, nt),
                    "t_x": block(j, ot, j, ox, nt, 3),
                    "t_phi": block(j, ot, j, op, nt, 3),
                    "t_lam": block(j, ot, j, ol, nt, nc),
                    "t_tau": block(j, ot, j, ot, nt, nt),
                }
            )
        return idx

    #: Jacobian blocks taken from the compiled pass's ``blk`` (:meth:`_band_from_blk`):
    #: block name -> (slot in blk, nodes from 1 to n - 1 or to n - 2).
    _BLK_SLOTS = {
        "m_prev": (0, False), "m_diag": (1, False), "m_next": (2, True),
        "p_phiprev": (3, False), "p_phi": (4, False), "m_x": (5, False),
        "m_Fprev": (6, False), "m_F": (7, True), "f_xnext": (8, False),
        "f_phinext": (9, False),
    }  # fmt: skip

    def _workspace(self, k: int, tangent: bool) -> dict:
        """Arrays of :meth:`_assemble` that do not leave it, reused from call to call (by the
        stack size and ``tangent``): frames, magnetization, the compiled pass's Jacobian
        blocks (the same entries written every call), placeholders, and in a uniform field
        the field, zero gradient and zero positions and forces."""
        key = (k, tangent)
        ws = self._work.get(key)
        if ws is None:
            n = self.n
            if len(self._work) >= 8:
                self._work.clear()
            ws = {
                "frames": np.empty((k, n, 3, 3)),
                "m": np.empty((k, n, 3)),
                "blk": np.zeros(((k, n) if tangent else (1, 1)) + (10, 3, 3)),
                "diag": np.zeros((1, 1, 3, 3)),
                "H": np.zeros((1, 1, 3, 3, 3)),
            }
            if self.uniform:
                ws["B"] = np.ascontiguousarray(np.broadcast_to(self._b_uniform, (k, n, 3)))
                ws["G"] = np.zeros((k, n, 3, 3))
                ws["X"] = np.zeros((k, n, 3))
            self._work[key] = ws
        return ws

    def _band_from_blk(self, k: int, blk: np.ndarray) -> np.ndarray:
        """LAPACK band storage (as :meth:`_scatter`) of a stack without contact: a template
        with the constant blocks and one gather of the varying entries from the compiled
        pass's ``blk`` (k, n, 10, 3, 3) through precomputed flat indices (cached per k)."""
        template, dst, src = self._blk_gather(k)
        ab = template.copy(order="F")
        ab.ravel(order="K")[dst] = blk.ravel()[src]
        return ab

    def _blk_gather(self, k: int):
        """(template, dst, src) of :meth:`_band_from_blk` for a stack of k (cached): the band
        storage with the constant blocks, and the flat band and ``blk`` indices of the
        varying entries."""
        key = ("blk", k)
        cached = self._band_cache.get(key)
        if cached is None:
            n, rows = self.n, 2 * self.kl + self.ku + 1
            template = np.zeros((rows, k * self.size), order="F")
            flat = template.ravel(order="K")
            member = (np.arange(k) * self.size * rows)[:, None]
            I3 = np.eye(3)
            consts = {"clamp_phi": I3}
            if not self.uniform:
                consts.update({"clamp_x": I3, "p_x": I3, "p_xprev": -I3, "f_F": I3, "f_Fnext": -I3})
            for name, value in consts.items():
                r, c = self._index[name]
                flat[(r + c * rows).reshape(1, -1) + member] = np.broadcast_to(
                    value, r.shape
                ).reshape(1, -1)
            dst, src = [], []
            ab3 = np.arange(9).reshape(3, 3)
            for name, (slot, short) in self._BLK_SLOTS.items():
                if name not in self._index:
                    continue
                r, c = self._index[name]
                nodes = np.arange(1, n - 1 if short else n)
                dst.append((r + c * rows).reshape(-1))
                src.append(((nodes[:, None, None] * 10 + slot) * 9 + ab3).reshape(-1))
            dst = (np.concatenate(dst)[None] + member).ravel()
            src = (np.concatenate(src)[None] + (np.arange(k) * n * 90)[:, None]).ravel()
            cached = self._band_cache[key] = (template, dst, src)
        return cached

    def _scatter(self, k: int, blocks: dict) -> np.ndarray:
        """LAPACK band storage (2 kl + ku + 1, k size) of the stacked Jacobians: a template
        holding the constant blocks (cached per k), the state-dependent ones written through
        precomputed flat indices in one assignment."""
        key = ("scatter", k, tuple(blocks))
        cached = self._band_cache.get(key)
        if cached is None:
            rows = 2 * self.kl + self.ku + 1
            template = np.zeros((rows, k * self.size), order="F")
            flat = template.ravel(order="K")
            member = (np.arange(k) * self.size * rows)[:, None]
            varying = []
            for name, values in blocks.items():
                r, c = self._index[name]
                idx = (r + c * rows).reshape(1, -1) + member  # (k, entries)
                if np.ndim(values) == 2:  # a constant 3x3 block
                    flat[idx] = np.broadcast_to(values, r.shape).reshape(1, -1)
                else:
                    varying.append((name, idx))
            order = [name for name, _ in varying]
            index = np.concatenate([i for _, i in varying], axis=1) if varying else None
            cached = self._band_cache[key] = (template, order, index)
        template, order, index = cached
        ab = template.copy(order="F")
        if index is not None:
            vals = []
            for name in order:  # (np.broadcast_to only where a block is shared)
                v, shape = blocks[name], (k,) + self._index[name][0].shape
                vals.append((v if v.shape == shape else np.broadcast_to(v, shape)).reshape(k, -1))
            vals = np.concatenate(vals, axis=1)
            ab.ravel(order="K")[index] = vals
        return ab

    def _assemble(
        self, U: np.ndarray, S: np.ndarray, tangent: bool, core=None, band=True, fields=None
    ):
        """Residual (k, size), load rate (k, size), band storage and symmetric blocks of a
        stack: the per-node algebra by ``core`` (default: the pass of
        :mod:`coilrod.rod._compiled_spatial`, numpy until compiling pays;
        :func:`numpy_core` is the same in numpy, rounding differently), the
        contact terms (:meth:`_contact_rows`, :meth:`_contact_blocks`) and the second
        variation's blocks (:meth:`_second_variation`) added here.  ``band`` False: no band
        storage (None; the blocks alone, for an inertia count).  ``fields``: (B (k n, 3),
        G (k n, 3, 3), H (k n, 3, 3, 3) or None) at the nodes, already evaluated."""
        if core is None:
            core = _compiled_core() or _spatial_module().spatial_pass

        k, n, nv = U.shape[0], self.n, self.nv
        ws = self._workspace(k, tangent)
        V = U.reshape(k, n, nv)
        phi = np.ascontiguousarray(V if self.uniform else V[:, :, 3:6])  # self.rotations(U)
        if self.uniform:
            B, G, Hs, X = ws["B"], ws["G"], None, ws["X"]
            F = X
        else:
            X = np.ascontiguousarray(V[:, :, 0:3])
            F = np.ascontiguousarray(V[:, :, 6:9])
            B, G, Hs = self._field_by_member(X, tangent) if fields is None else fields
            # C-contiguous field inputs (a copy only of a strided view, e.g. the magnet pose's
            # Hessian): the compiled pass, called directly here, has one compiled version
            B, G = (
                np.ascontiguousarray(B.reshape(k, n, 3)),
                np.ascontiguousarray(G.reshape(k, n, 3, 3)),
            )
            if Hs is not None:
                Hs = np.ascontiguousarray(Hs.reshape(k, n, 3, 3, 3))
        frames, blk, m = ws["frames"], ws["blk"], ws["m"]
        # residual and load rate in one array (_maxima; linearize keeps it as lin.pair)
        pair = self._pair = np.zeros((2, k, n, nv))
        R, R1 = pair[0], pair[1]
        # (diag and A_ab travel with the tangent: new arrays, every entry written by core)
        diag = np.empty((k, n, 3, 3)) if tangent else ws["diag"]
        A_ab = np.empty((k, n - 1, 3, 3)) if tangent else ws["diag"]
        has_h = Hs is not None
        S = S if S.dtype == float else np.asarray(S, float)
        # the compiled pass writes the uniform layout's band itself (into the template's copy)
        direct = band and tangent and self.uniform and not self.nc
        ab = self._blk_gather(k)[0].copy(order="F") if direct else _NO_BAND
        # each member's error, largest rotation component and finiteness from the compiled
        # pass (the numpy passes leave the -1: linearize and error compute them); not with
        # contact (its rows are added below)
        stats = np.full((k, 3), -1.0) if not self.nc else _NO_STATS
        wrote = core(
            phi, X, F, S, B, G, Hs if has_h else ws["H"], has_h, self.uniform, tangent,
            self.mu, self.K, self.mesh.h, self.mesh.w, self.R0, self.L, frames, R, R1, blk,
            diag, A_ab, m, ab, self.kl + self.ku, direct, self._econ, self.tol, _FLOOR * _EPS,
            stats,
        )  # fmt: skip
        self._stats = stats if stats.shape[0] and stats[0, 2] >= 0.0 else None
        if self.nc and self._contact_kernel(k, tangent, band):
            return self._compiled_contact(U, S, V, X, frames, phi, blk, m, G, pair, diag, A_ab,
                                          tangent)  # fmt: skip
        contact = self._contact_rows(V, X, frames, R, tangent) if self.nc else None
        if contact is not None and k == 1:  # the state's gaps for its event tests
            self._remember_gaps(U, contact["gaps"].copy())
        R = R.reshape(k, -1)
        R1 = R1.reshape(k, -1)
        if not tangent:
            return R, R1, None, None
        if not self.nc:  # every varying block is an entry of blk: one gather into the band
            if not wrote:
                ab = self._band_from_blk(k, blk) if band else None
            if self.uniform:
                return R, R1, ab, (diag[:, 1:], A_ab[:, 1:])
            # the second variation only where a stability count asks for it (lazily; the
            # arrays of the workspace copied, the others are this call's own)
            args = (S, G, m.copy(), frames.copy(), blk[:, 1:, 8].copy(), diag, A_ab, None)
            return R, R1, ab, _Deferred(self._second_variation, args)
        # one state of a frictionless contact: its blocks kept for a load step's prediction
        # (:meth:`_every_active_band`; blk is the workspace's, overwritten by the next call)
        keep = k == 1 and band and not self.nt
        if keep:
            blk = blk.copy()
        I3 = np.eye(3)
        blocks = {
            "clamp_phi": I3,
            "m_prev": blk[:, 1:, 0],
            "m_diag": blk[:, 1:, 1],
            "m_next": blk[:, 1:-1, 2],
        }
        blocks.update(
            {
                "clamp_x": I3,
                "p_x": I3,
                "p_xprev": -I3,
                "p_phiprev": blk[:, 1:, 3],
                "p_phi": blk[:, 1:, 4],
                "m_x": blk[:, 1:, 5],
                "m_Fprev": blk[:, 1:, 6],
                "m_F": blk[:, 1:-1, 7],
                "f_F": I3,
                "f_Fnext": -I3,
                "f_xnext": blk[:, 1:, 8],
                "f_phinext": blk[:, 1:, 9],
            }
        )
        sym = self._contact_blocks(contact, frames, phi, blocks, keep)
        ab = self._scatter(k, blocks) if band else None
        if keep:
            self._kept = (U.tobytes(), S.tobytes(), blocks, contact["every"], R1, R)
        # the second variation lazily here too (a contact solve's predictions and Newton
        # steps never count; the workspace's arrays copied)
        args = (S, G, m.copy(), frames.copy(), blocks["f_xnext"].copy(), diag, A_ab, sym)
        return R, R1, ab, _Deferred(self._second_variation, args)

    def _contact_rows(self, V, X, frames, R, tangent):
        """Add the contact terms to the residual R (k, n, nv) in place: the force and moment
        of the normal force and friction at the contact points, the complementarity rows of
        the normal multipliers and the friction rows (:meth:`_friction_rows`).  Returns what
        :meth:`_contact_blocks` needs (a dict)."""
        cc, om = self._contact_geometry()
        tt = frames[:, :, :, 0]
        lam, gaps, normals, hess, arm = self._contact_terms(V, X, frames, tangent)
        friction = None
        if self.nt:  # tangential forces per length tau (k, n, nc, 3), applied at p_j
            friction = self._friction_rows(V, X, frames, lam, normals, hess)
        f_c, m_c = self._normal_force(lam, normals, tt, friction)
        m_arm = 0.0
        if arm is not None:  # the normal force acts at the rectangle's touching point, p - arm
            m_arm = om[:, None] * np.einsum("kno,knoi->kni", lam, cross(arm, normals))
        R[:, :-1, 6:9] -= om[1:, None] * f_c[:, 1:]
        R[:, 1:, 3:6] += (m_c + m_arm)[:, 1:]
        ol, ot = 9, 9 + self.nc
        ncp = self._ncp(lam, gaps)  # (its partials for _contact_blocks)
        R[:, :, ol:ot] = ncp[0]
        R[:, 0, ol:ot] = lam[:, 0]
        if friction is not None:
            k, n = V.shape[:2]
            R[:, :, ot:] = friction[0].reshape(k, n, -1)
            R[:, 0, ot:] = friction[1][:, 0].reshape(k, -1)
        return {
            "lam": lam, "gaps": gaps, "normals": normals, "hess": hess, "arm": arm,
            "f_c": f_c, "m_c": m_c, "m_arm": m_arm, "friction": friction, "ncp": ncp,
        }  # fmt: skip

    def _normal_force(self, lam, normals, tt, friction=None):
        """The contact force per length f_c (k, n, 3) at the contact points (the normal
        forces, plus the friction forces ``friction[1]`` (k, n, nc, 3) if given) and its
        moment about the nodes m_c (k, n, 3) (world), from the multipliers (k, n, nc), the
        normals (k, n, nc, 3) and the node tangents tt (k, n, 3)."""
        cc, om = self._contact_geometry()
        f_c = np.einsum("kno,knoi->kni", lam, normals)  # (k, n, 3)
        if friction is not None:
            f_c = f_c + friction[1].sum(axis=2)
        return f_c, -(om * cc)[:, None] * cross(tt, f_c)

    # -- the contact terms by the compiled kernel ------------------------------------------------
    def _contact_kernel(self, k: int, tangent: bool, band: bool) -> bool:
        """Whether :meth:`_assemble` adds the contact terms of a stack of k by the compiled
        kernel (:mod:`coilrod.rod._compiled_contact`): a frictionless round section with the
        class's complementarity function, rows alone or with the band, once compiling pays
        (its ski rental; else the numpy twin, :meth:`_contact_rows` and
        :meth:`_contact_blocks`, runs and is charged)."""
        return (
            not self.nt and self._round and self.ncp in ("min", "fb")
            and "_ncp" not in self.__dict__ and (band or not tangent)
            and _contact_module().compiled_pays(k, self.n)
        )  # fmt: skip

    def _constant_blocks(self) -> dict:
        """The contact layout's state-independent blocks (the clamp's rows and the
        identities of the position and force rows): the band template of the compiled
        contact terms (:meth:`_scatter` caches it per stack size)."""
        out = self.__dict__.get("_constants")
        if out is None:
            I3 = np.eye(3)
            out = self.__dict__["_constants"] = {
                "clamp_phi": I3, "clamp_x": I3, "p_x": I3, "p_xprev": -I3, "f_F": I3,
                "f_Fnext": -I3, "clamp_lam": np.eye(self.nc),
            }  # fmt: skip
        return out

    def _contact_band(self, terms, frames, phi, blk, R, tangent, every=False):
        """Run the compiled contact kernel (:func:`~coilrod.rod._compiled_contact.contact_core`)
        on a stack: the contact terms added to R (k, n, nv) in place; with ``tangent``
        returns the band storage (a new array) and the second variation's pieces
        (:meth:`_contact_variation`), else None.  ``terms``: (lam, gaps, normals, hess) of
        :meth:`_contact_terms`, C-contiguous; ``every``: every contact row the gap's
        (:meth:`_every_active_band`)."""
        cmod = _contact_module()
        lam, gaps, normals, hess = terms
        k, n, nc = lam.shape
        mode = cmod.MODES["every" if every or self._every_rows else self.ncp]
        cc, om = self._contact_geometry()
        m_c = np.zeros((k, n, 3))
        if tangent:
            ab = self._scatter(k, self._constant_blocks())
            var, turn = np.empty((k, n, 3, 3, 3)), np.empty((k, n, nc, 3))
        else:
            ab, var, turn = _NO_BAND, _NO_VAR, _NO_TURN
        cmod.contact_core(
            lam, gaps, normals, _NO_HESS if hess is None else hess, frames, phi, blk, cc, om,
            self.kappa, self.L, mode, tangent, R, ab, self.kl + self.ku, var, m_c, turn,
        )  # fmt: skip
        return (ab, (var, m_c, turn)) if tangent else None

    def _compiled_contact(self, U, S, V, X, frames, phi, blk, m, G, pair, diag, A_ab, tangent):
        """The end of :meth:`_assemble` for a contact problem with the contact terms by the
        compiled kernel (:meth:`_contact_band`): the same outputs (the residual, load rate,
        band and the second variation, lazily, by :meth:`_contact_variation`), the state's
        gaps remembered and a one-state tangent's inputs kept (:meth:`_every_active_band`)."""
        k = U.shape[0]
        lam, gaps, normals, hess, _ = self._contact_terms(V, X, frames, tangent)
        if k == 1:  # the state's gaps for its event tests
            self._remember_gaps(U, gaps.copy())
        terms = (np.ascontiguousarray(lam), gaps, normals, hess)
        out = self._contact_band(terms, frames, phi, blk, pair[0], tangent)
        R, R1 = pair[0].reshape(k, -1), pair[1].reshape(k, -1)
        if not tangent:
            return R, R1, None, None
        ab, pieces = out
        frames = frames.copy()  # (the workspace's, overwritten by the next call)
        if k == 1:
            self._kept = (U.tobytes(), S.tobytes(), None, (terms, frames, phi, blk.copy()), R1, R)
        args = (S, G, m.copy(), frames, pieces, lam, gaps, normals, diag, A_ab)
        return R, R1, ab, _Deferred(self._contact_variation, args)

    def _contact_variation(self, S, G, m, frames, pieces, lam, gaps, normals, diag, A_ab):
        """The second variation (:meth:`_second_variation`) of a linearization whose contact
        terms the compiled kernel formed, from its ``pieces`` (the ones
        :meth:`_contact_blocks` returns, to rounding)."""
        var, m_c, turn = pieces
        act = (self.kappa * gaps < lam)[:, 1:]
        n_t = np.swapaxes(normals[:, 1:], -1, -2)
        sym = (var[:, 1:, 0], var[:, 1:, 1], m_c, act, n_t, np.swapaxes(turn[:, 1:], -1, -2))
        return self._second_variation(S, G, m, frames, var[:, 1:, 2], diag, A_ab, sym)

    def _friction_rows(self, V, X, frames, lam, normals, hess):
        """Coulomb friction at the contact points: ``(Phi, tau, derivatives)``.

        ``tau`` (k, n, nc, 3) is the tangential force per length on the rod at contact point
        p_j from each obstacle (unknowns, EI_z / L^3 units), ``Phi = tau - proj(P tau - r u)``
        (k, n, nc, 3) its row: ``P = I - n n^T`` the projection on the wall's tangent plane at
        p_j, ``u = P (p_j - p_ref)`` the tangential displacement of the contact point since
        the last accepted state (:meth:`accept_state`), ``r`` = :attr:`kappa` and ``proj`` the
        projection on the disk ``|.| <= mu max(lam, 0)``.  Phi = 0 iff n . tau = 0 and either
        u = 0 (stick, exactly) with |tau| <= mu lam, or |tau| = mu lam with tau along -u
        (slip).  Several sticking points of an inextensible rod leave a combination of their
        forces undetermined (a straight span between them carries any axial force): the
        Jacobian of the stick rows in tau is singular.  The derivative returned is therefore
        that of the rows with ``tau`` replaced by ``(1 - eps) tau + eps tau_k`` in ``proj``,
        tau_k the current iterate and eps = :attr:`stick_slack` -- a proximal term on the
        multiplier that is zero at the iterate, so the rows (and the converged state) stay
        exact while each Newton step is regular and moves the undetermined combination only
        as far as the rest needs (it stays near the predictor's).
        With ``hess`` (the gap hessians, 1/m) the derivatives ``(d Phi/d tau (k, n, nc, 3,
        3), d Phi/d lam (k, n, nc, 3), d Phi/d p (k, n, nc, 3, 3))``, else None."""
        k, n, nc = V.shape[0], self.n, self.nc
        cc, _ = self._contact_geometry()
        tau = V[:, :, 9 + nc :].reshape(k, n, nc, 3)
        r, eps = self.kappa, self.stick_slack
        d = (X + cc[:, None] * frames[..., :, 0] - self._p_ref)[:, :, None, :]  # (k, n, 1, 3)
        nd = np.einsum("knoi,knoi->kno", normals, np.broadcast_to(d, normals.shape))
        v = tau  # the row is exact: eps enters only its derivative (the Newton step)
        nv_ = np.einsum("knoi,knoi->kno", normals, v)
        a = v - normals * nv_[..., None] - r * (d - normals * nd[..., None])
        rho = self.mu_f * np.maximum(lam, 0.0)
        na = np.sqrt(np.einsum("knoi,knoi->kno", a, a))
        inside = na < rho  # stick (strict: rho = 0 is a free point, tau = 0)
        safe = np.where(na > 0, na, 1.0)
        ahat = a / safe[..., None]
        proj = np.where(inside[..., None], a, rho[..., None] * ahat)
        Phi = tau - proj
        if hess is None:
            return Phi, tau, None
        I3 = np.eye(3)
        Dp = np.where(
            inside[..., None, None], I3, (rho / safe)[..., None, None] * (I3 - _outer(ahat, ahat))
        )
        P = I3 - _outer(normals, normals)
        d_tau = I3 - (1.0 - eps) * Dp @ P
        slip = (~inside) & (lam > 0)
        d_lam = -(slip * self.mu_f)[..., None] * ahat
        LH = self.L * hess
        LHv = np.einsum("knoij,knoj->knoi", LH, v)
        LHd = np.einsum("knoij,knoj->knoi", LH, np.broadcast_to(d, tau.shape))
        da_dp = -nv_[..., None, None] * LH - _outer(normals, LHv)
        da_dp = da_dp - r * (P - nd[..., None, None] * LH - _outer(normals, LHd))
        return Phi, tau, (d_tau, d_lam, -Dp @ da_dp)

    def _contact_blocks(self, contact, frames, phi, blocks, every=False):
        """Add the contact terms' Jacobian blocks to ``blocks`` (in place: the force and
        moment rows' blocks of the nodes, the multipliers' and friction rows' own blocks);
        returns the pieces of the second variation (:meth:`_second_variation`).  ``every``:
        also the blocks ``c_x``, ``c_phi`` with every contact row the gap's (``kappa`` times
        its gradient), as ``contact["every"]`` (:meth:`_every_active_band`)."""
        lam, gaps, normals, hess, arm = (contact[key] for key in ("lam", "gaps", "normals",
                                                                   "hess", "arm"))  # fmt: skip
        f_c, m_c, L = contact["f_c"], contact["m_c"], self.L
        k, n, nc = lam.shape[0], self.n, self.nc
        cc, om = self._contact_geometry()
        oc = (om * cc)[1:, None, None]
        tt = frames[:, 1:, :, 0]
        That, Jl = hat(tt), left_jacobian(phi[:, 1:])
        LH = L * np.einsum("kno,knoij->knij", lam[:, 1:], hess[:, 1:])  # sum lam L H
        # world-rotation derivatives of the contact point p = x + c t: dp = -c hat(t) d
        fc_d = oc * (LH @ That)  # force row wrt the world rotation d_j
        m_x = blocks["m_x"] - oc * (That @ LH)  # moment row wrt x_j (the transpose of fc_d)
        # moment row wrt d_j: the second variation of -om lam g(p) minus hat(m_c) / 2
        mc_d = -(om * cc)[1:, None, None] * _sym_term(tt, f_c[:, 1:])
        mc_d = mc_d + (oc * cc[1:, None, None]) * (That @ LH @ That)
        mc_d_sym = mc_d
        mc_d = mc_d - 0.5 * hat(m_c[:, 1:])
        d_lam, d_gap = (a[:, 1:] for a in contact["ncp"][1:])  # (elementwise: the free nodes')
        c_lam = np.zeros((k, n - 1, nc, nc))
        c_lam[..., np.arange(nc), np.arange(nc)] = d_lam
        n_t = np.swapaxes(normals[:, 1:], -1, -2)  # (k, n-1, 3, nc)
        tn = cross(tt[:, :, None, :], normals[:, 1:])  # (k, n-1, nc, 3): dg/dd / c
        gx = normals[:, 1:]  # d(surface gap)/dx, (k, n-1, nc, 3)
        gd = cc[1:, None, None] * tn  # d(surface gap)/dd
        turn_lam = -oc * np.swapaxes(tn, -1, -2)  # d(moment row)/dlam
        if arm is not None:  # the corner's gap n . arm turns with the frame and n(p)
            a1 = arm[:, 1:]
            w_ = L * np.einsum("knoij,knoj->knoi", hess[:, 1:], a1)  # L H arm
            an = cross(a1, normals[:, 1:])  # (k, n-1, nc, 3)
            gx = gx - w_
            gd = cc[1:, None, None] * cross(tt[:, :, None, :], normals[:, 1:] - w_) - an
            turn_lam = turn_lam + om[1:, None, None] * np.swapaxes(an, -1, -2)
            ahat = hat(a1)  # (k, n-1, nc, 3, 3)
            aLH = np.einsum("kno,knoij,knojl->knil", lam[:, 1:], ahat, L * hess[:, 1:])
            m_x = m_x + om[1:, None, None] * aLH
            frame_turn = np.einsum("kno,knoij,knojl->knil", lam[:, 1:], hat(normals[:, 1:]),
                                   ahat)  # fmt: skip
            arm_d = om[1:, None, None] * (frame_turn - cc[1:, None, None] * aLH @ That)
            # the arm's own turn as the cosines d_a = n . d_a change (FACE_ROUNDING):
            # d(arm) = sum_a half_a f''(d_a) d(d_a) d_a, d(d_a) = w_a . dx + v_a . d with
            # w_a = L H d_a, v_a = c t x w_a + d_a x n (a face turning against the wall)
            axes = np.swapaxes(frames[:, 1:, :, 1:3], -1, -2)  # (k, n-1, 2, 3)
            d = np.einsum("knoi,knai->knoa", normals[:, 1:], axes)
            kap = om[1:, None, None] * lam[:, 1:, :, None] * _face_support(d, 2)[2] * self._half
            e_ = cross(axes[:, :, None], normals[:, 1:, :, None])  # (k, n-1, nc, 2, 3)
            w_a = L * np.einsum("knoij,knaj->knoai", hess[:, 1:], axes)
            v_a = cc[1:, None, None, None] * cross(tt[:, :, None, None, :], w_a) + e_
            m_x = m_x + np.einsum("knoa,knoai,knoaj->knij", kap, e_, w_a)
            arm_d = arm_d + np.einsum("knoa,knoai,knoaj->knij", kap, e_, v_a)
            mc_d = mc_d + arm_d  # (a derivative of the row: no hat(m) / 2 term)
            # the second variation (stability) takes its symmetric part and the whole
            # moment's hat(m)/2 (zero at an equilibrium with the core's)
            mc_d_sym = mc_d_sym + 0.5 * (arm_d + np.swapaxes(arm_d, -1, -2))
            m_c = m_c + contact["m_arm"]
        ck = (d_gap * self.kappa)[..., None]
        if every:  # d_gap = 1 for every row: the same products as below, bitwise
            contact["every"] = (self.kappa * gx, (self.kappa * gd) @ Jl)
        blocks.update(
            {
                "m_x": m_x,
                "m_diag": blocks["m_diag"] + mc_d @ Jl,
                "f_xnext": blocks["f_xnext"] - om[1:, None, None] * LH,
                "f_phinext": blocks["f_phinext"] + fc_d @ Jl,
                "clamp_lam": np.eye(nc),
                "f_lamnext": -om[1:, None, None] * n_t,
                "m_lam": turn_lam,
                "c_x": ck * gx,
                "c_phi": (ck * gd) @ Jl,
                "c_lam": c_lam,
            }
        )
        if self.nt:
            self._friction_blocks(contact["friction"][2], tt, That, Jl, blocks)
        act = (self.kappa * gaps < lam)[:, 1:]
        return fc_d, mc_d_sym, m_c, act, n_t, turn_lam

    def _friction_blocks(self, deriv, tt, That, Jl, blocks):
        """The friction's Jacobian blocks (:meth:`_friction_rows`) into ``blocks``: the force
        and moment rows wrt tau, the friction rows wrt x, phi, lam and tau (nodes 1..N)."""
        d_tau, d_lam, d_p = (a[:, 1:] for a in deriv)
        k, nf, nc = d_lam.shape[:3]
        cc, om = self._contact_geometry()
        nt = 3 * nc
        t_lam = np.zeros((k, nf, nc, 3, nc))
        t_tau = np.zeros((k, nf, nc, 3, nc, 3))
        for o in range(nc):
            t_lam[:, :, o, :, o] = d_lam[:, :, o]
            t_tau[:, :, o, :, o, :] = d_tau[:, :, o]
        d_rot = d_p @ (-cc[1:, None, None] * That)[:, :, None]  # wrt the world rotation
        blocks.update(
            {
                "clamp_tau": np.eye(nt),
                "f_taunext": np.tile(-om[1:, None, None] * np.eye(3), (1, 1, nc)),
                "m_tau": np.tile(-(om * cc)[1:, None, None] * That, (1, 1, 1, nc)),
                "t_x": d_p.reshape(k, nf, nt, 3),
                "t_phi": (d_rot @ Jl[:, :, None]).reshape(k, nf, nt, 3),
                "t_lam": t_lam.reshape(k, nf, nt, nc),
                "t_tau": t_tau.reshape(k, nf, nt, nt),
            }
        )

    def _second_variation(self, S, G, m, frames, f_x, diag, A_ab, sym):
        """The second variation (Lagrangian Hessian) of the mixed layout in blocks Z_j =
        (x_j, F_{j-1}, d_j, lam_j, tau_j) of the free nodes: diagonal D (k, n-1, nv, nv) and
        upper E (k, n-2, nv, nv) blocks.  Friction is not conservative: its forces enter as
        dead loads at the state and its unknowns decouple (identity)."""
        k, n = frames.shape[:2]
        h, w, L = self.mesh.h, self.mesh.w, self.L
        I3 = np.eye(3)
        nf, b = n - 1, self.nv
        D = np.zeros((k, nf, b, b))
        E = np.zeros((k, max(nf - 1, 0), b, b))
        t = frames[:, :, :, 0]
        half_that = 0.5 * h[:, None, None] * hat(t[:, 1:])
        cwL = S[:, None, None, None] * (w[None, 1:, None, None] * L)
        D[:, :, 0:3, 0:3] = f_x
        D[:, :, 0:3, 3:6] = I3
        D[:, :, 3:6, 0:3] = I3
        D[:, :, 0:3, 6:9] = cwL * (np.swapaxes(G[:, 1:], -1, -2) @ hat(m[:, 1:]))
        D[:, :, 6:9, 0:3] = np.swapaxes(D[:, :, 0:3, 6:9], -1, -2)
        D[:, :, 3:6, 6:9] = half_that
        D[:, :, 6:9, 3:6] = -half_that
        D[:, :, 6:9, 6:9] = diag[:, 1:]
        E[:, :, 0:3, 3:6] = -I3
        E[:, :, 6:9, 3:6] = -0.5 * h[1:, None, None] * hat(t[:, 1:-1])
        E[:, :, 6:9, 6:9] = A_ab[:, 1:]
        if sym is None:
            return D, E
        fc_d, mc_d_sym, m_c, act, n_t, turn_lam = sym
        nc, ol, ot = self.nc, 9, 9 + self.nc
        D[:, :, 0:3, 6:9] += fc_d
        D[:, :, 6:9, 0:3] += np.swapaxes(fc_d, -1, -2)
        D[:, :, 6:9, 6:9] += mc_d_sym - 0.5 * hat(m_c[:, 1:])
        coupling = -self._contact_geometry()[1][1:, None, None] * n_t
        coupling = np.where(act[:, :, None, :], coupling, 0.0)
        D[:, :, 0:3, ol:ot] = coupling
        D[:, :, ol:ot, 0:3] = np.swapaxes(coupling, -1, -2)
        turn = np.where(act[:, :, None, :], turn_lam, 0.0)
        D[:, :, 6:9, ol:ot] = turn
        D[:, :, ol:ot, 6:9] = np.swapaxes(turn, -1, -2)
        D[:, :, ol:ot, ol:ot][..., np.arange(nc), np.arange(nc)] = np.where(act, 0.0, 1.0)
        if self.nt:
            D[:, :, ot:, ot:] = np.eye(self.nt)
        return D, E

    # -- stability ------------------------------------------------------------------------------
    def stability(self, lin: Linearization, precise: bool = False) -> np.ndarray:
        """Smallest eigenvalue mu of the second variation ``H z = mu W z`` (W: trapezoid
        weights) in the free nodes' world rotations (positions and forces eliminated), in
        EI_z / L^3 units.  The cheap indicator is +1 for a stable state and minus the number
        of negative eigenvalues otherwise (:meth:`inertia_signs`; it counts a double
        eigenvalue -- a circular section in a load symmetric about the rod's axis -- which
        the determinant's sign would miss).  ``precise``: the smallest eigenvalue itself
        (dense spectrum up to :data:`_DENSE_STABILITY` free unknowns, else ARPACK on the
        eigenvalue closest to zero, signed by the inertia)."""
        signs = self.inertia_signs(lin)
        if not precise:
            return signs
        out = np.full(lin.tangent.k, np.nan)
        for j in range(lin.tangent.k):
            if signs[j] == 0:
                continue
            one = _take_tangent(lin.tangent, [j])
            out[j] = self._lowest(one, lin.u[j], signs[j])
        return out

    def negative_count(self, lin: Linearization) -> np.ndarray:
        """Number of negative eigenvalues of the second variation of each member (k,) (-1
        where it is not finite), by block LDL^T (:mod:`coilrod.rod._inertia`)."""
        from ._inertia import block_tridiagonal_inertia

        D, E = lin.tangent.blocks
        neg, _ = block_tridiagonal_inertia(D, E)
        if not self.uniform:  # the Lagrangian's Hessian has one negative per constraint
            constraints = 3 * (self.n - 1)
            if self.nc:  # and one per active contact
                c_lam = D[:, :, 9 : 9 + self.nc, 9 : 9 + self.nc]
                constraints = constraints + np.count_nonzero(
                    np.einsum("knii->kni", c_lam) == 0.0, axis=(1, 2)
                )
            neg = np.where(neg >= 0, neg - constraints, neg)
        return neg

    def inertia_signs(self, lin: Linearization) -> np.ndarray:
        """+1 where the second variation is positive definite, minus the number of negative
        eigenvalues where not, 0 where it cannot be evaluated; shape (k,)."""
        neg = self.negative_count(lin)
        if neg.shape == (1,):  # one member: in Python scalars
            v = int(neg[0])
            return np.array([1.0 if v == 0 else -float(v) if v > 0 else 0.0])
        return np.where(neg == 0, 1.0, np.where(neg > 0, -neg.astype(float), 0.0))

    def _rotation_rows(self):
        op = self._slots()[1]
        return (self.nv * np.arange(1, self.n)[:, None] + op + np.arange(3)).ravel()

    def _lowest(self, tan: RodTangent, u: np.ndarray, sign: float) -> float:
        rows = self._rotation_rows()
        sq = np.repeat(np.sqrt(self.mesh.w[1:]), 3)
        Jl = left_jacobian(self.rotations(u)[1:])  # world rotation = J_l dphi

        def apply(V):  # V (q, 3(n-1)) -> W^1/2 H^-1 W^1/2 V
            rhs = np.zeros((V.shape[0], self.size))
            rhs[:, rows] = sq * V
            sol = _solve_many(tan, rhs)
            dphi = sol[:, rows].reshape(V.shape[0], self.n - 1, 3)
            return sq * np.einsum("nij,qnj->qni", Jl, dphi).reshape(V.shape[0], -1)

        nf = rows.size
        if nf <= _DENSE_STABILITY:
            Sm = apply(np.eye(nf))
            Sm = 0.5 * (Sm + Sm.T)
            if not np.all(np.isfinite(Sm)):
                return float("nan")
            return _lowest_from_inverse(Sm)
        return closest_to_zero(lambda v: apply(np.ravel(v)[None])[0], nf, sign)


class _Deferred:
    """The pair ``fn(*args)`` (the second variation's (D, E) blocks), computed on first use:
    unpacks, indexes and iterates like the tuple it stands for."""

    __slots__ = ("_fn", "_args", "_value")

    def __init__(self, fn, args):
        self._fn, self._args, self._value = fn, args, None

    def _get(self) -> tuple:
        if self._value is None:
            self._value = tuple(self._fn(*self._args))
            self._fn = self._args = None
        return self._value

    def __iter__(self):
        return iter(self._get())

    def __getitem__(self, i):
        return self._get()[i]

    def __len__(self) -> int:
        return 2


def _solve_many(tan: RodTangent, rhs: np.ndarray) -> np.ndarray:
    """Solve one member's Jacobian (k = 1) for several right-hand sides (q, size)."""
    from ._compiled import band_solve

    lu = tan.factor()
    if tan.bad[0]:
        return np.full(rhs.shape, np.nan)
    x = np.ascontiguousarray(rhs.T)
    band_solve(lu[0], tan.kl, tan.ku, lu[1], x)
    return x.T


def numpy_core(
    phi, X, F, S, B, G, H, has_h, uniform, tangent, mu, K, h, w, R0, L,
    frames, R, R1, blk, diag, A_ab, m_out, ab=None, kv=0, band=False, econ=None, tol=0.0,
    floor=0.0, stats=None,
):  # fmt: skip
    """:func:`coilrod.rod._compiled_spatial.spatial_core` in numpy, with the same arguments and
    outputs (the band storage ``ab`` and ``stats`` left alone: returns None, the caller
    gathers the band from ``blk`` and computes the statistics itself): the reference the
    compiled pass is tested against (the equations are in the module docstring)."""
    op = 0 if uniform else 3
    inv_h = 1.0 / h
    Rm = expm(phi) @ R0  # (k, n, 3, 3)
    frames[:] = Rm
    t = Rm[..., :, 0]
    m = _matvec(Rm, mu)  # (k, n, 3)
    m_out[:] = m
    # bending: psi_i = log(R_i^T R_{i+1}), p_i = R_{i+1} J_l^-1(psi_i) K psi_i / h_i
    Rb = Rm[:, 1:]
    psi = logm(np.swapaxes(Rm[:, :-1], -1, -2) @ Rb)  # (k, n-1, 3)
    g = psi * K * inv_h[:, None]
    theta = np.sqrt(np.einsum("kni,kni->kn", psi, psi))
    cc, dc = inv_right_jacobian_coefficients(theta)
    psi_g = cross(psi, g)
    p = _matvec(Rb, g - 0.5 * psi_g + cc[..., None] * cross(psi, psi_g))
    Sc = S[:, None, None]
    M1 = -w[:, None] * cross(m, B)  # moment rows per unit scale
    M = Sc * M1
    M[:, 1:] += p
    M[:, :-1] -= p
    if not uniform:
        hF = 0.5 * h[:, None] * F[:, :-1]  # h_i F_i / 2, (k, n-1, 3)
        M[:, 1:] -= cross(t[:, 1:], hF)
        M[:, :-1] -= cross(t[:, :-1], hF)
    M[:, 0] = phi[:, 0]
    M1[:, 0] = 0.0
    R[:, :, op : op + 3], R1[:, :, op : op + 3] = M, M1
    if not uniform:
        # positions: C_{j-1} = x_j - x_{j-1} - h (t_{j-1} + t_j) / 2
        R[:, 0, 0:3] = X[:, 0]
        R[:, 1:, 0:3] = X[:, 1:] - X[:, :-1] - 0.5 * h[:, None] * (t[:, :-1] + t[:, 1:])
        # forces: F_j - F_{j+1} - c w_{j+1} L G_{j+1}^T m_{j+1}
        f1 = -(w[:, None] * L) * np.einsum("knij,kni->knj", G, m)  # (k, n, 3)
        R1[:, :-1, 6:9] = f1[:, 1:]
        R[:, :-1, 6:9] = F[:, :-1] - F[:, 1:] + Sc * f1[:, 1:]
        R[:, -1, 6:9] = F[:, -1]
    if not tangent:
        return
    # segment Hessian: P = Rb (M^T K/h M + S) Rb^T, M = J_r^-1(psi)
    I3 = np.eye(3)
    Psi = hat(psi)
    Minv = I3 + 0.5 * Psi + cc[..., None, None] * (Psi @ Psi)  # J_r^-1(psi)
    MtKM = np.swapaxes(Minv, -1, -2) @ ((K[None, :, None] * inv_h[:, None, None]) * Minv)
    Gm = hat(g)
    N = (
        -0.5 * Gm
        - cc[..., None, None] * (Gm @ Psi)
        - cc[..., None, None] * hat(cross(g, psi))
        + dc[..., None, None] * _outer(psi, _matvec(Psi @ Psi, g))
    )
    MtN = np.swapaxes(Minv, -1, -2) @ N
    P = Rb @ (MtKM + 0.5 * (MtN + np.swapaxes(MtN, -1, -2))) @ np.swapaxes(Rb, -1, -2)
    hp = 0.5 * hat(p)
    A_ab[:] = -P + hp  # d(moment row i) / d(rotation i+1)
    A_ba = -P - hp  # d(moment row i+1) / d(rotation i)
    diag[:] = 0.0
    diag[:, 1:] += P
    diag[:, :-1] += P
    diag -= Sc[..., None] * w[:, None, None] * _sym_term(m, B)
    if not uniform:
        diag[:, 1:] -= _sym_term(t[:, 1:], hF)
        diag[:, :-1] -= _sym_term(t[:, :-1], hF)
    diag -= 0.5 * hat(M)
    Jl = left_jacobian(phi)  # (k, n, 3, 3)
    blk[:, 1:, 0] = A_ba @ Jl[:, :-1]
    blk[:, 1:, 1] = diag[:, 1:] @ Jl[:, 1:]
    blk[:, 1:-1, 2] = A_ab[:, 1:] @ Jl[:, 2:]
    if uniform:
        return
    half = 0.5 * h[:, None, None]
    That = hat(t)
    mhat = hat(m)
    cwL = Sc[..., None] * (w[:, None, None] * L)
    blk[:, 1:, 3] = (half * That[:, :-1]) @ Jl[:, :-1]
    blk[:, 1:, 4] = (half * That[:, 1:]) @ Jl[:, 1:]
    blk[:, 1:, 5] = (-cwL * (mhat @ G))[:, 1:]
    blk[:, 1:, 6] = -half * That[:, 1:]
    blk[:, 1:-1, 7] = -half[1:] * That[:, 1:-1]
    blk[:, 1:, 8] = 0.0
    if has_h:
        blk[:, 1:, 8] = (-cwL * L * np.einsum("kni,kniac->knac", m, H))[:, 1:]
    blk[:, 1:, 9] = (cwL * (np.swapaxes(G, -1, -2) @ mhat))[:, 1:] @ Jl[:, 1:]
