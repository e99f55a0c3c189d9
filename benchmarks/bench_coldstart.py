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
- ``all three``: the three in one process (goal <= 10 s CPU cold, the issue 19 budget).

Then the steady-state speed of the compiled coil kernel against its alternatives on the same
points (the vectorised numpy kernel of ``benchmarks/_numpy_kernel.py`` and magpylib), so that the
cold-start cost can be set against what the kernel saves per evaluation.

Run:  python benchmarks/bench_coldstart.py   (writes benchmarks/results/coldstart.md)
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


def run(args, cache_dir):
    """(CPU s, wall s) of one subprocess with NUMBA_CACHE_DIR=cache_dir."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), PYTHONPATH=str(ROOT))
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, *args], env=env, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall


def cold_and_warm(args):
    with tempfile.TemporaryDirectory() as cache:
        cold = run(args, cache)
        warm = run(args, cache)
    return cold, warm


def kernel_speed(lines):
    """Steady state: the compiled kernel against numpy and magpylib on the same points."""
    import numpy as np

    import coils

    sys.path.insert(0, str(HERE))
    import _numpy_kernel as numpy_kernel

    coil = coils.Coil(0.05, 100, 1.0)
    pts = np.random.default_rng(1).uniform(-0.03, 0.03, (10_000, 3))

    def best(f, n=5):
        f()
        ts = []
        for _ in range(n):
            t0 = time.perf_counter()
            f()
            ts.append(time.perf_counter() - t0)
        return min(ts)

    rows = [
        ("compiled (coils): B + grad B", best(lambda: coil.B_and_gradient(pts))),
        (
            "numpy kernel (9501399): B + grad B",
            best(lambda: numpy_kernel.B_and_gradient(coil, pts)),
        ),
        ("compiled (coils): hessian", best(lambda: coil.hessian(pts))),
        ("numpy kernel (9501399): hessian", best(lambda: numpy_kernel.hessian(coil, pts))),
    ]
    try:
        import magpylib

        loop = magpylib.current.Circle(current=100.0, diameter=0.1)
        rows.append(("magpylib Circle: B only", best(lambda: loop.getB(pts))))
    except ImportError:  # pragma: no cover - magpylib is a dependency, but be tolerant
        pass
    lines += ["", "## Steady state: one loop, 10^4 points (best of 5)", ""]
    lines += ["| kernel | time (ms) |", "|---|---|"]
    lines += [f"| {name} | {1e3 * t:.2f} |" for name, t in rows]


def main():
    lines = ["# Cold start (fresh NUMBA_CACHE_DIR) against warm (cache filled)", ""]
    lines += ["| scenario | cold CPU (s) | cold wall (s) | warm CPU (s) | warm wall (s) |"]
    lines += ["|---|---|---|---|---|"]
    todo = {"--help": ["-m", "coilrod", "--help"]}
    todo |= {name: ["-c", code] for name, code in SCENARIOS.items()}
    for name, args in todo.items():
        (c_cpu, c_wall), (w_cpu, w_wall) = cold_and_warm(args)
        lines.append(f"| {name} | {c_cpu:.2f} | {c_wall:.2f} | {w_cpu:.2f} | {w_wall:.2f} |")
        print(lines[-1], flush=True)
    kernel_speed(lines)
    text = "\n".join(lines) + "\n"
    print(text)
    OUT.write_text(text)


if __name__ == "__main__":
    main()
