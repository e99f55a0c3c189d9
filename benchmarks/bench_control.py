"""Control benchmark: currents for a target tip position on a three-pair system.

Prints (and writes to benchmarks/results/control.md): for targets across the workspace of M(1)
in a compact three-axis Helmholtz system (radii 40-60 mm), ``coilrod.solve_currents`` (exact
current sensitivities, minimum-power Gauss-Newton) against scipy ``least_squares`` on the
currents with finite-difference Jacobians (the obvious alternative), started from the same
ideal-field currents; forward solves, CPU time and the final miss (checked by an independent
forward solve).  The ideal-field controller's miss is listed too.

3D targets on a calibrated eMNS (CardioMag, ``coils.presets.cardiomag()``, an MPEM): targets
(x, y, z) made by known currents (a field, and a field with a gradient, at the centre),
``solve_currents`` from its own start; forward-solve equivalents (its CPU time over one
real-field forward solve at the answer, the best of three), against the issue's budget of 15;
the miss by an independent forward solve.  The same targets with the tip direction of the
made state too (five conditions on eight coils): solves of the search and of the start, with
the start using the direction (``solve_currents``) and ignoring it (the position-only start),
and with the Gauss-Newton steps inverting every singular value of the Jacobian (the old
steps, ``STEP_RCOND = 0``; this rod's tip pose moves with only three current combinations,
see ``coilrod.control.currents._moved``), all in one run.

Every kernel runs compiled (ski-rental thresholds 0, ``_machine.compile_at_once``): the
figures are a warm process's; ``bench_coldstart.py`` measures what a fresh one pays.

Run:  python benchmarks/bench_control.py            (both parts)
      python benchmarks/bench_control.py --3d       (the CardioMag part only)
      python benchmarks/bench_control.py --quick    (one target of each part, printed only)
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

import coils
from coilrod import presets, solve_currents, solve_rod

sys.path.insert(0, str(Path(__file__).parent))
from _machine import bench_args, compile_at_once, machine_info  # noqa: E402

warnings.simplefilter("ignore")
ROD = presets.seed_rod(presets.M1())
L = ROD.length
SYSTEM = coils.presets.three_axis_helmholtz(radii=(0.04, 0.05, 0.06), max_current=50.0)
SCALES = np.arange(1, 11) / 10
FIELDS = [(0.0, 0.004, 0.0), (0.003, 0.006, 0.0), (-0.002, -0.008, 0.0), (-0.006, 0.004, 0.0)]


def tip(currents, tol=1e-9):
    return solve_rod(ROD, SYSTEM.with_currents(currents), SCALES, tol=tol).tip[-1, :2]


CARDIOMAG = coils.presets.cardiomag()
TARGETS_3D = [
    {"B": (0.003, 0.004, -0.003)},
    {"B": (-0.002, -0.006, 0.003)},
    {"B": (0.003, 0.004, -0.003), "gradient": np.diag([0.05, -0.02, -0.03])},
]
BUDGET_3D = 15  # forward-solve equivalents (issue 21)


def tip_3d(system, currents, tol=1e-9):
    res = solve_rod(ROD, system.with_currents(currents), SCALES, tol=tol)
    assert res.model == "spatial"
    return res.tip[-1]


def cardiomag_3d(targets=TARGETS_3D) -> list[str]:
    """The CardioMag rows: 3D targets, forward-solve equivalents against the budget."""
    out = [
        "\n## 3D targets on CardioMag (calibrated MPEM, 8 coils)\n",
        "| target (mm) | made by | solves (start) | forward-solve equivalents | CPU (s) | "
        "miss (L) | within 15 |",
        "|---|---|---|---|---|---|---|",
    ]
    # compile outside the timing: a forward solve and a whole 3D solve (start, sensitivities)
    warm = tip_3d(CARDIOMAG, CARDIOMAG.currents_for(B=(0.0, 0.003, 0.002)))
    solve_currents(ROD, CARDIOMAG, warm)
    for made in targets:
        target = tip_3d(CARDIOMAG, CARDIOMAG.currents_for(**made), tol=1e-12)
        t0 = time.process_time()
        ours = solve_currents(ROD, CARDIOMAG, target)
        t_ours = time.process_time() - t0
        times = []
        for _ in range(3):
            t0 = time.process_time()
            tip_3d(CARDIOMAG, ours.currents)
            times.append(time.process_time() - t0)
        eq = t_ours / min(times)
        miss = np.linalg.norm(tip_3d(CARDIOMAG, ours.currents, 1e-12) - target) / L
        label = "(" + ", ".join(f"{1e3 * v:.1f}" for v in target) + ")"
        how = "B" + (" + gradient" if "gradient" in made else "")
        out.append(
            f"| {label} | {how} | {ours.solves} ({ours.start_solves}) | {eq:.1f} | "
            f"{t_ours:.2f} | {miss:.1e} | {'yes' if eq <= BUDGET_3D else 'NO'} |"
        )
    out += [
        "\n### with the made state's tip direction "
        "(start with / without the direction; old steps)\n",
        "| target (mm) | made by | solves + start, direction start | solves + start, "
        "position-only start | solves + start, every singular value (old steps) | "
        "CPU (s) direction / position-only / old | forward-solve equivalents (direction "
        "start) | miss (L) | direction miss (rad) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    from coilrod.control import currents

    for made in targets:
        res = solve_rod(
            ROD, CARDIOMAG.with_currents(CARDIOMAG.currents_for(**made)), SCALES, tol=1e-12
        )
        target, direction = res.tip[-1], res.frames(len(res) - 1)[-1, :, 0]
        rows = []
        for use, rcond in ((True, currents.STEP_RCOND), (False, currents.STEP_RCOND), (True, 0.0)):
            start = currents._start_3d
            if not use:  # the position-only start: the direction hidden from _start_3d

                def start(p, _orig=currents._start_3d):
                    from dataclasses import replace

                    return _orig(replace(p, direction=None))

            saved, currents._start_3d = currents._start_3d, start
            saved_rcond, currents.STEP_RCOND = currents.STEP_RCOND, rcond
            try:
                t0 = time.process_time()
                o = solve_currents(ROD, CARDIOMAG, target, direction=direction)
                rows.append((o, time.process_time() - t0))
            finally:
                currents._start_3d, currents.STEP_RCOND = saved, saved_rcond
        (o1, t1), (o2, t2), (o3, t3) = rows
        times = []
        for _ in range(3):
            t0 = time.process_time()
            tip_3d(CARDIOMAG, o1.currents)
            times.append(time.process_time() - t0)
        eq = t1 / min(times)
        label = "(" + ", ".join(f"{1e3 * v:.1f}" for v in target) + ")"
        how = "B" + (" + gradient" if "gradient" in made else "")
        out.append(
            f"| {label} | {how} | {o1.solves} + {o1.start_solves} ({o1.status}) | "
            f"{o2.solves} + {o2.start_solves} ({o2.status}) | "
            f"{o3.solves} + {o3.start_solves} ({o3.status}) | {t1:.2f} / {t2:.2f} / {t3:.2f} | "
            f"{eq:.1f} ({'within' if eq <= BUDGET_3D else 'NOT within'} {BUDGET_3D}) | "
            f"{o1.miss / L:.1e} | {o1.direction_miss:.1e} |"
        )
    return out


def main():
    args = bench_args(__doc__)
    compile_at_once()
    quick = args.quick
    fields, targets = (FIELDS[:1], TARGETS_3D[:1]) if quick else (FIELDS, TARGETS_3D)
    if "--3d" in args.rest:
        text = "\n".join(
            ["# Control benchmark (3D part)\n", machine_info(), *cardiomag_3d(targets)]
        )
        print(text)
        if not quick:
            Path(__file__).with_name("results").joinpath("control_3d.md").write_text(text + "\n")
        return
    out = ["# Control benchmark\n", machine_info(), ""]
    out.append(
        "| target (mm) | method | forward solves | forward-solve equivalents (time) | "
        "CPU (s) | miss (L) |"
    )
    out.append("|---|---|---|---|---|---|")
    ratios_solves, ratios_time, ratios_eq = [], [], []
    for B in fields:
        target = tip(SYSTEM.currents_for(B=B), tol=1e-12)
        t0 = time.process_time()
        ours = solve_currents(ROD, SYSTEM, target)
        t_ours = time.process_time() - t0
        t0 = time.process_time()
        for _ in range(3):
            tip(ours.currents)
        t_forward = (time.process_time() - t0) / 3  # one real-field forward solve
        n_ours = ours.solves + ours.start_solves
        ideal = solve_currents(ROD, SYSTEM, target, model="ideal")
        count, hit = [0], [None]

        def fun(I, count=count, hit=hit, target=target):
            count[0] += 1
            r = (tip(I) - target) / L
            if hit[0] is None and np.linalg.norm(r) <= 1e-7:
                hit[0] = count[0]
            return r

        t0 = time.process_time()
        fit = least_squares(fun, ideal.currents, jac="2-point", xtol=1e-12, ftol=1e-12, gtol=1e-12)
        t_ls = time.process_time() - t0
        miss_ours = np.linalg.norm(tip(ours.currents, 1e-12) - target) / L
        miss_ls = np.linalg.norm(tip(fit.x, 1e-12) - target) / L
        label = f"({target[0] * 1e3:.1f}, {target[1] * 1e3:.1f})"
        eq = t_ours / t_forward
        row = f"| {label} | solve_currents | {n_ours} ({ours.solves} real) | {eq:.1f} | "
        out.append(row + f"{t_ours:.2f} | {miss_ours:.1e} |")
        n_ls = hit[0] if hit[0] is not None else count[0]
        out.append(
            f"| | least_squares, FD Jacobian | {n_ls} to 1e-7 L ({count[0]} in all) | "
            f"{t_ls / t_forward:.1f} | {t_ls:.2f} | {miss_ls:.1e} |"
        )
        out.append(f"| | ideal-field controller | 1 | | | {ideal.miss / L:.1e} |")
        ratios_solves.append(n_ls / ours.solves)
        ratios_eq.append(n_ls / eq)
        ratios_time.append(t_ls / t_ours)
    out.append(
        f"\nReal-field forward solves: solve_currents needs 1/{np.min(ratios_solves):.1f} to "
        f"1/{np.max(ratios_solves):.1f} of least_squares' solves to 1e-7 L; counting all its "
        f"work in forward-solve equivalents (its CPU time over one real-field solve: the "
        f"uniform-field start, the start grid, the sensitivities), 1/{np.min(ratios_eq):.1f} to "
        f"1/{np.max(ratios_eq):.1f}; CPU time 1/{np.min(ratios_time):.1f} to "
        f"1/{np.max(ratios_time):.1f} of least_squares' whole run.\n"
    )
    out += cardiomag_3d(targets)
    text = "\n".join(out)
    print(text)
    if not quick:
        Path(__file__).with_name("results").joinpath("control.md").write_text(text + "\n")


if __name__ == "__main__":
    main()
