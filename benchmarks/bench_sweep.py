"""Sweep benchmark: points per second serially, in 2 local processes and on a 2-worker Dask
LocalCluster, on the same grids, on this machine.

Two grids of 32 points (8 coil radii x 4 Young's moduli) of the shipped scene
``helmholtz_vs_ideal`` (rod model in the real Helmholtz pair and in its ideal field):

1. as shipped (15 load steps, one filament per coil): a light point;
2. with 3 x 3-filament windings, 40 load steps and 256 rod segments: a heavier point.

Every executor writes the same rows (checked here); times are wall clock (parallelism is what is
measured), best of ``REPEAT`` interleaved runs.  The process pool is started by each sweep (its
start-up is in the time); the LocalCluster is started once, before the runs, and its start-up is
reported separately.  The ceiling: the same run also measures how much faster two processes
burn a pure-Python loop than one (on a shared or hyperthreaded machine, less than 2x).

The ski-rental thresholds are 0 in this process (``_machine.compile_at_once``: kernels compile
or load from numba's cache at their first call), and so in the local pool's forked workers; the
Dask workers keep the defaults, which compile at once when numba's cache holds the kernel (the
serial warm-up below fills it).

Run:  python benchmarks/bench_sweep.py   (needs dask[distributed]: pip install -e ".[cluster]")
      python benchmarks/bench_sweep.py --quick   (the light grid, one run, printed only)
"""

from __future__ import annotations

import copy
import sys
import time
import tomllib
from pathlib import Path

import coilrod
from coilrod.scene.cli import shipped_scenes

sys.path.insert(0, str(Path(__file__).parent))
from _machine import bench_args, compile_at_once, machine_info  # noqa: E402

REPEAT = 3
WORKERS = 2
PARAMS = {"field.coil.0.radius": "60 mm:200 mm:8", "robot.youngs_modulus": "0.5 MPa:2 MPa:4"}


def scenes() -> dict[str, dict]:
    light = tomllib.loads(shipped_scenes()["helmholtz_vs_ideal"].read_text(encoding="utf-8"))
    heavy = copy.deepcopy(light)
    heavy["field"]["coil"][0].update(winding=["10 mm", "10 mm"], filaments=[3, 3])
    heavy["load"]["steps"] = 40
    heavy["rod"] = {"nodes": 256}
    return {"light (as shipped)": light, "heavy (3x3 windings, 40 steps, 256 segments)": heavy}


def burn(n: int = 3_000_000) -> float:
    """Wall time of a pure-Python loop (one core's worth of work)."""
    t0 = time.perf_counter()
    total = 0
    for i in range(n):
        total += i * i
    return time.perf_counter() - t0


def parallel_ceiling() -> float:
    """Throughput of WORKERS processes burning loops over one process doing the same."""
    from concurrent.futures import ProcessPoolExecutor

    one = min(burn() for _ in range(REPEAT))
    with ProcessPoolExecutor(WORKERS) as pool:
        list(pool.map(burn, [1000] * WORKERS))  # started
        many = min(max(pool.map(burn, [3_000_000] * WORKERS)) for _ in range(REPEAT))
    return WORKERS * one / many


def best_runs(fns: dict) -> dict:
    """Label -> (smallest wall time of REPEAT interleaved calls, last result)."""
    best = {label: (float("inf"), None) for label in fns}
    for _ in range(REPEAT):
        for label, fn in fns.items():
            t0 = time.perf_counter()
            result = fn()
            best[label] = (min(best[label][0], time.perf_counter() - t0), result)
    return best


def main(quick: bool = False) -> str:
    from distributed import Client, LocalCluster

    global REPEAT
    compile_at_once()
    if quick:
        REPEAT = 1

    lines = []

    def out(text=""):
        print(text, flush=True)
        lines.append(text)

    out("# Sweep benchmark")
    out()
    out(f"Machine: {machine_info()}.")
    out(
        f"Grid: {' x '.join(f'{k} = {v}' for k, v in PARAMS.items())} (32 points); wall clock, "
        f"best of {REPEAT}."
    )
    out()
    ceiling = parallel_ceiling()
    t0 = time.perf_counter()
    cluster = LocalCluster(
        n_workers=WORKERS, threads_per_worker=1, processes=True, dashboard_address=None
    )
    client = Client(cluster, set_as_default=False)
    start = time.perf_counter() - t0
    try:
        out("| grid | executor | wall time (s) | points/s | speed-up over serial |")
        out("|---|---|---|---|---|")
        for name, data in list(scenes().items())[: 1 if quick else None]:
            coilrod.sweep(data, {"robot.youngs_modulus": [1e6]}, workers=1, progress=False)
            runs = {
                "serial (workers=1)": lambda d=data: coilrod.sweep(
                    d, PARAMS, workers=1, progress=False
                ),
                f"{WORKERS} local processes (workers={WORKERS})": lambda d=data: coilrod.sweep(
                    d, PARAMS, workers=WORKERS, progress=False
                ),
                f"Dask LocalCluster, {WORKERS} workers x 1 thread": lambda d=data: coilrod.sweep(
                    d, PARAMS, client=client, progress=False
                ),
            }
            serial_time, rows = None, None
            for label, (seconds, result) in best_runs(runs).items():
                assert not result.failed, result.failed
                if rows is None:
                    serial_time, rows = seconds, result.rows
                assert result.rows == rows, f"{label}: rows differ from the serial run"
                n = len(result.rows)
                out(
                    f"| {name} | {label} | {seconds:.2f} | {n / seconds:.1f} | "
                    f"{serial_time / seconds:.2f} |"
                )
        out()
        out(
            f"Ceiling on this machine in this run: {WORKERS} processes burn a pure-Python loop "
            f"{ceiling:.2f}x as fast as one."
        )
        out(
            f"Every executor wrote the same rows. Starting the LocalCluster took {start:.1f} s "
            "(not in the times above); the process pool starts with each sweep (in the times)."
        )
    finally:
        client.close()
        cluster.close()
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    quick = bench_args(__doc__).quick
    text = main(quick)
    if quick:
        sys.exit()
    target = Path(__file__).parent / "results" / "sweep.md"
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(text)
    print(f"written to {target}")
