"""Shared benchmark helpers: describe the machine and time callables (best of several runs).

Timings use the process CPU time (``time.process_time``) by default: on a machine shared with
other jobs, wall time measures the neighbours as much as the code.  Set ``BENCH_CLOCK=wall`` in
the environment to time by wall clock instead (the two agree on an idle machine with
single-threaded numpy).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import importlib
import os
import platform
import time


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown cpu"


def machine_info() -> str:
    """One paragraph naming the platform, CPU, core count, load and library versions."""
    import magpylib
    import numpy
    import scipy

    try:
        load = "load average {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())
    except OSError:
        load = "load average n/a"
    return (
        f"{platform.platform()}; {_cpu_model()}; {os.cpu_count()} cores ({load}); "
        f"Python {platform.python_version()}, numpy {numpy.__version__}, "
        f"scipy {scipy.__version__}, magpylib {magpylib.__version__}"
    )


def clock():
    """The timer in use: process CPU time, or wall time if ``BENCH_CLOCK=wall``."""
    return time.perf_counter() if os.environ.get("BENCH_CLOCK") == "wall" else time.process_time()


def clock_name() -> str:
    return "wall" if os.environ.get("BENCH_CLOCK") == "wall" else "process CPU"


def best_time(fn, repeat: int = 3, number: int = 1) -> float:
    """Smallest time (s, :func:`clock`) of ``repeat`` runs of ``number`` calls of ``fn``, per
    call."""
    best = float("inf")
    for _ in range(repeat):
        t0 = clock()
        for _ in range(number):
            fn()
        best = min(best, (clock() - t0) / number)
    return best


def best_times(fns, repeat: int = 3, number: int = 1) -> list[float]:
    """Like :func:`best_time` for several callables, interleaved so that a burst of load from
    other processes hits all of them alike; returns the best time per call of each."""
    best = [float("inf")] * len(fns)
    for _ in range(repeat):
        for k, fn in enumerate(fns):
            t0 = clock()
            for _ in range(number):
                fn()
            best[k] = min(best[k], (clock() - t0) / number)
    return best


def best_run(fn, repeat: int = 3):
    """Smallest time (s, :func:`clock`: process CPU unless ``BENCH_CLOCK=wall``) of ``repeat``
    calls of ``fn``, and the last call's result."""
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = clock()
        out = fn()
        best = min(best, clock() - t0)
    return best, out


def best_wall(fn, repeat: int = 3):
    """Smallest wall time (s) of ``repeat`` calls of ``fn``, and the last call's result."""
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


@contextlib.contextmanager
def phase_timers(targets):
    """Time functions in place: each ``(label, owner, name)`` of ``targets`` has
    ``owner.name`` wrapped by a process-CPU-time accumulator for the ``with`` block (restored
    after it).  Yields ``{label: [calls, CPU s]}``; ``reset(acc)`` zeroes it (after a warm-up)."""
    acc = {label: [0, 0.0] for label, _, _ in targets}
    saved = []

    def wrap(label, fn):
        @functools.wraps(fn)
        def timed(*a, **k):
            t0 = time.process_time()
            try:
                return fn(*a, **k)
            finally:
                acc[label][0] += 1
                acc[label][1] += time.process_time() - t0

        return timed

    for label, owner, name in targets:
        saved.append((owner, name, getattr(owner, name)))
        setattr(owner, name, wrap(label, getattr(owner, name)))
    try:
        yield acc
    finally:
        for owner, name, fn in reversed(saved):
            setattr(owner, name, fn)


def reset(acc) -> None:
    """Zero the accumulators of :func:`phase_timers`."""
    for entry in acc.values():
        entry[:] = [0, 0.0]


# the kernels with a numpy twin and a ski-rental threshold (README "Cold start")
_RENTED = (
    "coils.coaxial",
    "coilrod.rod._compiled",
    "coilrod.rod._compiled_spatial",
    "coilrod.rod._inertia",
    "coilrod.rod._planar_newton",
    "coilrod.rod._mixed_newton",
)


def compile_at_once(warm_up: bool = True) -> None:
    """Time the compiled paths: set every ski-rental threshold (``COMPILE_AFTER``) to 0, so
    each kernel compiles (or loads from numba's cache) at its first call instead of running
    its numpy twin first, and (``warm_up``) make those first calls now, on 4-segment rods: a
    planar state in a uniform field and in a coil pair's field, a spatial state.  No timed
    call then pays a compile, also where numba's cache is not used (``PYTHONDONTWRITEBYTECODE``
    on the shared machines: every process compiles).  The benchmarks that measure the steady
    state call this; what a fresh process pays is ``bench_coldstart.py``'s job.  (A module an
    older checkout timed alongside does not have is skipped.)"""
    for name in _RENTED:
        try:
            module = importlib.import_module(name)
        except ImportError:
            continue
        if hasattr(module, "COMPILE_AFTER"):
            module.COMPILE_AFTER = 0.0
        if hasattr(module, "ODD_COMPILE_AFTER"):  # coilrod.rod._compiled's out-of-plane blocks
            module.ODD_COMPILE_AFTER = 0.0
    if warm_up:
        _warm_up()


def _warm_up() -> None:
    import warnings

    import coils
    from coilrod import presets, solve_rod

    rod = presets.seed_rod(presets.M1())
    b = rod.field_for_lambda(3.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        solve_rod(rod, coils.UniformField(B=(0.0, b, 0.0)), [1.0], nodes=4)
        solve_rod(rod, coils.HelmholtzPair(0.08, 100, 2.0, axis="y"), [1.0], nodes=4)
        spatial = coils.UniformField(B=(0.3 * b, b, 0.4 * b))
        solve_rod(rod, spatial, [1.0], model="spatial", nodes=4)


def bench_args(
    doc: str, argv=None, quick_help: str = "a short run: small cases, one repeat, nothing written"
) -> argparse.Namespace:
    """The common command line of a benchmark: ``--help`` (its docstring) and ``--quick``."""
    parser = argparse.ArgumentParser(
        description=doc, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help=quick_help)
    args, rest = parser.parse_known_args(argv)
    args.rest = rest
    return args


if __name__ == "__main__":
    print(machine_info())
