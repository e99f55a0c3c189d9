"""Cold start: what a fresh environment pays before its first results, next to the warm times.

Each scenario runs in its own Python subprocess with ``NUMBA_CACHE_DIR`` pointing at a fresh,
empty temporary folder (numba then compiles everything it uses: the state of a new virtual
environment, and of the test suite in CI), then a second time with that folder filled (warm: the
compiled code is loaded from disk). CPU time is the children's user + system time
(``resource.getrusage(RUSAGE_CHILDREN)``), wall time around the subprocess. Scenarios:

- ``--help``: ``python -m coilrod --help`` (goal <= 0.3 s);
- ``coil field``: B, grad B and the hessian of a Helmholtz pair with 3x3-filament windings;
- ``coil rod``: one planar rod state (M(1)) in that pair's real field;
- ``spatial``: one spatial rod state (tilted magnetization, oblique uniform field);
- ``all three``: the three in one process (goal <= 10 s CPU cold, the issue 19 budget);
- ``demo``: ``python -m coilrod demo --quiet`` (the README's quick start; its files go to a
  temporary folder).

Then what each compiled kernel costs to compile (numba's compile events in one process with an
empty cache, the numpy alternatives switched off; the two contact kernels each in a process of
its own, a catheter in a vessel bend), and the steady-state speed of each kernel that
has a numpy alternative (the coil pass, :mod:`coils._vectorised`; the planar mixed kernel,
:mod:`coilrod.rod._mixed_numpy`; the spatial per-node pass, :mod:`coilrod.rod._spatial_numpy`;
the inertia count) next to it, with the number of calls after
which compiling pays: compile cost / (numpy time - compiled time).  The library runs the numpy
alternative until its estimated cost reaches the compile cost (``COMPILE_AFTER``), then
compiles.

This is the benchmark of what a fresh process pays; every other benchmark times the compiled
paths (ski-rental thresholds 0, ``_machine.compile_at_once``).

Run:  python benchmarks/bench_coldstart.py   (writes benchmarks/results/coldstart.md)
      python benchmarks/bench_coldstart.py --help
      python benchmarks/bench_coldstart.py --compare OTHER_TREE ["all three" ...]
      (cold CPU of this tree and another, e.g. ``git archive main | tar -x -C OTHER_TREE``,
      alternating; printed only)
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).parent
ROOT = HERE.parent
OUT = HERE / "results" / "coldstart.md"

COIL = """
import numpy as np, coils
pair = coils.HelmholtzPair(0.08, 100, 2.0, axis="y", winding=(0.01, 0.01), filaments=(3, 3))
pts = np.random.default_rng(0).uniform(-0.02, 0.02, (200, 3))
pair.B(pts); pair.gradient(pts); pair.hessian(pts)
"""
ROD = """
import coils
from coilrod import presets, solve_rod
rod = presets.seed_rod(presets.M1())
solve_rod(rod, coils.HelmholtzPair(0.08, 100, 2.0, axis="y"), [1.0])
"""
SPATIAL = """
import numpy as np, coils
from coilrod import presets, solve_rod
rod = presets.seed_rod(presets.M1())
b = rod.field_for_lambda(3)
solve_rod(rod, coils.UniformField(B=(0.3 * b, b, 0.4 * b)), [1.0], model="spatial")
"""
SCENARIOS = {
    "coil field": COIL,
    "coil rod": ROD,
    "spatial": SPATIAL,
    "all three": COIL + ROD + SPATIAL,
}


def run(args, cache_dir, root=ROOT):
    """(CPU s, wall s) of one subprocess with NUMBA_CACHE_DIR=cache_dir, importing the
    package from ``root``."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), PYTHONPATH=str(root))
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    # cwd: ``python -c`` puts the working folder first on sys.path
    subprocess.run(
        [sys.executable, *args], env=env, check=True, stdout=subprocess.DEVNULL, cwd=root
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall


def cold_and_warm(args, root=ROOT):
    with tempfile.TemporaryDirectory() as cache:
        cold = run(args, cache, root)
        warm = run(args, cache, root)
    return cold, warm


def side_by_side(names, other, repeats):
    """Cold CPU of the scenarios ``names`` for this tree and the tree at ``other`` (e.g. an
    export of main), alternating, ``repeats`` times; printed, not written."""
    todo = {"--help": ["-m", "coilrod", "--help"]}
    todo |= {name: ["-c", code] for name, code in SCENARIOS.items()}
    print("| scenario | this tree: cold CPU (s) | other tree: cold CPU (s) |", flush=True)
    print("|---|---|---|", flush=True)
    for name in names:
        ours, theirs = [], []
        for _ in range(repeats):
            for root, out in ((ROOT, ours), (Path(other), theirs)):
                with tempfile.TemporaryDirectory() as cache:
                    out.append(run(todo[name], cache, root)[0])
        fmt = ", ".join
        print(f"| {name} | {fmt(f'{t:.2f}' for t in ours)} | {fmt(f'{t:.2f}' for t in theirs)} |",
              flush=True)  # fmt: skip


COMPILE_EVENTS = """
import importlib, json, sys, time
from numba.core import event
for name in sys.argv[2].split():  # module:threshold, set to 0: compile what the scenario uses
    module, attr = name.split(":")
    setattr(importlib.import_module(module), attr, 0.0)
starts, out = {}, {}
class Listener(event.Listener):
    def on_start(self, ev):
        starts[id(ev.data["dispatcher"])] = time.process_time()
    def on_end(self, ev):
        d = ev.data["dispatcher"]
        out[d.py_func.__module__ + "." + d.py_func.__name__] = time.process_time() - starts[id(d)]
event.register("numba:compile", Listener())
exec(sys.argv[1])
print(json.dumps(out))
"""
#: the kernels a scenario may compile (callees' compile time is inside their caller's)
KERNELS = {
    "coils._compiled.coaxial_field": "coil pass",
    "coilrod.rod._compiled._mixed_compiled": "planar mixed kernel",
    "coilrod.rod._compiled.band_lu": "band LU",
    "coilrod.rod._compiled.band_solve": "band solve",
    "coilrod.rod._compiled.mixed_error": "planar error measure",
    "coilrod.rod._compiled._odd_blocks_compiled": "out-of-plane blocks (mixed layout)",
    "coilrod.rod._inertia._inertia": "block inertia",
    "coilrod.rod._compiled_spatial.spatial_core": "spatial per-node pass",
    "coilrod.rod._planar_newton._newton": "planar uniform-field Newton corrector",
    "coilrod.rod._compiled_contact.contact_core": "contact terms of a spatial linearization",
    "coilrod.contact._compiled_search.closed_form_search": "vessel's closest-point search",
}
#: the thresholds set to 0 in the scenarios' process (COMPILE_EVENTS)
EVERY_KERNEL = (
    "coils.coaxial:COMPILE_AFTER coilrod.rod._compiled:COMPILE_AFTER "
    "coilrod.rod._compiled:ODD_COMPILE_AFTER coilrod.rod._inertia:COMPILE_AFTER "
    "coilrod.rod._compiled_spatial:COMPILE_AFTER coilrod.rod._planar_newton:COMPILE_AFTER"
)
#: a catheter pressed on a vessel bend's wall (16 segments): the contact kernels, each compiled
#: cold in a process of its own (the shared helpers of the spatial pass included; the rest of
#: the solve on numpy)
CONTACT = """
import numpy as np, coils
from coilrod import Circle, Magnetization, Rod, Vessel, solve_rod
from coilrod.contact.insertion import _default_clamp
rod = Rod(0.025, 1e6, Circle(1e-3), Magnetization.segments([0.015, 0.01], [0, 128e3], [0, 0]))
vessel = Vessel.bend(bend_radius=0.02, angle=np.pi / 2, radius=0.002, straight_before=0.02,
                     straight_after=0.03)
p0, R0 = _default_clamp(vessel)
solve_rod(rod, coils.UniformField(B=(0, 0.01, 0)), [1.0], nodes=16, clamp_position=p0,
          clamp_rotation=R0, obstacles=[vessel], model="spatial", richardson=False,
          stability=False)
"""
CONTACT_NOTE = (
    "The last two rows: each compiled in a process of its own with an empty cache, a catheter "
    "pressed on a vessel bend's wall (16 segments, the rest of the solve on numpy), the helpers "
    "it shares with the spatial per-node pass included; the scenarios above compile neither."
)
CONTACT_KERNELS = (
    "coilrod.rod._compiled_contact:COMPILE_AFTER",
    "coilrod.contact._compiled_search:COMPILE_AFTER",
)
#: a planar state in a uniform field (the uniform-field corrector; no scenario above uses it)
UNIFORM = """
import coils
from coilrod import presets, solve_rod
rod = presets.seed_rod(presets.M1())
solve_rod(rod, coils.UniformField(B=(0, rod.field_for_lambda(5), 0)), [1.0])
"""


def compile_costs():
    """CPU seconds each kernel takes to compile on an empty cache (all three scenarios, the
    numpy alternatives switched off; each contact kernel in a process of its own, the
    catheter in a bend of :data:`CONTACT`)."""
    import json

    runs = [(COIL + ROD + SPATIAL + UNIFORM, EVERY_KERNEL)]
    runs += [(CONTACT, threshold) for threshold in CONTACT_KERNELS]
    costs = {}
    for code, thresholds in runs:
        with tempfile.TemporaryDirectory() as cache:
            env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(ROOT))
            res = subprocess.run(
                [sys.executable, "-c", COMPILE_EVENTS, code, thresholds],
                env=env, check=True, capture_output=True,
            )  # fmt: skip
        costs |= json.loads(res.stdout.decode().splitlines()[-1])
    return costs


def best(f, n=5):
    """Least CPU seconds of one call of f over n repetitions of enough calls for 20 ms."""
    f()
    reps = 1
    while True:
        t0 = time.process_time()
        for _ in range(reps):
            f()
        if time.process_time() - t0 > 0.02:
            break
        reps *= 4
    ts = []
    for _ in range(n):
        t0 = time.process_time()
        for _ in range(reps):
            f()
        ts.append((time.process_time() - t0) / reps)
    return min(ts)


def coil_rows():
    """(case, compiled s, numpy s) of the coil pass at the sizes a rod solve, the coil-field
    scenario and a field map use."""
    import math

    import numpy as np

    import coils
    import coils.coaxial as cx

    cx._rental.held = lambda: False
    pair = coils.HelmholtzPair(0.08, 100, 2.0, axis="y")
    wound = coils.HelmholtzPair(0.08, 100, 2.0, axis="y", winding=(0.01, 0.01), filaments=(3, 3))
    rng = np.random.default_rng(1)
    cases = [
        ("pair, 65 nodes (a rod solve), B + grad B + hessian", pair, 65),
        ("pair 3x3 filaments, 200 points, B + grad B + hessian", wound, 200),
        ("pair, 10^4 points (a field map), B + grad B + hessian", pair, 10_000),
    ]
    rows = []
    for name, field, n in cases:
        pts = rng.uniform(-0.02, 0.02, (n, 3))
        times = []
        for ready, after in ((True, 0.0), (False, math.inf)):
            cx._rental.ready, cx.COMPILE_AFTER = ready, after
            times.append(best(lambda f=field, p=pts: f.B_gradient_hessian(p)))
        rows.append((name, *times))
    cx._rental.ready, cx.COMPILE_AFTER = False, 3.0
    return rows


def rod_rows():
    """(case, compiled s, numpy s) of the planar mixed kernel (with the Jacobian) at 65 nodes
    and of the block inertia count."""
    import numpy as np

    from coilrod.rod._compiled import _mixed_compiled
    from coilrod.rod._mixed_numpy import mixed_assembly_numpy

    rng = np.random.default_rng(2)
    k, n = 1, 65
    U = rng.normal(size=(k, 5 * n))
    args = [U, np.ones(k), rng.normal(size=(k * n, 3)), rng.normal(size=(k * n, 3, 3))]
    args += [rng.normal(size=(k * n, 3, 3, 3)), True, 0.1, rng.normal(size=(n, 2))]
    args += [np.full(n - 1, 1 / 64), np.full(n, 1 / 64), 0.0, True, np.empty_like(U)]
    args += [np.empty_like(U), np.zeros((21, 5 * n * k), order="F"), np.empty(k, dtype=bool)]
    rows = [
        (
            "planar mixed kernel, 65 nodes, residual + Jacobian",
            best(lambda: _mixed_compiled(*args)),
            best(lambda: mixed_assembly_numpy(*args)),
        )
    ]
    rows.append(("spatial per-node pass, 65 nodes, residual + Jacobian", *spatial_times()))
    from coilrod.rod._inertia import _inertia, _inertia_numpy

    for b, what in ((3, "a planar rod's out-of-plane count"), (12, "a spatial rod's count")):
        D, E = rng.normal(size=(1, 65, b, b)), rng.normal(size=(1, 64, b, b))
        out = (np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), 1e-13)
        rows.append(
            (
                f"block inertia, 65 blocks of {b}x{b} ({what})",
                best(lambda D=D, E=E, o=out: _inertia(D, E, *o)),
                best(lambda D=D, E=E, o=out: _inertia_numpy(D, E, *o)),
            )
        )
    return rows


def spatial_times():
    """(compiled s, numpy s) of the spatial per-node pass with the Jacobian, one member of 65
    nodes in a coil pair's field (the arguments :meth:`SpatialRod._assemble` passes)."""
    import numpy as np

    import coils
    from coilrod.rod import so3
    from coilrod.rod._compiled_spatial import spatial_core
    from coilrod.rod._spatial_numpy import spatial_core_numpy
    from coilrod.rod.mesh import RodMesh
    from coilrod.rod.spatial import SpatialRod

    rng = np.random.default_rng(4)
    field = coils.HelmholtzPair(0.05, 100, 2.0, axis="y")
    rod = SpatialRod(
        RodMesh(64), rng.normal(size=(65, 3)), [0.6, 4.0, 1.0], field, 0.04, np.zeros(3),
        so3.expm(np.array([0.3, -0.2, 0.5])),
    )  # fmt: skip
    U = (rod.straight() + 0.2 * rng.normal(size=rod.size))[None]
    captured = {}
    rod._assemble(U, np.ones(1), True, core=lambda *a: captured.setdefault("args", a))
    args = captured["args"]
    return best(lambda: spatial_core(*args)), best(lambda: spatial_core_numpy(*args))


def kernel_speed(lines, costs):
    """Steady state of each kernel with a numpy alternative, and where compiling pays."""
    names = {"coil": "coils._compiled.coaxial_field", "planar": "coilrod.rod._compiled."}
    lines += ["", "## Compile cost of each kernel (empty cache, CPU s, callees included)", ""]
    lines += ["| kernel | compile CPU (s) |", "|---|---|"]
    lines += [f"| {KERNELS[k]} (`{k}`) | {costs[k]:.2f} |" for k in KERNELS if k in costs]
    lines += ["", CONTACT_NOTE]
    lines += ["", "## Steady state: compiled against the numpy alternative (best of 5, CPU)", ""]
    lines += ["| kernel and size | compiled (ms) | numpy (ms) | compiling pays after |"]
    lines += ["|---|---|---|---|"]
    coil_cost = costs.get(names["coil"], float("nan"))
    rod_cost = costs.get(names["planar"] + "_mixed_compiled", float("nan"))
    inertia_cost = costs.get("coilrod.rod._inertia._inertia", float("nan"))
    spatial_cost = costs.get("coilrod.rod._compiled_spatial.spatial_core", float("nan"))
    rows = [(row, coil_cost) for row in coil_rows()]
    for row in rod_rows():
        name = row[0]
        cost = rod_cost
        if "inertia" in name:
            cost = inertia_cost
        elif name.startswith("spatial"):
            cost = spatial_cost
        rows.append((row, cost))
    for (name, tc, tn), cost in rows:
        calls = cost / (tn - tc)
        lines.append(f"| {name} | {1e3 * tc:.3f} | {1e3 * tn:.3f} | {calls:,.0f} calls |")
        print(lines[-1], flush=True)


def main():
    if len(sys.argv) > 1:  # --compare OTHER_TREE [SCENARIO ...]: side by side, cold only
        import argparse

        parser = argparse.ArgumentParser(
            description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
        )
        parser.add_argument("--compare", required=True, help="another tree's root folder")
        parser.add_argument("--repeats", type=int, default=2)
        parser.add_argument("scenarios", nargs="*", default=["spatial", "all three"])
        opts = parser.parse_args()
        side_by_side(opts.scenarios, opts.compare, opts.repeats)
        return
    sys.path.insert(0, str(HERE))
    from _machine import machine_info

    lines = ["# Cold start (fresh NUMBA_CACHE_DIR) against warm (cache filled)", ""]
    lines += [f"Machine: {machine_info()}; one run of each scenario.", ""]
    lines += ["| scenario | cold CPU (s) | cold wall (s) | warm CPU (s) | warm wall (s) |"]
    lines += ["|---|---|---|---|---|"]
    todo = {"--help": ["-m", "coilrod", "--help"]}
    todo |= {name: ["-c", code] for name, code in SCENARIOS.items()}
    with tempfile.TemporaryDirectory() as demo_out:
        todo["demo"] = ["-m", "coilrod", "demo", "--quiet", "--out", demo_out]
        for name, args in todo.items():
            (c_cpu, c_wall), (w_cpu, w_wall) = cold_and_warm(args)
            row = f"| {name} | {c_cpu:.2f} | {c_wall:.2f} | {w_cpu:.2f} | {w_wall:.2f} |"
            lines.append(row)
            print(row, flush=True)
    costs = compile_costs()
    kernel_speed(lines, costs)
    lines += ["", f"Machine at the end: {machine_info()}"]
    text = "\n".join(lines) + "\n"
    print(text)
    OUT.write_text(text)


if __name__ == "__main__":
    main()
