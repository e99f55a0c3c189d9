"""Stability of planar states in 3D: the spatial rod's second variation at a planar state.

The planar rod (:mod:`coilrod.rod.planar`) sees in-plane perturbations only; a state that is
stable among them can buckle out of the plane (twist and bend about the in-plane normal), e.g.
the seed's M(2b) in a field at 255 deg.  A planar state is an exact state of the spatial rod
(:mod:`coilrod.rod.spatial`: its discrete energy restricted to rotations about z is the planar
one), so the full 3D stability of a planar state is the inertia of the spatial rod's second
variation there.  :class:`OutOfPlane` maps planar states (both layouts) to spatial ones and
counts the negative eigenvalues of that second variation (block LDL^T, exact count), in total
and in the out-of-plane subspace alone.

Reflection through the plane maps a planar state in a planar load (``B_z = 0``,
``dB_z/dx = dB_z/dy = 0`` on the plane; curl-free, so ``dB_x/dz = dB_y/dz = 0`` there too) to
itself, so the second variation splits into the even (in-plane: x, y, F_x, F_y and the rotation
about z) and odd (out-of-plane: z, F_z and the rotations about x and y) subspaces; the count of
the odd block is the number of out-of-plane unstable modes.

All quantities are non-dimensional like the rods' (eigenvalues in EI_z / L^3 per unit length).
"""

from __future__ import annotations

import numpy as np

from ..path.protocol import Linearization

__all__ = ["OutOfPlane"]

# positions of the out-of-plane unknowns in the second variation's blocks
_ODD_UNIFORM = np.array([0, 1])  # world rotations about x and y (blocks: rotations)
_ODD_MIXED = np.array([2, 5, 6, 7])  # x_z, F_z, rotations about x and y (blocks: x, F, d)


class OutOfPlane:
    """The spatial twin of a planar rod problem, for the 3D stability of its states.

    Parameters
    ----------
    planar : PlanarRod
        The planar problem (mesh, node magnetization, field, clamp, layout).
    stiffness : array-like, shape (3,)
        (GJ, EI_y, EI_z) / EI_z of the rod (torsion, out-of-plane and in-plane bending).
    """

    def __init__(self, planar, stiffness):
        self.planar = planar
        self.theta0 = planar.theta0
        self.stiffness = np.asarray(stiffness, float)
        self._twin = None

    @property
    def twin(self):
        """The :class:`~coilrod.rod.spatial.SpatialRod` of the same rod, field, clamp, mesh and
        layout (built on first use)."""
        if self._twin is None:
            from .so3 import about_z
            from .spatial import SpatialRod

            P = self.planar
            mu = np.zeros((P.n, 3))
            mu[:, :2] = P.mu
            self._twin = SpatialRod(
                P.mesh, mu, self.stiffness, P.field, P.L, P.clamp, about_z(P.theta0), P.tol,
                mixed=not P.uniform,
            )  # fmt: skip
        return self._twin

    # -- states -----------------------------------------------------------------------------
    def spatial_states(self, U: np.ndarray) -> np.ndarray:
        """Spatial states (k, twin.size) of planar states (k, planar.size): rotations
        ``(0, 0, theta - theta_0)`` about z, positions ``(x, y, 0)``, forces ``(F_x, F_y, 0)``."""
        U = np.atleast_2d(U)
        k, n = U.shape[0], self.planar.n
        out = np.zeros((k, n, 3 if self.planar.uniform else 9))
        if self.planar.uniform:
            out[:, :, 2] = U - self.theta0
        else:
            v = U.reshape(k, n, 5)
            out[:, :, 0:2] = v[:, :, 0:2]
            out[:, :, 5] = v[:, :, 2] - self.theta0
            out[:, :, 6:8] = v[:, :, 3:5]
        return out.reshape(k, -1)

    def _with_fields(self, fields, run):
        """``run()`` with the twin's uniform field replaced by one per member (k, 3) T."""
        twin = self.twin
        if fields is None or not twin.uniform:
            return run()
        saved = twin._b_uniform
        try:
            twin._b_uniform = np.asarray(fields, float)[:, None, :]
            return run()
        finally:
            twin._b_uniform = saved

    def linearize(self, lin: Linearization, fields=None) -> Linearization:
        """The twin's linearization (with its tangent) at the planar states of ``lin``;
        ``fields`` (k, 3) T: a uniform field per member (a fan of field directions)."""
        U3 = self.spatial_states(lin.u)
        return self._with_fields(fields, lambda: self.twin.linearize(U3, lin.scale))

    def odd_count(self, lin: Linearization, fields=None) -> np.ndarray:
        """Negative eigenvalues of the out-of-plane block of the 3D second variation at the
        planar states of ``lin``, shape (k,) int (-1 where not finite)."""
        from ._inertia import block_tridiagonal_inertia

        S = np.broadcast_to(np.asarray(lin.scale, float), (np.atleast_2d(lin.u).shape[0],))
        S = S.copy()
        fv = getattr(lin, "field_values", None)
        known = None
        if fv is not None and not self.twin.uniform:
            H = getattr(lin, "field_hessian", None)
            if H is not None or self.twin.linear:  # the planar pass's field at the same nodes
                known = (fv[0].reshape(-1, 3), fv[1].reshape(-1, 3, 3), H)

        def blocks():
            with np.errstate(all="ignore"):
                if self.twin.uniform:  # numpy, at planar states: nothing to compile
                    b = self.twin._b_uniform
                    return uniform_blocks(self.planar.theta(lin.u), S, self.twin, b)
                U3 = self.spatial_states(lin.u)
                return self.twin._assemble(U3, S, True, band=False, fields=known)[3]

        D, E = self._with_fields(fields, blocks)
        odd = _ODD_UNIFORM if self.twin.uniform else _ODD_MIXED
        Do = np.ascontiguousarray(D[:, :, odd][:, :, :, odd])
        Eo = np.ascontiguousarray(E[:, :, odd][:, :, :, odd])
        out, _ = block_tridiagonal_inertia(Do, Eo)
        if not self.twin.uniform:  # one negative per z-position constraint of a free node
            out = np.where(out >= 0, out - (self.planar.n - 1), out)
        return out

    def lowest(self, lin3: Linearization, counts: np.ndarray) -> np.ndarray:
        """Smallest eigenvalue of the 3D second variation ``H z = mu W z`` of each member
        (see :meth:`coilrod.rod.spatial.SpatialRod.stability`) from the twin's linearization
        and the negative counts (k,), shape (k,)."""
        from .planar import _take_tangent

        out = np.full(lin3.tangent.k, np.nan)
        for j in range(lin3.tangent.k):
            if counts[j] < 0:
                continue
            one = _take_tangent(lin3.tangent, [j])
            out[j] = self.twin._lowest(one, lin3.u[j], 1.0 if counts[j] == 0 else -1.0)
        return out


def uniform_blocks(theta: np.ndarray, S: np.ndarray, twin, b) -> tuple[np.ndarray, np.ndarray]:
    """The spatial rod's second variation in world rotations, diagonal (k, n - 1, 3, 3) and
    upper (k, n - 2, 3, 3) blocks of the free nodes, at planar states with node angles theta
    (k, n) in a uniform field ``b`` ((3,) or (k, 1, 3), T at scale 1) at scales S (k,).

    The uniform-layout tangent of :func:`coilrod.rod.spatial.numpy_core` specialised to
    rotations about z: the segment rotation is psi_i = (0, 0, theta_{i+1} - theta_i), so the
    frames, logarithms and the terms of ``psi x g`` need no series (tested against the
    spatial rod's own blocks to round-off)."""
    from .so3 import about_z, cross, hat, inv_right_jacobian_coefficients
    from .spatial import _sym_term

    K, h, w = twin.K, twin.mesh.h, twin.mesh.w
    k, n = theta.shape
    R = about_z(theta)  # (k, n, 3, 3)
    m = np.einsum("knij,nj->kni", R, twin.mu)
    B = np.broadcast_to(np.asarray(b, float), (k, n, 3))
    delta = np.diff(theta, axis=1)  # (k, n - 1)
    psi = np.zeros((k, n - 1, 3))
    psi[..., 2] = delta
    g = psi * (K / h[:, None])[None]
    cc, _ = inv_right_jacobian_coefficients(np.abs(delta))
    Psi = hat(psi)
    Minv = np.eye(3) + 0.5 * Psi + cc[..., None, None] * (Psi @ Psi)
    MtKM = np.swapaxes(Minv, -1, -2) @ ((K[None, :, None] / h[:, None, None]) * Minv)
    Gm = hat(g)
    N = -0.5 * Gm - cc[..., None, None] * (Gm @ Psi)  # psi || g: the other terms vanish
    MtN = np.swapaxes(Minv, -1, -2) @ N
    Rb = R[:, 1:]
    P = Rb @ (MtKM + 0.5 * (MtN + np.swapaxes(MtN, -1, -2))) @ np.swapaxes(Rb, -1, -2)
    p = np.einsum("knij,knj->kni", Rb, g)
    Sc = np.asarray(S, float)[:, None, None]
    M = -Sc * w[None, :, None] * cross(m, B)
    M[:, 1:] += p
    M[:, :-1] -= p
    A_ab = -P + 0.5 * hat(p)
    diag = np.zeros((k, n, 3, 3))
    diag[:, 1:] += P
    diag[:, :-1] += P
    diag -= Sc[..., None] * w[None, :, None, None] * _sym_term(m, B)
    diag -= 0.5 * hat(M)
    return diag[:, 1:], A_ab[:, 1:]
