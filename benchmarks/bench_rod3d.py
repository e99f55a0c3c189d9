"""The spatial rod and contact: time against tip error, next to the obvious alternatives.

Prints (and writes to benchmarks/results/rod3d.md):

1. planar cases solved by both models (M(1) in a uniform field and in a Helmholtz pair's real
   field): the spatial rod's time over the planar rod's (goal <= 5x) and their tip difference;
2. a genuinely 3D state (magnetization with an elevation, an oblique field, a rectangular
   section): time and tip error against the node count, next to scipy ``solve_bvp`` on the 3D
   Kirchhoff equations (tests/rod3d_bvp_reference.py) at tol 1e-6 and 1e-8; the error
   reference is that solve at tol 1e-11;
3. PyElastica 1.0 dynamic relaxation of the same non-dimensional problem
   (benchmarks/peers/pyelastica_spatial.py, run in its own environment; its JSON in
   benchmarks/results/pyelastica_spatial.json): time and tip error against ours;
4. contact: a state pushed against a wall against the free state at the same node count
   (goal <= 3x), and an insertion of 50 steps through a bend (goal <= 2 s on one core);
5. the cost of one Newton iteration of the 3D state of section 2 (one mesh, no Richardson):
   per iteration at 4 and 64 segments (the part that does not scale with the mesh is the
   fixed cost) and the model's parts at the converged state (evaluation with and without the
   tangent, the compiled per-node pass alone, band solve, convergence measure), and a 50-step
   sweep to the same load.  ``profile_rod3d.py`` breaks the per-iteration cost down further
   (side by side with another checkout; results/rod3d_profile.md).

Timings: process CPU time (``BENCH_CLOCK=wall`` for wall clock), best of ``REPEAT`` runs (3 for
solve_bvp and the insertion), every kernel compiled from its first call (ski-rental thresholds
0, ``_machine.compile_at_once``: the steady state; ``bench_coldstart.py`` measures what a fresh
process pays).  Section 3 reads PyElastica's JSON (PyElastica runs in its own environment); where
there is none it says so and is skipped.

Run:  python benchmarks/bench_rod3d.py
      python benchmarks/bench_rod3d.py --quick   (sections 1-3 at 64 segments, one run, printed)
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

import coilrod
import coils
from coilrod import Circle, Magnetization, Rod, presets, solve_rod

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
from _machine import (  # noqa: E402
    bench_args,
    best_run,
    best_time,
    clock_name,
    compile_at_once,
    machine_info,
)
from rod3d_bvp_reference import spatial_reference  # noqa: E402

REPEAT = 5
NODES = (8, 16, 32, 64, 128, 256)
OUT = HERE / "results" / "rod3d.md"
L = 0.04


def best(fn, repeat=None):
    """Smallest time (s, process CPU unless ``BENCH_CLOCK=wall``) of ``repeat`` calls of ``fn``
    (default ``REPEAT``), and the last call's result."""
    return best_run(fn, REPEAT if repeat is None else repeat)


def timing() -> str:
    return f"{clock_name()} time, best of {REPEAT}."


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def planar_cases(lines):
    lines += ["## 1. Planar cases by both models", "", timing(), ""]
    lines += ["| case | planar (s) | spatial (s) | ratio | tip difference / L |"]
    lines += ["|---|---|---|---|---|"]
    rod = presets.seed_rod(presets.M1())
    cases = {
        "M(1), uniform field, lambda = 5": coils.UniformField(B=(0, rod.field_for_lambda(5), 0)),
        "M(1), Helmholtz pair (real field)": coils.HelmholtzPair(0.05, 100, 2.0, axis="y"),
        "M(1), uniform, 10-step sweep": coils.UniformField(B=(0, rod.field_for_lambda(10), 0)),
    }
    ratios = []
    for name, field in cases.items():
        scales = np.linspace(0.1, 1, 10) if "sweep" in name else [1.0]
        tp, rp = best(lambda f=field, s=scales: solve_rod(rod, f, s, model="planar"))
        ts, rs = best(lambda f=field, s=scales: solve_rod(rod, f, s, model="spatial"))
        diff = np.abs(rp.tip - rs.tip).max() / rod.length
        ratios.append(ts / tp)
        lines.append(f"| {name} | {tp:.4f} | {ts:.4f} | {ts / tp:.1f}x | {diff:.1e} |")
    lines += ["", f"Spatial / planar: **{min(ratios):.1f}-{max(ratios):.1f}x** (goal <= 5x).", ""]


def _case():
    """The 3D case: rectangular section, M with angle 0.3 and elevation 0.4 rad, oblique
    uniform field at lambda = 3 (as the PyElastica script, non-dimensionally the same)."""
    rod = Rod(L, 1e6, Circle(2e-3), Magnetization(128e3, 0.3, elevation=0.4), poisson_ratio=0.5)
    field = coils.UniformField(B=rod.field_for_lambda(3.0) * _unit([0.3, 1.0, 0.5]))
    return rod, field


def _reference(rod, field, tol):
    K = np.asarray(rod.stiffnesses, float)
    return spatial_reference(
        rod.length, K, rod.area, rod.magnetization.vector3, field, [1.0], tol=tol
    )[0]


def spatial_case(lines):
    rod, field = _case()
    ref = _reference(rod, field, 1e-11)["tip"]
    lines += ["## 2. A 3D state: time and tip error against node count", ""]
    lines += [
        "M with angle 0.3 rad and elevation 0.4 rad, circular section (GJ = EI / 1.5), uniform "
        "field along (0.3, 1, 0.5) at lambda = 3; reference: solve_bvp on the 3D Kirchhoff "
        f"equations at tol 1e-11.  {timing()} (solve_bvp: best of 3)",
        "",
        "| method | time (s) | tip error / L |",
        "|---|---|---|",
    ]
    out = {}
    for n in NODES:
        for rich in (False, True):
            t, res = best(lambda n=n, r=rich: solve_rod(rod, field, [1.0], nodes=n, richardson=r))
            err = np.linalg.norm(res.tip[0] - ref) / L
            label = f"solve_rod, {n} segments" + (" + Richardson" if rich else "")
            if n == 64 and rich:
                label += " (defaults)"
                out["ours"] = (t, err)
            lines.append(f"| {label} | {t:.4f} | {err:.1e} |")
    for tol in (1e-6, 1e-8):
        t, r = best(lambda tol=tol: _reference(rod, field, tol), 3)
        err = np.linalg.norm(r["tip"] - ref) / L
        out[f"bvp{tol:g}"] = (t, err)
        name = f"scipy solve_bvp (3D Kirchhoff, quaternions), tol {tol:g}"
        lines.append(f"| {name} | {t:.4f} | {err:.1e} |")
    t_ours = out["ours"][0]
    lines += [
        "",
        f"solve_bvp tol 1e-6 / solve_rod: **{out['bvp1e-06'][0] / t_ours:.0f}x** the time; tol "
        f"1e-8: {out['bvp1e-08'][0] / t_ours:.0f}x.",
        "",
    ]
    return out, ref


def pyelastica(lines, ours, ref):
    path = HERE / "results" / "pyelastica_spatial.json"
    lines += ["## 3. PyElastica 1.0 (dynamic relaxation), the same problem", ""]
    if not path.exists():
        try:
            import elastica  # noqa: F401

            here = "PyElastica is installed here"
        except ImportError:
            here = "PyElastica is not installed here"
        lines += [
            f"Skipped: no PyElastica run found ({path.name}; {here}).  PyElastica runs in its "
            "own environment: see benchmarks/peers/pyelastica_spatial.py for the commands, and "
            f"write its JSON to benchmarks/results/{path.name}.",
            "",
        ]
        return
    runs = json.loads(path.read_text())
    t_ours, e_ours = ours
    lines += [
        "PyElastica's rod is extensible and shearable (effects ~1e-4 at L/r = 40) and stops "
        "when the tip moves < 1e-6 L per period of the first mode; numbers from "
        "benchmarks/results/pyelastica_spatial.json (same machine; PyElastica's wall time "
        "against our time in this run).",
        "",
        "| n_elem | time (s) | tip error / L | time / ours | error / ours |",
        "|---|---|---|---|---|",
    ]
    for r in runs:
        err = float(np.linalg.norm(np.asarray(r["tip"]) - ref / L))
        lines.append(
            f"| {r['n_elem']} | {r['wall_s']:.2f} | {err:.1e} | {r['wall_s'] / t_ours:.0f}x | "
            f"{err / e_ours:.0e}x |"
        )
    lines += ["", f"Ours (defaults): {t_ours:.4f} s at {e_ours:.1e} L.", ""]


def contact(lines):
    lines += ["## 4. Contact", "", f"{timing()} (the insertion: best of 3)", ""]
    rod = presets.seed_rod(presets.M1())
    field = coils.UniformField(B=(0, rod.field_for_lambda(3.0), 0))
    wall = coilrod.Wall(point=(0, 0.2 * rod.length, 0), normal=(0, -1, 0))
    t_free, _ = best(lambda: solve_rod(rod, field, [1.0], model="spatial"))
    t_wall, res = best(lambda: solve_rod(rod, field, [1.0], obstacles=[wall]))
    # the free state in the mixed layout (positions and forces as unknowns, as contact has):
    # a field with a small gradient
    grad = coils.LinearField(B0=field.B0, gradient=np.diag([-0.5, 1.0, -0.5]) * 1e-6)
    t_mixed, _ = best(lambda: solve_rod(rod, grad, [1.0], model="spatial"))
    lines += [
        "| state (64 + 128 segments, Richardson) | time (s) | Newton iterations |",
        "|---|---|---|",
        f"| M(1), lambda = 3, free (spatial rod, rotations only) | {t_free:.4f} | |",
        f"| the same, free, mixed layout (a 1e-6 T/m gradient) | {t_mixed:.4f} | |",
        f"| the same against a wall at y = 0.2 L (tip contact) | {t_wall:.4f} | "
        f"{int(res.iterations[0])} |",
        "",
        f"Contact / free: **{t_wall / t_free:.1f}x** the uniform layout, "
        f"**{t_wall / t_mixed:.1f}x** the mixed layout (goal <= 3x); wall force "
        f"{res.obstacle_forces(0)[0][1] * 1e3:.4f} mN.",
        "",
    ]
    vessel = coilrod.Vessel.bend(
        bend_radius=0.02, angle=np.pi / 2, radius=0.002, straight_before=0.02,
        straight_after=0.03,
    )  # fmt: skip
    tip = Magnetization.segments([0.04, 0.01], [0.0, 128e3], [0.0, 0.0])
    cath = Rod(0.05, 1e6, Circle(1e-3), tip)
    lengths = np.linspace(0.012, 0.05, 50)

    def schedule(k, length):
        a = np.pi / 2 * min(1.0, max(0.0, (length - 0.015) / 0.02))
        return coils.UniformField(B=0.01 * np.array([np.cos(a), np.sin(a), 0.0]))

    t_ins, ins = best(lambda: coilrod.insert(cath, vessel, lengths, schedule, nodes=48), 3)
    force = np.linalg.norm(ins.wall_force, axis=1)
    lines += [
        f"Insertion through a 90 deg bend (radius 20 mm, lumen 2 mm), 50 steps, 48 segments: "
        f"**{t_ins:.2f} s** (goal <= 2 s on one core); {int(ins.substeps.sum())} Newton solves; "
        f"largest wall force {force.max() * 1e3:.2f} mN; smallest gap {ins.min_gap.min():.1e} m.",
        "",
    ]


def _per_call(fn, number=200):
    """Best time (s, the clock of benchmarks/_machine.py) per call of ``fn``."""
    return best_time(fn, repeat=5, number=number)


def iteration_cost(lines):
    """Section 5: one Newton iteration of the 3D state, and its parts."""
    from coilrod.rod import _compiled_spatial

    rod, field = _case()
    lines += [
        "## 5. One Newton iteration of the 3D state",
        "",
        f"{clock_name()} time, best of 5.",
        "",
    ]
    lines += [
        "| segments | state (s) | Newton iterations | per iteration (ms) |",
        "|---|---|---|---|",
    ]
    per = {}
    for n in (4, 64):
        res = solve_rod(rod, field, [1.0], nodes=n, richardson=False)
        t = best_time(lambda n=n: solve_rod(rod, field, [1.0], nodes=n, richardson=False), 5)
        its = int(res.iterations[0])
        per[n] = t / its
        lines.append(f"| {n} | {t:.4f} | {its} | {1e3 * per[n]:.3f} |")
    res = solve_rod(rod, field, [1.0], nodes=64, richardson=False)
    P, U = res._solution.problems[0], np.atleast_2d(res._solution.states[0])
    S = np.array([1.0])
    lin = P.linearize(U, S)
    du = 1e-3 * np.ones_like(U)
    captured = {}

    def capture(*args):
        captured["args"] = args
        _compiled_spatial.spatial_core(*args)

    P._assemble(U, S, True, core=capture)
    parts = {
        "evaluation with tangent (`linearize`)": lambda: P.linearize(U, S),
        "evaluation without tangent": lambda: P.linearize(U, S, tangent=False),
        "of which the compiled per-node pass (`spatial_core`)": lambda: (
            _compiled_spatial.spatial_core(*captured["args"])
        ),
        "band LU + solve": lambda: P.solve(P.linearize(U, S), -lin.residual),
        "convergence measure (`error`)": lambda: P.error(lin, du),
        "step length and distance (`step_limit`, `distance`)": lambda: (
            P.step_limit(U, du),
            P.distance(du),
        ),
    }
    times = {name: _per_call(fn) for name, fn in parts.items()}
    times["band LU + solve"] -= times["evaluation with tangent (`linearize`)"]
    lines += ["", "| part (64 segments, uniform layout) | time per call (us) |", "|---|---|"]
    lines += [f"| {name} | {1e6 * t:.1f} |" for name, t in times.items()]
    fixed = (16 * per[4] - per[64]) / 15  # per-iteration time extrapolated to no segments
    scales = np.linspace(0.02, 1.0, 50)
    sweep = solve_rod(rod, field, scales)
    t_sweep = best_time(lambda: solve_rod(rod, field, scales), 3)
    lines += [
        "",
        f"Per-iteration fixed cost (the 4- and 64-segment times extrapolated to no segments): "
        f"**{1e6 * fixed:.0f} us**; 64 segments: {1e6 * per[64]:.0f} us per iteration.  "
        f"50-step sweep to the same load (defaults): {t_sweep:.3f} s, "
        f"{int(sweep.iterations.sum())} Newton iterations.",
        "",
    ]


def main():
    global REPEAT, NODES
    quick = bench_args(__doc__).quick
    compile_at_once()
    if quick:
        REPEAT, NODES = 1, (64,)
    lines = ["# Spatial rod and contact benchmark", "", f"Machine: {machine_info()}", ""]
    planar_cases(lines)
    ours, ref = spatial_case(lines)
    pyelastica(lines, ours["ours"], ref)
    if quick:
        print("\n".join(lines))
        return
    contact(lines)
    iteration_cost(lines)
    text = "\n".join(lines)
    print(text)
    OUT.write_text(text + "\n")


if __name__ == "__main__":
    main()
