"""Design benchmark: sensitivities, workspaces and magnetization optimisation, on this machine.

Prints (and writes to benchmarks/results/design.md):

1. exact sensitivities (adjoint) of an M(4.2) state in a uniform field and in a Helmholtz pair's
   Biot-Savart field, for every parameter, against central differences of solve_rod (the
   obvious alternative: two solves per parameter): time and relative error, both against a
   five-point difference at tolerance 1e-12; and the adjoint's cost in Newton steps of the
   state (the batched cost per state for a 16-state sweep too);
2. the workspace of M(1) (72 directions x 16 magnitudes, b_max 20 mT): all directions followed
   together (coilrod.workspace) against one solve_rod per direction; the tips' difference;
3. with ``--optimise``: magnetization optimisation (4 segments, 24 x 6 workspaces): the
   gradient method against differential evolution, workspace solves to reach 99 % of the best
   area either found.

Every kernel runs compiled (ski-rental thresholds 0, ``_machine.compile_at_once``): the
figures are a warm process's; ``bench_coldstart.py`` measures what a fresh one pays.

Run:  python benchmarks/bench_design.py [--optimise]
      python benchmarks/bench_design.py --quick   (part 1 alone, printed only)
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import coils
from coilrod import Magnetization, presets, sensitivities, solve_rod, workspace
from coilrod.design.sensitivity import tip_derivatives

sys.path.insert(0, str(Path(__file__).parent))
from _machine import bench_args, best_wall, compile_at_once, machine_info  # noqa: E402

warnings.simplefilter("ignore")
ROD = presets.seed_rod(presets.M42())
M = ROD.magnetization
LENGTHS = np.diff(M.segment_edges)


def _rod(mags=None, angles=None, E=None):
    mags = M.segment_magnitudes if mags is None else mags
    angles = M.segment_angles if angles is None else angles
    rod = dataclasses.replace(ROD, magnetization=Magnetization.segments(LENGTHS, mags, angles))
    return rod if E is None else dataclasses.replace(rod, youngs_modulus=E)


def _moved(label, d):
    """The rod moved by d in one parameter."""
    if label.startswith("magnitudes"):
        j = int(label[11:-1])
        mags = M.segment_magnitudes.copy()
        mags[j] += d
        return _rod(mags=mags)
    if label.startswith("angles"):
        j = int(label[7:-1])
        angs = M.segment_angles.copy()
        angs[j] += d
        return _rod(angles=angs)
    return _rod(E=ROD.youngs_modulus + d)


STEP = {"magnitudes": 1e3, "angles": 1e-3, "youngs_modulus": 1e4}


def sensitivity_table(out):
    cases = {
        "uniform 20 mT at 90 deg": coils.UniformField(B=(0.0, 0.02, 0.0)),
        "Helmholtz pair R = L, 20 mT": _helmholtz(0.02),
    }
    out.append("## 1. Sensitivities of one state (M(4.2), 10 parameters)\n")
    out.append(
        "| field | adjoint (ms) | central differences (ms) | ratio | adjoint error | "
        "differences error | adjoint / Newton step | per state, 16 states |"
    )
    out.append("|---|---|---|---|---|---|---|---|")
    for name, field in cases.items():
        res = solve_rod(ROD, field, [1.0])
        t_adj, sens = best_wall(lambda res=res: sensitivities(res, 0, wrt=WRT), 7)
        labels = [p for p in sens.parameters if not p.startswith("scale")]

        def differences(field=field, labels=labels, h_scale=1.0):
            cols = []
            for lab in labels:
                h = STEP[lab.split("[")[0]] * h_scale
                a = solve_rod(_moved(lab, h), field, [1.0]).tip[0]
                b = solve_rod(_moved(lab, -h), field, [1.0]).tip[0]
                cols.append((a - b) / (2 * h))
            return np.array(cols)

        t_fd, fd = best_wall(differences, 3)
        ref = _five_point(field, labels)
        idx = [sens.parameters.index(lab) for lab in labels]
        err_adj = _rel(sens.tip[idx], ref)
        err_fd = _rel(fd, ref)
        sol = res._solution
        res._min_eigenvalue = np.asarray(res.min_eigenvalue)

        def newton_step(sol=sol, res=res):
            for p, U in zip(sol.problems, sol.states, strict=True):
                lin = p.linearize(U, res.scales)
                lin.tangent.solve(lin.residual)

        t_newton, _ = best_wall(newton_step, 15)
        t_raw, _ = best_wall(lambda res=res: tip_derivatives(res, [0], WRT, check=False), 15)
        sweep = solve_rod(ROD, field, np.linspace(1 / 16, 1, 16))
        sweep._min_eigenvalue = np.asarray(sweep.min_eigenvalue)
        t_batch, _ = best_wall(lambda s=sweep: tip_derivatives(s, np.arange(16), WRT), 7)
        out.append(
            f"| {name} | {t_adj * 1e3:.2f} | {t_fd * 1e3:.1f} | 1/{t_fd / t_adj:.0f} | "
            f"{err_adj:.1e} | {err_fd:.1e} | {t_raw / t_newton:.1f} | "
            f"{t_batch / 16 * 1e3:.2f} ms |"
        )
    out.append(
        "\nErrors: max over parameters of |d - reference| / max |reference| (tip position), the "
        "reference a five-point difference of solves at tol 1e-12.  'adjoint / Newton step': the "
        "adjoint's cost (three transposed solves with the state's factors, O(n) per parameter) "
        "over one Newton step of the same state (assembly, factorisation, solve), both meshes.\n"
    )


WRT = ("magnitudes", "angles", "youngs_modulus")


def _helmholtz(b):
    from coils.design import current_for_field

    unit = coils.HelmholtzPair(ROD.length, 200, 1.0, axis="y", center=(ROD.length / 2, 0, 0))
    return unit.with_current(current_for_field(unit, b))


def _five_point(field, labels):
    cols = []
    for lab in labels:
        h = STEP[lab.split("[")[0]]
        f = {
            d: solve_rod(_moved(lab, d * h), field, [1.0], tol=1e-12).tip[0] for d in (-2, -1, 1, 2)
        }
        cols.append((8 * (f[1] - f[-1]) - (f[2] - f[-2])) / (12 * h))
    return np.array(cols)


def _rel(a, ref):
    return float(np.max(np.abs(a - ref)) / np.max(np.abs(ref)))


def workspace_table(out):
    rod = presets.seed_rod(presets.M1())
    t_grid, ws = best_wall(lambda: workspace(rod, 0.02, refine=0), 5)

    def one_by_one():
        tips = []
        for phi in ws.directions:
            b = 0.02 * np.array([math.cos(phi), math.sin(phi), 0.0])
            tips.append(solve_rod(rod, coils.UniformField(B=b), np.arange(1, 17) / 16).tip)
        return np.array(tips)

    t_single, tips = best_wall(one_by_one, 3)
    diff = np.max(np.abs(tips - ws.tips[:, 1:])) / rod.length
    t_ref, ref = best_wall(lambda: workspace(rod, 0.02), 2)
    fine = workspace(rod, 0.02, directions=144, magnitudes=32, refine=8, tolerance=2.5e-4)
    out.append("## 2. Workspace of M(1), b_max 20 mT\n")
    out.append("| method | time (s) | area (mm^2) | max tip difference (L) |")
    out.append("|---|---|---|---|")
    out.append(
        f"| coilrod.workspace, default accuracy (72 x 16 refined: {ref.directions.size} x "
        f"{ref.magnitudes.size - 1}) | {t_ref:.3f} | {ref.area * 1e6:.1f} +- "
        f"{ref.area_error * 1e6:.1f} | |"
    )
    out.append(
        f"| refined further (144 x 32, 8 levels, tolerance 2.5e-4: {fine.directions.size} x "
        f"{fine.magnitudes.size - 1}) | | {fine.area * 1e6:.1f} +- {fine.area_error * 1e6:.1f} | |"
    )
    out.append(
        f"| 72 x 16 grid, unrefined (refine=0; directions together) | {t_grid:.3f} | "
        f"{ws.area * 1e6:.1f} | reference |"
    )
    out.append(f"| 72 x 16, solve_rod per direction | {t_single:.3f} | | {diff:.1e} |")
    out.append(
        f"\ndefault accuracy / unrefined grid: {t_ref / t_grid:.1f} x the time; default within "
        f"{abs(ref.area / fine.area - 1) * 100:.2f} % of the further refined area; "
        f"directions together / one by one: 1/{t_single / t_grid:.1f}.\n"
    )


def optimisation_table(out):
    from coilrod import optimize_magnetization

    rod = presets.seed_rod(presets.M1())
    kw = dict(segments=4, b_max=0.02, max_magnitude=128e3, directions=24, magnitudes=6)
    grid = dict(directions=24, magnitudes=6)
    t0 = time.process_time()
    grad = optimize_magnetization(rod, method="gradient", budget=300, starts=4, **kw)
    t_grad = time.process_time() - t0
    t0 = time.process_time()
    evo = optimize_magnetization(rod, method="evolution", budget=3000, seed=0, **kw)
    t_evo = time.process_time() - t0
    best = max(grad.area, evo.area)

    def reach(h):
        ok = h[:, 1] >= 0.99 * best
        return int(h[np.argmax(ok), 0]) if ok.any() else None

    out.append("## 3. Magnetization optimisation: 4 segments, 24 x 6 workspaces, |M| <= 128 kA/m\n")
    out.append(
        "| method | best area (mm^2) | workspace solves | solves to 99 % of best | CPU (s) |"
    )
    out.append("|---|---|---|---|---|")
    for name, r, t in (
        ("gradient (4 starts)", grad, t_grad),
        ("differential evolution", evo, t_evo),
    ):
        out.append(f"| {name} | {r.area * 1e6:.1f} | {r.solves} | {reach(r.history)} | {t:.0f} |")
    presets_area = {
        name: workspace(dataclasses.replace(rod, magnetization=m), 0.02, **grid).area
        for name, m in (
            ("M(1)", presets.M1()),
            ("M(2a)", presets.M2(variant="a")),
            ("M(2b)", presets.M2(variant="b")),
            ("M(4.1)", presets.M41()),
            ("M(4.2)", presets.M42()),
        )
    }
    out.append(
        "\nPresets at the same resolution (mm^2): "
        + ", ".join(f"{k} {v * 1e6:.1f}" for k, v in presets_area.items())
        + f".  Gradient layout: |M| {np.round(grad.magnitudes / 1e3, 1).tolist()} kA/m, "
        f"angles {np.round(grad.angles, 3).tolist()} rad; {grad.ratio:.3f} x the uniform "
        f"magnetization's area ({grad.uniform_area * 1e6:.1f} mm^2).\n"
    )


def main():
    args = bench_args(__doc__)
    compile_at_once()
    out = ["# Design benchmark\n", machine_info(), ""]
    sensitivity_table(out)
    if args.quick:
        print("\n".join(out))
        return
    workspace_table(out)
    if "--optimise" in args.rest:
        optimisation_table(out)
    text = "\n".join(out)
    print(text)
    Path(__file__).with_name("results").joinpath("design.md").write_text(text + "\n")


if __name__ == "__main__":
    main()
