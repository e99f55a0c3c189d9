"""Coil-field benchmark: time against error, in one run, against the obvious alternatives.

a) our closed-form B + exact gradient (Helmholtz and Maxwell filament pairs) against magpylib
   ``getB`` with a 7-point central stencil, at 10^5 points in a box of half-size 0.5 R; both
   measured against an independent 30-digit reference (mpmath: Simpson's closed form, gradient
   by ``mpmath.diff``) at 200 of the points.
b) the gridded cache (coils.GriddedField) against direct evaluation, at 10^5 and at 300 points
   (a rod solve's query size), build time reported separately.
c) finite windings: Gauss-filament models against the turn-by-turn model.

Relative error = max |X - X_ref| / max |X_ref| over all entries and points.
Run: ``python benchmarks/bench_coils.py`` (needs mpmath); writes benchmarks/results/coils.md.
"""

from __future__ import annotations

import os

# one BLAS thread: the benchmark compares single-threaded code paths, and idle OpenBLAS threads
# spin (inflating CPU time) on a machine whose 2 cores are shared with other jobs
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.constants import mu_0  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _machine import best_time, best_times, clock, clock_name, machine_info  # noqa: E402

import coils  # noqa: E402

R = 0.1  # coil radius, m
TURNS, CURRENT = 100, 2.0
N_POINTS = 100_000
N_REF = 200
RESULTS = Path(__file__).parent / "results" / "coils.md"

out_lines: list[str] = []


def emit(line: str = "") -> None:
    print(line, flush=True)
    out_lines.append(line)


def rel(a, ref) -> float:
    return float(np.abs(a - ref).max() / np.abs(ref).max())


def table(header: list[str], rows: list[list[str]]) -> None:
    emit("| " + " | ".join(header) + " |")
    emit("|" + "|".join("---" for _ in header) + "|")
    for row in rows:
        emit("| " + " | ".join(row) + " |")
    emit()


# -- independent high-precision reference -------------------------------------------------------
def mp_reference(field: coils.CoaxialCoils, pts: np.ndarray, dps: int = 30):
    """B (n, 3) and gradient (n, 3, 3) of a coaxial filament group at 30 digits.

    B of each loop from Simpson et al. (NASA 2001) with mpmath's K(m), E(m); the gradient by
    ``mpmath.diff`` of that B.  Uses only the geometry (filaments, frame, centre) of ``field``.
    """
    import mpmath as mp

    mp.mp.dps = dps
    mu0 = mp.mpf(mu_0)
    Rm = [[mp.mpf(float(v)) for v in row] for row in field.rotation]
    c = [mp.mpf(float(v)) for v in field.center]
    fil = [tuple(mp.mpf(float(v)) for v in row) for row in field.filaments]

    def B_global(x, y, z):
        d = (x - c[0], y - c[1], z - c[2])
        loc = [sum(Rm[i][j] * d[i] for i in range(3)) for j in range(3)]  # R^T d
        rho = mp.sqrt(loc[0] ** 2 + loc[1] ** 2)
        b_rho_over_rho, b_ax = mp.mpf(0), mp.mpf(0)
        for z0, a, cur in fil:
            zz = loc[2] - z0
            r2 = rho**2 + zz**2
            alpha2 = a**2 + r2 - 2 * a * rho
            beta2 = a**2 + r2 + 2 * a * rho
            beta = mp.sqrt(beta2)
            m = 1 - alpha2 / beta2
            K, E = mp.ellipk(m), mp.ellipe(m)
            C = mu0 * cur / mp.pi
            b_rho_over_rho += C * zz / (2 * alpha2 * beta * rho**2) * ((a**2 + r2) * E - alpha2 * K)
            b_ax += C / (2 * alpha2 * beta) * ((a**2 - r2) * E + alpha2 * K)
        bl = (b_rho_over_rho * loc[0], b_rho_over_rho * loc[1], b_ax)
        return [sum(Rm[i][j] * bl[j] for j in range(3)) for i in range(3)]

    B = np.empty((len(pts), 3))
    G = np.empty((len(pts), 3, 3))
    for k, p in enumerate(pts):
        P = [mp.mpf(float(v)) for v in p]
        B[k] = [float(v) for v in B_global(*P)]
        for j in range(3):
            for i in range(3):

                def comp(t, i=i, j=j, P=P):
                    Q = list(P)
                    Q[j] = Q[j] + t
                    return B_global(*Q)[i]

                G[k, i, j] = float(mp.diff(comp, 0))
    return B, G


# -- a) closed form vs magpylib stencil ---------------------------------------------------------
def stencil(collection, pts: np.ndarray, h: float):
    """B and the 7-point central-difference gradient from magpylib getB (one stacked call)."""
    n = pts.shape[0]
    shifts = np.vstack([np.zeros(3), h * np.eye(3), -h * np.eye(3)])
    allB = collection.getB((pts[None, :, :] + shifts[:, None, :]).reshape(-1, 3)).reshape(7, n, 3)
    G = np.empty((n, 3, 3))
    for j in range(3):
        G[:, :, j] = (allB[1 + j] - allB[4 + j]) / (2 * h)
    return allB[0], G


def part_a(rng) -> None:
    emit("## a) B + gradient at 10^5 points: closed form vs magpylib 7-point stencil")
    emit()
    emit(
        f"R = {R} m, N = {TURNS}, I = {CURRENT} A, axis y, points uniform in a box of half-size "
        f"0.5 R; errors against a 30-digit mpmath reference at {N_REF} of the points."
    )
    emit()
    pts = rng.uniform(-0.5 * R, 0.5 * R, (N_POINTS, 3))
    sub = slice(0, N_REF)
    rows, steps_rows = [], []
    for name, pair in (
        ("Helmholtz", coils.HelmholtzPair(R, TURNS, CURRENT, axis="y")),
        ("Maxwell", coils.MaxwellPair(R, TURNS, CURRENT, axis="y")),
    ):
        Bref, Gref = mp_reference(pair, pts[sub])
        col = pair.to_magpylib()
        B, G = pair.B_and_gradient(pts)
        h = 1e-5 * R
        Bm, Gm = stencil(col, pts, h)
        t_ours, t_ours_B, t_mp = best_times(
            [
                lambda pair=pair: pair.B_and_gradient(pts),
                lambda pair=pair: pair.B(pts),
                lambda col=col, h=h: stencil(col, pts, h),
            ],
            repeat=5,
        )
        rows.append(
            [
                name,
                f"{t_ours:.3f}",
                f"{t_ours_B:.3f}",
                f"{t_mp:.3f}",
                f"{t_ours / t_mp:.3f} (1/{t_mp / t_ours:.1f})",
                f"{rel(B[sub], Bref):.1e}",
                f"{rel(G[sub], Gref):.1e}",
                f"{rel(Bm[sub], Bref):.1e}",
                f"{rel(Gm[sub], Gref):.1e}",
            ]
        )
        for s in (1e-3, 1e-4, 1e-5, 1e-6, 1e-7):
            _, Gs = stencil(col, pts[sub], s * R)
            steps_rows.append([name, f"{s:g} R", f"{rel(Gs, Gref):.1e}"])
    table(
        [
            "pair",
            "ours B+G (s)",
            "ours B only (s)",
            "magpylib 7-pt (s)",
            "time ratio ours/stencil",
            "ours err B",
            "ours err G",
            "stencil err B",
            "stencil err G (h=1e-5 R)",
        ],
        rows,
    )
    emit("Stencil step scan (gradient error against the mpmath reference):")
    emit()
    table(["pair", "step h", "stencil err G"], steps_rows)


# -- b) gridded cache vs direct -----------------------------------------------------------------
def part_b(rng) -> None:
    half = 0.25 * R
    tol, tol_g = 1e-6, 1e-5
    emit("## b) gridded cache (GriddedField) vs direct evaluation")
    emit()
    emit(
        f"Box of half-size {half / R:g} R around the centre; grid chosen automatically with "
        f"tol = {tol:g} (B) and tol_gradient = {tol_g:g}; errors measured against the direct "
        f"field at the 10^5 query points (not the grid's own estimate, shown as 'est.')."
    )
    emit()
    w = (0.1 * R, 0.1 * R)
    fields = [
        ("Helmholtz filament pair", coils.HelmholtzPair(R, TURNS, CURRENT, axis="y")),
        (
            "Helmholtz winding 0.1R x 0.1R, (3,3) filaments",
            coils.HelmholtzPair(R, TURNS, CURRENT, axis="y", winding=w, filaments=(3, 3)),
        ),
        (
            "Helmholtz + Maxwell system, windings (3,3)",
            coils.CoilSystem(
                [
                    coils.HelmholtzPair(R, TURNS, CURRENT, axis="y", winding=w, filaments=(3, 3)),
                    coils.MaxwellPair(R, TURNS, CURRENT, axis="y", winding=w, filaments=(3, 3)),
                ]
            ),
        ),
        (
            "Helmholtz winding 0.1R x 0.1R, turn by turn (200 filaments)",
            coils.HelmholtzPair(R, TURNS, CURRENT, axis="y", winding=w, turn_layout=(10, 10)),
        ),
    ]
    pts = rng.uniform(-half, half, (N_POINTS, 3))
    pts300 = rng.uniform(-half, half, (300, 3))
    rows = []
    for name, field in fields:
        t0 = clock()
        grid = coils.GriddedField(field, (-half,) * 3, (half,) * 3, tol=tol, tol_gradient=tol_g)
        t_build = clock() - t0
        Bd, Gd = field.B_and_gradient(pts)
        B, G = grid.B_and_gradient(pts)
        t_direct, t_grid = best_times(
            [
                lambda field=field: field.B_and_gradient(pts),
                lambda grid=grid: grid.B_and_gradient(pts),
            ],
            repeat=2 if "turn" in name else 5,
        )
        t_direct300, t_grid300 = best_times(
            [
                lambda field=field: field.B_and_gradient(pts300),
                lambda grid=grid: grid.B_and_gradient(pts300),
            ],
            repeat=5,
            number=20,
        )
        rows.append(
            [
                name,
                f"{grid.shape[0]}^3 ({grid.nbytes / 1e6:.0f} MB)",
                f"{t_build:.2f}",
                f"{t_direct:.3f}",
                f"{t_grid:.3f}",
                f"{t_direct / t_grid:.1f}x",
                f"{1e3 * t_direct300:.2f}",
                f"{1e3 * t_grid300:.2f}",
                f"{t_direct300 / t_grid300:.1f}x",
                f"{rel(B, Bd):.1e} (est. {grid.error_B:.1e})",
                f"{rel(G, Gd):.1e} (est. {grid.error_gradient:.1e})",
            ]
        )
        del grid
    table(
        [
            "field",
            "grid",
            "build (s)",
            "direct 1e5 (s)",
            "grid 1e5 (s)",
            "speed-up",
            "direct 300 (ms)",
            "grid 300 (ms)",
            "speed-up 300",
            "err B",
            "err G",
        ],
        rows,
    )


# -- c) finite windings -------------------------------------------------------------------------
def part_c(rng) -> None:
    w = (0.1 * R, 0.1 * R)
    emit("## c) finite windings: Gauss filaments vs turn-by-turn")
    emit()
    emit(
        f"Helmholtz pair R = {R} m, {TURNS} turns per coil wound 10 x 10 in a 0.1 R x 0.1 R "
        "section; reference: one filament per turn (turn_layout=(10, 10), 200 filaments). "
        "Errors at 2000 points in the uniformity region (box of half-size 0.25 R); times for "
        "B + gradient at 10^5 points.  The last column compares with a (12, 12) Gauss model, "
        "i.e. a uniform current density: the turn-by-turn model differs from it by the "
        "discreteness of the turns."
    )
    emit()
    pts = rng.uniform(-0.25 * R, 0.25 * R, (2000, 3))
    pts_t = rng.uniform(-0.25 * R, 0.25 * R, (N_POINTS, 3))
    ref = coils.HelmholtzPair(R, TURNS, CURRENT, axis="y", winding=w, turn_layout=(10, 10))
    Bt, Gt = ref.B_and_gradient(pts)
    cont = coils.HelmholtzPair(R, TURNS, CURRENT, axis="y", winding=w, filaments=(12, 12))
    Bc, Gc = cont.B_and_gradient(pts)
    rows = []
    single = coils.HelmholtzPair(R, TURNS, CURRENT, axis="y")
    models = [("single filament (no winding)", single)] + [
        (
            f"Gauss {n}x{n}",
            coils.HelmholtzPair(R, TURNS, CURRENT, axis="y", winding=w, filaments=(n, n)),
        )
        for n in (1, 2, 3, 4)
    ]
    times = best_times([lambda model=model: model.B_and_gradient(pts_t) for _, model in models])
    for (name, model), t in zip(models, times, strict=True):
        B, G = model.B_and_gradient(pts)
        rows.append(
            [
                name,
                str(model.filaments.shape[0]),
                f"{t:.3f}",
                f"{rel(B, Bt):.1e}",
                f"{rel(G, Gt):.1e}",
                f"{rel(B, Bc):.1e}",
                f"{rel(G, Gc):.1e}",
            ]
        )
    t_ref = best_time(lambda: ref.B_and_gradient(pts_t), repeat=2)
    rows.append(
        [
            "turn-by-turn 10x10 (reference)",
            "200",
            f"{t_ref:.3f}",
            "0",
            "0",
            f"{rel(Bt, Bc):.1e}",
            f"{rel(Gt, Gc):.1e}",
        ]
    )
    header = ["model", "filaments", "time 1e5 (s)", "err B vs turns", "err G vs turns"]
    table(header + ["err B vs uniform", "err G vs uniform"], rows)


def main() -> None:
    rng = np.random.default_rng(2026)
    emit("# coils benchmark: time against error")
    emit()
    emit(f"Machine: {machine_info()}")
    emit()
    emit(
        f"Times are the best of several interleaved runs, {clock_name()} time in seconds "
        "(the machine is shared; see benchmarks/_machine.py)."
    )
    emit()
    part_a(rng)
    part_b(rng)
    part_c(rng)
    emit(f"Machine at the end: {machine_info()}")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text("\n".join(out_lines) + "\n")
    print(f"written {RESULTS}")


if __name__ == "__main__":
    main()
