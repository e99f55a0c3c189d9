"""FEM benchmark: the default 3D Circle curve (issue 23 "Slow"), time against tip error.

The problem a user gets without choosing anything: ``solve_fem(seed_rod(M(1)),
HelmholtzPair(radius=0.08, turns=200, current=6.7, axis="y"), linspace(0.1, 1, 10))`` -- 3D,
Circle section on the quadratic O-grid, Q2 mixed u-p, default mesh (20, 2, 1).

Prints (and writes to benchmarks/results/fem3d.md), with the machine:

1. the whole curve: time, the path engine's counters and the cost of each part of one Newton
   iteration (tangent assembly, factorisation, residual, solve); with ``--baseline DIR`` (a
   checkout of an older coilrod, e.g. ``git archive 5643283 | tar -x -C DIR``) the same curve
   solved by that code in a child process of the same run, and the largest tip difference
   between the two (/ L);
2. plain scikit-fem on the same O-grid: one tangent assembly as a ``BilinearForm``
   (displacement-form neo-Hookean, as ``bench_fem.py``) at the end state, and SuperLU's
   ``spsolve`` of it -- times the factorisations coilrod needed, a lower bound of a plain
   scikit-fem Newton solve of this curve (no residuals, no magnetic terms);
3. time against tip error for several O-grids: error = largest tip difference over the 10
   scales against the finest mesh of the table (40, 2, 1), next to the Kirchhoff rod
   (``solve_rod``, the model difference, not a discretisation error).

Timings: process CPU time by default (``BENCH_CLOCK=wall`` for wall clock), best of
``--repeat`` runs; one BLAS thread unless ``OMP_NUM_THREADS``/``OPENBLAS_NUM_THREADS`` say
otherwise (as bench_fem.py).

The Helmholtz pair's coil pass runs compiled from the first call (ski-rental thresholds 0,
``_machine.compile_at_once``; the baseline's child process without the warm-up, its first
repeat compiles): the steady state;
``bench_coldstart.py`` measures what a fresh process pays.

Run:  python benchmarks/bench_fem3d.py [--baseline DIR] [--repeat 2]
      python benchmarks/bench_fem3d.py --quick   (section 1, one run, printed only)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))

from _machine import clock, compile_at_once  # noqa: E402
from bench_fem import machine_line, skfem_bilinear_tangent  # noqa: E402

OUT: list[str] = []
SCALES = np.linspace(0.1, 1.0, 10)


def emit(line: str = "") -> None:
    print(line, flush=True)
    OUT.append(line)


def problem():
    import coils
    from coilrod import presets

    rod = presets.seed_rod(presets.M1())
    field = coils.HelmholtzPair(radius=0.08, turns=200, current=6.7, axis="y")
    return rod, field


def timed_curve(repeat: int, **kw):
    """Best time of ``repeat`` solves of the curve (after one warm-up scale) and the result."""
    import coilrod

    rod, field = problem()
    coilrod.solve_fem(rod, field, SCALES[:1], **kw)  # imports, compiled kernels
    best, res = np.inf, None
    for _ in range(repeat):
        t0 = clock()
        res = coilrod.solve_fem(rod, field, SCALES, **kw)
        best = min(best, clock() - t0)
    return best, res


def child(repeat: int) -> None:
    """Solve the curve with whatever coilrod is importable; print time, counters, tips."""
    t, res = timed_curve(repeat)
    st = res.stats
    print(
        json.dumps(
            {
                "time": t,
                "iterations": int(np.sum(res.iterations)),
                "factorizations": st.factorizations,
                "evaluations": st.evaluations,
                "steps": st.steps,
                "tips": res.tip.tolist(),
            }
        )
    )


def run_baseline(path: str, repeat: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(Path(path).resolve()))
    out = subprocess.run(
        [sys.executable, __file__, "--child", "--repeat", str(repeat)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def best_of(fn, repeat: int = 3):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = clock()
        out = fn()
        best = min(best, clock() - t0)
    return best, out


def iteration_parts(res):
    """Time of each part of one Newton iteration at the end state of ``res``."""
    asm = res._asm
    z, s = res._states[-1], float(res.scales[-1])
    t_res, _ = best_of(lambda: asm.evaluate(z, s, tangent=False))
    t_tan, ev = best_of(lambda: asm.evaluate(z, s, tangent=True))
    t_fac, f = best_of(lambda: asm.factorize(ev))
    t_sol, _ = best_of(lambda: f.solve(ev.residual))
    return {"residual": t_res, "tangent": t_tan - t_res, "factor": t_fac, "solve": t_sol}


def section_curve(args):
    import coilrod

    t, res = timed_curve(args.repeat)
    rod, _ = problem()
    L = rod.length
    st = res.stats
    emit("## 1. Default 3D Circle curve: seed rod M(1), Helmholtz pair, scales 0.1 ... 1")
    emit()
    emit(
        f"Mesh {coilrod.fem.default_elements(rod, 3)} (length, core, ring), "
        f"{res._asm.nel} Q2 elements, {res._asm.nfree} free displacement dofs; tip at scale 1: "
        f"{np.round(res.tip[-1, :2] / L, 5).tolist()} L."
    )
    emit()
    emit("| code | time (s) | Newton its | factorisations | evaluations | load steps |")
    emit("|---|---|---|---|---|---|")
    emit(
        f"| this checkout | {t:.2f} | {int(np.sum(res.iterations))} | {st.factorizations} | "
        f"{st.evaluations} | {st.steps} |"
    )
    if args.baseline:
        base = run_baseline(args.baseline, args.repeat)
        diff = np.abs(np.array(base["tips"]) - res.tip).max() / L
        emit(
            f"| baseline `{args.baseline}` | {base['time']:.2f} | {base['iterations']} | "
            f"{base['factorizations']} | {base['evaluations']} | {base['steps']} |"
        )
        emit()
        emit(
            f"Ratio this / baseline: **{t / base['time']:.2f}**; largest tip difference over "
            f"the 10 scales: {diff:.1e} L."
        )
    emit()
    parts = iteration_parts(res)
    emit(
        "One Newton iteration at the end state (s): "
        + ", ".join(f"{k} {v:.4f}" for k, v in parts.items())
        + "."
    )
    emit()
    return t, res


def section_skfem(res, t_curve):
    from scipy.sparse.linalg import spsolve

    from coilrod.fem.material import moduli

    asm_ = res._asm
    rod, _ = problem()
    G, K = moduli(rod.youngs_modulus, 0.4995)
    u_full = asm_.full(res._states[-1])
    basis, assemble = skfem_bilinear_tangent(res.mesh, u_full, G, K)
    t_form, Kf = best_of(assemble, 2)
    fixed = basis.get_dofs(lambda x: np.abs(x[0]) < 1e-12).all()
    free = np.setdiff1d(np.arange(basis.N), fixed)
    Kff = Kf[free][:, free].tocsc()
    b = np.ones(free.size)
    t_spsolve, _ = best_of(lambda: spsolve(Kff, b), 2)
    n = res.stats.factorizations
    emit("## 2. Plain scikit-fem on the same O-grid")
    emit()
    emit("| | time (s) |")
    emit("|---|---|")
    emit(f"| one tangent assembly, `BilinearForm` (displacement-form neo-Hookean) | {t_form:.3f} |")
    emit(f"| one `spsolve` (SuperLU) of that tangent on the free dofs | {t_spsolve:.3f} |")
    emit(f"| {n} of each (the factorisations coilrod needed) | {n * (t_form + t_spsolve):.2f} |")
    emit(f"| whole coilrod curve (section 1) | {t_curve:.2f} |")
    emit(
        f"| ratio coilrod curve / ({n} plain assemblies + solves) | "
        f"**{t_curve / (n * (t_form + t_spsolve)):.2f}** |"
    )
    emit()


def section_meshes(res_default, t_default):
    import coilrod

    rod, field = problem()
    L = rod.length
    cases = [(10, 1, 1), (20, 1, 1), (20, 2, 1), (40, 2, 1)]
    runs = {}
    for el in cases:
        if el == (20, 2, 1):
            runs[el] = (t_default, res_default)
            continue
        t0 = clock()
        res = coilrod.solve_fem(rod, field, SCALES, elements=el)
        runs[el] = (clock() - t0, res)
    ref = runs[cases[-1]][1].tip
    t0 = clock()
    rr = coilrod.solve_rod(rod, field, SCALES)
    t_rod = clock() - t0
    emit("## 3. Time against tip error (O-grids; reference: the (40, 2, 1) mesh)")
    emit()
    emit(
        "| model | elements (length, core, ring) | dofs | time (s) | Newton its "
        "| max tip error / L |"
    )
    emit("|---|---|---|---|---|---|")
    for el, (t, res) in runs.items():
        err = np.abs(res.tip - ref).max() / L
        label = f"{err:.1e}" if el != cases[-1] else "(reference)"
        mark = " (default)" if el == (20, 2, 1) else ""
        emit(
            f"| FEM 3D Q2 | {el}{mark} | {res._asm.nfree} | {t:.2f} | "
            f"{int(np.sum(res.iterations))} | {label} |"
        )
    err = np.abs(rr.tip - ref).max() / L
    emit(f"| Kirchhoff rod (`solve_rod`, defaults) | - | - | {t_rod:.2f} | - | {err:.1e} |")
    emit()


def main():
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--baseline", help="a checkout of an older coilrod to time alongside")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="section 1, one run, nothing written")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:  # an older checkout: its kernels compile in the first of the repeats
        compile_at_once(warm_up=False)
        child(args.repeat)
        return
    compile_at_once()
    if args.quick:
        args.repeat = 1
    emit("# FEM benchmark: the default 3D Circle curve (benchmarks/bench_fem3d.py)")
    emit()
    emit(machine_line(f"best of {args.repeat} (section 3: one run)"))
    emit()
    t, res = section_curve(args)
    if args.quick:
        return
    section_skfem(res, t)
    section_meshes(res, t)
    out = Path(__file__).parent / "results" / "fem3d.md"
    out.parent.mkdir(exist_ok=True)
    out.write_text("\n".join(OUT) + "\n")
    print(f"written {out}")


if __name__ == "__main__":
    main()
