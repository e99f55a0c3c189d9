"""Magnet pose benchmark: the pose of a permanent magnet that puts the tip on a target.

Prints (and writes to benchmarks/results/magnet_pose.md): for targets made by the magnet at
known poses (planar and 3D), and the same targets rounded to 0.1 mm,
``coilrod.solve_magnet_pose`` from the same start pose -- forward
solves (in the finite magnet's field, + the scout's cheap ones in its point dipole's field on a
coarse mesh), CPU time in forward-solve equivalents (the pose solve's CPU time over that of one
forward solve at the target's pose, default discretisation), the final miss checked by an
independent forward solve at the magnet returned -- and the dipole controller's miss (the pose
found with the magnet's point dipole, the finite magnet placed there).  Goal (issue 21): a pose
solve <= 20 forward-solve equivalents.  Then one forward solve of the scout (the magnet's point
dipole, ``SCOUT_NODES`` segments, ``SCOUT_STEPS`` load steps) against one real forward solve
(the cylinder, defaults, 10 load steps) at the first target's pose, best of 5 each.

Every kernel runs compiled (ski-rental thresholds 0, ``_machine.compile_at_once``): the
figures are a warm process's; ``bench_coldstart.py`` measures what a fresh one pays.

Run:  python benchmarks/bench_magnet_pose.py
      python benchmarks/bench_magnet_pose.py --quick   (the first planar target, printed only)
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

import coils
from coilrod import presets, solve_magnet_pose, solve_rod

sys.path.insert(0, str(Path(__file__).parent))
from _machine import bench_args, best_times, compile_at_once, machine_info  # noqa: E402

warnings.simplefilter("ignore")
ROD = presets.seed_rod(presets.M1())
L = ROD.length
SCALES = np.arange(1, 11) / 10


def magnet(center=(0.0, -0.06, 0.0), rotvec=(0.0, 0.0, 0.0)):
    """A 20 mm x 20 mm N45-like cylinder (M = 1e6 A/m) magnetised along y, turned by rotvec."""
    R = Rotation.from_rotvec(rotvec).as_matrix() @ START.rotation
    return coils.CylinderMagnet(0.02, 0.02, 1e6, center, orientation=R)


START = coils.CylinderMagnet(0.02, 0.02, 1e6, (0.0, -0.06, 0.0), "y")
CASES = [
    ("planar", (0.01, -0.058, 0.0), (0.0, 0.0, 0.2)),
    ("planar", (-0.008, -0.063, 0.0), (0.0, 0.0, -0.15)),
    ("planar", (0.012, -0.065, 0.0), (0.0, 0.0, 0.35)),
    ("3D", (0.006, -0.06, 0.008), (0.15, 0.0, 0.1)),
    ("3D", (-0.004, -0.062, -0.006), (-0.1, 0.05, -0.1)),
]


def tip(m, planar):
    t = solve_rod(ROD, m, SCALES).tip[-1]
    return t[:2] if planar else t


def scout_cost() -> str:
    """One scout forward solve against one real one (the README's '~1/4'), best of 5 each."""
    from coilrod.control.magnet_pose import SCOUT_NODES, SCOUT_STEPS

    m = magnet(*CASES[0][1:])
    scout_scales = np.arange(1, SCOUT_STEPS + 1) / SCOUT_STEPS
    t_real, t_scout = best_times(
        [
            lambda: solve_rod(ROD, m, SCALES),
            lambda: solve_rod(ROD, m.dipole(), scout_scales, nodes=SCOUT_NODES),
        ],
        repeat=5,
    )
    return (
        f"One scout forward solve (point dipole, {SCOUT_NODES} segments, {SCOUT_STEPS} load "
        f"steps): {t_scout * 1e3:.1f} ms CPU against {t_real * 1e3:.1f} ms for the real one "
        f"(cylinder, defaults, {len(SCALES)} steps): **{t_scout / t_real:.2f}x**."
    )


def main():
    quick = bench_args(__doc__).quick
    compile_at_once()
    cases = [CASES[0] + (False,)] if quick else [c + (r,) for c in CASES for r in (False, True)]
    out = ["# Magnet pose benchmark\n", machine_info(), ""]
    out.append(
        "| case | target (mm) | forward solves (+ scout) | forward-solve equivalents (time) | "
        "CPU (s) | miss (L) | dipole controller's miss (mm, % L) |"
    )
    out.append("|---|---|---|---|---|---|---|")
    tip(START, True)  # compile (the real model's forward solve) ...
    solve_magnet_pose(ROD, START, tip(START, True))  # ... and the scout's (met at the start)
    eqs, t_all = [], []
    for kind, c, rv, rounded in cases:
        planar = kind == "planar"
        goal = tip(magnet(c, rv), planar)
        if rounded:  # the target as a user types it: to 0.1 mm, off the poses tried
            goal = np.round(goal, 4)
            kind += ", 0.1 mm"
        t0 = time.process_time()
        for _ in range(3):
            tip(magnet(c, rv), planar)
        t_forward = (time.process_time() - t0) / 3  # one forward solve at the target's pose
        t_all.append(t_forward)
        t0 = time.process_time()
        try:
            res = solve_magnet_pose(ROD, START, goal)
            status, m_at = res.status, res.magnet
            solves = f"{res.solves} (+ {res.scout_solves})"
        except Exception as err:  # report, do not hide
            res = getattr(err, "result", None)
            status = f"error: {type(err).__name__}"
            solves = f"{res.solves} (+ {res.scout_solves})" if res is not None else "0"
            m_at = res.magnet if res is not None else None
        t = time.process_time() - t0
        eq = t / t_forward
        eqs.append(eq)
        miss = np.linalg.norm(tip(m_at, planar) - goal) / L if m_at is not None else np.nan
        try:
            d = solve_magnet_pose(ROD, START, goal, model="dipole")
            dip = f"{d.miss * 1e3:.3f} mm, {d.miss_percent:.2f} %"
        except Exception as err:
            dip = f"error: {type(err).__name__}"
        out.append(
            f"| {kind} ({status}) | {np.round(np.asarray(goal) * 1e3, 2).tolist()} | {solves} | "
            f"{eq:.1f} | {t:.2f} | {miss:.1e} | {dip} |"
        )
        print(out[-1], flush=True)
    out.append("")
    out.append(
        f"One forward solve (at the target's pose): {np.median(t_all) * 1e3:.0f} ms CPU.  "
        f"Forward-solve equivalents: median {np.median(eqs):.1f}, max {np.max(eqs):.1f} "
        "(goal <= 20)."
    )
    out.append("")
    out.append(scout_cost())
    text = "\n".join(out) + "\n"
    print(text)
    if not quick:
        (Path(__file__).parent / "results" / "magnet_pose.md").write_text(text)


if __name__ == "__main__":
    main()
