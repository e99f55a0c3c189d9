"""FEM element kernels and global assembly against direct (slow, independent) constructions.

Cross-checks:

* ``inverse_and_determinant`` (cofactors) against ``numpy.linalg.inv`` and ``det``;
* the dyadic form of the neo-Hookean tangent against the dense ``dP/dF`` array formed dyad
  by dyad as in the material's Notes (isochoric, d2J, volumetric);
* the element kernel of a dyadic tangent (never forms ``A``) against
  ``einsum("eqaJ,eqiJkL,eqbL->eaibk")`` of the dense tangent, in 3D and in 2D plane strain;
* the global tangent (scatter matrix) against a COO assembly of the element matrices.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import coilrod
import coils
from coilrod.fem.assembly import Assembler
from coilrod.fem.material import (
    inverse_and_determinant,
    isochoric,
    jacobian_derivatives,
    moduli,
    neo_hookean,
)
from coilrod.fem.mesh import box_mesh, rod_mesh


def _random_F(n=7, seed=0):
    rng = np.random.default_rng(seed)
    return np.eye(3) + 0.3 * rng.normal(size=(n, 3, 3))


def test_inverse_and_determinant_match_numpy():
    F = _random_F(50)
    Fi, J = inverse_and_determinant(F)
    np.testing.assert_allclose(J, np.linalg.det(F), rtol=1e-12)
    np.testing.assert_allclose(Fi, np.linalg.inv(F), rtol=1e-10, atol=1e-12)


def test_dyadic_tangents_match_dense_dyads():
    F = _random_F()
    Fi = np.linalg.inv(F)
    FiT = np.swapaxes(Fi, 1, 2)
    J = np.linalg.det(F)
    I1 = np.einsum("nij,nij->n", F, F)
    eye = np.eye(3)
    dd = np.einsum("ik,JL->iJkL", eye, eye)
    dyad = lambda a, b: np.einsum("niJ,nkL->niJkL", a, b)  # noqa: E731
    cross = np.einsum("nJk,nLi->niJkL", Fi, Fi)
    c = (1.3 * J ** (-2.0 / 3.0))[:, None, None, None, None]
    I1e = I1[:, None, None, None, None]
    iso = c * (
        dd
        - 2.0 / 3.0 * (dyad(F, FiT) + dyad(FiT, F))
        + 2.0 / 9.0 * I1e * dyad(FiT, FiT)
        + 1.0 / 3.0 * I1e * cross
    )
    d2J = J[:, None, None, None, None] * (dyad(FiT, FiT) - cross)
    np.testing.assert_allclose(isochoric(F, 1.3)[2], iso, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(isochoric(F, 1.3, dyadic=True)[2].dense(), iso, rtol=1e-12)
    np.testing.assert_allclose(jacobian_derivatives(F)[2], d2J, rtol=1e-12, atol=1e-12)
    K = 40.0
    p = (K * (J - 1.0))[:, None, None, None, None]
    dJ = J[:, None, None] * FiT
    vol = p * d2J + K * dyad(dJ, dJ)
    np.testing.assert_allclose(neo_hookean(F, 1.3, K)[2], iso + vol, rtol=1e-11, atol=1e-11)


@pytest.mark.parametrize(("dim", "formulation"), [(3, "mixed"), (3, "displacement"), (2, "mixed")])
def test_dyadic_kernel_matches_dense_einsum(dim, formulation):
    rod = coilrod.Rod(0.04, 1e6, coilrod.Rectangle(2e-3, 2e-3), coilrod.presets.M1())
    G, K = moduli(1e6, 0.45)
    el = (3, 1, 1) if dim == 3 else (4, 1)
    field = coils.UniformField((0.0, 0.02, 0.0))
    # uniform layers (the graded clamp's short elements would fold under the random u)
    mesh = box_mesh(0.04, 2e-3, 2e-3, *el) if dim == 3 else rod_mesh(rod, dim, el)
    asm = Assembler(mesh, 2, rod, field, G, K, "strain", True)
    rng = np.random.default_rng(4)
    u = asm.full(3e-4 * rng.normal(size=asm.nfree))
    ue = u[asm.edofs].reshape(asm.nel, asm.nb, dim)
    F = np.einsum("eqaJ,eai->eqiJ", asm.dN, ue) + np.eye(dim)
    F3 = np.zeros((asm.nel * asm.nq, 3, 3))
    F3[:, :dim, :dim] = F.reshape(-1, dim, dim)
    if dim == 2:
        F3[:, 2, 2] = 1.0
    if formulation == "mixed":
        T = isochoric(F3, G, dyadic=True)[2] + jacobian_derivatives(F3, dyadic=True)[2].scaled(
            np.linspace(-2e5, 3e5, F3.shape[0])
        )
    else:
        T = neo_hookean(F3, G, K, dyadic=True)[2]
    A = T.dense()[:, :dim, :dim, :dim, :dim].reshape(asm.nel, asm.nq, *(dim,) * 4)
    wdN = asm.w[:, :, None, None] * asm.dN
    ref = np.einsum("eqaJ,eqiJkL,eqbL->eaibk", wdN, A, asm.dN)
    n = asm.nb * dim
    got = asm._dyadic_kernel(T).reshape(asm.nel, n, n)
    np.testing.assert_allclose(
        got, ref.reshape(asm.nel, n, n), rtol=1e-10, atol=1e-12 * abs(ref).max()
    )
    # the dense kernel (used for plane stress) agrees as well
    dense = asm._elastic_kernel(A)
    np.testing.assert_allclose(dense, ref.reshape(asm.nel, n, n), atol=1e-12 * abs(ref).max())


def test_scatter_matches_coo_assembly():
    rod = coilrod.Rod(0.04, 1e6, coilrod.Rectangle(2e-3, 2e-3), coilrod.presets.M1())
    G, K = moduli(1e6, 0.45)
    asm = Assembler(rod_mesh(rod, 3, (3, 1, 1)), 2, rod, coils.UniformField((0, 0.02, 0)), G, K)
    n = asm.nb * 3
    Ke = np.random.default_rng(5).normal(size=(asm.nel, n, n))
    rows = np.repeat(asm.edofs, n, axis=1).ravel()
    cols = np.tile(asm.edofs, (1, n)).ravel()
    full = sp.coo_matrix((Ke.ravel(), (rows, cols)), shape=(asm.ndof,) * 2).tocsr()
    ref = full[asm.free][:, asm.free].toarray()
    np.testing.assert_allclose(asm._sparse(Ke).toarray(), ref, rtol=1e-13, atol=1e-13)
