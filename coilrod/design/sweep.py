"""Sweeps: a scene solved over a grid of parameter values, serially, in local processes or on a
Dask cluster, one CSV row per point.

A parameter is a scene key (``field.coil.0.radius``, ``robot.youngs_modulus``) with its values,
given as ``"START:STOP:N"`` with units (``"60 mm:120 mm:4"``: N evenly spaced values) or as a
sequence.  The grid is every combination, the first parameter varying slowest.  Each point's
scene is the scene's TOML data with those values put in, validated again by the scene parser,
so a value that makes one point invalid (a coil that now cuts through the robot) makes that
point's row an error instead of stopping the sweep.  Every point runs the scene as
``coilrod run`` would (:func:`coilrod.scene.runner.run_scene`), and its row holds, for each
model, the tip in each field at the scene's last load scale, whether it got there, whether that
equilibrium is stable, and the shift between the real and the ideal field.
"""

from __future__ import annotations

import copy
import itertools
import math
import numbers
import os
import re
import socket
import sys
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..scene import limits
from ..scene.keys import MISSING, assign, lookup, spell_key, split_key
from ..scene.parse import Scene, SceneError, load_scene, parse_scene
from ..scene.units import SI_UNITS, UnitError, read_quantity
from .sweep_file import SweepFile

__all__ = ["sweep", "SweepResult", "Parameter", "sweep_parameters", "solve_point"]

#: The CSV file a sweep writes in its output folder.
FILENAME = "sweep.csv"
#: Column-name suffix of a parameter's SI unit.
_UNIT_SUFFIX = {
    "length": "m",
    "flux density": "T",
    "gradient": "T_per_m",
    "magnetization": "A_per_m",
    "pressure": "Pa",
    "current": "A",
    "angle": "rad",
}
_INTEGER = re.compile(r"^\s*[-+]?\d+\s*$")


@dataclass(frozen=True)
class Parameter:
    """One swept scene key and its values.

    Attributes
    ----------
    key : str
        The key as given, dotted (``field.coil.0.radius``).
    parts : tuple of str and int
        The key's path in the scene data.
    values : tuple of float or int
        The values, in SI units (m, T, T/m, A/m, Pa, A, rad) when ``dimension`` is set, else
        plain numbers.
    dimension : str or None
        "length", "pressure", ... (:data:`coilrod.scene.units.DIMENSIONS`); None for a plain
        number (``robot.magnetization.phi``, ``field.coil.0.turns``).
    """

    key: str
    parts: tuple
    values: tuple
    dimension: str | None

    @property
    def column(self) -> str:
        """The CSV column: the key and its SI unit, e.g. ``field.coil.0.radius_m``."""
        return self.key + (f"_{_UNIT_SUFFIX[self.dimension]}" if self.dimension else "")

    def scene_value(self, value):
        """``value`` as the scene file spells it: SI with its unit, e.g. ``"0.06 m"``."""
        if self.dimension is None:
            return value
        return f"{float(value)!r} {SI_UNITS[self.dimension]}"


@dataclass
class SweepResult:
    """The rows of a sweep, in grid order.

    Attributes
    ----------
    parameters : list of Parameter
    columns : list of str
        ``point``, one column per parameter (SI; see :attr:`Parameter.column`), then per model
        ``<model>_<field>_tip_x_m``, ``..._tip_y_m``, ``..._tip_z_m`` (tip at the last load
        scale, m), ``<model>_<field>_converged`` (every scale reached),
        ``<model>_<field>_stable`` (the last state is a stable equilibrium) for each field
        (``coils``, ``ideal``), ``<model>_shift_m`` (distance between the two tips, m) when the
        scene compares them, and ``error`` (empty for a point that solved).
    rows : list of dict
        One per grid point: column -> value (float, int, bool, str; None where a model did not
        reach the load).
    path : Path or None
        The CSV file, if one was written.
    solved : int
        Points solved by this call.
    reused : int
        Points read back from the CSV file (``resume=True``).
    executor : str
        How the points were solved: "serially", "in N local processes", "on the Dask cluster
        at ADDRESS" ("" if there was nothing to solve).
    seconds : float
        Wall time spent solving, s.
    """

    parameters: list[Parameter]
    columns: list[str]
    rows: list[dict]
    path: Path | None = None
    solved: int = 0
    reused: int = 0
    executor: str = ""
    seconds: float = 0.0

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def failed(self) -> list[dict]:
        """The rows with an error (an invalid point, or a model that did not reach the load)."""
        return [r for r in self.rows if r["error"]]

    def to_pandas(self):
        """The rows as a ``pandas.DataFrame`` (pandas is imported here; it is optional)."""
        import pandas as pd

        return pd.DataFrame(self.rows, columns=self.columns)


# -- parameters -------------------------------------------------------------------------------
def _label(key) -> str:
    return f"sweep parameter {key}"


def _about(key, parts, line: str) -> str:
    """A scene problem ``line`` as a problem of the parameter ``key`` (its key said once)."""
    own = f"{spell_key(parts)}: "
    return f"{_label(key)}: {line.removeprefix(own)}"


def _number_values(items, label: str):
    """(values, dimension, plain_kind) of a sequence of numbers and quantity strings."""
    values, dims = [], set()
    for i, item in enumerate(items):
        if isinstance(item, str):
            value, dim = read_quantity(item, f"{label}[{i}]")
            values.append(value)
            dims.add(dim)
        elif isinstance(item, numbers.Real) and not isinstance(item, bool | np.bool_):
            if not math.isfinite(item):
                raise SceneError(f"{label}[{i}]: must be finite; got {item!r}")
            values.append(int(item) if isinstance(item, numbers.Integral) else float(item))
            dims.add("SI")
        else:
            raise SceneError(f"{label}[{i}]: expected a number or a quantity such as '60 mm'")
    units = dims - {None, "SI"}
    if len(units) > 1:
        raise SceneError(f"{label}: values of different kinds ({', '.join(sorted(units))})")
    if units and None in dims:
        raise SceneError(f"{label}: some values have a unit and some do not")
    return values, (units.pop() if units else None), ("SI" if "SI" in dims else None)


def _range(spec: str, label: str):
    """(values, dimension, plain) of ``"START:STOP:N"``."""
    example = "e.g. '60 mm:120 mm:4' (4 values from 60 mm to 120 mm)"
    pieces = spec.split(":")
    if len(pieces) != 3 or not all(p.strip() for p in pieces):
        raise SceneError(f"{label}: expected START:STOP:N, {example}; got {spec!r}")
    start_s, stop_s, n_s = (p.strip() for p in pieces)
    if not _INTEGER.match(n_s):
        raise SceneError(f"{label}: N must be a whole number of values, {example}; got {n_s!r}")
    n = int(n_s)
    if n < 1:
        raise SceneError(f"{label}: N must be at least 1 (the number of values); got {n}")
    if n > limits.MAX_SWEEP_POINTS:
        raise SceneError(f"{label}: at most {limits.MAX_SWEEP_POINTS} values; got {n}")
    start, d0 = read_quantity(start_s, f"{label} START")
    stop, d1 = read_quantity(stop_s, f"{label} STOP")
    if d0 != d1:
        what = [f"a {d}" if d else "a plain number" for d in (d0, d1)]
        raise SceneError(
            f"{label}: START {start_s!r} is {what[0]} but STOP {stop_s!r} is {what[1]}; give "
            f"both with units, {example}"
        )
    values = np.linspace(start, stop, n).tolist()
    if d0 is None and _INTEGER.match(start_s) and _INTEGER.match(stop_s):
        if all(float(v).is_integer() for v in values):
            values = [int(v) for v in values]
    return values, d0, None


def _parameter(key, spec, data: dict) -> Parameter:
    label = _label(key)
    try:
        parts = split_key(key)
    except SceneError as exc:
        raise SceneError(f"{label}: {exc.problems[0].removeprefix(f'{key!r}: ')}") from None
    try:
        current = lookup(data, parts)
    except SceneError as exc:
        raise SceneError(_about(key, parts, exc.problems[0])) from None
    try:
        if isinstance(spec, str):
            values, dim, plain = _range(spec, label)
        elif isinstance(spec, Sequence | np.ndarray) and not isinstance(spec, bytes):
            items = np.asarray(spec).tolist() if isinstance(spec, np.ndarray) else list(spec)
            if not items:
                raise SceneError(f"{label}: no values (an empty sequence)")
            if len(items) > limits.MAX_SWEEP_POINTS:
                raise SceneError(f"{label}: at most {limits.MAX_SWEEP_POINTS} values")
            values, dim, plain = _number_values(items, label)
        else:
            raise SceneError(
                f"{label}: expected 'START:STOP:N' (e.g. '60 mm:120 mm:4') or a sequence of "
                f"values; got {spec!r}"
            )
    except UnitError as exc:
        raise SceneError(str(exc)) from None
    here = spell_key(parts)
    if isinstance(current, bool):
        raise SceneError(f"{label}: is a boolean in the scene; only numbers are swept")
    scene_dim = None
    if isinstance(current, str):
        try:
            _, scene_dim = read_quantity(current, here)
        except UnitError:
            raise SceneError(
                f"{label}: is {current!r} in the scene, not a number; only numbers are swept"
            ) from None
    plain_in_scene = current is not MISSING and scene_dim is None
    if dim == "angle" and plain_in_scene and current == 0:
        plain_in_scene = False  # scenes may write a zero angle without a unit
    if dim is not None and plain_in_scene:
        raise SceneError(
            f"{label}: is a plain number in the scene ({current!r}); got a {dim} ({spec!r})"
        )
    if dim is not None and scene_dim is not None and dim != scene_dim:
        raise SceneError(
            f"{label}: is a {scene_dim} in the scene ({current!r}); got a {dim} ({spec!r})"
        )
    if dim is None and scene_dim is not None:
        if plain != "SI":  # "START:STOP:N" without units
            raise SceneError(
                f"{label}: missing unit in {spec!r}; it is a {scene_dim} (the scene has "
                f"{current!r}): give START and STOP with units"
            )
        dim = scene_dim  # numbers in a sequence are SI
    if dim is not None:
        values = [float(v) for v in values]
    return Parameter(key=_dotted(parts), parts=parts, values=tuple(values), dimension=dim)


def _dotted(parts) -> str:
    return ".".join(str(p) for p in parts)


def sweep_parameters(params: Mapping, scene: Scene) -> list[Parameter]:
    """Check the parameters of a sweep of ``scene`` and read their values.

    Parameters
    ----------
    params : mapping
        Scene key -> ``"START:STOP:N"`` (units on START and STOP, e.g. ``"60 mm:120 mm:4"``;
        N evenly spaced values, START alone for N = 1) or a sequence of values (numbers in SI,
        or strings with units such as ``"60 mm"``).
    scene : Scene
        A scene with its TOML data (:attr:`Scene.data`).

    Returns
    -------
    list of Parameter

    Raises
    ------
    SceneError
        Every problem, one line each: a key the scene cannot have (an unknown key, an index past
        the end of a list), a malformed or empty range, a value of the wrong kind (a length for
        a pressure), a key given twice, a grid of more than
        :data:`coilrod.scene.limits.MAX_SWEEP_POINTS` points.
    """
    if not isinstance(params, Mapping) or not params:
        raise SceneError(
            "sweep parameters: expected at least one scene key and its values, e.g. "
            "{'field.coil.0.radius': '60 mm:120 mm:4'}"
        )
    problems: dict[str, list[str]] = {}  # by key, reported in the order given
    found: list[Parameter] = []
    seen: dict[tuple, str] = {}
    for key, spec in params.items():
        problems[key] = []
        try:
            p = _parameter(key, spec, scene.data)
        except SceneError as exc:
            problems[key] += exc.problems
            continue
        if p.parts in seen:
            problems[key].append(f"{_label(key)}: given twice (also as {seen[p.parts]})")
            continue
        seen[p.parts] = key
        found.append(p)
    for key, lines in _unknown_keys(found, scene).items():
        problems[key] += lines
    lines = [line for key_lines in problems.values() for line in key_lines]
    if lines:
        raise SceneError(lines)
    total = math.prod(len(p.values) for p in found)
    if total > limits.MAX_SWEEP_POINTS:
        raise SceneError(
            f"sweep parameters: {total} points, more than the {limits.MAX_SWEEP_POINTS} allowed; "
            "sweep fewer values"
        )
    return found


def _unknown_keys(found: list[Parameter], scene: Scene) -> dict[str, list[str]]:
    """The parser's "unknown key" problems of each parameter.

    A key the scene does not set is put in (at the first grid point): the parser must know it,
    else it is an error of the sweep, not of every row.
    """
    fresh = [p for p in found if lookup(scene.data, p.parts) is MISSING]
    if not fresh:
        return {}
    data = _point_data(scene.data, fresh, [p.values[0] for p in fresh])
    try:
        parse_scene(data, scene.source)
    except SceneError as exc:
        out = {}
        for p in fresh:
            n = len(p.parts)
            prefixes = [f"{spell_key(p.parts[:i])}: unknown key" for i in range(1, n + 1)]
            lines = [line for line in exc.problems if line.startswith(tuple(prefixes))]
            if lines:
                out[p.key] = [_about(p.key, p.parts, line) for line in lines]
        return out
    return {}


def _point_data(base: dict, parameters: list[Parameter], values) -> dict:
    data = copy.deepcopy(base)
    for p, v in zip(parameters, values, strict=True):
        assign(data, p.parts, p.scene_value(v))
    return data


# -- one point --------------------------------------------------------------------------------
def result_columns(scene: Scene) -> list[str]:
    """The result columns of a sweep of ``scene`` (see :class:`SweepResult`)."""
    cols = []
    for model in scene.models:
        for label in scene.fields:
            name = f"{model}_{label}"
            cols += [f"{name}_tip_{c}_m" for c in "xyz"]
            cols += [f"{name}_converged", f"{name}_stable"]
        if "coils" in scene.fields and "ideal" in scene.fields:
            cols.append(f"{model}_shift_m")
    return cols


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def solve_point(data: dict, source: str = "<embedded>") -> dict:
    """Validate and run one point's scene; its result columns (see :class:`SweepResult`).

    Never raises for a bad point: an invalid scene or a failed solve is the ``error`` entry.
    Solver warnings are not shown (``stable`` says whether the last state is stable), so the
    row does not depend on the caller's warning filters.

    Parameters
    ----------
    data : dict
        The point's scene as TOML data.
    source : str
        Where the scene came from (for its default name).

    Returns
    -------
    dict
        Column -> value for the columns that apply, and ``error`` ("" if the point solved).
    """
    from ..scene.runner import run_scene

    try:
        scene = parse_scene(data, source)
    except SceneError as exc:
        return {"error": _one_line("invalid scene at this point: " + "; ".join(exc.problems))}
    try:
        with warnings.catch_warnings(record=True):
            warnings.simplefilter("always")
            result = run_scene(scene, progress=False)
    except Exception as exc:  # a failed point is a row, whatever went wrong
        return {"error": _one_line(f"{type(exc).__name__}: {exc}")}
    row: dict = {}
    errors, tips = [], {}
    for run in result.runs:
        name = f"{run.model}_{run.field_label}"
        converged = getattr(run.result, "converged", None)
        done = (
            not run.error
            and len(run.scales) == len(scene.scales)
            and (converged is None or bool(np.all(converged)))
        )
        row[f"{name}_converged"] = done
        if done:
            tip = np.asarray(run.tip[-1], dtype=float)
            for c, value in zip("xyz", tip, strict=True):
                row[f"{name}_tip_{c}_m"] = float(value)
            row[f"{name}_stable"] = bool(run.stable[-1])
            tips[run.model, run.field_label] = tip
        else:
            why = run.error or "did not reach every load scale"
            errors.append(f"{run.model} in the {run.field_label} field: {why}")
    for model in scene.models:
        if (model, "coils") in tips and (model, "ideal") in tips:
            shift = np.linalg.norm(tips[model, "coils"] - tips[model, "ideal"])
            row[f"{model}_shift_m"] = float(shift)
    row["error"] = _one_line("; ".join(errors))
    return row


def _failed(message: str) -> dict:
    return {"error": _one_line(message)}


# -- running the points -----------------------------------------------------------------------
def _ignore_sigint() -> None:  # pragma: no cover - runs in the worker processes
    """Worker processes leave Ctrl-C to the parent (which stops the sweep)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run_serial(tasks, source, done: Callable) -> None:
    for point, data in tasks:
        done(point, solve_point(data, source))


def _start_pool(workers: int):
    """A pool of ``workers`` processes, started now and the platform's default way (fork on
    Linux before Python 3.14: the workers start with coilrod imported), before any thread of
    the sweep (the progress bar's) exists."""
    from concurrent.futures import ProcessPoolExecutor

    pool = ProcessPoolExecutor(workers, initializer=_ignore_sigint)
    pool.submit(int).result()
    return pool


def _run_processes(tasks, source, pool, done: Callable) -> None:
    from concurrent.futures import as_completed

    try:
        futures = {pool.submit(solve_point, data, source): point for point, data in tasks}
        for future in as_completed(futures):
            try:
                row = future.result()
            except Exception as exc:  # the worker process died (BrokenProcessPool)
                row = _failed(f"worker process: {type(exc).__name__}: {exc}")
            done(futures[future], row)
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()


#: Seconds to wait for the scheduler's port to answer, before dask is asked to connect.
CONNECT_TIMEOUT = 10.0


def _check_address(address: str) -> None:
    """A scheduler address dask can read, whose host is known and whose port answers."""
    from distributed.comm import parse_address
    from distributed.comm.addressing import parse_host_port
    from distributed.comm.registry import backends

    example = "e.g. tcp://10.0.0.5:8786"
    if not address.strip():
        raise SceneError(f"scheduler: expected the address of a Dask scheduler, {example}")
    try:
        scheme, location = parse_address(address)
        if scheme not in backends:
            raise ValueError(f"unknown scheme {scheme!r}; known: {', '.join(sorted(backends))}")
        if scheme in ("tcp", "tls", "ws", "wss"):
            host, port = parse_host_port(location)
    except ValueError as exc:
        raise SceneError(f"scheduler {address}: not an address, {example} ({exc})") from None
    if scheme not in ("tcp", "tls", "ws", "wss"):
        return
    try:
        socket.create_connection((host, port), timeout=CONNECT_TIMEOUT).close()
    except socket.gaierror:
        raise SceneError(f"scheduler {address}: unknown host {host!r}") from None
    except OSError as exc:
        why = exc.strerror or type(exc).__name__
        raise SceneError(
            f"scheduler {address}: cannot connect ({why}); is a Dask scheduler running there "
            "(dask scheduler) and its port open?"
        ) from None


def _identify(address: str):
    """What answers at ``address`` to dask's "identity" request (a dict for a scheduler)."""
    import asyncio
    from concurrent.futures import ThreadPoolExecutor

    from distributed.comm import connect

    async def ask():
        comm = await connect(address, timeout=CONNECT_TIMEOUT)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await asyncio.wait_for(comm.read(), CONNECT_TIMEOUT)
        finally:
            await comm.close()

    with ThreadPoolExecutor(1) as thread:  # its own event loop, also under a running one
        return thread.submit(asyncio.run, ask()).result()


def _connect(address: str):
    """A dask Client of the scheduler at ``address``; SceneError if it cannot be reached."""
    try:
        from distributed import Client
    except ImportError:
        raise SceneError(
            f"scheduler {address}: running on a Dask cluster needs dask.distributed "
            "(pip install 'coilrod[cluster]')"
        ) from None
    _check_address(address)
    if address.startswith("tcp://") or "://" not in address:
        try:
            identity = _identify(address)
            what = f"a dask {identity.get('type')}" if isinstance(identity, dict) else "no reply"
        except Exception as exc:  # whatever answered, it does not speak dask
            identity, what = None, f"no dask handshake: {type(exc).__name__}"
        if not isinstance(identity, dict) or identity.get("type") != "Scheduler":
            raise SceneError(
                f"scheduler {address}: not a Dask scheduler ({what}); give the address "
                "'dask scheduler' prints"
            )
    try:
        return Client(address, set_as_default=False)
    except Exception as exc:
        raise SceneError(
            f"scheduler {address}: cannot connect ({_one_line(str(exc)) or type(exc).__name__})"
        ) from None


def _run_dask(tasks, source, client, done: Callable) -> None:
    from distributed import as_completed

    futures = {}
    for point, data in tasks:
        futures[client.submit(solve_point, data, source, pure=False)] = point
    try:
        for future in as_completed(list(futures), loop=client.loop):
            try:
                row = future.result()
            except Exception as exc:  # a worker died or could not run the task
                row = _failed(f"dask: {type(exc).__name__}: {exc}")
            done(futures[future], row)
    except BaseException:
        client.cancel(list(futures))
        raise


def _as_scene(scene) -> Scene:
    if isinstance(scene, Scene):
        if scene.data is None:
            raise SceneError(
                "scene: this Scene was built without its TOML data (Scene.data); give the "
                "scene file or its dict to sweep it"
            )
        return scene
    if isinstance(scene, dict):
        return parse_scene(scene)
    if isinstance(scene, str | os.PathLike):
        return load_scene(scene)
    raise SceneError(f"scene: expected a scene file, its dict or a Scene; got {scene!r}")


def _check_workers(workers, client) -> int | None:
    if workers is None:
        return None
    if client is not None:
        raise SceneError("workers: give either workers (local processes) or a client, not both")
    if isinstance(workers, bool) or not isinstance(workers, numbers.Integral) or workers < 1:
        raise SceneError(f"workers: expected a whole number of at least 1; got {workers!r}")
    return int(workers)


def sweep(
    scene: Scene | dict | str | os.PathLike,
    params: Mapping[str, str | Sequence],
    client=None,
    *,
    workers: int | None = None,
    out: str | os.PathLike | None = None,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool | None = None,
) -> SweepResult:
    """Run a scene over the grid of parameter values: one row per point.

    Parameters
    ----------
    scene : str, Path, dict or Scene
        A scene file, its TOML data, or a Scene parsed from one (it keeps its data).
    params : mapping
        Scene key -> values.  Keys as in scene files, list entries by index:
        ``"robot.youngs_modulus"``, ``"field.coil.0.radius"`` (or ``field.coil[0].radius``),
        ``"robot.magnetization.phi"``, ``"rod.nodes"``.  Values: ``"START:STOP:N"`` with units
        (``"60 mm:120 mm:4"``: N evenly spaced values, START alone for N = 1; a plain number
        key such as ``phi`` takes ``"0.1:0.3:3"``), or a sequence of values (numbers in SI
        units, or strings with units such as ``"60 mm"``).
    client : distributed.Client or str, optional
        Run the points on this Dask cluster (a Client, or the scheduler's address such as
        ``"tcp://10.0.0.5:8786"``, connected to and closed here).  Needs the ``cluster``
        extra; dask is imported only then.
    workers : int, optional
        Without a client: the number of local worker processes (default: the CPU count; at
        most one per point to solve).  1 solves the points one after another in this process.
    out : str or Path, optional
        A folder: the rows go to ``out/sweep.csv`` as the points finish (each row appended and
        flushed), and the file is rewritten in grid order at the end.
    resume : bool
        Keep the points already in ``out/sweep.csv`` (from a sweep that was stopped) and solve
        only the others.  The file must be this sweep's: same columns and the same parameter
        values at each point number.  A cut last line (a sweep killed while writing it) is
        dropped and that point solved again.
    overwrite : bool
        Replace an existing ``out/sweep.csv`` (without it, and without ``resume``, an existing
        file is an error).
    progress : bool, optional
        Show a progress bar (tqdm, on stderr); default: when stderr is a terminal.

    Returns
    -------
    SweepResult
        ``rows`` in grid order (the first parameter varying slowest), values in SI.

    Raises
    ------
    SceneError
        Before anything is solved, one line per problem: an invalid scene, unknown parameter
        keys, malformed or empty ranges (N < 1), values of the wrong kind, a folder that cannot
        be written, an existing file of another sweep, a scheduler that cannot be reached.
        Problems of single points are not raised: they are the ``error`` of their row.

    Notes
    -----
    Every point runs the whole scene (each model in each field) as ``coilrod run`` does, with
    the scene's load path; the row reports the last load state.  The points do not depend on
    each other, so the rows are the same whichever way they are run (serially, in processes,
    on a cluster) and in whatever order the points finish.

    Examples
    --------
    >>> scene = {
    ...     "robot": {"length": "40 mm", "diameter": "2 mm", "youngs_modulus": "1 MPa",
    ...               "magnetization": {"preset": "M1"}},
    ...     "field": {"type": "uniform", "B": "5 mT"},
    ...     "load": {"steps": 2}, "rod": {"nodes": 8}}
    >>> result = sweep(scene, {"robot.youngs_modulus": "1 MPa:2 MPa:3"}, workers=1,
    ...                progress=False)
    >>> [row["robot.youngs_modulus_Pa"] for row in result.rows]
    [1000000.0, 1500000.0, 2000000.0]
    >>> [round(1e3 * row["rod_ideal_tip_y_m"], 2) for row in result.rows]  # stiffer: less
    [27.0, 23.17, 20.01]
    """
    scene = _as_scene(scene)
    problems: list[str] = []
    parameters: list[Parameter] = []
    try:
        parameters = sweep_parameters(params, scene)
    except SceneError as exc:
        problems += exc.problems
    try:
        workers = _check_workers(workers, client)
    except SceneError as exc:
        problems += exc.problems
    if client is not None and not isinstance(client, str) and not hasattr(client, "submit"):
        problems.append(f"client: expected a dask Client or a scheduler address; got {client!r}")
    if resume and out is None:
        problems.append("resume: needs the folder of the sweep to resume (out)")
    file = None
    if out is not None:
        from ..scene.outputs import prepare_output_dir

        try:
            prepare_output_dir(out, create=False, key="out")
        except SceneError as exc:
            problems += exc.problems
    if problems:
        raise SceneError(problems)

    columns = ["point", *(p.column for p in parameters), *result_columns(scene), "error"]
    grid = list(itertools.product(*(p.values for p in parameters)))
    rows: dict[int, dict] = {}
    if out is not None:
        kinds = {c: "number" for c in columns}
        kinds.update({"point": "int", "error": "text"})
        kinds.update({c: "bool" for c in columns if c.endswith(("_converged", "_stable"))})
        file = SweepFile(Path(out) / FILENAME, columns, kinds)
        rows = file.check(resume=resume, overwrite=overwrite)
        _check_resumed(rows, grid, parameters, file.path)
    reused = len(rows)
    todo = [i for i in range(len(grid)) if i not in rows]

    own_client = None
    if isinstance(client, str):
        client = own_client = _connect(client)
    try:
        if file is not None:
            from ..scene.outputs import prepare_output_dir

            prepare_output_dir(out, create=True, key="out")
            file.open()
        t0 = time.perf_counter()
        executor = _run(scene, parameters, grid, todo, rows, file, client, workers, progress)
        seconds = time.perf_counter() - t0
    finally:
        if file is not None:
            file.close()
        if own_client is not None:
            own_client.close()
    ordered = [rows[i] for i in range(len(grid))]
    if file is not None:
        file.rewrite(ordered)
    return SweepResult(
        parameters,
        columns,
        ordered,
        file.path if file else None,
        solved=len(todo),
        reused=reused,
        executor=executor,
        seconds=seconds,
    )


def _check_resumed(rows: dict, grid: list, parameters: list[Parameter], path: Path) -> None:
    """The rows of an existing file must be points of this grid."""
    outside = [point for point in rows if not 0 <= point < len(grid)]
    if outside:
        raise SceneError(
            f"{path}: has point {outside[0]}, this sweep has points 0 to {len(grid) - 1}: it is "
            "from another sweep; use another folder or overwrite it"
        )
    for point, row in rows.items():
        for p, value in zip(parameters, grid[point], strict=True):
            if row[p.column] != value:
                raise SceneError(
                    f"{path}: has {p.column} = {row[p.column]!r} at point {point}, this sweep "
                    f"{value!r}: it is from another sweep; use another folder or overwrite it"
                )


def _run(scene, parameters, grid, todo, rows, file, client, workers, progress) -> str:
    """Solve the points ``todo``, fill ``rows`` and append them to ``file``; says how."""
    import multiprocessing

    from tqdm.auto import tqdm

    n = 0 if client is not None or not todo else min(workers or os.cpu_count() or 1, len(todo))
    first = None
    if n > 1 and multiprocessing.get_start_method() == "fork":
        # solve one point here first: forked workers then start with the kernels loaded
        data = _point_data(scene.data, parameters, grid[todo[0]])
        first = (todo[0], solve_point(data, scene.source))
        todo = todo[1:]
        n = min(n, len(todo))
    pool = _start_pool(n) if n > 1 else None
    show = sys.stderr.isatty() if progress is None else bool(progress)
    names = result_columns(scene)
    tasks = ((i, _point_data(scene.data, parameters, grid[i])) for i in todo)
    bar = tqdm(
        total=len(grid),
        initial=len(grid) - len(todo) - (first is not None),
        desc="sweep",
        unit="point",
        disable=not show,
    )

    def done(point: int, result: dict) -> None:
        row = {"point": point}
        row.update({p.column: v for p, v in zip(parameters, grid[point], strict=True)})
        row.update({c: result.get(c) for c in names})
        row["error"] = result.get("error", "")
        rows[point] = row
        if file is not None:
            file.append(row)
        bar.update()

    try:
        if first is not None:
            done(*first)
        if not todo and first is None:
            return ""
        if client is not None:
            _run_dask(tasks, scene.source, client, done)
            return f"on the Dask cluster at {client.scheduler.address}"
        if pool is not None:
            _run_processes(tasks, scene.source, pool, done)
            return f"in {n} local processes"
        _run_serial(tasks, scene.source, done)
        return "serially"
    finally:
        bar.close()
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
