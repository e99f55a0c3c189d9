"""FEM linearisation: every analytic derivative against central finite differences.

Cross-checks (all independent of the code under test except the function differentiated):

* material: P = dW/dF and A = dP/dF of the neo-Hookean energy by central differences;
  plane stress: P_33 = 0 and the condensed 2D tangent against differences of the 2D stress;
* discrete model: residual = d(energy)/du and tangent = d(residual)/du for uniform,
  linear-gradient (Maxwell) and position-dependent (non-linear, hessian term) fields, in 2D
  plane stress and plane strain and in 3D, for order 1 and 2, mixed and displacement forms;
* the tangent is symmetric (the model has a potential for any field B(x)).
"""

from __future__ import annotations

import numpy as np
import pytest

import coilrod
import coils
from coilrod.fem.assembly import Assembler
from coilrod.fem.material import moduli, neo_hookean, plane_stress
from coilrod.fem.mesh import rod_mesh


class CurvedField(coils.Field):
    """A smooth field with non-zero second derivatives (closed-form B and gradient)."""

    def _B(self, p):
        x, y, z = p.T
        return np.stack([50 * x * y, 0.01 + 3 * x**2 + 20 * y * z, 0.2 * y * z], axis=1)

    def _gradient(self, p):
        x, y, z = p.T
        G = np.zeros((p.shape[0], 3, 3))
        G[:, 0, 0], G[:, 0, 1] = 50 * y, 50 * x
        G[:, 1, 0], G[:, 1, 1], G[:, 1, 2] = 6 * x, 20 * z, 20 * y
        G[:, 2, 1], G[:, 2, 2] = 0.2 * z, 0.2 * y
        return G

    @property
    def length_scale(self):
        return 0.01


def _random_F(rng, n=5):
    return np.eye(3) + 0.2 * rng.normal(size=(n, 3, 3))


def test_material_stress_and_tangent_by_differences():
    rng = np.random.default_rng(1)
    F = _random_F(rng)
    assert np.all(np.linalg.det(F) > 0)
    G, K = 1.3, 40.0
    W, P, A = neo_hookean(F, G, K)
    h = 1e-6
    for i in range(3):
        for j in range(3):
            dF = np.zeros((3, 3))
            dF[i, j] = h
            Wp, Pp, _ = neo_hookean(F + dF, G, K)
            Wm, Pm, _ = neo_hookean(F - dF, G, K)
            np.testing.assert_allclose((Wp - Wm) / (2 * h), P[:, i, j], rtol=1e-7, atol=1e-8)
            np.testing.assert_allclose((Pp - Pm) / (2 * h), A[:, :, :, i, j], rtol=1e-6, atol=1e-7)


def test_material_is_stress_free_and_isotropic_at_rest():
    W, P, A = neo_hookean(np.eye(3)[None], 2.0, 7.0)
    assert W[0] == pytest.approx(0.0, abs=1e-14)
    np.testing.assert_allclose(P[0], 0.0, atol=1e-14)
    # small-strain limit: A = K I(x)I + G (I(x)I sym part with deviatoric projection)
    eye = np.eye(3)
    lin = 7.0 * np.einsum("ij,kl->ijkl", eye, eye) + 2.0 * (
        np.einsum("ik,jl->ijkl", eye, eye)
        + np.einsum("il,jk->ijkl", eye, eye)
        - 2.0 / 3.0 * np.einsum("ij,kl->ijkl", eye, eye)
    )
    np.testing.assert_allclose(A[0], lin, atol=1e-12)


def test_plane_stress_condensation():
    rng = np.random.default_rng(2)
    F2 = np.eye(2) + 0.2 * rng.normal(size=(6, 2, 2))
    G, K = 1.0, 500.0
    W, P2, A2, lam3 = plane_stress(F2, G, K)
    F3 = np.zeros((6, 3, 3))
    F3[:, :2, :2], F3[:, 2, 2] = F2, lam3
    _, P3, _ = neo_hookean(F3, G, K)
    np.testing.assert_allclose(P3[:, 2, 2], 0.0, atol=1e-10)
    h = 1e-6
    for i in range(2):
        for j in range(2):
            dF = np.zeros((2, 2))
            dF[i, j] = h
            _, Pp, _, _ = plane_stress(F2 + dF, G, K)
            _, Pm, _, _ = plane_stress(F2 - dF, G, K)
            np.testing.assert_allclose((Pp - Pm) / (2 * h), A2[:, :, :, i, j], rtol=1e-6, atol=1e-6)


CASES = [
    # dim, order, plane, formulation, field
    (3, 2, "stress", "mixed", "uniform"),
    (3, 2, "stress", "mixed", "linear"),
    (3, 2, "stress", "mixed", "curved"),
    (3, 1, "stress", "displacement", "linear"),
    (3, 1, "stress", "mixed", "curved"),
    (2, 2, "stress", "mixed", "curved"),
    (2, 2, "strain", "mixed", "curved"),
    (2, 1, "strain", "displacement", "linear"),
    (2, 1, "stress", "displacement", "uniform"),
]


def _field(kind):
    if kind == "uniform":
        return coils.UniformField((0.0, 0.02, 0.0))
    if kind == "linear":
        return coils.LinearField((0.0, 0.01, 0.0), coils.maxwell_gradient(0.5), (0.01, 0, 0))
    return CurvedField()


@pytest.mark.parametrize(("dim", "order", "plane", "formulation", "kind"), CASES)
def test_residual_and_tangent_by_differences(dim, order, plane, formulation, kind):
    rod = coilrod.Rod(0.04, 1e6, coilrod.Rectangle(2e-3, 2e-3), coilrod.presets.M2())
    G, K = moduli(1e6, 0.45)
    el = (4, 1) if dim == 2 else (3, 1, 1)
    asm = Assembler(
        rod_mesh(rod, dim, el), order, rod, _field(kind), G, K, plane, formulation == "mixed"
    )
    rng = np.random.default_rng(3)
    npad = asm.size - asm.nfree
    z = asm.with_consistent_pressure(
        np.concatenate([1e-4 * rng.normal(size=asm.nfree), np.zeros(npad)])
    )
    dz = np.concatenate([1e-4 * rng.normal(size=asm.nfree), np.zeros(npad)])
    scale = 1.7
    ev = asm.evaluate(z, scale)
    assert ev.ok
    h = 1e-3
    ep, em = asm.evaluate(z + h * dz, scale), asm.evaluate(z - h * dz, scale)
    # residual = gradient of the energy (at consistent pressures)
    dE = (ep.energy - em.energy) / (2 * h)
    assert dE == pytest.approx(ev.residual @ dz[: asm.nfree], rel=1e-6)
    # tangent = derivative of the residual
    fd = (ep.residual - em.residual) / (2 * h)
    an = ev.tangent @ dz[: asm.nfree]
    assert np.linalg.norm(fd - an) <= 1e-6 * np.linalg.norm(an)
    # load rate = d residual / d scale (the residual is affine in the scale)
    e2 = asm.evaluate(z, scale + 1.0)
    np.testing.assert_allclose(
        e2.residual - ev.residual, ev.load_rate, atol=1e-9 * np.abs(ev.load_rate).max()
    )
    T = ev.tangent
    assert abs(T - T.T).max() <= 1e-12 * abs(T).max()


def test_uniform_field_adds_no_stiffness():
    """Uniform B: the magnetic term is a dead load (tangent independent of the scale)."""
    rod = coilrod.Rod(0.04, 1e6, coilrod.Rectangle(2e-3, 2e-3), coilrod.presets.M1())
    G, K = moduli(1e6, 0.45)
    asm = Assembler(rod_mesh(rod, 2, (4, 1)), 2, rod, _field("uniform"), G, K, "stress", True)
    z = asm.with_consistent_pressure(1e-4 * np.random.default_rng(4).normal(size=asm.size))
    T0, T5 = asm.evaluate(z, 0.0).tangent, asm.evaluate(z, 5.0).tangent
    # equal up to the round-off of the plane-stress thickness iteration
    assert abs(T0 - T5).max() <= 1e-12 * abs(T0).max()


def test_tangent_in_a_real_coil_field():
    """Biot-Savart Helmholtz + Maxwell pairs (non-linear field, hessian term) in 3D."""
    field = coils.HelmholtzPair(0.05, 200, 1.0, axis="y") + coils.MaxwellPair(
        0.05, 200, 1.0, axis="y", center=(0.01, 0.0, 0.0)
    )
    assert not field.linear
    rod = coilrod.Rod(0.04, 1e6, coilrod.Rectangle(2e-3, 2e-3), coilrod.presets.M1())
    G, K = moduli(1e6, 0.45)
    asm = Assembler(rod_mesh(rod, 3, (3, 1, 1)), 2, rod, field, G, K)
    rng = np.random.default_rng(5)
    npad = asm.size - asm.nfree
    z = asm.with_consistent_pressure(
        np.concatenate([1e-4 * rng.normal(size=asm.nfree), np.zeros(npad)])
    )
    dz = np.concatenate([1e-4 * rng.normal(size=asm.nfree), np.zeros(npad)])
    ev = asm.evaluate(z, 30.0)
    h = 1e-3
    fd = (asm.evaluate(z + h * dz, 30.0).residual - asm.evaluate(z - h * dz, 30.0).residual) / (
        2 * h
    )
    an = ev.tangent @ dz[: asm.nfree]
    assert np.linalg.norm(fd - an) <= 1e-6 * np.linalg.norm(an)
    # the magnetic part alone (scale 30 minus scale 0) is matched as well
    e0 = asm.evaluate(z, 0.0)
    mag_an = (ev.tangent - e0.tangent) @ dz[: asm.nfree]
    fd0 = (asm.evaluate(z + h * dz, 0.0).residual - asm.evaluate(z - h * dz, 0.0).residual) / (
        2 * h
    )
    assert np.linalg.norm((fd - fd0) - mag_an) <= 1e-5 * np.linalg.norm(mag_an)
