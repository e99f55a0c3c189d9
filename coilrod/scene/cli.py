"""The ``coilrod`` command line: run scenes, check them, list the shipped ones, run the demo.

``check`` and ``run`` share one validation path (:func:`prepare`): the scene file is read and
validated completely (every problem at once, each on its own line), and the output folder is
checked (``run``: created and test-written) before anything is solved.

Exit codes: 0 success, 1 a solver could not reach its load (``sweep``: a point failed), 2
invalid scene, parameters, output folder, scheduler or usage; 130 interrupted.
"""

from __future__ import annotations

import argparse
import os
import sys
import textwrap
import time
from importlib import resources
from pathlib import Path

__all__ = ["main", "prepare", "shipped_scenes", "DEMO_SCENES"]

DESCRIPTION = """\
coilrod: how far do real Helmholtz and Maxwell coil pairs move a magnetic soft continuum
robot away from what the ideal (uniform / constant-gradient) field predicts?

A scene file (TOML) describes the robot, the field (ideal, or coils from Biot-Savart), the
load path and the models (rod, fem2d, fem3d); a control scene gives a coil system and a tip
target ([control]) and finds the currents. Quantities carry units: "40 mm", "15 mT",
"640 kA/m", "1 MPa", "0.4 T/m", "90 deg", "10 A".
"""

EPILOG = """\
examples:
  coilrod demo --out demo-out          the seed's robot in a real Helmholtz pair vs ideal
  coilrod scenes                       list the shipped scenes
  coilrod scenes --show helmholtz_vs_ideal > my.toml   copy one to edit
  coilrod check my.toml                validate a scene and print what would run
  coilrod check my.toml --out results  ... and that the results can be written there
  coilrod run my.toml --out results    run it: tables (CSV, JSON), figures (PNG), summary
  coilrod run control_three_axis       the coil currents that put the tip on a target
  coilrod sweep my.toml --param field.coil.0.radius=60mm:120mm:4 --out sweep1
                                       run it over a grid of values -> sweep1/sweep.csv
"""

#: The demo's scenes: the seed's robot with M(1) and M(2a) in a real Helmholtz pair vs ideal.
DEMO_SCENES = {
    "M1": {"preset": "M1", "M0": "640 kA/m", "phi": 0.2},
    "M2a": {"preset": "M2a", "M0": "640 kA/m", "phi": 0.2},
}


def _version() -> str:
    """The installed coilrod's version ("unknown" for a source tree that is not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("coilrod")
    except PackageNotFoundError:  # pragma: no cover
        return "unknown"


def _demo_scene(name: str, magnetization: dict) -> dict:
    return {
        "name": f"demo: seed robot, {name}, Helmholtz pair R = 80 mm vs ideal Config (A)",
        "robot": {
            "length": "40 mm",
            "diameter": "2 mm",
            "youngs_modulus": "1 MPa",
            "magnetization": magnetization,
        },
        "field": {
            "type": "coils",
            "compare_ideal": True,
            "coil": [
                {"type": "helmholtz", "radius": "80 mm", "turns": 200, "B": "15 mT", "axis": "y"}
            ],
        },
        "load": {"steps": 24},
        "models": {"run": ["rod", "fem2d"]},
        "fem": {"order": 2, "elements2d": [40, 2]},
    }


def shipped_scenes() -> dict[str, Path]:
    """Name -> path of the scenes shipped in ``coilrod/scene/examples``."""
    folder = resources.files("coilrod.scene") / "examples"
    return {Path(p.name).stem: Path(str(p)) for p in folder.iterdir() if p.name.endswith(".toml")}


def _resolve_scene(arg: str) -> Path:
    path = Path(arg)
    if path.exists():
        return path
    shipped = shipped_scenes()
    if arg in shipped:
        return shipped[arg]
    return path  # load_scene reports the missing file


def _print_err(msg: str) -> None:
    print(f"coilrod: error: {msg}", file=sys.stderr)


def _default_out(scene) -> Path:
    return Path("coilrod-out") / Path(scene.source).stem


def prepare(scene_arg: str, out: Path | None, *, create_out: bool):
    """The one validation path of ``check`` and ``run``: the scene, then the output folder.

    Parameters
    ----------
    scene_arg : str
        A scene file or the name of a shipped scene.
    out : Path or None
        The output folder; None: ``coilrod-out/<scene file stem>`` when ``create_out`` (run),
        no folder check otherwise (check without ``--out``).
    create_out : bool
        Create the folder and test-write it (run) or only check that this would work (check).

    Returns
    -------
    (Scene, Path or None)

    Raises
    ------
    SceneError
        Every problem of the scene and of the folder, one line each.
    """
    from .outputs import prepare_output_dir
    from .parse import SceneError, load_scene

    problems = []
    scene = None
    try:
        scene = load_scene(_resolve_scene(scene_arg))
    except SceneError as exc:
        problems += exc.lines
    if out is None and create_out and scene is not None:
        out = _default_out(scene)
    if out is not None:
        try:
            prepare_output_dir(out, create=False)
        except SceneError as exc:
            problems += exc.problems
    if problems:
        raise SceneError(problems)
    if out is not None and create_out:
        prepare_output_dir(out, create=True)
    return scene, out


def _run(scene, out: Path | None, quiet: bool, no_cache: bool, progress: bool | None) -> int:
    from .planner import plan_scene
    from .runner import run_scene

    plan = plan_scene(scene, cache=False if no_cache else None)
    log = None if quiet else (lambda m: print(m, flush=True))
    if not quiet:
        print(plan, flush=True)
    t0 = time.perf_counter()
    result = run_scene(scene, plan=plan, progress=progress, log=log)
    print(result.summary())
    if out is not None:
        for path in result.write(out):
            if not quiet:
                print(f"wrote {path}")
    if not quiet:
        print(f"done in {time.perf_counter() - t0:.1f} s")
    return 0 if result.ok else 1


def _add_run_commands(sub) -> None:
    """The ``demo``, ``run`` and ``check`` subcommands."""
    p_demo = sub.add_parser(
        "demo",
        help="the seed's robot in a real Helmholtz pair vs ideal",
        description="Run the embedded demo (no file needed): the seed's "
        "robot (L = 40 mm, D = L/20, M0 = 640 kA/m) with M(1) and M(2a) in "
        "a Helmholtz pair of radius 80 mm against the ideal uniform field.",
    )
    p_demo.add_argument(
        "--out",
        type=Path,
        default=Path("coilrod-demo"),
        help="output folder (default: ./coilrod-demo)",
    )
    p_demo.add_argument("--quiet", action="store_true", help="print only the summary")

    p_run = sub.add_parser(
        "run",
        help="run a scene file",
        description="Validate, plan and run a scene; write tables (CSV, "
        "JSON) and figures (PNG) to --out.",
    )
    p_run.add_argument("scene", help="scene file (.toml) or the name of a shipped scene")
    p_run.add_argument(
        "--out", type=Path, default=None, help="output folder (default: ./coilrod-out/<scene name>)"
    )
    p_run.add_argument("--quiet", action="store_true", help="print only the summary")
    p_run.add_argument(
        "--no-cache", action="store_true", help="evaluate coil fields directly (no gridded cache)"
    )
    p_run.add_argument("--no-progress", action="store_true", help="hide progress bars")

    p_check = sub.add_parser(
        "check",
        help="validate a scene and print the plan",
        description="Validate a scene and print what would run and what "
        "is skipped, without solving.",
    )
    p_check.add_argument("scene", help="scene file (.toml) or the name of a shipped scene")
    p_check.add_argument(
        "--out",
        type=Path,
        default=None,
        help="also check that results could be written to this folder (nothing is created)",
    )


def _add_sweep_command(sub) -> None:
    """The ``sweep`` subcommand."""
    p_sweep = sub.add_parser(
        "sweep",
        help="run a scene over a grid of parameter values",
        description="Run a scene at every combination of the --param values (the first varying "
        "slowest) and write one row per point to OUT/sweep.csv: the values (SI), each model's "
        "tip in each field at the last load scale, the real-vs-ideal shift, converged, stable "
        "and the error of a point that failed. Local processes by default; --scheduler runs on "
        "an existing Dask cluster (pip install 'coilrod[cluster]').",
    )
    p_sweep.add_argument("scene", help="scene file (.toml) or the name of a shipped scene")
    p_sweep.add_argument(
        "--param",
        action="append",
        required=True,
        metavar="KEY=START:STOP:N",
        help="a scene key and N evenly spaced values with units, e.g. "
        "field.coil.0.radius=60mm:120mm:4 or robot.youngs_modulus=0.5MPa:2MPa:4; repeat for "
        "a grid",
    )
    p_sweep.add_argument("--out", type=Path, required=True, help="output folder (sweep.csv)")
    p_sweep.add_argument(
        "--workers",
        metavar="N",
        default=None,
        help="local worker processes (default: one per CPU; 1: serially in this process)",
    )
    p_sweep.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        default=None,
        help="run on the Dask cluster of this scheduler, e.g. tcp://10.0.0.5:8786",
    )
    p_sweep.add_argument(
        "--resume",
        action="store_true",
        help="keep the points already in OUT/sweep.csv (refused if OUT/sweep.json names "
        "another scene or coilrod version)",
    )
    p_sweep.add_argument(
        "--overwrite", action="store_true", help="replace an existing OUT/sweep.csv"
    )
    p_sweep.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p_sweep.add_argument("--quiet", action="store_true", help="print only the summary")


def _add_scenes_command(sub) -> None:
    """The ``scenes`` subcommand."""
    p_list = sub.add_parser(
        "scenes",
        help="list the shipped scenes",
        description="List the scenes shipped with coilrod, or print one.",
    )
    p_list.add_argument("--show", metavar="NAME", help="print the scene file NAME")


def _parser() -> argparse.ArgumentParser:
    """The ``coilrod`` argument parser."""
    parser = argparse.ArgumentParser(
        prog="coilrod",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"coilrod {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    _add_run_commands(sub)
    _add_sweep_command(sub)
    _add_scenes_command(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``coilrod`` console script."""
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse exits 2 on usage errors, 0 on --help
        return int(exc.code or 0)

    from .parse import SceneError, load_scene, parse_scene

    if args.command is None:
        parser.print_help()
        return 2
    try:
        return _command(args, load_scene, parse_scene)
    except SceneError as exc:
        for line in exc.lines:
            _print_err(line)
        return 2
    except BrokenPipeError:  # the reader of our output went away (``coilrod scenes | head``)
        # the docs' recipe: no second error when Python flushes stdout at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except OSError as exc:  # a file that could not be written or read after the checks
        _print_err(str(exc))
        return 2
    except KeyboardInterrupt:
        print("coilrod: interrupted", file=sys.stderr)
        return 130


def _command(args, load_scene, parse_scene) -> int:
    if args.command == "scenes":
        shipped = shipped_scenes()
        if args.show:
            if args.show not in shipped:
                _print_err(f"no shipped scene {args.show!r}; see 'coilrod scenes'")
                return 2
            print(shipped[args.show].read_text(encoding="utf-8"), end="")
            return 0
        for name, path in sorted(shipped.items()):
            scene = load_scene(path)
            print(f"{name:22s} {scene.name}")
        return 0
    if args.command == "check":
        from .planner import plan_scene

        scene, out = prepare(args.scene, args.out, create_out=False)
        print(f"{scene.source}: valid scene '{scene.name}'")
        if scene.description:
            print(textwrap.indent(textwrap.fill(scene.description, 90), "  "))
        if out is not None:
            print(f"results can be written to {out}")
        print(plan_scene(scene))
        return 0
    if args.command == "run":
        scene, out = prepare(args.scene, args.out, create_out=True)
        return _run(scene, out, args.quiet, args.no_cache, False if args.no_progress else None)
    if args.command == "sweep":
        return _sweep(args)
    if args.command == "demo":
        from .outputs import prepare_output_dir

        scenes = {
            name: parse_scene(_demo_scene(name, mag), source=f"demo-{name}")
            for name, mag in DEMO_SCENES.items()
        }
        for name in scenes:  # every output folder before the first solve
            prepare_output_dir(args.out / name)
        code = 0
        for name, scene in scenes.items():
            if not args.quiet:
                print(f"== {scene.name}")
            code = max(code, _run(scene, args.out / name, args.quiet, False, None))
        return code
    return 2


def _sweep_options(args) -> tuple[dict, int | None, list[str]]:
    """The --param values by key, --workers, and the problems of the options."""
    problems = []
    params: dict[str, str] = {}
    for text in args.param:
        key, sep, spec = text.partition("=")
        if not sep or not key.strip():
            problems.append(
                f"--param {text!r}: expected KEY=START:STOP:N, e.g. "
                "field.coil.0.radius=60mm:120mm:4"
            )
        elif key.strip() in params:
            problems.append(f"--param {key.strip()}: given twice")
        else:
            params[key.strip()] = spec
    workers = None
    if args.workers is not None:
        try:
            workers = int(args.workers)
        except ValueError:
            workers = 0
        if workers < 1:
            problems.append(f"--workers: expected a whole number of at least 1; got {args.workers}")
            workers = None
        elif args.scheduler is not None:
            problems.append(
                "--workers: give either --workers (local processes) or --scheduler, not both"
            )
    return params, workers, problems


def _sweep(args) -> int:
    from ..design.sweep import sweep, sweep_parameters
    from .outputs import prepare_output_dir
    from .parse import SceneError, load_scene

    params, workers, problems = _sweep_options(args)
    scene = None
    try:
        scene = load_scene(_resolve_scene(args.scene))
    except SceneError as exc:
        problems = exc.lines + problems
    refused = []
    if scene is not None:
        from ..design.sweep import not_swept

        refused = not_swept(scene)
        problems += refused
    if scene is not None and params and not refused:
        try:
            sweep_parameters(params, scene)
        except SceneError as exc:
            problems += exc.problems
    try:
        prepare_output_dir(args.out, create=False)
    except SceneError as exc:
        problems += exc.problems
    if problems:
        raise SceneError(problems)
    try:
        result = sweep(
            scene,
            params,
            client=args.scheduler,
            workers=workers,
            out=args.out,
            resume=args.resume,
            overwrite=args.overwrite,
            progress=False if (args.no_progress or args.quiet) else None,
        )
    except KeyboardInterrupt:
        print(
            f"coilrod: interrupted; the finished points are in {args.out / 'sweep.csv'} "
            "(add --resume to continue)",
            file=sys.stderr,
        )
        return 130
    parts = []
    if result.reused:
        parts.append(f"{result.reused} from {result.path}")
    if result.solved:
        rate = f", {result.solved / result.seconds:.3g} points/s" if result.seconds > 0 else ""
        parts.append(f"{result.solved} solved {result.executor} in {result.seconds:.1f} s{rate}")
    print(
        f"sweep of {scene.name}: {len(result)} points ({'; '.join(parts)}), "
        f"{len(result.failed)} failed"
    )
    if not args.quiet:
        for row in result.failed[:5]:
            values = ", ".join(f"{p.column} = {row[p.column]}" for p in result.parameters)
            print(f"  point {row['point']} ({values}): {row['error']}")
        if len(result.failed) > 5:
            print(f"  ... and {len(result.failed) - 5} more (the error column of the file)")
        print(f"wrote {result.path}")
    return 1 if result.failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
