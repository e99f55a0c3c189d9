"""Stability of planar states in 3D: the out-of-plane block of the spatial rod's second variation.

The planar rod (:mod:`coilrod.rod.planar`) sees in-plane perturbations only; a state that is
stable among them can buckle out of the plane (twist and bend about the in-plane normal), e.g.
the seed's M(2b) in a field at 255 deg.  A planar state is an exact state of the spatial rod
(:mod:`coilrod.rod.spatial`: its discrete energy restricted to rotations about z is the planar
one), so the full 3D stability of a planar state is the inertia of the spatial rod's second
variation there.

Reflection through the plane maps a planar state in a planar load (``B_z = 0``,
``dB_z/dx = dB_z/dy = 0`` on the plane; curl-free, so ``dB_x/dz = dB_y/dz = 0`` there too) to
itself, so the second variation splits into the even (in-plane: x, y, F_x, F_y and the rotation
about z -- the planar rod's own) and the odd (out-of-plane) subspaces.  :class:`OutOfPlane`
assembles the odd block directly from the planar state, vectorised, in blocks per free node j:

* uniform layout: the world rotations ``(d_x, d_y)`` of node j (2 x 2 blocks);
* mixed layout: ``(x_z, F_z, d_x, d_y)`` -- the node's out-of-plane position, the out-of-plane
  force of the segment before it (the multiplier of its position constraint) and the rotations
  (4 x 4 blocks of the Lagrangian's Hessian, one negative eigenvalue per constraint).

Notes
-----
At a planar state the relative rotation of segment i is ``psi_i = (0, 0, delta_i)``,
``delta_i = theta_{i+1} - theta_i``, and ``J_r(psi)^-1 = I + hat(psi)/2 + c hat(psi)^2`` has the
in-plane block ``a I + b J`` (``b = delta / 2``, ``a = 1 - c delta^2 = b cot b``, ``J`` the
quarter turn),
so the segment's bending block ``P_i = R_{i+1} (M^T K M / h + sym(M^T N)) R_{i+1}^T`` of
:func:`coilrod.rod.spatial.numpy_core` is, in the plane,

    P_i = alpha_i I + [[r_i, q_i], [q_i, -r_i]],
    alpha_i = ((GJ + EI_y)(a^2 + b^2) / 2 + a (1 - a) - b^2) / h_i,
    r_i + i q_i = (GJ - EI_y) / (2 h_i) conj(a + i b)^2 exp(2 i theta_{i+1}),

(stiffnesses over EI_z).  The node blocks add the magnetic term ``-c w (m b^T + b m^T)/2 +
c w (m . b) I``, the internal forces' ``-sym(t, h F / 2)`` of both adjacent segments and
``-hat(M)/2`` (``M`` the moment residual, zero at an equilibrium); the blocks above the
diagonal are ``-P_i + hat(p_i)/2`` with ``p_i = delta_i / h_i e_z``.  The mixed layout adds the
field's curvature ``-c w L^2 m . d^2 b / dz^2`` on ``x_z``, its coupling
``c w L dB_z/dz (-m_y, m_x)`` to the rotations and the constraints' rows
``x_z,j - x_z,j-1 - h (t_z,j-1 + t_z,j) / 2`` (``dt_z = d_x t_y - d_y t_x``).

All quantities are non-dimensional like the rods' (eigenvalues in EI_z / L^3 per unit length).
The count is exact (block LDL^T, :mod:`coilrod.rod._inertia`); tested against the spatial rod's
own blocks and against closed-form out-of-plane buckling loads.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_banded
from scipy.linalg.lapack import dpbtrf

from ..path.protocol import Linearization
from ._spectrum import closest_to_zero, lowest_from_inverse

__all__ = ["OutOfPlane"]

#: Free rotational unknowns (two per free node) up to which the odd block's eigenvalue is
#: found from its dense inverse (banded solves), beyond by ARPACK: 200 free nodes, where the
#: spatial rod switches too.
_DENSE = 400


class OutOfPlane:
    """The out-of-plane (odd) block of the 3D second variation at the states of a planar rod.

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
        self.uniform = planar.uniform
        self.nb = 2 if self.uniform else 4  # unknowns per free node in the odd block
        if self.uniform:
            self._b = planar.clamp_field  # (the planar rod's: evaluated once)

    # -- states -----------------------------------------------------------------------------
    def spatial_states(self, U: np.ndarray) -> np.ndarray:
        """States of the spatial rod's layout (k, n nv) (nv = 3 uniform, 9 mixed) of planar
        states (k, planar.size): rotations ``(0, 0, theta - theta_0)`` about z, positions
        ``(x, y, 0)``, forces ``(F_x, F_y, 0)`` (to compare with
        :class:`~coilrod.rod.spatial.SpatialRod`)."""
        U = np.atleast_2d(U)
        k, n = U.shape[0], self.planar.n
        out = np.zeros((k, n, 3 if self.uniform else 9))
        if self.uniform:
            out[:, :, 2] = U - self.theta0
        else:
            v = U.reshape(k, n, 5)
            out[:, :, 0:2] = v[:, :, 0:2]
            out[:, :, 5] = v[:, :, 2] - self.theta0
            out[:, :, 6:8] = v[:, :, 3:5]
        return out.reshape(k, -1)

    # -- the odd block ----------------------------------------------------------------------
    def _node_fields(self, lin: Linearization, fields, k: int):
        """(B_x, B_y) T at the free nodes ((k, n - 1) each; uniform layout: scalars or
        (k, 1)); mixed layout also dB_z/dz (k, n) T/m and
        ``m . d^2 b / dz^2`` needs the hessian ``H[:, :, 0:2, 2, 2]`` (k, n, 2) T/m^2 (zeros for
        a linear field)."""
        n = self.planar.n
        if self.uniform:  # (bx, by): scalars, or (k, 1) arrays for one field per member
            if fields is None:
                return (self._b[0], self._b[1]), None, None
            b = np.asarray(fields, float).reshape(-1, 3)
            return (b[:, 0:1], b[:, 1:2]), None, None
        B, G, H = self._mixed_fields(lin, k)
        B = B.reshape(k, n, 3)
        B = (B[:, 1:, 0], B[:, 1:, 1])
        Gzz = G.reshape(k, n, 3, 3)[..., 2, 2]
        Hzz = None if H is None else H.reshape(k, n, 3, 3, 3)[..., 0:2, 2, 2]
        return B, Gzz, Hzz

    def _mixed_fields(self, lin: Linearization, k: int):
        """B, G and H (None for a linear field) at the nodes of the states of ``lin`` (mixed
        layout): the linearization's own, or evaluated here where it has no hessian."""
        P, n = self.planar, self.planar.n
        fv = getattr(lin, "field_values", None)
        H = getattr(lin, "field_hessian", None)
        if fv is None or (H is None and not P.linear):  # evaluate here (hessian included)
            x = np.atleast_2d(lin.u).reshape(k, n, 5)[:, :, 0:2]
            if fv is not None and hasattr(P.field, "filaments"):
                # coaxial coils: their hessian pass alone gives the combined pass's numbers
                # (and B, G are the linearization's): a third less of the kernel's work
                return fv[0], fv[1], P._hessian_by_member(x)
            return P._field_by_member(x, True)
        return fv[0], fv[1], H

    def odd_blocks(self, lin: Linearization, fields=None, band: bool = False):
        """Diagonal (k, n - 1, nb, nb) and upper (k, n - 2, nb, nb) blocks of the
        out-of-plane block of the 3D second variation at the planar states of ``lin``, free
        nodes only (nb = 2: ``(d_x, d_y)``; mixed layout nb = 4: ``(x_z, F_z, d_x, d_y)``);
        ``fields`` (k, 3) T: a uniform field per member (a fan of field directions).
        ``band`` (uniform layout): instead, the symmetric part in LAPACK's upper band storage
        (k, 4, 2 (n - 1)) of the unknowns ``(d_x1, d_y1, d_x2, ...)``."""
        P = self.planar
        U = np.atleast_2d(lin.u)
        k, n = U.shape[0], P.n
        S = np.asarray(lin.scale, float)
        S = S[:, None] if S.shape == (k,) else np.broadcast_to(S, (k,))[:, None]
        h, w, inv_h = P.mesh.h, P.mesh.w, P._inv_h
        if not self.uniform:
            from . import _compiled as pc

            if pc.odd_blocks_pays(k, n):  # the compiled assembly (ski rental)
                B, G, H = self._mixed_fields(lin, k)
                D = np.zeros((k, n - 1, 4, 4))
                E = np.zeros((k, max(n - 2, 0), 4, 4))
                k1, k2 = self.stiffness[0], self.stiffness[1]
                pc.odd_blocks_mixed(U, S[:, 0], P.mu, h, w, inv_h, k1, k2, P.L, B, G, H, D, E)
                return D, E
        th = P.theta(U)
        thf = th[:, 1:]  # free nodes: everything below is per free node or per segment
        c, s = np.cos(thf), np.sin(thf)
        mu = P.mu[1:]
        mx = c * mu[:, 0] - s * mu[:, 1]
        my = s * mu[:, 0] + c * mu[:, 1]
        (bx, by), Gzz, Hzz = self._node_fields(lin, fields, k)
        # bending blocks of the segments (module notes); a = 1 - c delta^2 = b cot b
        b = 0.5 * (thf - th[:, :-1])
        sb = np.sin(b)
        a = np.divide(b * np.cos(b), sb, out=np.ones_like(b), where=sb != 0.0)
        k1, k2 = self.stiffness[0], self.stiffness[1]
        aa, bb = a * a, b * b
        alpha = (0.5 * (k1 + k2) * (aa + bb) + a - aa - bb) * inv_h
        zr, zi = aa - bb, -2.0 * a * b
        c2, s2 = c * c - s * s, 2.0 * c * s  # of 2 theta_{i+1}
        fac = 0.5 * (k1 - k2) * inv_h
        r = fac * (zr * c2 - zi * s2)
        q = fac * (zr * s2 + zi * c2)
        pz = 2.0 * b * inv_h
        Ap, Am = alpha + r, alpha - r
        # free node j: segments j - 1 and j (the last node has only the first), magnetic
        # term and the moment residual about z
        Sw = S * w[1:]
        dxx = Sw * (my * by) + Ap
        dyy = Sw * (mx * bx) + Am
        dxy = q - 0.5 * Sw * (mx * by + my * bx)
        dxx[:, :-1] += Ap[:, 1:]
        dyy[:, :-1] += Am[:, 1:]
        dxy[:, :-1] += q[:, 1:]
        if band and self.uniform:  # symmetric part, LAPACK upper band storage (kd = 3)
            ab = np.zeros((k, 4, 2 * (n - 1)))  # of (d_x1, d_y1, d_x2, ...)
            ab[:, 3, 0::2], ab[:, 3, 1::2], ab[:, 2, 1::2] = dxx, dyy, dxy
            ab[:, 2, 2::2] = (0.5 * pz - q)[:, 1:]  # (y_j, x_j+1)
            ab[:, 1, 2::2], ab[:, 1, 3::2] = -Ap[:, 1:], -Am[:, 1:]
            ab[:, 0, 3::2] = (-q - 0.5 * pz)[:, 1:]  # (x_j, y_j+1)
            return ab
        Mz = pz - Sw * (mx * by - my * bx)  # (the antisymmetric part: not in the band)
        Mz[:, :-1] -= pz[:, 1:]
        if self.uniform:
            D = np.stack([dxx, dxy + 0.5 * Mz, dxy - 0.5 * Mz, dyy], axis=-1)
            E = np.stack([-Ap, -q - 0.5 * pz, -q + 0.5 * pz, -Am], axis=-1)[:, 1:]
            return D.reshape(k, n - 1, 2, 2), E.reshape(k, n - 2, 2, 2)
        # internal forces h F / 2 of the segments before and after each free node
        V = U.reshape(k, n, 5)
        fx, fy = 0.5 * h * V[:, :-1, 3], 0.5 * h * V[:, :-1, 4]
        fx[:, :-1] += fx[:, 1:]
        fy[:, :-1] += fy[:, 1:]
        Mz -= c * fy - s * fx
        dxx += s * fy
        dyy += c * fx
        dxy -= 0.5 * (c * fy + s * fx)
        D = np.zeros((k, n - 1, 4, 4))
        E = np.zeros((k, max(n - 2, 0), 4, 4))
        D[:, :, 2, 2] = dxx
        D[:, :, 3, 3] = dyy
        D[:, :, 2, 3] = dxy + 0.5 * Mz
        D[:, :, 3, 2] = dxy - 0.5 * Mz
        E[:, :, 2, 2] = -Ap[:, 1:]
        E[:, :, 3, 3] = -Am[:, 1:]
        E[:, :, 2, 3] = -q[:, 1:] - 0.5 * pz[:, 1:]
        E[:, :, 3, 2] = -q[:, 1:] + 0.5 * pz[:, 1:]
        L = P.L
        cwL = Sw * L
        if Hzz is not None:
            D[:, :, 0, 0] = -cwL * L * (mx * Hzz[:, 1:, 0] + my * Hzz[:, 1:, 1])
        D[:, :, 0, 1] = D[:, :, 1, 0] = 1.0
        D[:, :, 0, 2] = D[:, :, 2, 0] = -cwL * Gzz[:, 1:] * my
        D[:, :, 0, 3] = D[:, :, 3, 0] = cwL * Gzz[:, 1:] * mx
        hh = 0.5 * h
        D[:, :, 1, 2] = D[:, :, 2, 1] = -hh * s
        D[:, :, 1, 3] = D[:, :, 3, 1] = hh * c
        E[:, :, 0, 1] = -1.0
        E[:, :, 2, 1] = -hh[1:] * s[:, :-1]
        E[:, :, 3, 1] = hh[1:] * c[:, :-1]
        return D, E

    def odd_count(self, lin: Linearization, fields=None) -> np.ndarray:
        """Negative eigenvalues of the out-of-plane block of the 3D second variation at the
        planar states of ``lin``, shape (k,) int (-1 where not finite)."""
        from ._inertia import block_tridiagonal_inertia

        known = getattr(lin, "odd_definite", None) if self.uniform and fields is None else None
        if known is not None and known.all():  # (the common case: no count needed)
            return np.zeros(known.shape[0], dtype=int)
        with np.errstate(all="ignore"):
            if self.uniform:  # a Cholesky factorisation proves a stable state at once
                # (done by the compiled corrector for the states it returns)
                if known is not None:
                    out = np.where(known, 0, -1)
                else:
                    out = _positive_definite(self.odd_blocks(lin, fields, band=True)) - 1
                todo = np.flatnonzero(out < 0)
                if todo.size == 0:
                    return out
                lin = _members(lin, todo, fields)
                fields = None if fields is None else np.asarray(fields)[todo]
            D, E = self.odd_blocks(lin, fields)
        counts, _ = block_tridiagonal_inertia(D, E)
        if self.uniform:
            out[todo] = counts
            return out
        # one negative per z-position constraint of a free node
        return np.where(counts >= 0, counts - (self.planar.n - 1), counts)

    def lowest(self, lin: Linearization, fields=None, counts=None) -> np.ndarray:
        """Smallest eigenvalue of the out-of-plane block's ``H z = mu W z`` (W: the trapezoid
        weight of each rotation; positions and forces eliminated) at the planar states of
        ``lin``, shape (k,) (NaN where not finite): with the planar rod's in-plane figure,
        the smallest of the two is the 3D one (the subspaces decouple).  ``counts`` (k,): the
        block's negative eigenvalues (:meth:`odd_count`), which sign the eigenvalue closest to
        zero of a large block (ARPACK)."""
        with np.errstate(all="ignore"):
            D, E = self.odd_blocks(lin, fields)
        k, nf, nb = D.shape[0], D.shape[1], self.nb
        rot = np.arange(nf)[:, None] * nb + (nb - 2) + np.arange(2)  # rows of (d_x, d_y)
        rot = rot.ravel()
        sq = np.repeat(np.sqrt(self.planar.mesh.w[1:]), 2)
        out = np.full(k, np.nan)
        i = np.arange(nf)
        for j in range(k):
            if not (np.isfinite(D[j]).all() and np.isfinite(E[j]).all()):
                continue
            if rot.size > _DENSE:
                sign = -1.0 if counts is not None and counts[j] > 0 else 1.0
                out[j] = _lowest_sparse(D[j], E[j], rot, sq, sign)
                continue
            A = np.zeros((nf, nf, nb, nb))
            A[i, i] = D[j]
            A[i[:-1], i[1:]] = E[j]
            A[i[1:], i[:-1]] = np.swapaxes(E[j], -1, -2)
            A = A.transpose(0, 2, 1, 3).reshape(nf * nb, nf * nb)
            rhs = np.zeros((nf * nb, rot.size))
            rhs[rot, np.arange(rot.size)] = sq
            bw = 2 * nb - 1  # bandwidth of a block tridiagonal matrix of nb x nb blocks
            ab = np.zeros((2 * bw + 1, nf * nb))
            for off in range(-bw, bw + 1):  # ab[bw + r - c, c] = A[r, c]
                diag = np.diagonal(A, off)
                ab[bw - off, max(off, 0) : max(off, 0) + diag.size] = diag
            try:
                Sm = sq[:, None] * solve_banded((bw, bw), ab, rhs, check_finite=False)[rot]
            except np.linalg.LinAlgError:
                continue
            out[j] = lowest_from_inverse(0.5 * (Sm + Sm.T))
        return out


def _lowest_sparse(D, E, rot, sq, sign) -> float:
    """:meth:`OutOfPlane.lowest` of one large block, diagonal blocks D (nf, nb, nb) and upper
    E (nf - 1, nb, nb), by ARPACK with a sparse LU."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import splu

    nf, nb = D.shape[0], D.shape[1]
    i = np.arange(nf)
    R = np.concatenate([i, i[:-1], i[1:]])  # block rows and columns: diagonal, upper, lower
    C = np.concatenate([i, i[1:], i[:-1]])
    data = np.concatenate([D, E, np.swapaxes(E, -1, -2)])
    a = np.arange(nb)
    rows = np.broadcast_to(R[:, None, None] * nb + a[None, :, None], data.shape)
    cols = np.broadcast_to(C[:, None, None] * nb + a[None, None, :], data.shape)
    size = nf * nb
    A = coo_matrix((data.ravel(), (rows.ravel(), cols.ravel())), shape=(size, size))
    lu = splu(A.tocsc())
    rhs = np.zeros(size)

    def matvec(v):
        rhs[:] = 0.0
        rhs[rot] = sq * np.ravel(v)
        return sq * lu.solve(rhs)[rot]

    return closest_to_zero(matvec, rot.size, sign)


def _members(lin: Linearization, rows: np.ndarray, fields) -> Linearization:
    """The states and scales of members ``rows`` of ``lin`` (what :meth:`OutOfPlane.odd_blocks`
    reads in the uniform layout)."""
    k = np.atleast_2d(lin.u).shape[0]
    S = np.broadcast_to(np.asarray(lin.scale, float), (k,))
    return Linearization(u=np.atleast_2d(lin.u)[rows], scale=S[rows], residual=None, ok=None)


def _positive_definite(ab: np.ndarray) -> np.ndarray:
    """1 for each member of a stack of symmetric band matrices (k, kd + 1, m) (LAPACK upper
    band storage, no coupling into a member's first kd columns) that a Cholesky factorisation
    proves positive definite, else 0, shape (k,).  The members are factorised as one block
    diagonal band matrix (one LAPACK call while they are all positive definite; after a
    failing member, the factorisation restarts behind it)."""
    k, rows, m = ab.shape
    out = np.zeros(k, dtype=int)
    finite = np.isfinite(ab).all(axis=(1, 2))
    if not finite.all():  # (a NaN can pass LAPACK's pivot test): a stand-in, counted apart
        ab = ab.copy()
        ab[~finite] = 0.0
        ab[~finite, -1] = 1.0
    flat = ab[0] if k == 1 else np.ascontiguousarray(np.moveaxis(ab, 0, 1).reshape(rows, k * m))
    start = 0
    while start < k:
        _, info = dpbtrf(flat[:, start * m :], lower=0)
        if info == 0:
            out[start:] = 1
            break
        fail = start + (info - 1) // m
        out[start:fail] = 1
        start = fail + 1
    out[~finite] = 0
    return out
