"""Vectorised assembly of energy, residual and consistent tangent on scikit-fem bases.

scikit-fem supplies the meshes, the shape functions and their gradients at the quadrature
points (once); the element kernels are einsum/matmul contractions over quadrature points and
element dofs, and the global sparse matrix reuses one sparsity pattern (its data array is
refilled with a single ``bincount``).  Dofs are interleaved: ``dof = node * dim + component``.
Clamped dofs (``x = 0`` face) are eliminated: vectors and matrices live on the free dofs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from . import magnetic as mag
from .linalg import SymmetricFactorizer
from .material import (
    inverse_and_determinant,
    isochoric,
    jacobian_derivatives,
    neo_hookean,
    plane_stress,
)

__all__ = ["Assembler", "Evaluation", "INTORDER"]

#: Gauss rule (exact polynomial degree) per element order: 2 and 3 points per direction.
INTORDER = {1: 3, 2: 5}


def _element(dim: int, order: int):
    from skfem import ElementHex1, ElementHex2, ElementQuad1, ElementQuad2

    return {(2, 1): ElementQuad1, (2, 2): ElementQuad2, (3, 1): ElementHex1, (3, 2): ElementHex2}[
        (dim, order)
    ]()


@dataclass
class Evaluation:
    """One evaluation of the discrete problem at a displacement ``u`` and load ``scale``.

    Attributes
    ----------
    ok : bool
        False if some quadrature point has ``det F <= 0`` or the field is not finite there
        (nothing else is then computed).
    min_jacobian : float
        Smallest ``det F`` over the quadrature points.
    energy : float
        Total potential energy, J.
    residual : ndarray, shape (n_free,)
        Out-of-balance force on the free dofs, N (zero at equilibrium).
    load_rate : ndarray, shape (n_free,)
        ``d residual / d scale`` at fixed ``u`` (the magnetic residual per unit scale), N.
    tangent : scipy.sparse.csr_matrix or None
        ``d residual / d u`` on the free dofs, N/m.
    internal_norm : float
        Norm of the elastic internal force (a force scale for tolerances), N.
    constraint_norm : float
        Mixed formulation: largest element mean of ``|J - 1 - p/K|`` (0 otherwise).
    """

    ok: bool
    min_jacobian: float
    energy: float = np.nan
    residual: np.ndarray | None = None
    load_rate: np.ndarray | None = None
    tangent: sp.csr_matrix | None = None
    internal_norm: float = np.nan
    constraint_norm: float = 0.0
    constraint_residual: np.ndarray | None = None
    constraint_matrix: np.ndarray | None = None


class Assembler:
    """Discretised hard-magnetic neo-Hookean body on a scikit-fem mesh.

    Parameters
    ----------
    mesh : skfem.Mesh
        Reference mesh (MeshQuad1 in 2D; MeshHex1 or MeshHex2 in 3D), clamped at ``x = 0``.
    order : int
        Displacement element order, 1 or 2.
    rod : coilrod.Rod
        Supplies the magnetization profile (evaluated at each quadrature point's x = arc
        length).
    field : coils.Field
        Applied field at load scale 1.
    shear, bulk : float
        Neo-Hookean G and K, Pa.
    plane : {"stress", "strain"}
        2D assumption (ignored in 3D).
    mixed : bool
        Use the mixed displacement/pressure formulation (discontinuous pressure P1 for
        order 2, P0 for order 1, condensed element by element); ignored for plane stress.
    """

    def __init__(
        self,
        mesh,
        order: int,
        rod,
        field,
        shear: float,
        bulk: float,
        plane: str = "stress",
        mixed: bool = True,
    ):
        from skfem import Basis

        self.mesh = mesh
        self.dim = dim = mesh.p.shape[0]
        self.order = order
        self.field = field
        self.shear, self.bulk = float(shear), float(bulk)
        self.plane_stress = dim == 2 and plane == "stress"
        self.mixed = bool(mixed) and not self.plane_stress
        self.length = float(rod.length)
        self.rod = rod

        elem = _element(dim, order)
        basis = Basis(mesh, elem, intorder=INTORDER[order])
        self.basis = basis
        self._quadrature(basis)
        self._magnetization(rod)
        self._clamp_and_tip(mesh, basis, elem, order)
        self._pressure_basis(order)
        self._lam3 = None
        # factorisations: levels of the block Cholesky grow from the clamped end
        x_free = self.nodes[0][self.free // dim]
        self._factorizer = SymmetricFactorizer(
            start=np.flatnonzero(x_free <= x_free.min() + 1e-9 * self.length)
        )

    def _quadrature(self, basis) -> None:
        """Shape functions, their gradients and weights at the quadrature points, and the
        layouts of the batched kernels."""
        dim = self.dim
        nb = len(basis.basis)
        self.nel, self.nq, self.nb = self.mesh.t.shape[1], basis.X.shape[1], nb
        self.n_nodes = basis.N
        self.ndof = basis.N * dim
        # shape functions at quadrature points: N (e, q, a), dN (e, q, a, J)
        self.N = np.ascontiguousarray(
            np.stack([np.asarray(basis.basis[a][0]) for a in range(nb)]).transpose(1, 2, 0)
        )
        self.dN = np.ascontiguousarray(
            np.stack([basis.basis[a][0].grad for a in range(nb)]).transpose(2, 3, 0, 1)
        )
        self.w = np.asarray(basis.dx)
        nq = basis.X.shape[1]
        # layouts for batched matmul: (e, (q,J), a), (e, a, (q,J)), (e, a, q)
        self._dN_qJ_a = np.ascontiguousarray(
            self.dN.transpose(0, 1, 3, 2).reshape(self.nel, nq * dim, nb)
        )
        self._dN_a_qJ = np.ascontiguousarray(
            self.dN.transpose(0, 2, 1, 3).reshape(self.nel, nb, nq * dim)
        )
        self._N_a_q = np.ascontiguousarray(self.N.transpose(0, 2, 1))
        self.X = np.ascontiguousarray(np.asarray(basis.global_coordinates()).transpose(1, 2, 0))
        self.nodes = np.asarray(basis.doflocs)

    def _magnetization(self, rod) -> None:
        """The magnetization ``M`` (e, q, dim), A/m, in the reference configuration at the
        quadrature points."""
        dim = self.dim
        # magnetization in the reference configuration at the quadrature points (e, q, dim):
        # |M| (cos th cos psi, sin th cos psi, sin psi) in 3D, the planar (cos th, sin th) in 2D
        if dim == 2:
            rod.magnetization.check_planar("2D FEM")
        s = self.X[..., 0]
        mg = rod.magnetization.magnitude(s)
        an = rod.magnetization.angle(s)
        M = np.zeros(s.shape + (dim,))
        if dim == 3 and not rod.magnetization.is_planar:
            el = rod.magnetization.elevation(s)
            M[..., 2] = mg * np.sin(el)
            mg = mg * np.cos(el)
        M[..., 0], M[..., 1] = mg * np.cos(an), mg * np.sin(an)
        self.M = M

    def _clamp_and_tip(self, mesh, basis, elem, order) -> None:
        """Element dofs, the clamped dofs at x = 0 (and the sparsity pattern of the free ones),
        and the tip: the centroid of the free end face x = L."""
        from skfem import FacetBasis

        dim = self.dim
        # vector dofs of each element, (e, a*dim + i)
        nodes_e = basis.element_dofs.T
        self.edofs = (nodes_e[:, :, None] * dim + np.arange(dim)).reshape(self.nel, self.nb * dim)
        # clamp at x = 0
        tol = 1e-9 * self.length
        clamp_facets = mesh.facets_satisfying(lambda x: np.abs(x[0]) < tol)
        if len(clamp_facets) == 0:
            raise ValueError("mesh has no facet on the clamped face x = 0")
        clamp_nodes = basis.get_dofs(facets=clamp_facets).all()
        fixed = np.zeros(self.ndof, bool)
        fixed[(clamp_nodes[:, None] * dim + np.arange(dim)).ravel()] = True
        self.free = np.flatnonzero(~fixed)
        self._build_pattern(fixed)
        # tip: centroid of the free end face, tip = X_c + sum_n c_n u_n
        end_facets = mesh.facets_satisfying(lambda x: np.abs(x[0] - self.length) < tol)
        if len(end_facets) == 0:
            raise ValueError("mesh has no facet on the free end x = L")
        fb = FacetBasis(mesh, elem, facets=end_facets, intorder=INTORDER[order])
        area = float(fb.dx.sum())
        c = np.zeros(basis.N)
        for a in range(len(fb.basis)):
            np.add.at(c, fb.element_dofs[a], (np.asarray(fb.basis[a][0]) * fb.dx).sum(axis=1))
        self.tip_weights = c / area
        Xf = np.asarray(fb.global_coordinates())
        self.tip_reference = np.einsum("dfq,fq->d", Xf, fb.dx) / area

    def _pressure_basis(self, order) -> None:
        """Mixed formulation: the discontinuous pressure basis ``phi`` (e, q, m) and its mass
        matrices ``Mp``, ``Minv`` (e, m, m)."""
        dim = self.dim
        # mixed formulation: discontinuous pressure basis phi (e, q, m), Minv (e, m, m);
        # linear in the physical (unmapped) coordinates for order 2 -- the stable, optimal
        # Q2-P1 pair also on curved and distorted elements -- and constant for order 1
        if self.mixed:
            one = np.ones((self.nel, self.nq, 1))
            if order == 2:
                vol = self.w.sum(axis=1)
                centre = np.einsum("eq,eqd->ed", self.w, self.X) / vol[:, None]
                size = vol ** (1.0 / dim)
                rel = (self.X - centre[:, None, :]) / size[:, None, None]
                self.phi = np.concatenate([one, rel], axis=2)
            else:
                self.phi = one
            self.Mp = np.einsum("eq,eqi,eqj->eij", self.w, self.phi, self.phi)
            self.Minv = np.linalg.inv(self.Mp)
            self.volumes = self.w.sum(axis=1)

    # -- sparsity ---------------------------------------------------------------------------
    def _build_pattern(self, fixed: np.ndarray) -> None:
        red = np.full(self.ndof, -1)
        red[~fixed] = np.arange(int((~fixed).sum()))
        self.nfree = int((~fixed).sum())
        re = red[self.edofs]  # (e, n)
        rows = np.broadcast_to(re[:, :, None], (self.nel,) + (re.shape[1],) * 2).ravel()
        cols = np.broadcast_to(re[:, None, :], (self.nel,) + (re.shape[1],) * 2).ravel()
        keep = np.flatnonzero((rows >= 0) & (cols >= 0))
        key = rows[keep].astype(np.int64) * self.nfree + cols[keep]
        uniq, inv = np.unique(key, return_inverse=True)
        r, c = np.divmod(uniq, self.nfree)
        self._indices = c.astype(np.int32)
        self._indptr = np.concatenate(
            [[0], np.cumsum(np.bincount(r, minlength=self.nfree))]
        ).astype(np.int32)
        self.nnz = uniq.size
        # scatter matrix: tangent data = S @ Ke.ravel() (row = stored entry, columns = the
        # element-matrix entries that add up to it, in element order)
        self._scatter = sp.csr_matrix(
            (np.ones(keep.size), (inv.ravel(), keep)), shape=(self.nnz, rows.size)
        )
        self._scatter.sort_indices()

    def _sparse(self, Ke: np.ndarray) -> sp.csr_matrix:
        """Global tangent on the free dofs from element matrices ``Ke`` (e, nb*d, nb*d)."""
        data = self._scatter @ Ke.reshape(-1)
        return sp.csr_matrix((data, self._indices, self._indptr), shape=(self.nfree,) * 2)

    def _vector(self, re: np.ndarray) -> np.ndarray:
        out = np.bincount(self.edofs.ravel(), weights=re.ravel(), minlength=self.ndof)
        return out[self.free]

    # -- state vector -----------------------------------------------------------------------
    # z = [free displacement dofs (n_free), pressure coefficients (n_el * n_phi) if mixed]
    @property
    def size(self) -> int:
        """Length of the state vector ``z`` (free displacements, then element pressures)."""
        return self.nfree + (self.phi.shape[2] * self.nel if self.mixed else 0)

    def full(self, z: np.ndarray) -> np.ndarray:
        """Full displacement dof vector (clamped dofs zero), shape (ndof,), m."""
        u = np.zeros(self.ndof)
        u[self.free] = z[: self.nfree]
        return u

    def nodal(self, z: np.ndarray) -> np.ndarray:
        """Displacement per node, shape (dim, n_nodes), m."""
        return self.full(z).reshape(-1, self.dim).T

    def pressure(self, z: np.ndarray) -> np.ndarray | None:
        """Pressure at the quadrature points, shape (n_el, n_q), Pa (None if not mixed)."""
        if not self.mixed:
            return None
        return np.einsum("ei,eqi->eq", z[self.nfree :].reshape(self.nel, -1), self.phi)

    def with_consistent_pressure(self, z: np.ndarray) -> np.ndarray:
        """``z`` with the element pressures that satisfy their equations, ``a = K Minv g``."""
        if not self.mixed:
            return z
        d, nel, nq, nb = self.dim, self.nel, self.nq, self.nb
        ue = self.full(z)[self.edofs].reshape(nel, nb, d)
        F = np.matmul(self._dN_qJ_a, ue).reshape(nel, nq, d, d).transpose(0, 1, 3, 2) + np.eye(d)
        J = np.linalg.det(F)  # plane strain: F33 = 1
        g = np.einsum("eq,eqi->ei", self.w * (J - 1.0), self.phi)
        a = self.bulk * np.einsum("eij,ej->ei", self.Minv, g)
        return np.concatenate([z[: self.nfree], a.ravel()])

    def tip(self, z: np.ndarray) -> np.ndarray:
        """Centroid of the deformed free end face, shape (3,), m (z = 0 in 2D)."""
        t = self.tip_reference + self.nodal(z) @ self.tip_weights
        return np.concatenate([t, np.zeros(3 - self.dim)])

    def increment_norm(self, dz: np.ndarray) -> float:
        """Largest displacement component of an increment ``dz``, m."""
        return float(np.max(np.abs(dz[: self.nfree]))) if self.nfree else 0.0

    def field_at(self, x: np.ndarray, need_hessian: bool):
        """Field at points ``x`` (n, dim): B (n, dim), G (n, dim, dim) and H (n, d, d, d).

        G is None for a uniform field, H for a uniform or linear one (or without
        ``need_hessian``); a coil field's three come from one compiled pass."""
        d = self.dim
        pts = x if d == 3 else np.concatenate([x, np.zeros((x.shape[0], 1))], axis=1)
        f = self.field
        G = Hs = None
        if f.uniform:
            B = f.B(pts)
        elif need_hessian and not f.linear:
            B, G, Hs = f.B_gradient_hessian(pts)
            G, Hs = G[:, :d, :d], Hs[:, :d, :d, :d]
        else:
            B, G = f.B_and_gradient(pts)
            G = G[:, :d, :d]
        return B[:, :d], G, Hs

    # -- linear algebra of a Newton step ----------------------------------------------------
    def factorize(self, ev: Evaluation):
        """Factorisation of the (condensed, symmetric) tangent of ``ev``.

        Returns a :class:`coilrod.fem.linalg.Factorization`: ``factor.solve(b)`` for ``b`` of
        shape (n_free,) or (n_free, k); :func:`~coilrod.fem.linalg.determinant_sign` and
        :func:`~coilrod.fem.linalg.negative_eigenvalues` read its sign and inertia.  The
        fill-reducing ordering of the fixed sparsity pattern is computed at the first call
        and reused.
        """
        return self._factorizer(ev.tangent)

    def _recover(self, ev: Evaluation, du: np.ndarray, ra) -> np.ndarray:
        """Append the element pressure increments ``K Minv (ra + B du)`` to ``du``."""
        if not self.mixed:
            return du
        due = self.full(du)[self.edofs]  # (e, nb*d)
        rhs = np.einsum("eia,ea->ei", ev.constraint_matrix, due)
        if ra is not None:
            rhs = rhs + ra
        da = self.bulk * np.einsum("eij,ej->ei", self.Minv, rhs)
        return np.concatenate([du, da.ravel()])

    def newton_step(self, ev: Evaluation, lu) -> np.ndarray:
        """Newton increment ``dz`` of the state from ``ev`` with the factorisation ``lu``."""
        du = -lu.solve(ev.residual)
        return self._recover(ev, du, ev.constraint_residual)

    def load_tangent(self, ev: Evaluation, lu) -> np.ndarray:
        """``dz/ds`` along the equilibrium path (tangent predictor), same shape as ``z``."""
        du = -lu.solve(ev.load_rate)
        return self._recover(ev, du, None)

    # -- the kernel -------------------------------------------------------------------------
    def evaluate(self, z: np.ndarray, scale: float, tangent: bool = True) -> Evaluation:
        """Energy, residual, load rate and (optionally) tangent at state ``z`` and ``scale``.

        For the mixed formulation the residual is the condensed one,
        ``R_u + K B^T Minv R_p`` with ``R_p = int phi (J - 1) - Minv^-1 a / K`` the element
        pressure equations, and the tangent is ``K_uu + K B^T Minv B``.
        """
        d, nel, nq, nb = self.dim, self.nel, self.nq, self.nb
        u = self.full(z)
        ue = u[self.edofs].reshape(nel, nb, d)
        F = np.matmul(self._dN_qJ_a, ue).reshape(nel, nq, d, d).transpose(0, 1, 3, 2) + np.eye(d)
        Ff = F.reshape(-1, d, d)
        if d == 3:
            Fi3, J = inverse_and_determinant(Ff)
        else:
            Fi3, J = None, Ff[:, 0, 0] * Ff[:, 1, 1] - Ff[:, 0, 1] * Ff[:, 1, 0]
        minJ = float(J.min()) if np.all(np.isfinite(J)) else -np.inf
        if not minJ > 0:
            return Evaluation(ok=False, min_jacobian=minJ)
        # magnetic field at the deformed quadrature points
        x = (self.X + np.matmul(self.N, ue)).reshape(-1, d)
        B, G, Hs = self.field_at(x, tangent)
        if not (
            np.all(np.isfinite(B))
            and (G is None or np.all(np.isfinite(G)))
            and (Hs is None or np.all(np.isfinite(Hs)))
        ):
            return Evaluation(ok=False, min_jacobian=minJ)
        w = self.w.reshape(-1)
        Mf = self.M.reshape(-1, d)
        ev = Evaluation(ok=True, min_jacobian=minJ)
        energy, P, A, condensed = self._elastic(Ff, Fi3, J, z, tangent, ev)
        # elastic and magnetic (per unit scale) stresses tested with grad(du) in one matmul
        Pm = mag.magnetic_stress(Mf, B)
        PP = np.concatenate([P, Pm], axis=1) * w[:, None, None]  # (n, 2d, d): [i or d+i, J]
        PP = PP.reshape(nel, nq, 2 * d, d).transpose(0, 1, 3, 2).reshape(nel, nq * d, 2 * d)
        rr = np.matmul(self._dN_a_qJ, PP)  # (e, a, 2d)
        r_el, r_m = rr[:, :, :d], rr[:, :, d:]
        if G is not None:
            f = mag.body_force(Ff, Mf, G).reshape(nel, nq, d) * self.w[:, :, None]
            r_m = r_m - np.matmul(self._N_a_q, f)
        energy += scale * float(w @ mag.magnetic_energy(Ff, Mf, B))
        rel = self._vector(r_el)
        rm = self._vector(r_m)
        ev.energy = energy
        ev.internal_norm = float(np.linalg.norm(rel))
        ev.residual = rel + scale * rm
        if condensed is not None:
            ev.residual += self._vector(condensed[0])
        ev.load_rate = rm
        if tangent:
            ev.tangent = self._tangent(A, Ff, Mf, G, Hs, scale, condensed)
        return ev

    def _elastic(self, Ff, Fi3, J, z, tangent: bool, ev: Evaluation):
        """Elastic energy (J), first Piola-Kirchhoff stress P (n, d, d) and its tangent A (a
        dense (n, d, d, d, d) array for plane stress, else a DyadicTangent; None without
        ``tangent``) of the deformation gradients ``Ff`` (n, d, d) with determinants ``J``
        (``Fi3`` their inverses in 3D); for the mixed formulation also the condensation
        (residual term, B, K Minv B), else None, and ``ev``'s constraint fields."""
        d = self.dim
        w = self.w.reshape(-1)
        if self.plane_stress:
            lam0 = self._lam3 if self._lam3 is not None and self._lam3.size == J.size else None
            W, P, A, self._lam3 = plane_stress(Ff, self.shear, self.bulk, lam0, tangent)
            return float(w @ W), P, A, None
        if d == 3:
            F3, inv = Ff, (Fi3, J)
        else:  # plane strain: F33 = 1
            F3 = np.pad(Ff, ((0, 0), (0, 1), (0, 1)))
            F3[:, 2, 2] = 1.0
            Fi3 = np.zeros_like(F3)
            Fi3[:, 0, 0], Fi3[:, 1, 1] = Ff[:, 1, 1] / J, Ff[:, 0, 0] / J
            Fi3[:, 0, 1], Fi3[:, 1, 0] = -Ff[:, 0, 1] / J, -Ff[:, 1, 0] / J
            Fi3[:, 2, 2] = 1.0
            inv = (Fi3, J)
        if not self.mixed:
            W, P, A = neo_hookean(F3, self.shear, self.bulk, tangent, dyadic=True, inv=inv)
            return float(w @ W), P[:, :d, :d], A, None
        return self._mixed_elastic(F3, inv, z, tangent, ev)

    def _mixed_elastic(self, F3, inv, z, tangent: bool, ev: Evaluation):
        """The mixed formulation's part of :meth:`_elastic`: isochoric energy plus the element
        pressures ``a`` (the last dofs of ``z``) times the volume constraint, condensed."""
        d, nel, nq, nb = self.dim, self.nel, self.nq, self.nb
        w = self.w.reshape(-1)
        W, P, A = isochoric(F3, self.shear, tangent, dyadic=True, inv=inv)
        J3, dJ, d2J = jacobian_derivatives(F3, tangent, dyadic=True, inv=inv)
        a = z[self.nfree :].reshape(nel, -1)
        p = np.einsum("ei,eqi->eq", a, self.phi).reshape(-1)
        g = np.einsum("eq,eqi->ei", self.w * (J3 - 1.0).reshape(nel, nq), self.phi)
        Ma = np.einsum("eij,ej->ei", self.Mp, a)
        ra = g - Ma / self.bulk
        energy = (
            float(w @ W)
            + float(np.einsum("ei,ei->", a, g))
            - 0.5 * float(np.einsum("ei,ei->", a, Ma)) / self.bulk
        )
        P = P + p[:, None, None] * dJ
        dJe = dJ[:, :d, :d].reshape(nel, nq, d, d)
        h = np.matmul(self.dN, np.swapaxes(dJe, 2, 3))  # (e, q, b, k)
        wphi = (self.w[:, :, None] * self.phi).transpose(0, 2, 1)  # (e, i, q)
        Bm = np.matmul(wphi, h.reshape(nel, nq, nb * d))  # (e, i, b*d)
        KMB = self.bulk * np.einsum("eij,ejb->eib", self.Minv, Bm)
        r_extra = np.matmul(ra[:, None, :], KMB)[:, 0]
        ev.constraint_matrix = Bm
        ev.constraint_residual = ra
        ev.constraint_norm = float(np.max(np.abs(ra) / self.volumes[:, None]))
        if tangent:
            A = A + d2J.scaled(p)
        return energy, P[:, :d, :d], A, (r_extra, Bm, KMB)

    def _tangent(self, A, Ff, Mf, G, Hs, scale: float, condensed) -> sp.csr_matrix:
        """The tangent of the free dofs: elastic (``A``), condensed pressure (``condensed``)
        and magnetic (at ``scale``) element matrices, assembled."""
        d, nel, nq = self.dim, self.nel, self.nq
        magnetic = G is not None and scale != 0.0
        if self.plane_stress:
            Ke = self._elastic_kernel(A.reshape(nel, nq, d, d, d, d))
            if magnetic:
                Ke += scale * self._magnetic_kernel(Ff, Mf, G, Hs)
        else:
            # the mixed and magnetic terms are added chunk by chunk, while the chunk's
            # element matrices are in cache
            terms = []
            if self.mixed:
                _, Bm, KMB = condensed
                BmT = np.swapaxes(Bm, 1, 2)
                terms.append(lambda sl, K: K.__iadd__(np.matmul(BmT[sl], KMB[sl])))
            if magnetic:
                terms.append(self._magnetic_terms(Ff, Mf, scale * G, Hs, scale))
            Ke = self._dyadic_kernel(A, add=terms)
        return self._sparse(Ke)

    def _elastic_kernel(self, A: np.ndarray, chunk: int = 256) -> np.ndarray:
        """``K[e, a*d+i, b*d+k] = sum_q w dN_aJ A_iJkL dN_bL``, shape (e, nb*d, nb*d).

        Two batched matmuls: ``Y[e,q,(J,i,k),b] = A[e,q,(J,i,k),L] (w dN)[e,q,L,b]`` and
        ``K[e,a,(i,k,b)] = dN[e,a,(q,J)] Y[e,(q,J),(i,k,b)]``.
        """
        d, nq, nb = self.dim, self.nq, self.nb
        out = np.empty((self.nel, nb * d, nb * d))
        for s in range(0, self.nel, chunk):
            sl = slice(s, s + chunk)
            ne = A[sl].shape[0]
            AJ = A[sl].transpose(0, 1, 3, 2, 4, 5).reshape(ne, nq, d**3, d)  # (e,q,Jik,L)
            wdNT = self.w[sl, :, None, None] * np.swapaxes(self.dN[sl], 2, 3)  # (e,q,L,b)
            Y = np.matmul(AJ, wdNT).reshape(ne, nq * d, d * d * nb)  # (e,(q,J),(i,k,b))
            K = np.matmul(self._dN_a_qJ[sl], Y).reshape(ne, nb, d, d, nb)  # (e,a,i,k,b)
            out[sl] = K.transpose(0, 1, 2, 4, 3).reshape(ne, nb * d, nb * d)
        return out

    def _dyadic_kernel(self, T, chunk: int = 16, add=()) -> np.ndarray:
        """The elastic kernel of a :class:`~coilrod.fem.material.DyadicTangent`, without
        forming the tangent array; shape (e, nb*d, nb*d).

        With ``phi_ai = dN_aJ F_iJ`` and ``psi_ai = dN_aJ Fi_Ji`` (``Fi = F^-1``) at each
        quadrature point, ``K[a,i,b,k] = sum_q w [ identity (dN_a . dN_b) d_ik
        + mixed (phi_ai psi_bk + psi_ai phi_bk) + inverse psi_ai psi_bk
        + cross psi_ak psi_bi ]``: one batched matmul over ``(q, 2)`` for the mixed and inverse
        terms, one over ``q`` for the cross term (added with ``i`` and ``k`` swapped) and one
        over ``(q, J)`` for the identity term (added on the diagonal ``i = k``).  Each callable
        of ``add`` is called as ``f(sl, K)`` to add further terms to the element matrices
        ``K`` (ne, nb*d, nb*d) of the chunk of elements ``sl``.
        """
        d, nq, nb, nel = self.dim, self.nq, self.nb, self.nel
        nd = nb * d
        # in 2D only the in-plane block of F and F^-T enters (plane strain: F33 = 1)
        FT = np.ascontiguousarray(np.swapaxes(T.F[:, :d, :d], 1, 2)).reshape(nel, nq, d, d)
        Fi = np.ascontiguousarray(np.swapaxes(T.FiT[:, :d, :d], 1, 2)).reshape(nel, nq, d, d)
        w = self.w.reshape(-1)
        c_id, c_mix, c_inv, c_cross = (
            (w * getattr(T, name)).reshape(nel, nq, 1, 1)
            for name in ("identity", "mixed", "inverse", "cross")
        )
        out = np.empty((nel, nd, nd))
        for s in range(0, nel, chunk):
            sl = slice(s, s + chunk)
            dN = self.dN[sl]
            ne = dN.shape[0]
            U = np.empty((ne, nq, 2, nb, d))  # [e, q, s, a, i], s: phi, psi
            phi, psi = U[:, :, 0], U[:, :, 1]
            np.matmul(dN, FT[sl], out=phi)  # phi_ai = dN_aJ F_iJ
            np.matmul(dN, Fi[sl], out=psi)  # psi_ai = dN_aJ Fi_Ji
            V = np.empty_like(U)
            np.multiply(c_mix[sl], psi, out=V[:, :, 0])
            np.multiply(c_mix[sl], phi, out=V[:, :, 1])
            V[:, :, 1] += c_inv[sl] * psi
            K = out[sl]
            np.matmul(
                np.swapaxes(U.reshape(ne, nq * 2, nd), 1, 2), V.reshape(ne, nq * 2, nd), out=K
            )
            K5 = K.reshape(ne, nb, d, nb, d)
            # cross: C[e, (a,k), (b,i)] = sum_q w c psi_ak psi_bi, added at [a, i, b, k]
            Pq = np.ascontiguousarray(psi).reshape(ne, nq, nd)
            C5 = np.matmul(np.swapaxes(Pq, 1, 2), (c_cross[sl][:, :, 0] * Pq)).reshape(K5.shape)
            # identity: g_ab = sum_q w c dN_a . dN_b on the diagonal i = k
            wdN = (c_id[sl] * dN).transpose(0, 1, 3, 2).reshape(ne, nq * d, nb)
            g = np.matmul(self._dN_a_qJ[sl], wdN)
            for i in range(d):
                K5[:, :, i, :, i] += g
            K5 += C5.transpose(0, 1, 4, 3, 2)  # [a, k, b, i] added at [a, i, b, k]
            for term in add:
                term(sl, K)
        return out

    def _magnetic_terms(self, Ff, Mf, C, Hs, scale: float):
        """The magnetic stiffness as a chunk callable for :meth:`_dyadic_kernel`: adds
        ``Y[a,b,i,k] + Y[b,a,k,i]`` (see :meth:`_magnetic_kernel`; ``C = -scale G`` here
        enters with the sign of ``G``, ``scale`` multiplies the curvature term)."""
        d, nel, nq, nb = self.dim, self.nel, self.nq, self.nb
        mvec = np.matmul(self.dN, Mf.reshape(nel, nq, d, 1))[..., 0]  # (e, q, a)
        wm = self.w[:, :, None] * mvec
        C = -C.reshape(nel, nq, 1, d * d)
        Hk = None
        if Hs is not None:
            Hk = scale * mag.curvature_stiffness(Ff, Mf, Hs).reshape(nel, nq, 1, d * d)
            wN = 0.5 * self.w[:, :, None] * self.N

        def term(sl, K):
            ne = K.shape[0]
            N = self.N[sl][:, :, :, None]
            if Hk is None:
                U, V = wm[sl], N * C[sl]
            else:
                U = np.concatenate([wm[sl], wN[sl]], axis=1)
                V = np.concatenate([N * C[sl], N * Hk[sl]], axis=1)
            Y = np.matmul(np.swapaxes(U, 1, 2), V.reshape(ne, -1, nb * d * d))
            Y = Y.reshape(ne, nb, nb, d, d)
            K5 = K.reshape(ne, nb, d, nb, d)
            K5 += Y.transpose(0, 1, 3, 2, 4)
            K5 += Y.transpose(0, 2, 4, 1, 3)

        return term

    def _magnetic_kernel(self, Ff, Mf, G, Hs) -> np.ndarray:
        """Gradient (and curvature) stiffness of the magnetic term per unit scale.

        ``K[a,i,b,k] = Y[a,b,i,k] + Y[b,a,k,i]`` with ``Y[a,b,i,k] = sum_q w (m_a N_b C_ik
        + N_a N_b H_ik / 2)``, ``m_a = dN_a . M``, ``C = -G`` and ``H`` the curvature
        stiffness (symmetric): one batched matmul over the quadrature points (both terms
        stacked along ``q``) and one symmetrising sum; shape (e, nb*d, nb*d).
        """
        d, nel, nq, nb = self.dim, self.nel, self.nq, self.nb
        mvec = np.matmul(self.dN, Mf.reshape(nel, nq, d, 1))[..., 0]  # (e, q, a)
        U = self.w[:, :, None] * mvec  # (e, q, a)
        V = self.N[:, :, :, None] * (-G).reshape(nel, nq, 1, d * d)  # (e, q, b, ik)
        if Hs is not None:
            Hk = mag.curvature_stiffness(Ff, Mf, Hs).reshape(nel, nq, 1, d * d)
            U = np.concatenate([U, 0.5 * self.w[:, :, None] * self.N], axis=1)  # (e, 2q, a)
            V = np.concatenate([V, self.N[:, :, :, None] * Hk], axis=1)  # (e, 2q, b, ik)
        Y = np.matmul(np.swapaxes(U, 1, 2), V.reshape(nel, -1, nb * d * d))
        Y = Y.reshape(nel, nb, nb, d, d)
        out = np.empty((nel, nb, d, nb, d))
        np.add(Y.transpose(0, 1, 3, 2, 4), Y.transpose(0, 2, 4, 1, 3), out=out)
        return out.reshape(nel, nb * d, nb * d)
