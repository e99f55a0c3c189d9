"""Coil-field benchmark: time against error, in one run, against the obvious alternatives.

a) our closed-form B + exact gradient (Helmholtz and Maxwell filament pairs) against magpylib
   ``getB`` with a 7-point central stencil, at 10^5 points in a box of half-size 0.5 R; both
   measured against an independent 30-digit reference (mpmath: Simpson's closed form, gradient
   by ``mpmath.diff``) at 200 of the points.
b) the gridded cache (coils.GriddedField) against direct evaluation, at 10^5 and at 300 points
   (a rod solve's query size), build time reported separately.
c) finite windings: Gauss-filament models against the turn-by-turn model.
d) B + gradient + hessian per call at 130, 1300 and 10^5 points (a rod solver's Newton
   iteration): the compiled fused kernel against the previous numpy kernel (kept in
   benchmarks/_numpy_kernel.py for this comparison) and a magpylib 19-point stencil.
e) far field, 10 R .. 10^10 R: error of the compiled kernel, the previous numpy kernel and
   magpylib against an mpmath reference with enough digits for the cancellation.
f) JIT warm-up: first call with an empty and with a warm numba cache.
g) when the gridded cache pays: direct evaluation against the cache at 300 and 3000 points for
   fields of 2 to 200 filaments, B + gradient and B + gradient + hessian; the break-even
   filament count sets the scene planner's ``CACHE_MIN_FILAMENTS``.

Relative error = max |X - X_ref| / max |X_ref| over all entries and points.
Run: ``python benchmarks/bench_coils.py`` (needs mpmath); writes benchmarks/results/coils.md.
``python benchmarks/bench_coils.py g`` (any subset of the letters a-g) runs only those parts and
writes nothing; ``--quick`` runs part d alone.

Parts a-e and g time the compiled coil pass: the ski-rental threshold is set to 0
(``coils.coaxial.COMPILE_AFTER``, see ``_machine.compile_at_once``), so it compiles or loads
from numba's cache at the first call instead of running its numpy twin first; part f and
``bench_coldstart.py`` measure what a fresh process pays.
"""

from __future__ import annotations

import os

# one BLAS thread: the benchmark compares single-threaded code paths, and idle OpenBLAS threads
# spin (inflating CPU time) on a machine whose 2 cores are shared with other jobs
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.constants import mu_0  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _machine import (  # noqa: E402
    bench_args,
    best_time,
    best_times,
    clock,
    clock_name,
    compile_at_once,
    machine_info,
)

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
def _mp_B_function(field: coils.CoaxialCoils):
    """B(x, y, z) (mpf, global frame) of a coaxial filament group from Simpson et al. (NASA
    2001) with mpmath's K(m), E(m), at the current mpmath precision.  Uses only the geometry
    (filaments, frame, centre) of ``field``."""
    import mpmath as mp

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

    return B_global


def mp_reference(field: coils.CoaxialCoils, pts: np.ndarray, dps: int = 30):
    """B (n, 3) and gradient (n, 3, 3) of a coaxial filament group at ``dps`` digits.

    B of each loop from Simpson et al. (NASA 2001) with mpmath's K(m), E(m); the gradient by
    ``mpmath.diff`` of that B.  Uses only the geometry (filaments, frame, centre) of ``field``.
    """
    import mpmath as mp

    mp.mp.dps = dps
    B_global = _mp_B_function(field)
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


# -- d) fused B + gradient + hessian per call: compiled kernel vs previous numpy kernel ---------
def mp_hessian_reference(field: coils.CoaxialCoils, pts: np.ndarray, dps: int = 30):
    """H (n, 3, 3, 3) of a coaxial group by ``mpmath.diff`` of Simpson's closed form for B."""
    import mpmath as mp

    mp.mp.dps = dps
    B_global = _mp_B_function(field)
    H = np.empty((len(pts), 3, 3, 3))
    for k, p in enumerate(pts):
        P = [mp.mpf(float(v)) for v in p]
        for i in range(3):
            for j in range(3):
                for m in range(j, 3):
                    order = [0, 0, 0]
                    order[j] += 1
                    order[m] += 1
                    val = mp.diff(lambda *q, i=i: B_global(*q)[i], P, tuple(order))
                    H[k, i, j, m] = H[k, i, m, j] = float(val)
    return H


def best_call(fns, calls: int, rounds: int = 3) -> list[float]:
    """Smallest wall time (s) of single calls of each of ``fns``: ``rounds`` rounds of
    ``calls`` consecutive calls of each.  For calls of tens of microseconds the minimum is the
    time of a call that no other job interrupted (the machine is shared), with warm caches."""
    best = [float("inf")] * len(fns)
    for _ in range(rounds):
        for k, fn in enumerate(fns):
            for _ in range(calls):
                t0 = time.perf_counter_ns()
                fn()
                best[k] = min(best[k], (time.perf_counter_ns() - t0) * 1e-9)
    return best


def stencil19(collection, pts: np.ndarray, h: float):
    """B, gradient and hessian from magpylib getB on a 19-point stencil (one stacked call):
    central first and second differences along the axes, four-point mixed differences."""
    n = pts.shape[0]
    e = np.eye(3)
    shifts = [np.zeros(3)] + [s * h * e[j] for j in range(3) for s in (1, -1)]
    pairs = [(j, m) for j in range(3) for m in range(j + 1, 3)]
    shifts += [h * (s * e[j] + t * e[m]) for j, m in pairs for s in (1, -1) for t in (1, -1)]
    allB = collection.getB((pts[None] + np.array(shifts)[:, None]).reshape(-1, 3)).reshape(19, n, 3)
    B0 = allB[0]
    G = np.empty((n, 3, 3))
    H = np.empty((n, 3, 3, 3))
    for j in range(3):
        plus, minus = allB[1 + 2 * j], allB[2 + 2 * j]
        G[:, :, j] = (plus - minus) / (2 * h)
        H[:, :, j, j] = (plus - 2 * B0 + minus) / h**2
    for q, (j, m) in enumerate(pairs):
        pp, pm, mp_, mm = allB[7 + 4 * q : 11 + 4 * q]
        H[:, :, j, m] = H[:, :, m, j] = (pp - pm - mp_ + mm) / (4 * h * h)
    return B0, G, H


def part_d(rng) -> None:
    import _numpy_kernel as old

    emit("## d) B + gradient + hessian per call (a Newton iteration of a rod solver)")
    emit()
    emit(
        f"Helmholtz filament pair, R = {R} m, points uniform in a box of half-size 0.5 R. "
        "'compiled': `pair.B_gradient_hessian(points)` (one numba pass, validation included); "
        "'previous numpy': `B_and_gradient` + `hessian` of the former numpy kernel (copy in "
        "benchmarks/_numpy_kernel.py); 'magpylib': getB on a 19-point stencil (h = 1e-4 R). "
        "Errors at 20 points against a 30-digit mpmath reference (B from Simpson's closed "
        "form, G and H by `mpmath.diff`).  Times: at 130 and 1300 points the fastest of "
        "hundreds of consecutive single calls (wall clock, warm caches: what a call costs when "
        "no other job interrupts it), at 10^5 points the best of 3 runs (CPU time)."
    )
    emit()
    pair = coils.HelmholtzPair(R, TURNS, CURRENT, axis="y")
    col = pair.to_magpylib()
    pts_ref = rng.uniform(-0.5 * R, 0.5 * R, (20, 3))
    Bref, Gref = mp_reference(pair, pts_ref)
    Href = mp_hessian_reference(pair, pts_ref)
    h = 1e-4 * R
    B, G, H = pair.B_gradient_hessian(pts_ref)
    Bo, Go = old.B_and_gradient(pair, pts_ref)
    Ho = old.hessian(pair, pts_ref)
    Bm, Gm, Hm = stencil19(col, pts_ref, h)
    errors = {
        "compiled": (rel(B, Bref), rel(G, Gref), rel(H, Href)),
        "previous numpy": (rel(Bo, Bref), rel(Go, Gref), rel(Ho, Href)),
        "magpylib 19-pt": (rel(Bm, Bref), rel(Gm, Gref), rel(Hm, Href)),
    }
    rows = []
    for n, calls in ((130, 1000), (1300, 100), (100_000, 3)):
        pts = rng.uniform(-0.5 * R, 0.5 * R, (n, 3))
        fns = [
            lambda pts=pts: pair.B_gradient_hessian(pts),
            lambda pts=pts: (old.B_and_gradient(pair, pts), old.hessian(pair, pts)),
            lambda pts=pts: pair.B_and_gradient(pts),
            lambda pts=pts: old.B_and_gradient(pair, pts),
        ]
        if n < 100_000:
            t_new, t_old, t_new_b, t_old_b = best_call(fns, calls)
            (t_mag,) = best_call([lambda pts=pts: stencil19(col, pts, h)], calls // 50)
        else:
            t_new, t_old, t_new_b, t_old_b = best_times(fns, repeat=calls)
            (t_mag,) = best_times([lambda pts=pts: stencil19(col, pts, h)], repeat=1)
        rows.append(
            [
                f"{n}",
                f"{1e6 * t_new:.1f}",
                f"{1e6 * t_old:.1f}",
                f"{t_old / t_new:.1f}x",
                f"{1e6 * t_mag:.0f}",
                f"{t_mag / t_new:.0f}x",
                f"{1e6 * t_new_b:.1f}",
                f"{1e6 * t_old_b:.1f}",
                f"{t_old_b / t_new_b:.1f}x",
            ]
        )
    table(
        [
            "points",
            "compiled B+G+H (us)",
            "previous numpy B+G+H (us)",
            "speed-up",
            "magpylib 19-pt (us)",
            "speed-up",
            "compiled B+G (us)",
            "previous numpy B+G (us)",
            "speed-up",
        ],
        rows,
    )
    table(
        ["kernel", "err B", "err G", "err H"],
        [[name, *(f"{x:.1e}" for x in errs)] for name, errs in errors.items()],
    )


# -- e) far field: the multipole series vs the previous kernel and magpylib ---------------------
def part_e() -> None:
    import _numpy_kernel as old
    import mpmath as mp

    emit("## e) far field: relative error of B and gradient with distance")
    emit()
    emit(
        "A single loop (R = 0.1 m) and a Maxwell pair (its dipoles cancel), points along "
        "(0.3, -0.5, 0.81); reference: Simpson's closed form for B and `mpmath.diff` for G, "
        "with 40 + 2 log10(r/R) digits.  Relative error |X - X_ref| / |X_ref|."
    )
    emit()
    rows = []
    d = np.array([0.3, -0.5, 0.81])
    d /= np.linalg.norm(d)
    for name, field in (
        ("loop", coils.Coil(R, 1, CURRENT, axis="z")),
        ("Maxwell pair", coils.MaxwellPair(R, 1, CURRENT, axis="z")),
    ):
        col = field.to_magpylib()
        for dist in (1e1, 1e2, 1e4, 1e6, 1e8, 1e10):
            p = (dist * R * d)[None]
            Bref, Gref = mp_reference(field, p, dps=int(40 + 2 * np.log10(dist)))
            mp.mp.dps = 15
            B, G = field.B_and_gradient(p)
            with np.errstate(all="ignore"):
                Bo, Go = old.B_and_gradient(field, p)
                Bm = col.getB(p)
            rows.append(
                [
                    name,
                    f"{dist:.0e} R",
                    f"{rel(B, Bref):.1e}",
                    f"{rel(G, Gref):.1e}",
                    f"{rel(Bo, Bref):.1e}",
                    f"{rel(Go, Gref):.1e}",
                    f"{rel(Bm, Bref):.1e}",
                ]
            )
    table(
        [
            "source",
            "distance",
            "compiled err B",
            "compiled err G",
            "previous numpy err B",
            "previous numpy err G",
            "magpylib err B",
        ],
        rows,
    )


# -- f) JIT warm-up ------------------------------------------------------------------------------
_FIRST_CALL = """
import time
t0 = time.perf_counter()
import numpy as np
import coils
pair = coils.HelmholtzPair(0.1, 100, 2.0, axis="y")
pts = np.zeros((130, 3)) + 0.01
t1 = time.perf_counter()
pair.B_gradient_hessian(pts)
t2 = time.perf_counter()
print(t1 - t0, t2 - t1)
"""


def part_f() -> None:
    import subprocess
    import tempfile

    emit("## f) first call: numba compilation and its on-disk cache")
    emit()
    emit(
        "A fresh interpreter runs `import coils` and one `B_gradient_hessian` of a Helmholtz "
        "pair; 'cold': an empty numba cache (NUMBA_CACHE_DIR set to a new directory), "
        "'warm': the same directory again.  Wall time, seconds."
    )
    emit()
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        for label in ("cold (compile)", "warm (cache)", "warm (cache)"):
            out = subprocess.run(
                [sys.executable, "-c", _FIRST_CALL], env=env, capture_output=True, text=True
            )
            t_import, t_first = (float(v) for v in out.stdout.split())
            rows.append([label, f"{t_import:.2f}", f"{t_first:.2f}"])
    table(["numba cache", "import coils (s)", "first call (s)"], rows)


# -- g) when does the gridded cache pay? ------------------------------------------------------
#: (filaments of the pair, Gauss points per winding) of the fields compared in part g.
CACHE_FIELDS = (
    (2, None),
    (8, (2, 2)),
    (18, (3, 3)),
    (32, (4, 4)),
    (50, (5, 5)),
    (100, (5, 10)),
    (200, (10, 10)),
)
#: Query sizes of part g: a rod solve (2 x 150 nodes) and a 2D/3D FEM assembly.
CACHE_POINTS = (300, 3000)
#: Calls per round for each query size (3 rounds, the fastest call counts).
CACHE_CALLS = {300: 150, 3000: 25}


def _break_even(filaments, direct, grid) -> float:
    """Filament count where the direct time, fitted as ``a + b N`` (least squares), reaches the
    grid's time (its median: a grid query does not depend on the wrapped field)."""
    b, a = np.polyfit(np.asarray(filaments, dtype=float), np.asarray(direct), 1)
    return float((np.median(grid) - a) / b)


def part_g(rng) -> dict:
    from coilrod.scene.planner import CACHE_MIN_FILAMENTS

    lower = np.array([-0.5, -0.5, -0.025]) * R
    upper = -lower
    emit("## g) gridded cache vs direct evaluation by filament count (the planner's threshold)")
    emit()
    emit(
        f"Helmholtz pair R = {R} m along y, a 0.1 R x 0.1 R winding per coil modelled by n x m "
        "Gauss filaments (2 filaments: no winding, one per coil), all in one coaxial group.  "
        "Cache: `GriddedField` over a robot's reach, the box [-0.5 R, 0.5 R]^2 x "
        "[-0.025 R, 0.025 R], with the scene runner's tolerances (tol = 1e-7, tol_gradient = "
        "1e-5).  Queries: points uniform in the box; 'B+G' = `B_and_gradient`, 'B+G+H' = "
        "`B_gradient_hessian`.  Times: the fastest of 3 rounds of consecutive single calls "
        "(wall clock, microseconds); speed-up = direct / grid (below 1: the cache is slower)."
    )
    emit()
    points = {n: rng.uniform(lower, upper, (n, 3)) for n in CACHE_POINTS}
    w = (0.1 * R, 0.1 * R)
    times = {}  # (quantity, n) -> ([direct per field], [grid per field])
    rows = {"B+G": [], "B+G+H": []}
    builds = []
    for n_fil, gauss in CACHE_FIELDS:
        kw = {} if gauss is None else {"winding": w, "filaments": gauss}
        field = coils.HelmholtzPair(R, TURNS, CURRENT, axis="y", **kw)
        assert field.filaments.shape[0] == n_fil
        t0 = time.perf_counter()
        grid = coils.GriddedField(field, lower, upper, tol=1e-7, tol_gradient=1e-5)
        builds.append(
            f"{n_fil}: {time.perf_counter() - t0:.2f} s ({'x'.join(map(str, grid.shape))} nodes)"
        )
        row = {"B+G": [f"{n_fil}"], "B+G+H": [f"{n_fil}"]}
        for n in CACHE_POINTS:
            pts = points[n]
            t_d, t_g, t_dh, t_gh = best_call(
                [
                    lambda field=field, pts=pts: field.B_and_gradient(pts),
                    lambda grid=grid, pts=pts: grid.B_and_gradient(pts),
                    lambda field=field, pts=pts: field.B_gradient_hessian(pts),
                    lambda grid=grid, pts=pts: grid.B_gradient_hessian(pts),
                ],
                CACHE_CALLS[n],
            )
            for quantity, direct, cached in (("B+G", t_d, t_g), ("B+G+H", t_dh, t_gh)):
                d_list, g_list = times.setdefault((quantity, n), ([], []))
                d_list.append(direct)
                g_list.append(cached)
                row[quantity] += [f"{1e6 * direct:.0f}", f"{1e6 * cached:.0f}"]
                row[quantity].append(f"{direct / cached:.2f}x")
        for quantity in rows:
            rows[quantity].append(row[quantity])
        del grid
    filaments = [n for n, _ in CACHE_FIELDS]
    header = ["filaments"]
    for n in CACHE_POINTS:
        header += [f"direct {n} (us)", f"grid {n} (us)", f"speed-up {n}"]
    for quantity, quantity_rows in rows.items():
        emit(f"{quantity}:")
        emit()
        table(header, quantity_rows)
    emit(f"Cache build (s, grid nodes) by filament count: {'; '.join(builds)}.")
    emit()
    even = {key: _break_even(filaments, *val) for key, val in times.items()}
    emit(
        "Break-even filament count (direct time fitted as a + b N over the fields above, "
        "grid time = its median over them):"
    )
    emit()
    table(
        ["query", *(f"{n} points" for n in CACHE_POINTS)],
        [
            [quantity, *(f"{even[quantity, n]:.0f}" for n in CACHE_POINTS)]
            for quantity in ("B+G", "B+G+H")
        ],
    )
    largest = max(even.values())
    emit(
        f"The cache is faster for every query type and size only above {largest:.0f} "
        f"filaments; the planner caches from CACHE_MIN_FILAMENTS = {CACHE_MIN_FILAMENTS} "
        f"({CACHE_MIN_FILAMENTS / largest:.2f} x that)."
    )
    emit()
    return even


PARTS = {
    "a": part_a,
    "d": part_d,
    "e": lambda rng: part_e(),
    "f": lambda rng: part_f(),
    "b": part_b,
    "c": part_c,
    "g": part_g,
}


def main(argv: list[str] | None = None) -> None:
    args = bench_args(__doc__, argv)
    compile_at_once()
    chosen = "".join(args.rest) or ("d" if args.quick else "".join(PARTS))
    unknown = sorted(set(chosen) - set(PARTS))
    if unknown:
        raise SystemExit(f"unknown part(s) {', '.join(unknown)}; choose from {''.join(PARTS)}")
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
    for letter, part in PARTS.items():
        if letter in chosen:
            part(rng)
    emit(f"Machine at the end: {machine_info()}")
    if set(chosen) == set(PARTS):
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        RESULTS.write_text("\n".join(out_lines) + "\n")
        print(f"written {RESULTS}")


if __name__ == "__main__":
    main()
