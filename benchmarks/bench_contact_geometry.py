"""Contact geometry benchmark: time per point of the gap (and of gap + gradient + hessian) of
``coilrod.contact`` obstacles at 10^5 points, against shapely's ``distance`` on the same points.

Points are uniform in each obstacle's bounding box grown by one radius (most lie outside the
lumen, as the nodes of a rod far from contact would not; the search cost is the same).
Shapely measures the 2D distance to a LineString (its geometry is planar, so the polyline and
the bend lie in z = 0 and shapely gets the x-y coordinates; the bend's arc is given to shapely
as 512 chords): it is the natural alternative for a planar polyline, not for splines, arcs or
radii that vary, which it cannot represent.  Errors are max |gap - (R - shapely distance)|.

A second table times one call at 65 points (a 64-segment rod's contact points, where a
contact solve spends its searches: numpy's per-call cost, not the pairs) by the numpy search
and by the compiled search of :mod:`coilrod.contact._compiled_search` (lines and
constant-radius arcs, up to 24 pieces), a new point set each call (no remembered search).

Run: ``python benchmarks/bench_contact_geometry.py`` (prints markdown tables; the target is
well under 1 s for 10^5 points, i.e. < 10 us per point).  ``--quick``: 10^4 points, one run.
The compiled search is compiled before timing (its ski rental bought at once); the first
table is compiled where it applies.  A vessel remembers its last few searches: they are
dropped before each timed query (a repeated query would time the memory, not the search).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import math  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import shapely  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _machine import bench_args, best_time, best_times, clock_name, machine_info  # noqa: E402

from coilrod.contact import Vessel  # noqa: E402

try:  # (a tree before the compiled search: numpy only, the second table left out)
    from coilrod.contact import _compiled_search
except ImportError:  # pragma: no cover
    _compiled_search = None

N = 100_000
R = 1e-3


def cases():
    rng = np.random.default_rng(1)
    walk = np.cumsum(np.c_[np.full(60, 1.0), rng.normal(size=(60, 2)) * 0.5], axis=0) * 2e-3
    walk[:, 2] = 0.0
    polyline = np.concatenate([np.zeros((1, 3)), walk])
    t = np.linspace(0, 2.5, 12)
    helix = np.c_[0.02 * np.cos(t), 0.02 * np.sin(t), 0.002 * t]
    phi = np.linspace(0, math.pi / 2, 513)
    bend_xy = np.concatenate(
        [[[0.0, 0.0]], np.c_[0.01 + 0.01 * np.sin(phi), 0.01 - 0.01 * np.cos(phi)], [[0.02, 0.02]]]
    )
    return [
        ("straight tube", Vessel.straight(0.04, R, ends="round"), np.array([[0, 0], [0.04, 0]])),
        ("bend (exact arc)", Vessel.bend(0.01, math.pi / 2, R, 0.01, 0.01, ends="round"), bend_xy),
        ("polyline, 60 segments (KD-tree)", Vessel(polyline, R, ends="round"), polyline[:, :2]),
        ("C2 spline, 12 points", Vessel(helix, R, smooth=True), None),
        ("aneurysm (smooth radius)", Vessel.aneurysm(0.04, R, 2e-3), None),
        ("branch (2 tubes)", Vessel.branch(0.04, R, 0.02), None),
    ]


def forget(ob) -> None:
    """Drop the searches a vessel (or a network's vessels) remembers, so that a repeated
    query is timed as a search."""
    for v in getattr(ob, "vessels", [ob]):
        v.__dict__["_located_memo"] = None  # (a cache: rebuilt on the next query)


class numpy_search:
    """Within: every vessel search by numpy (the compiled search's rental not bought)."""

    def __enter__(self):
        rental = _compiled_search._rental
        self._ready, rental.ready = rental.ready, False
        rental.held = lambda: False  # (numba's cache not looked at)
        self._price, _compiled_search.COMPILE_AFTER = _compiled_search.COMPILE_AFTER, math.inf

    def __exit__(self, *exc):
        rental = _compiled_search._rental
        rental.ready = self._ready
        del rental.held  # (the class's method again)
        _compiled_search.COMPILE_AFTER = self._price


def per_call(repeat: int, points: int = 65, sets: int = 400) -> None:
    """Time of one call (gap, and gap + gradient + hessian) at ``points`` points, numpy against
    compiled."""
    print(f"## One call at {points} points (a contact solve's searches)")
    print()
    print("| obstacle | candidate pieces | gap, numpy (us) | compiled | gap+grad+hess, numpy "
          "(us) | compiled | ratio |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    rng = np.random.default_rng(2)
    for name, ob, _ in cases():
        lo, hi = ob.bounds
        batch = [rng.uniform(lo - R, hi + R, (points, 3)) for _ in range(sets)]
        members = getattr(ob, "vessels", [ob])
        if not all(v._all_pairs(points) for v in members):
            continue
        K = sum(v._m + len(v._extra) for v in members)

        def run(order, ob=ob, batch=batch):
            for p in batch:
                ob.evaluate(p, order)

        def by_numpy(order, run=run):
            with numpy_search():
                run(order)

        times = []
        for order in (0, 2):  # interleaved: a burst of load hits both alike
            pair = (lambda order=order: by_numpy(order), lambda order=order: run(order))
            times += [t / sets for t in best_times(pair, repeat)]
        us = " | ".join(f"{1e6 * t:.1f}" for t in times)
        print(f"| {name} | {K} | {us} | {times[2] / times[3]:.1f} |")
    print()


def main() -> None:
    quick = bench_args(__doc__).quick
    if _compiled_search is not None:  # compiled (or loaded from numba's cache) at once
        _compiled_search._rental.ready = True
        Vessel.straight(0.01, R).gap(np.zeros((1, 3)))
    n, repeat = (N // 10, 1) if quick else (N, 3)
    print(f"# Contact geometry: time per point, {n:.0e} points")
    print()
    print(f"Machine: {machine_info()}; {clock_name()} time, best of {repeat}.")
    print()
    print(
        "| obstacle | pieces | gap (us/pt) | gap+grad+hess (us/pt) | shapely (us/pt) | "
        "max diff to shapely (m) |"
    )
    print("|---|---|---|---|---|---|")
    rng = np.random.default_rng(0)
    for name, ob, line in cases():
        lo, hi = ob.bounds
        pts = rng.uniform(lo - R, hi + R, (n, 3))
        if line is not None:
            pts[:, 2] = 0.0
        t_gap = best_time(lambda ob=ob, pts=pts: (forget(ob), ob.gap(pts)), repeat)
        t_all = best_time(lambda ob=ob, pts=pts: (forget(ob), ob.evaluate(pts)), repeat)
        pieces = getattr(ob, "_m", None) or sum(v._m for v in ob.vessels)
        shap, diff = "-", "-"
        if line is not None:
            geom = shapely.LineString(line)
            sp = shapely.points(pts[:, :2])
            t_sh = best_time(lambda geom=geom, sp=sp: shapely.distance(geom, sp), repeat)
            d = shapely.distance(geom, sp)
            shap = f"{1e6 * t_sh / n:.2f}"
            diff = f"{np.max(np.abs(ob.gap(pts) - (R - d))):.1e}"
        print(
            f"| {name} | {pieces} | {1e6 * t_gap / n:.2f} | {1e6 * t_all / n:.2f} | {shap} | "
            f"{diff} |"
        )
    print()
    print(
        "The bend's difference to shapely is the sagitta of its 512 chords "
        "(rho (1 - cos(pi/2048)) = 1.2e-8 m); the others agree to rounding."
    )
    if _compiled_search is not None:
        print()
        per_call(repeat)


if __name__ == "__main__":
    main()
