"""FEM benchmark: assembly against sparse solve, the full 3D curve, time against tip error.

Prints (and writes to benchmarks/results/fem.md), with the machine:

1. one Newton iteration on a 3D quadratic (Q2, mixed) box mesh of >= 20,000 dofs: the
   vectorised assembly of residual + tangent (now: dyadic tangent; before: the dense
   3x3x3x3 tangent) against the factorisation + solve of the same tangent (before: SuperLU LU
   with COLAMD; SuperLU LDL^T in a fixed RCM or minimum-degree ordering; now:
   ``Assembler.factorize``, the level-by-level block Cholesky on this slender mesh);
2. the 3D order-2 20x1x1 box rod, M(1) in a uniform field, lambda to 10 in 20 requested
   scales: total time and the path engine's counters (Newton iterations, factorisations,
   evaluations, load sub-steps, cuts), against the time of 10 assemblies of the same
   (displacement-form) neo-Hookean tangent written as a plain scikit-fem ``BilinearForm``;
   the two tangents are compared entry by entry first;
3. time against tip error (max over the 20-step curve, against the closed-form elastica of
   ``coilrod.elastica``) for 2D/3D, order 1/2 and several meshes, next to the rod solver.

Times are process CPU (``BENCH_CLOCK=wall`` for wall clock; one BLAS thread, so the two agree
on an idle machine; before 2026-11-27 this benchmark timed wall clock).  The box FEM uses no
kernel with a ski-rental threshold; they are set to 0 anyway (``_machine.compile_at_once``:
the compiled paths, as the other benchmarks).

Run:  python benchmarks/bench_fem.py
      python benchmarks/bench_fem.py --quick   (section 3: 2D Q1 20x1, 3D Q2 10x1x1; printed)
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

# one BLAS thread (as the other benchmarks): OpenBLAS threads on the small dense blocks of a
# slender mesh double the CPU time of a curve for no gain in wall time on a shared machine
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))

from _machine import bench_args, clock_name, compile_at_once, machine_info  # noqa: E402
from _machine import best_run as best  # noqa: E402

import coilrod  # noqa: E402
import coils  # noqa: E402
from coilrod import presets  # noqa: E402
from coilrod.fem.assembly import Assembler  # noqa: E402
from coilrod.fem.material import moduli  # noqa: E402
from coilrod.fem.mesh import rod_mesh  # noqa: E402
from coilrod.rod.elastica import elastica  # noqa: E402

L = 0.04
D = L / 20
LAMBDAS = np.linspace(0.5, 10.0, 20)
OUT: list[str] = []


def emit(line: str = "") -> None:
    print(line, flush=True)
    OUT.append(line)


def machine_line(timing: str, clock: str | None = None) -> str:
    """The machine, scikit-fem and the BLAS threads, then ``timing`` (how the times were
    taken); shared by bench_fem.py and bench_fem3d.py."""
    import skfem

    return (
        f"Machine: {machine_info()}; scikit-fem {skfem.__version__}; threads "
        f"OMP={os.environ.get('OMP_NUM_THREADS', 'unset')} "
        f"OPENBLAS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}. "
        f"{clock or clock_name()} time, {timing}."
    )


def box_rod():
    return coilrod.Rod(L, 1e6, coilrod.Rectangle(D, D), presets.M1())


def uniform(rod, lam=1.0):
    return coils.UniformField((0.0, rod.field_for_lambda(lam), 0.0))


def _dense_tangent_evaluate(asm, z, scale):
    """The assembly as before the dyadic kernel: the (n, 3, 3, 3, 3) tangent formed point by
    point (two matrix inverses) and contracted by the dense kernel (mixed u-p, uniform
    field).  Returns the evaluation and the element matrices of the elastic part, next to
    those of the dyadic kernel for comparison."""
    from coilrod.fem.material import isochoric, jacobian_derivatives

    d, nel, nq, nb = asm.dim, asm.nel, asm.nq, asm.nb
    ev = asm.evaluate(z, scale, tangent=False)  # residual part (as before)
    ue = asm.full(z)[asm.edofs].reshape(nel, nb, d)
    F = np.matmul(asm._dN_qJ_a, ue).reshape(nel, nq, d, d).transpose(0, 1, 3, 2) + np.eye(d)
    Ff = F.reshape(-1, d, d)
    inv = (np.linalg.inv(Ff), np.linalg.det(Ff))
    _, _, A = isochoric(Ff, asm.shear, inv=inv)
    _, _, d2J = jacobian_derivatives(Ff, inv=(np.linalg.inv(Ff), inv[1]))
    p = asm.pressure(z).reshape(-1)
    A = A + p[:, None, None, None, None] * d2J
    Ke = asm._elastic_kernel(A.reshape(nel, nq, d, d, d, d))
    Ke += np.matmul(
        np.swapaxes(ev.constraint_matrix, 1, 2),
        asm.bulk * np.einsum("eij,ejb->eib", asm.Minv, ev.constraint_matrix),
    )
    ev.tangent = asm._sparse(Ke)
    return ev


def section_assembly_vs_solve():
    from scipy.sparse.linalg import splu

    from coilrod.fem.linalg import SYMMETRIC_OPTIONS, SymmetricFactorizer, negative_eigenvalues

    rod = box_rod()
    G, K = moduli(rod.youngs_modulus, 0.4995)
    mesh = rod_mesh(rod, 3, (40, 4, 5))
    asm = Assembler(mesh, 2, rod, uniform(rod, 2.0), G, K)
    # a mildly bent state with a positive definite tangent: the linear response to 1/200 of
    # the load, with consistent pressures (at larger fractions of the linear response the
    # spurious volume change of the unrotated bending field, times K/G = 1000, makes the
    # tangent indefinite: the LDL^T inertia counts the negative eigenvalues)
    ev0 = asm.evaluate(np.zeros(asm.size), 0.0)
    z = asm.with_consistent_pressure(0.005 * asm.load_tangent(ev0, asm.factorize(ev0)))
    t_asm, ev = best(lambda: asm.evaluate(z, 1.0, tangent=True))
    t_dense, ev_dense = best(lambda: _dense_tangent_evaluate(asm, z, 1.0), repeat=2)
    same = abs(ev_dense.tangent - ev.tangent).max() / abs(ev.tangent).max()
    Kt = ev.tangent
    rows = []  # (name, factorise, solve)
    t_fac, lu = best(lambda: splu(Kt.T, permc_spec="COLAMD"), repeat=2)
    t_sol, _ = best(lambda: lu.solve(ev.residual))
    rows.append(("SuperLU LU, COLAMD, partial pivoting (before)", t_fac, t_sol))
    for method in ("rcm", "mmd"):
        fz = SymmetricFactorizer(methods=(method,), block=False)
        fz(Kt)
        t_fac, f = best(lambda fz=fz: fz(Kt), repeat=2)
        t_sol, _ = best(lambda f=f: f.solve(ev.residual))
        rows.append((f"SuperLU LDL^T ({method.upper()} once, symmetric mode)", t_fac, t_sol))
    negatives = negative_eigenvalues(f)
    asm.factorize(ev)  # analysis of the pattern (orderings, levels), once per solve
    t_fac, f = best(lambda: asm.factorize(ev), repeat=2)
    t_sol, _ = best(lambda: f.solve(ev.residual))
    kind = type(f).__name__.replace("BlockCholeskyFactor", "block Cholesky")
    rows.append((f"Assembler.factorize: {kind} (now)", t_fac, t_sol))
    emit("## 1. One Newton iteration, 3D Q2 box 40x4x5 (mixed u-p)")
    emit()
    emit(
        f"free displacement dofs: {asm.nfree}, element pressures: {asm.size - asm.nfree}, "
        f"tangent nnz: {ev.tangent.nnz}; negative eigenvalues (LDL^T inertia): {negatives}; "
        f"SuperLU options {SYMMETRIC_OPTIONS['options']}"
    )
    emit()
    emit("| step | time (s) |")
    emit("|---|---|")
    emit(f"| assembly: residual + tangent (vectorised, dyadic tangent; now) | {t_asm:.3f} |")
    emit(
        f"| assembly: residual + tangent with the dense 3x3x3x3 tangent (before; same matrix "
        f"to {same:.0e}) | {t_dense:.3f} |"
    )
    for name, tf, ts in rows:
        emit(f"| factorisation: {name} | {tf:.3f} |")
        emit(f"| solve: {name} | {ts:.4f} |")
    t_fac, t_sol = rows[-1][1], rows[-1][2]
    emit(f"| ratio assembly / (factorisation + solve), now | {t_asm / (t_fac + t_sol):.2f} |")
    emit()


def skfem_bilinear_tangent(mesh, u_full, G, K):
    """The displacement-form neo-Hookean tangent as a plain scikit-fem BilinearForm."""
    from skfem import Basis, BilinearForm, ElementHex2, ElementVector, asm
    from skfem.helpers import ddot, det, grad, inv, mul, transpose

    basis = Basis(mesh, ElementVector(ElementHex2()), intorder=5)

    @BilinearForm
    def tangent(du, v, w):
        gu = grad(du)
        F = grad(w["disp"]) + np.eye(3)[:, :, None, None]
        J = det(F)
        Fi = inv(F)
        FiT = transpose(Fi)
        I1 = ddot(F, F)
        c = G * J ** (-2.0 / 3.0)
        FiT_gu = ddot(FiT, gu)
        F_gu = ddot(F, gu)
        cross = transpose(mul(Fi, mul(gu, Fi)))
        dP_iso = c * (
            gu
            - 2.0 / 3.0 * (F * FiT_gu + FiT * F_gu)
            + 2.0 / 9.0 * I1 * FiT * FiT_gu
            + 1.0 / 3.0 * I1 * cross
        )
        p = K * (J - 1.0)
        dP_vol = K * J * (2 * J - 1) * FiT * FiT_gu - p * J * cross
        return ddot(dP_iso + dP_vol, grad(v))

    disp = basis.interpolate(u_full)
    return basis, lambda: asm(tangent, basis, disp=disp)


def section_full_curve():
    rod = box_rod()
    field = uniform(rod)
    # warm up imports and caches
    coilrod.solve_fem(rod, field, [0.5], dim=3)
    t_curve, res = best(lambda: coilrod.solve_fem(rod, field, LAMBDAS, dim=3), repeat=3)
    its = int(res.iterations.sum())
    # the plain BilinearForm tangent, checked against ours (displacement form) at the end state
    G, K = moduli(rod.youngs_modulus, 0.4995)
    mesh = res.mesh
    ours = Assembler(mesh, 2, rod, field, G, K, mixed=False)
    z = res._states[-1][: ours.nfree]
    u_full = ours.full(z)
    basis, assemble = skfem_bilinear_tangent(mesh, _to_skfem_order(mesh, u_full), G, K)
    t_form, Kform = best(assemble, repeat=2)
    ev = ours.evaluate(z, LAMBDAS[-1], tangent=True)
    d_ours = np.sort(ev.tangent.diagonal())
    free_sk = _skfem_free(basis)
    d_form = np.sort(Kform.diagonal()[free_sk])
    rel = np.abs(d_ours - d_form).max() / np.abs(d_ours).max()
    fro = abs(np.linalg.norm(ev.tangent.data) / np.linalg.norm(Kform[free_sk][:, free_sk].data) - 1)
    t_ours_asm, _ = best(lambda: ours.evaluate(z, LAMBDAS[-1], tangent=True))
    emit("## 2. 3D Q2 20x1x1 box rod, M(1), uniform field, lambda 0.5 ... 10 in 20 steps")
    emit()
    emit(
        f"Newton iterations: {its} ({res.stats.factorizations} factorisations, "
        f"{res.stats.evaluations} evaluations, {res.stats.steps} load sub-steps for the "
        f"{len(LAMBDAS)} requested scales, {res.stats.cuts} step cuts); "
        f"tip at lambda = 10: {np.round(res.tip[-1, :2] / L, 5).tolist()} L"
    )
    emit()
    emit("| | time (s) |")
    emit("|---|---|")
    emit(f"| full curve, coilrod.solve_fem (mixed u-p, the coilrod.path engine) | {t_curve:.3f} |")
    emit(f"| one assembly, plain scikit-fem BilinearForm (displacement form) | {t_form:.3f} |")
    emit(f"| 10 such assemblies | {10 * t_form:.3f} |")
    emit(
        f"| one assembly, coilrod vectorised kernel (same tangent + residual) | {t_ours_asm:.4f} |"
    )
    emit(f"| full curve / one BilinearForm assembly | {t_curve / t_form:.2f} |")
    emit()
    emit(
        f"Tangent check (same state, displacement form): sorted diagonals agree to {rel:.1e} "
        f"(relative), Frobenius norms to {fro:.1e}."
    )
    emit(
        "For scale (not measured here; /work/shared/peers/side_by_side_fem.py, the same "
        "discrete problem in UFL, Q2 x DPC1, MUMPS, plain Newton, one process, best of 2, "
        "commit 700f85f): DOLFINx 0.11 takes 3.06 s wall for this curve with 94 Newton "
        "iterations, coilrod then 1.09 s with 104 (86 factorisations, 30 sub-steps): ratio "
        "0.36; on 40x2x2 19.6 s against 7.2 s: 0.37 (CPU time 0.30).  Since then the FEM's "
        "step cap is 0.2 L (was 0.15 L) and its chord steps start only after a thousandfold "
        "error cut (was 8-fold): the counts above."
    )
    emit()


def _to_skfem_order(mesh, u_full):
    """Our interleaved (node*3 + comp) vector in scikit-fem ElementVector dof order.

    scikit-fem numbers the dofs of ``ElementVector`` component-interleaved per scalar dof,
    the same layout; the tangent comparison below checks it.
    """
    from skfem import Basis, ElementHex2, ElementVector

    basis = Basis(mesh, ElementVector(ElementHex2()), intorder=1)
    scalar = Basis(mesh, ElementHex2(), intorder=1)
    assert basis.N == 3 * scalar.N
    np.testing.assert_array_equal(basis.nodal_dofs[:, :4], np.arange(12).reshape(4, 3).T)
    return u_full.copy()


def _skfem_free(basis):
    dofs = basis.get_dofs(lambda x: np.abs(x[0]) < 1e-12).all()
    free = np.ones(basis.N, bool)
    free[dofs] = False
    return np.flatnonzero(free)


QUICK_CASES = [(2, 1, (20, 1)), (3, 2, (10, 1, 1))]


def section_time_vs_error(quick: bool = False):
    emit("## 3. Time against tip error (M(1), lambda 0.5 ... 10, 20 steps)")
    emit()
    emit(
        "Error: max over the 20 states of |tip - elastica tip| / L, elastica in closed form "
        "(coilrod.elastica).  Rod section D x D, L/D = 20, nu = 0.4995 (mixed u-p in 3D; 2D "
        "plane stress)."
    )
    emit()
    emit("| model | order | elements | dofs | time (s) | Newton its | max error / L |")
    emit("|---|---|---|---|---|---|---|")
    rod = box_rod()
    field = uniform(rod)
    ref = np.array([elastica(lam, math.pi / 2, length=L).tip[:2] for lam in LAMBDAS])
    cases = (
        QUICK_CASES
        if quick
        else [
            (2, 1, (20, 1)),
            (2, 1, (80, 2)),
            (2, 1, (160, 4)),
            (2, 2, (10, 1)),
            (2, 2, (20, 1)),
            (2, 2, (40, 2)),
            (3, 1, (40, 2, 2)),
            (3, 1, (80, 4, 4)),
            (3, 2, (10, 1, 1)),
            (3, 2, (20, 1, 1)),
            (3, 2, (40, 2, 2)),
        ]
    )
    for dim, order, el in cases:
        t, res = best(
            lambda dim=dim, order=order, el=el: coilrod.solve_fem(
                rod, field, LAMBDAS, dim=dim, order=order, elements=el
            ),
            repeat=1,
        )
        err = np.linalg.norm(res.tip[:, :2] - ref, axis=1).max() / L
        emit(
            f"| FEM {dim}D | {order} | {'x'.join(map(str, el))} | {res._asm.nfree} | "
            f"{t:.2f} | {int(res.iterations.sum())} | {err:.2e} |"
        )
    t, rr = best(lambda: coilrod.solve_rod(rod, field, LAMBDAS), repeat=1)
    err = np.linalg.norm(rr.tip[:, :2] - ref, axis=1).max() / L
    emit(f"| rod (coilrod.solve_rod, defaults) | - | - | - | {t:.2f} | - | {err:.2e} |")
    emit()


def main():
    quick = bench_args(__doc__).quick
    compile_at_once(warm_up=False)
    emit("# FEM benchmark (benchmarks/bench_fem.py)")
    emit()
    emit(machine_line("best of 3 (2 for factorisations, 1 for section 3)"))
    emit()
    if quick:
        section_time_vs_error(quick=True)
        return
    section_assembly_vs_solve()
    section_full_curve()
    section_time_vs_error()
    out = Path(__file__).parent / "results" / "fem.md"
    out.parent.mkdir(exist_ok=True)
    out.write_text("\n".join(OUT) + "\n")
    print(f"written {out}")


if __name__ == "__main__":
    main()
