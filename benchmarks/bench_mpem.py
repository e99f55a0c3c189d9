"""MPEM benchmark: B + gradient of the calibrated eMNS models at 10^5 points.

The target (issue 21): B + grad B at 10^5 points in <= 30 ms.  For each shipped model (Navion:
9 sources, OctoMag-like: 8, CardioMag: 67 with the offset) the compiled dipole sum
(coils.MPEM.B_and_gradient) is timed against a vectorised numpy evaluation of the same sum
(broadcast over points, looped over sources) and their results compared.
The dipole kernels have no numpy twin (no ski rental): they compile, or load from numba's
cache, at the first call, which is not timed.
Run: ``python benchmarks/bench_mpem.py``; writes benchmarks/results/mpem.md.
``--quick``: 10^4 points, printed only.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _machine import bench_args, best_times, clock_name, machine_info  # noqa: E402

from coils import presets  # noqa: E402

N_POINTS = 100_000
RESULTS = Path(__file__).parent / "results" / "mpem.md"


def numpy_sum(model, pts):
    """B (n, 3) and G (n, 3, 3) of the model's dipoles, numpy, one source at a time."""
    scale = np.where(model.channel < 0, 1.0, model.currents[np.maximum(model.channel, 0)])
    B = np.zeros((len(pts), 3))
    G = np.zeros((len(pts), 3, 3))
    eye = np.eye(3)
    for c, p in zip(model.positions, model.moments * scale[:, None], strict=True):
        r = pts - c
        rr = np.einsum("ki,ki->k", r, r)
        inv5 = rr**-2.5
        s = r @ p
        B += 3 * r * (s * inv5)[:, None] - p * (inv5 * rr)[:, None]
        G += (
            3
            * inv5[:, None, None]
            * (s[:, None, None] * eye + r[:, :, None] * p + p[:, None] * r[:, None, :])
            - 15 * (s * inv5 / rr)[:, None, None] * r[:, :, None] * r[:, None, :]
        )
    return B, G


def main() -> None:
    quick = bench_args(__doc__).quick
    n_points = N_POINTS // 10 if quick else N_POINTS
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.05, 0.05, size=(n_points, 3))
    lines = [
        f"# MPEM benchmark (B + gradient at {n_points:.0e} points)",
        "",
        machine_info(),
        "",
        f"Times: best of 3, {clock_name()}.",
        "",
        "| model | sources | compiled (ms) | numpy (ms) | max rel. difference |",
        "|---|---:|---:|---:|---:|",
    ]
    for name, build in [
        ("Navion", presets.navion),
        ("OctoMag-like", lambda: presets.octomag(max_current=10.0)),
        ("CardioMag", presets.cardiomag),
    ]:
        model = build()
        model = model.with_currents(np.linspace(-1, 1, len(model.channels)) * 5.0)
        model.B_and_gradient(pts[:10])  # compile / load the numba cache
        B, G = model.B_and_gradient(pts)
        Bn, Gn = numpy_sum(model, pts)
        diff = max(np.abs(B - Bn).max() / np.abs(Bn).max(), np.abs(G - Gn).max() / np.abs(Gn).max())
        t_c, t_n = best_times(
            [lambda m=model: m.B_and_gradient(pts), lambda m=model: numpy_sum(m, pts)]
        )
        row = (
            f"| {name} | {model.positions.shape[0]} | {1e3 * t_c:.1f} | {1e3 * t_n:.1f} | "
            f"{diff:.1e} |"
        )
        print(row, flush=True)
        lines.append(row)
    if not quick:
        RESULTS.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
