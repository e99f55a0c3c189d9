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

import itertools
import numbers
import os
import sys
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..scene.parse import Scene, SceneError, load_scene, parse_scene
from .sweep_file import SceneFingerprint, SweepFile
from .sweep_params import Parameter, point_data, sweep_parameters

__all__ = ["sweep", "SweepResult", "Parameter", "sweep_parameters", "solve_point"]

#: The CSV file a sweep writes in its output folder.
FILENAME = "sweep.csv"
#: The scene fingerprint next to it (:class:`~coilrod.design.sweep_file.SceneFingerprint`).
FINGERPRINT = "sweep.json"
#: Errors of points whose worker died, not of the points: a resumed sweep solves them again.
RETRIED = ("worker process:", "dask:")
#: Why a control scene is not swept (its rows would be currents, not tips: not done yet).
CONTROL_NOT_SWEPT = (
    "control: a control scene ([control]) cannot be swept yet (a sweep row holds tips under a "
    "given field); run it with 'coilrod run'"
)
#: Why a navigation scene is not swept (its rows would be insertions, not load paths).
NAVIGATION_NOT_SWEPT = (
    "insertion: a navigation scene ([insertion]) cannot be swept yet (a sweep row holds tips "
    "under a load path, not an insertion); run it with 'coilrod run'"
)


def not_swept(scene) -> list[str]:
    """Why ``scene`` cannot be swept at all (a control or a navigation scene), [] if it can."""
    problems = [CONTROL_NOT_SWEPT] if scene.control is not None else []
    if "insertion" in getattr(scene, "rod_options", {}):
        problems.append(NAVIGATION_NOT_SWEPT)
    return problems


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


def _checked(scene, params, workers, client, resume, out):
    """The sweep's parameters and worker count, every problem of the arguments reported at once
    (SceneError)."""
    problems: list[str] = not_swept(scene)
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
    if out is not None:
        from ..scene.outputs import prepare_output_dir

        try:
            prepare_output_dir(out, create=False, key="out")
        except SceneError as exc:
            problems += exc.problems
    if problems:
        raise SceneError(problems)
    return parameters, workers


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
        flushed), and the file is rewritten in grid order at the end; ``out/sweep.json``
        holds the scene's fingerprint (see ``resume``).
    resume : bool
        Keep the points already in ``out/sweep.csv`` (from a sweep that was stopped) and solve
        only the others.  The file must be this sweep's: same columns and the same parameter
        values at each point number, and ``out/sweep.json`` (written with the first row) must
        name the same scene (its parsed TOML data: comments and layout do not count) and the
        same coilrod version.  A cut last line (a sweep killed while writing it) is
        dropped and that point solved again, and so are the points whose worker died (errors
        starting "worker process:" or "dask:"); the errors of the points themselves are kept.
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
        be written, an existing file of another sweep (other columns or values, another scene
        or coilrod version), a scheduler that cannot be reached.
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
    parameters, workers = _checked(scene, params, workers, client, resume, out)
    file = None
    columns = ["point", *(p.column for p in parameters), *result_columns(scene), "error"]
    grid = list(itertools.product(*(p.values for p in parameters)))
    rows: dict[int, dict] = {}
    if out is not None:
        kinds = {c: "number" for c in columns}
        kinds.update({"point": "int", "error": "text"})
        kinds.update({c: "bool" for c in columns if c.endswith(("_converged", "_stable"))})
        file = SweepFile(Path(out) / FILENAME, columns, kinds)
        fingerprint = SceneFingerprint(Path(out) / FINGERPRINT, scene.data)
        rows = file.check(resume=resume, overwrite=overwrite)
        if file.resumes:
            fingerprint.check(file.path)
        _check_resumed(rows, grid, parameters, file.path)
    retry = [i for i, row in rows.items() if row["error"].startswith(RETRIED)]
    for i in retry:
        del rows[i]
    reused = len(rows)
    todo = [i for i in range(len(grid)) if i not in rows]

    own_client = None
    if isinstance(client, str):
        from .sweep_cluster import connect

        client = own_client = connect(client)
    try:
        if file is not None:
            from ..scene.outputs import prepare_output_dir

            prepare_output_dir(out, create=True, key="out")
            fingerprint.write()  # before any row: a row is never without its scene
            if retry:  # the file without the rows solved again
                file.rewrite([rows[i] for i in sorted(rows)])
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
        data = point_data(scene.data, parameters, grid[todo[0]])
        first = (todo[0], solve_point(data, scene.source))
        todo = todo[1:]
        n = min(n, len(todo))
    pool = _start_pool(n) if n > 1 else None
    show = sys.stderr.isatty() if progress is None else bool(progress)
    names = result_columns(scene)
    tasks = ((i, point_data(scene.data, parameters, grid[i])) for i in todo)
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
            from .sweep_cluster import run_on_cluster

            def finished(point: int, result) -> None:
                if isinstance(result, BaseException):
                    result = _failed(f"dask: {type(result).__name__}: {result}")
                done(point, result)

            work = ((i, (data, scene.source)) for i, data in tasks)
            run_on_cluster(client, solve_point, work, finished)
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
