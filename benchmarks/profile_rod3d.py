"""Where one spatial rod state spends its time per Newton iteration: this checkout against a
baseline checkout, side by side.

Prints (and writes to benchmarks/results/rod3d_profile.md), one BLAS thread, process CPU
time, best of several runs, the two versions' subprocesses alternating over three rounds:

1. one state of the 3D case of ``bench_rod3d.py`` (oblique uniform field, magnetization with
   an elevation; one mesh, no Richardson) at 4, 16 and 64 segments, and of the same case
   with a field gradient (the mixed layout: positions and forces as unknowns) at 4 and 64:
   the whole ``solve_rod`` call per Newton iteration, and the model's share of one
   iteration (``linearize`` with the tangent, band LU + solve, ``error``, ``step_limit``,
   ``distance``, and a chord trial's ``linearize`` without the tangent) at the converged
   state; 4 segments is the fixed (size-independent) part;
2. a per-phase timer of this checkout (each model method wrapped by a process-time
   accumulator, no profiler), per state, at 4 segments.

Run:  python benchmarks/profile_rod3d.py [--base PATH] [--rounds N]   (PATH: a checkout to
compare with, e.g. ``git archive <commit> coilrod coils | tar -x -C PATH``; skipped if
absent; N: rounds of the two versions alternating, default 3)
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
os.environ.setdefault("MKL_NUM_THREADS", "1")

HERE = Path(__file__).parent
ROUNDS = 3
#: The results file's last section, kept when the file is rewritten (the rounds' history).
ROUNDS_HEADING = "## Rounds"
SEGMENTS = (4, 16, 64)

#: Run in a subprocess against either version (the public API is the same).
CHILD = r"""
import json, sys, time
import numpy as np
import coils
import coilrod.rod._compiled_spatial as cs
cs.COMPILE_AFTER = 0  # the compiled pass from the first call (not the numpy twin on a new cache)
from coilrod import Circle, Magnetization, Rod, solve_rod
L = 0.04
rod = Rod(L, 1e6, Circle(2e-3), Magnetization(128e3, 0.3, elevation=0.4), poisson_ratio=0.5)
d = np.array([0.3, 1.0, 0.5]); d /= np.linalg.norm(d)
field = coils.UniformField(B=rod.field_for_lambda(3.0) * d)
def best(fn, repeat, number):
    fn()
    out = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        for _ in range(number):
            fn()
        out = min(out, (time.process_time() - t0) / number)
    return out
# the mixed layout (positions and forces as unknowns) of a field with a gradient
grad = coils.LinearField(B0=field.B0, gradient=np.diag([-0.5, 1.0, -0.5]) * 1e-2)
out = {}
for n in SEGMENTS + tuple(f"mixed {m}" for m in (4, 64)):
    fld, n = (grad, int(n.split()[1])) if isinstance(n, str) else (field, n)
    key = str(n) if fld is field else f"mixed {n}"
    res = solve_rod(rod, fld, [1.0], nodes=n, richardson=False)
    its = int(res.iterations[0])
    state = best(lambda: solve_rod(rod, fld, [1.0], nodes=n, richardson=False), 7, 10)
    P, U = res._solution.problems[0], np.atleast_2d(res._solution.states[0])
    S = np.array([1.0])
    du = 1e-3 * np.ones_like(U)
    def model():
        lin = P.linearize(U, S)
        P.solve(lin, -lin.residual)
        P.error(lin, du)
        P.step_limit(U, du)
        P.distance(du)
        P.error(P.linearize(U + du, S, tangent=False), du)
    parts = best(model, 7, 100)
    out[key] = {"state": state, "its": its, "per_it": state / its, "model": parts,
              "tip": res.tip[0].tolist()}
print(json.dumps(out))
""".replace("SEGMENTS", repr(SEGMENTS))


def child(path: str) -> dict:
    env = dict(os.environ, PYTHONPATH=path)
    out = subprocess.run(
        [sys.executable, "-c", CHILD], env=env, cwd=path, capture_output=True, text=True,
        check=True,
    )  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def _best(a, b):
    if a is None:
        return b
    return {
        n: {key: min(a[n][key], b[n][key]) if key != "tip" else b[n][key] for key in b[n]}
        for n in b
    }


def phase_timer(states: int = 200, segments: int = 4):
    """CPU ms per state of the model's methods and the engine around them (this checkout)."""
    sys.path.insert(0, str(HERE))
    from _machine import phase_timers, reset
    from bench_rod3d import _case

    from coilrod.path import corrector, stepping
    from coilrod.rod import _compiled_spatial

    _compiled_spatial.COMPILE_AFTER = 0
    from coilrod.rod import solve as solve_module
    from coilrod.rod.spatial import SpatialRod

    targets = [
        ("solve_rod (whole call)", solve_module, "solve_rod"),
        ("  follow_load (path engine)", solve_module, "follow_load"),
        ("    newton (corrector)", stepping, "newton"),
        ("      line search (one state)", corrector._One, "_line_search"),
        ("model stability (inertia count)", SpatialRod, "stability"),
        ("  build_spatial_problem", solve_module, "build_spatial_problem"),
        ("model linearize (all)", SpatialRod, "linearize"),
        ("model solve (all)", SpatialRod, "solve"),
        ("model error (all)", SpatialRod, "error"),
        ("model step_limit (all)", SpatialRod, "step_limit"),
        ("model distance (all)", SpatialRod, "distance"),
        ("model event_fraction (all)", SpatialRod, "event_fraction"),
    ]
    rod, field = _case()
    with phase_timers(targets) as acc:
        run = lambda: solve_module.solve_rod(rod, field, [1.0], nodes=segments, richardson=False)  # noqa: E731
        run()
        reset(acc)
        for _ in range(states):
            run()
    rows = [(label, n / states, 1e3 * t / states) for label, (n, t) in acc.items()]
    model = sum(ms for label, _, ms in rows if label.startswith("model"))
    whole = rows[0][2]
    rows.append(("model methods (sum of the above)", float("nan"), model))
    rows.append(("the rest: path engine, setup, result", float("nan"), whole - model))
    return rows


def main(base: str, rounds: int = ROUNDS) -> str:
    lines = []

    def out(text=""):
        print(text)
        lines.append(text)

    sys.path.insert(0, str(HERE))
    from _machine import machine_info

    here = str(HERE.parent)
    have_base = Path(base, "coilrod").is_dir()
    new = old = None
    for _ in range(rounds):
        new = _best(new, child(here))
        if have_base:
            old = _best(old, child(base))
    out("# Spatial rod: per-iteration overhead and profile")
    out()
    out(
        f"Machine: {machine_info()}. One BLAS thread, process CPU time, best of 7 x {rounds} "
        "rounds."
    )
    out()
    out("## 1. One 3D state (bench_rod3d.py section 2 case, one mesh, no Richardson)")
    out()
    out("`state / it`: the whole `solve_rod` call per Newton iteration; `model / it`: the "
        "model's calls of one iteration (linearize with tangent, LU + solve, error, "
        "step_limit, distance, a chord trial without tangent + its error) at the converged "
        "state.")  # fmt: skip
    out()
    out("| segments | version | Newton its | state (ms) | state / it (ms) | model / it (ms) |")
    out("|---|---|---|---|---|---|")
    for n in [str(m) for m in SEGMENTS] + ["mixed 4", "mixed 64"]:
        for name, r in (("this", new), ("base", old)):
            if r is None:
                continue
            e = r[n]
            out(
                f"| {n} | {name} | {e['its']} | {1e3 * e['state']:.3f} | "
                f"{1e3 * e['per_it']:.3f} | {1e3 * e['model']:.3f} |"
            )
    if old is not None:
        diff = max(
            max(abs(a - b) for a, b in zip(new[n]["tip"], old[n]["tip"], strict=True)) for n in new
        )  # fmt: skip
        out()
        out(f"Largest tip difference this / base: {diff:.1e} m.")
    out()
    out("Goal (issue 19): <= 0.2 ms per iteration (state / it) at 4-64 segments.")
    out()
    out("## 2. Per-phase timer, this checkout, 200 states at 4 segments (CPU ms per state)")
    out()
    out("| phase | calls / state | CPU ms / state |")
    out("|---|---|---|")
    for label, calls, ms in phase_timer():
        depth = (len(label) - len(label.lstrip())) // 2
        shown = "" if calls != calls else f"{calls:.1f}"
        out(f"| {'. ' * depth}{label.strip()} | {shown} | {ms:.3f} |")
    out()
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", default="/tmp/hs/base", help="checkout to compare with")
    parser.add_argument("--rounds", type=int, default=ROUNDS, help="alternating rounds")
    args = parser.parse_args()
    text = main(args.base, args.rounds)
    target = HERE / "results" / "rod3d_profile.md"
    # the hand-kept history of the rounds (its own section, last) stays
    old = target.read_text() if target.exists() else ""
    if ROUNDS_HEADING in old:
        text += "\n" + old[old.index(ROUNDS_HEADING) :]
    target.write_text(text)
    print(f"written to {target}")
