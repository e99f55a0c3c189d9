"""Friction benchmark: the capstan law as the bending stiffness vanishes, and Coulomb's
push force on a flat wall.

1. A floppy rod drawn round a 90 degree bend (radius 20 mm, lumen 2 mm) by a magnet ahead
   of it (a dipole on the exit axis) wraps the bend's inner wall; sliding, its axial force
   grows across the wrap by exp(mu theta) (theta: the turn of the tangent between points
   on the free straight spans, s = 10 and 55 mm) against the motion -- toward the tip
   while it is inserted, toward the clamp while withdrawn.  The rope limit is EI -> 0 at
   a given tension T, i.e. EI / (T rho^2) -> 0: the pull is raised at fixed EI (E = 1 kPa),
   to 50 or 150 A m^2, for the withdrawal (1 mm, then 1 mm more) and the re-insertion
   (2 mm: the motion reversed under the high tension).  Columns: the relative error of the
   tension ratio against exp(mu theta), by mesh.
2. The same in, back and in again with 7 to 14 insertion steps on the way in (16 segments,
   the pull raised to 150 A m^2 for the reversals): every step count converges, with the
   same re-entry error.  Before, with the pull at 50 A m^2, 7, 12 and 13 steps failed (the
   rod, pushed against friction, folded at a coarse step: such a step is now halved), and
   at 150 A m^2 the re-entry failed 5 um in, at 7 and 12 steps (stick and slip cycled in
   Newton: the stick rows' proximal weight is now 1e-3).
3. A tip bent onto a flat wall parallel to the introducer slides along it: the push force
   at the introducer is mu times the wall's normal reaction (insertion) and minus it
   (withdrawal), exactly.
4. A touch-down within an insertion step: ``insert`` at a held length (the whole 40 mm
   rod of ``tests/test_friction.py``, d = 2 mm, E = 1 MPa, M axial) in a uniform field
   rising from lambda = 0.3 to 1.5, 3 and 4.5 (each interval in 1, 2, 3, 5 or 8 steps):
   its tip touches the rough wall y = 0.2 L (mu = 0.3) within the first interval.  After
   the touch the frictionless shape does not change with the field, so the frictionless
   state is the exact answer with friction too (no friction force): columns
   ``max |f_t / f_n|`` and the tip's largest distance from the frictionless tip (units of
   L), by step count.  Before the touch-down cut both moved with the step count (or the
   insertion failed at the landing).

Every kernel runs compiled (ski-rental thresholds 0, ``_machine.compile_at_once``): the CPU
columns are a warm process's; ``bench_coldstart.py`` measures what a fresh one pays.

Run: ``python benchmarks/bench_friction.py`` (prints markdown tables; ~50 s);
``--quick``: 16 segments, the first pull and step count only (touch-down: 8 segments, 1
and 3 steps).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import coils  # noqa: E402
from coilrod import Circle, Magnetization, Rod, Vessel, Wall, insert  # noqa: E402
from coilrod.errors import ConvergenceError  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _machine import bench_args, compile_at_once, machine_info  # noqa: E402

MU = 0.2


def capstan(nodes: int, pull: float, steps: int | None = None):
    """Rows (direction, EI/(T rho^2), ratio, exp(mu theta), relative error) of an insertion
    round the bend in ``steps`` steps (default 2 nodes / 3; dipole moment 5 A m^2), a
    withdrawal and a re-insertion at ``pull`` A m^2."""
    vessel = Vessel.bend(bend_radius=0.02, angle=np.pi / 2, radius=0.002, straight_before=0.02,
                         straight_after=0.06).with_friction(MU)  # fmt: skip
    mag = Magnetization.segments([0.09, 0.01], [0.0, 128e3], [0.0, 0.0])
    rod = Rod(0.1, 1e3, Circle(1e-3), mag)
    steps = 2 * nodes // 3 if steps is None else steps
    lengths = [*np.linspace(0.015, 0.08, steps), 0.079, 0.078, 0.08]
    fields = [coils.Dipole(moment=(0, m, 0), center=(0.04, 0.14, 0))
              for m in [5.0] * steps + [pull] * 3]  # fmt: skip
    t0 = time.process_time()
    ins = insert(rod, vessel, lengths, fields, nodes=nodes)
    cpu = time.process_time() - t0
    rows = []
    cases = (
        (steps - 1, 1.0, "insert"),
        (steps + 1, -1.0, "withdraw"),
        (steps + 2, 1.0, "re-insert"),
    )
    for k, sign, name in cases:
        s, axial = ins.s(k)[:-1], ins.axial_force(k)
        chord = np.diff(ins.centerline(k), axis=0)
        angle = np.arctan2(chord[:, 1], chord[:, 0])
        t_in, t_out = np.interp([0.01, 0.055], s, axial)
        theta = float(np.ptp(np.interp([0.01, 0.055], s, angle)))
        ratio = (t_out / t_in) ** sign
        ref = np.exp(MU * theta)
        stiff = rod.bending_stiffness / (max(t_in, t_out) * 0.0185**2)
        rows.append((name, nodes, stiff, ratio, ref, ratio / ref - 1, cpu))
    return rows


def flat_wall():
    mag = Magnetization.segments([0.04, 0.01], [0.0, 128e3], [0.0, 0.0])
    rod = Rod(0.05, 1e6, Circle(1e-3), mag)
    wall = Wall((0, 0.004, 0), (0, -1, 0), friction=MU)
    lengths = [0.02, 0.03, 0.035, 0.03]
    ins = insert(rod, wall, lengths, coils.UniformField(B=(0, 0.01, 0)),
                 clamp_position=(0, 0, 0), clamp_rotation=np.eye(3), nodes=32)  # fmt: skip
    return lengths, ins.push_force, ins.wall_force[:, 1]


def touchdown(nodes: int, steps: int, mu: float = 0.3):
    """(max |f_t / f_n| over the steps in contact, largest |tip - frictionless tip| / L) of
    the held-length insertion in a rising field (docstring, item 4) with ``steps`` steps per
    interval; ``mu = 0``: the frictionless insertion itself."""
    L = 0.04
    rod = Rod(L, 1e6, Circle(2e-3), Magnetization(128e3, 0.0))

    def run(mu, steps):
        knots = np.array([0.3, 1.5, 3.0, 4.5])
        grid = np.linspace(0.0, 1.0, steps + 1)[1:]
        lam = [knots[0], *(knots[:-1, None] + np.diff(knots)[:, None] * grid).ravel()]
        fields = [coils.UniformField(B=(0, rod.field_for_lambda(v), 0)) for v in lam]
        wall = Wall((0, 0.2 * L, 0), (0, -1, 0), friction=mu)
        ins = insert(rod, wall, [L] * len(lam), fields, clamp_position=(0, 0, 0),
                     clamp_rotation=np.eye(3), nodes=nodes)  # fmt: skip
        return ins.wall_force[::steps], ins.tip[::steps]

    _, free = run(0.0, 1)
    try:
        wall, tip = run(mu, steps)
    except ConvergenceError:
        return None
    touching = wall[:, 1] > 0
    ratio = float(np.abs(wall[touching, 0] / wall[touching, 1]).max())
    return ratio, float(np.abs(tip - free).max() / L)


def main():
    quick = bench_args(__doc__).quick
    compile_at_once()
    nodes_list, pulls, step_counts = (
        ((16,), (5.0,), (7,)) if quick else ((16, 32), (5.0, 50.0, 150.0), range(7, 15))
    )
    print(f"Machine: {machine_info()}; process CPU time, one run.\n")
    print(f"## Capstan round a bend (mu = {MU})\n")
    print("| step | segments | EI/(T rho^2) | T ratio | exp(mu theta) | rel. error | CPU s |")
    print("|---|---|---|---|---|---|---|")
    for nodes in nodes_list:
        for pull in pulls:
            rows = capstan(nodes, pull)
            for name, n, stiff, ratio, ref, err, cpu in rows[1 if pull != 5.0 else 0 :]:
                print(f"| {name} | {n} | {stiff:.1e} | {ratio:.5f} | {ref:.5f} | {err:+.1e} "
                      f"| {cpu:.2f} |")  # fmt: skip
    print(f"\n## In, back and in again by the number of steps in (16 segments, mu = {MU})\n")
    print("| steps in | re-entry T ratio | exp(mu theta) | rel. error | CPU s |")
    print("|---|---|---|---|---|")
    for steps in step_counts:
        *_, ratio, ref, err, cpu = capstan(16, 150.0, steps)[-1]
        print(f"| {steps} | {ratio:.5f} | {ref:.5f} | {err:+.1e} | {cpu:.2f} |")
    print("\n## A touch-down within an insertion step (held length, rising field, mu = 0.3)\n")
    mults = (1, 3) if quick else (1, 2, 3, 5, 8)
    print("| segments | " + " | ".join(f"{m} step{'s' * (m > 1)}" for m in mults) + " |")
    print("|---|" + "---|" * len(mults))
    for nodes in (8,) if quick else (8, 16, 32):
        cells = []
        for m in mults:
            got = touchdown(nodes, m)
            cells.append("fails" if got is None else f"{got[0]:.1e} / {got[1]:.1e}")
        print(f"| {nodes} | " + " | ".join(cells) + " |")
    print(f"\n## Push force on a flat wall (mu = {MU})\n")
    print("| free length mm | push mN | normal reaction mN | push / (mu N) |")
    print("|---|---|---|---|")
    for length, push, normal in zip(*flat_wall(), strict=True):
        print(f"| {length * 1e3:.0f} | {push * 1e3:.5f} | {normal * 1e3:.5f} | "
              f"{push / (MU * normal):+.9f} |")  # fmt: skip


if __name__ == "__main__":
    main()
