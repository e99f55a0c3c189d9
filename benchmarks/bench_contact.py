"""Contact benchmark: convergence of distributed contact and the cost of a contact state.

1. A cantilever laid on a flat floor by a body force per length q (a gradient field on an
   axial magnetization; graded magnetization for a non-uniform q = q0 (1 + 2 s^2 / L^2)):
   where the rod lies flat the contact force per length is q(s) exactly (no curvature, no
   shear), so max |p / q - 1| over 0.7 L < s < 0.95 L measures the discrete contact force.
   Contact is at the corners of the rod's polygon and the tip (coilrod.rod.spatial).
2. Newton iterations of a contact state against the free state in the same (mixed) layout
   at 16-128 segments (tip on a wall, the flat support, a catheter in a vessel bend), and an
   insertion through a bend (50 steps, 48 segments); the spatial and contact kernels
   compiled (compiled at the start if numba's cache does not hold them), and the contact
   kernel's cold compile cost (a fresh process on an empty cache).

Run: ``python benchmarks/bench_contact.py`` (prints markdown tables; ~1 min).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _machine import bench_args, machine_info  # noqa: E402

import coils  # noqa: E402
from coilrod import Circle, Magnetization, Rod, Vessel, Wall, insert, solve_rod  # noqa: E402

L = 0.04
M0 = 128e3


def flat_support(graded: bool, segments: int):
    """(max |p/q - 1| on the flat part, Newton iterations, CPU s)."""
    if graded:
        mag = Magnetization(lambda s: M0 * (1 + 2 * (np.asarray(s) / L) ** 2), 0.0)
    else:
        mag = Magnetization(M0, 0.0)
    rod = Rod(L, 1e6, Circle(2e-3), mag)
    q0 = rod.bending_stiffness / L**3
    G = np.zeros((3, 3))
    G[0, 1] = -q0 / (rod.area * M0)
    floor = Wall((0, -1e-3 * L - 1e-3, 0), (0, 1, 0))  # 1e-3 L below the 2 mm rod's surface
    t0 = time.process_time()
    res = solve_rod(rod, coils.LinearField(B0=(0, 0, 0), gradient=G), [1.0], nodes=segments,
                    richardson=False, obstacles=[floor], stability=False)  # fmt: skip
    cpu = time.process_time() - t0
    s = res.contact_s
    inner = (s > 0.7 * L) & (s < 0.95 * L)
    q = q0 * (1 + 2 * (s[inner] / L) ** 2) if graded else q0
    err = np.abs(res.contact_force(0)[inner, 1] / q - 1).max()
    return err, int(res.iterations[0]), cpu


def _best_cpu(run, repeats=3):
    """(least CPU s of ``repeats`` calls, the last call's result)."""
    best = np.inf
    for _ in range(repeats):
        t0 = time.process_time()
        out = run()
        best = min(best, time.process_time() - t0)
    return best, out


def free_against_contact(segments: int):
    """CPU s (best of three) and Newton iterations of the tip-contact cantilever and of the
    same load free, both by the spatial rod in its mixed layout (a gradient field; the
    planar rod would solve the free state alone)."""
    rod = Rod(L, 1e6, Circle(2e-3), Magnetization(M0, 0.0))
    b = rod.field_for_lambda(6.0)
    # a negligible gradient: the free state in the mixed layout too (a uniform field would
    # solve it in rotations alone)
    field = coils.LinearField(B0=(0, b, 0), gradient=1e-9 * np.diag([-0.5, 1.0, -0.5]))
    out = []
    for obstacles in (None, [Wall((0, 0.2 * L, 0), (0, -1, 0))]):
        cpu, res = _best_cpu(
            lambda obstacles=obstacles: solve_rod(
                rod, field, [1.0], nodes=segments, richardson=False, obstacles=obstacles,
                stability=False, model="spatial",
            )
        )  # fmt: skip
        out.append((cpu, int(res.iterations.sum())))
    return out


def bend_state(segments: int):
    """CPU s (best of three) and Newton iterations of a catheter pressed on the outer wall of
    a vessel bend by a field across it, and of the same load free (spatial rod, mixed
    layout)."""
    from coilrod.contact.insertion import _default_clamp

    mag = Magnetization.segments([0.015, 0.01], [0.0, 128e3], [0.0, 0.0])
    cath = Rod(0.025, 1e6, Circle(1e-3), mag)
    vessel = Vessel.bend(bend_radius=0.02, angle=np.pi / 2, radius=0.002,
                         straight_before=0.02, straight_after=0.03)  # fmt: skip
    p0, R0 = _default_clamp(vessel)
    field = coils.LinearField(B0=(0, 0.01, 0), gradient=1e-9 * np.diag([-0.5, 1.0, -0.5]))
    out = []
    for obstacles in (None, [vessel]):
        cpu, res = _best_cpu(
            lambda obstacles=obstacles: solve_rod(
                cath, field, [1.0], nodes=segments, richardson=False, clamp_position=p0,
                clamp_rotation=R0, obstacles=obstacles, stability=False, model="spatial",
            )
        )  # fmt: skip
        out.append((cpu, int(res.iterations.sum())))
    return out


def insertion():
    """(CPU s, best of three; Newton solves; Newton iterations) of an insertion through a
    90 deg bend, 50 steps, 48 segments.  Each step starts from the solution of the
    linearised complementarity problem at the carried shape
    (coilrod.rod.contact_predictor.active_set_start).  Its stability count per step runs
    compiled once that is in numba's cache (or once an insertion long enough to pay for
    compiling announces its counts), else on its numpy path (~0.3 s more here)."""
    import coilrod.contact.insertion as insertion

    mag = Magnetization.segments([0.04, 0.01], [0.0, 128e3], [0.0, 0.0])
    cath = Rod(0.05, 1e6, Circle(1e-3), mag)
    vessel = Vessel.bend(bend_radius=0.02, angle=np.pi / 2, radius=0.002,
                         straight_before=0.02, straight_after=0.03)  # fmt: skip

    def schedule(k, length):
        a = np.pi / 2 * min(1.0, max(0.0, (length - 0.015) / 0.02))
        return coils.UniformField(B=0.01 * np.array([np.cos(a), np.sin(a), 0.0]))

    def run():
        return insert(cath, vessel, np.linspace(0.012, 0.05, 50), schedule, nodes=48)

    cpu, ins = _best_cpu(run)
    # the Newton iterations of one more run (counted outside the timed ones)
    count, newton = [0], insertion.newton

    def counted(*args, **kwargs):
        res = newton(*args, **kwargs)
        count[0] += int(res.iterations)
        return res

    insertion.newton = counted
    try:
        run()
    finally:
        insertion.newton = newton
    return cpu, int(ins.substeps.sum()), count[0]


_COMPILE_SCRIPT = """
import time
import numpy as np
t0 = time.process_time()
from coilrod.rod._compiled_contact import contact_core
t1 = time.process_time()
k, n, nc, nv = 1, 3, 1, 10
ab = np.zeros((4, n * nv), order="F")
contact_core(np.ones((k, n, nc)), np.zeros((k, n, nc)), np.ones((k, n, nc, 3)),
             np.zeros((k, n, nc, 3, 3)), np.zeros((k, n, 3, 3)), np.zeros((k, n, 3)),
             np.zeros((k, n, 10, 3, 3)), np.ones(n), np.ones(n), 1.0, 1.0, 0, True,
             np.zeros((k, n, nv)), ab, 1, np.zeros((k, n, 3, 3, 3)), np.zeros((k, n, 3)),
             np.zeros((k, n, nc, 3)))
print(time.process_time() - t1)
"""


def contact_compile_cost() -> float:
    """CPU s of compiling the contact kernel (coilrod.rod._compiled_contact) on an empty numba
    cache (a fresh process; the helpers it shares with the spatial kernel included)."""
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        out = subprocess.run([sys.executable, "-c", _COMPILE_SCRIPT], env=env, check=True,
                             capture_output=True, text=True).stdout  # fmt: skip
    return float(out.split()[-1])


def main() -> None:
    warnings.simplefilter("ignore")
    # the compiled spatial and contact kernels and the contact predictor's event steps from
    # the first call (compiled now if numba's cache does not hold them): the tables measure
    # compiled code
    import coilrod.rod._compiled as band_kernels
    import coilrod.rod._compiled_contact as contact_kernel
    import coilrod.rod._compiled_spatial as spatial_kernel

    price = contact_kernel.COMPILE_AFTER
    spatial_kernel.COMPILE_AFTER = contact_kernel.COMPILE_AFTER = 0.0
    band_kernels.EVENTS_COMPILE_AFTER = 0.0
    print("# Contact: convergence and cost")
    print()
    print(f"Machine: {machine_info()}; CPU time, one run.")
    print()
    print("## Distributed contact on a flat support (contact at the polygon's corners)")
    print()
    print("| segments | uniform q: max abs(p/q - 1) | iterations | q = 1 + 2 s^2: max "
          "abs(p/q - 1) | rate | iterations | CPU (s) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    prev = None
    for n in (16, 32, 64, 128):
        e_u, it_u, _ = flat_support(False, n)
        e_g, it_g, cpu = flat_support(True, n)
        rate = "-" if prev is None else f"{np.log2(prev / e_g):.2f}"
        print(f"| {n} | {e_u:.1e} | {it_u} | {e_g:.2e} | {rate} | {it_g} | {cpu:.2f} |")
        prev = e_g
    print()
    print("## A contact state against the free state (Newton iterations, mixed layout)")
    print()
    print("Tip on a wall (cantilever, lambda = 6), the flat support above (uniform q), and a")
    print("catheter pressed on the outer wall of a 90 deg bend by a field across it; the free")
    print("state is the same load without the obstacle, by the same spatial rod (CPU: best of")
    print("three).  A load step that crosses a change of")
    print("the contact set is predicted by the linearised complementarity problem of the active")
    print("set (coilrod.rod.contact_predictor); complementarity by the min function.")
    print("An insertion step keeps Fischer-Burmeister and starts from the solution of the")
    print("linearised complementarity problem at the carried shape (its contact set by an")
    print("active-set iteration on one linearization).")
    print()
    print("| segments | tip: free | tip: contact | ratio | CPU ratio | flat support | "
          "bend: free | bend: contact | ratio | CPU ratio |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    free_against_contact(16)  # warm up (imports, compiled kernels)
    for n in (16, 32, 64, 128):
        (tf, itf), (tc, itc) = free_against_contact(n)
        _, it_flat, _ = flat_support(False, n)
        (tbf, itbf), (tbc, itbc) = bend_state(n)
        print(f"| {n} | {itf} | {itc} | {itc / itf:.2f} | {tc / tf:.1f} | {it_flat} | {itbf} | "
              f"{itbc} | {itbc / itbf:.2f} | {tbc / tbf:.1f} |")  # fmt: skip
    print()
    cpu, solves, iterations = insertion()
    print(f"Insertion through a bend, 50 steps, 48 segments: {cpu:.2f} s CPU (best of three), "
          f"{solves} solves, {iterations} Newton iterations.")  # fmt: skip
    print()
    print(f"Compiling the contact kernel on an empty numba cache: {contact_compile_cost():.1f} s "
          f"CPU (its ski rental's price: {price:.1f} s).")  # fmt: skip
    print()


if __name__ == "__main__":
    bench_args(__doc__, quick_help="not used: this benchmark has one size")  # --help: the docstring
    main()
