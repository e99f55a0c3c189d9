"""Run a control scene: each controller's currents for the target, the table of currents, power
and the tip they reach in the real field, the files and the figure.

Each controller is one call of :func:`coilrod.solve_currents` with the scene's rod, coil
system, target, limits, load steps and rod mesh.  A controller meets the target when, in its
own model (the real field for "real", the centre field for "ideal"), the tip lands within
``MET * L`` of it (and, with a target angle or direction, the real controller's tip angle or
tip tangent within ``MET`` rad of it).  A 3D target (x, y, z) runs the spatial rod; the table,
summary, JSON and figure then carry z (and, with a target direction, the direction miss).
One that does not -- the solver's ConvergenceError for an unreachable target, a
least-squares compromise for a pose the channels cannot make, an ideal controller stopped by
the limits -- is recorded with the message and the closest currents found; the other controller
still runs, and ``ok`` is False (``coilrod run`` exits 1, as for any load a solver cannot
reach).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..control import ControlResult, solve_currents
from ..errors import ConvergenceError
from .outputs import prepare_output_dir, save_figure, write_json, write_rows
from .parse import Scene
from .planner import Plan, plan_scene

__all__ = ["ControlRun", "ControlSceneResult", "run_control"]

#: A controller meets the target if its own model's tip lands within MET * L of it (and within
#: MET rad of a target angle): ten times solve_currents' default tolerance of 1e-7 L.
MET = 1e-6


@dataclass
class ControlRun:
    """One controller's outcome.

    Attributes
    ----------
    model : str
        "real" or "ideal".
    result : ControlResult or None
        The currents and where they put the tip in the real field; on failure the closest
        found, if the solver handed it over (else None).
    seconds : float
        Wall time, s.
    error : str
        Empty on success, else the solver's message.
    """

    model: str
    result: ControlResult | None
    seconds: float
    error: str = ""

    @property
    def own_miss(self) -> float | None:
        """Miss of the tip in the controller's own model (the real field for "real", the
        centre field for "ideal"), m; None without a result."""
        if self.result is None or not self.result.history:
            return None
        return float(min(self.result.history))


@dataclass
class ControlSceneResult:
    """The controllers' runs of a control scene, with their table, summary, files and figure."""

    scene: Scene
    plan: Plan
    runs: list[ControlRun] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True if every controller met the target."""
        return all(not r.error for r in self.runs)

    def run(self, model: str) -> ControlRun | None:
        """The run of the controller ``model`` ("real" or "ideal"), None if not run."""
        return next((r for r in self.runs if r.model == model), None)

    @property
    def channels(self) -> tuple[str, ...]:
        """The channel names of the coil system, in order."""
        return tuple(self.scene.fields["coils"].names)

    def table(self) -> list[dict]:
        """One row per controller: the currents (A), power (W), the tip in the real field (mm,
        deg; z for a 3D target), the miss (mm, % of L; the direction miss in deg with a target
        direction), the solves and the error ("" if it met the target).

        The current columns are ``current_<channel>_A`` (spaces in the channel name as ``_``);
        the values are None where a controller left no result.
        """
        L = self.scene.rod.length
        spec = self.scene.control
        rows = []
        for r in self.runs:
            out = r.result
            row: dict = {"model": r.model, "ok": not r.error}
            row["closest"] = bool(r.error) and out is not None
            for j, name in enumerate(self.channels):
                row[_column(name)] = None if out is None else float(out.currents[j])
            row["power_W"] = None if out is None or not math.isfinite(out.power) else out.power
            if out is not None:
                row.update(
                    tip_x_mm=1e3 * float(out.tip[0]),
                    tip_y_mm=1e3 * float(out.tip[1]),
                    tip_z_mm=1e3 * float(out.tip[2]),
                    tip_angle_deg=math.degrees(out.tip_angle),
                    miss_mm=1e3 * out.miss,
                    miss_percent_L=100 * out.miss / L,
                    angle_miss_deg=(
                        None if out.angle_miss is None else math.degrees(out.angle_miss)
                    ),
                    direction_miss_deg=(
                        None if out.direction_miss is None else math.degrees(out.direction_miss)
                    ),
                    own_miss_mm=1e3 * r.own_miss,
                    solves=out.solves,
                    start_solves=out.start_solves,
                )
            else:
                for k in ("tip_x_mm", "tip_y_mm", "tip_z_mm", "tip_angle_deg"):
                    row[k] = None
                row.update(miss_mm=None, miss_percent_L=None, angle_miss_deg=None)
                row.update(direction_miss_deg=None, own_miss_mm=None)
                row.update(solves=None, start_solves=None)
            if spec.angle is None:
                row.pop("angle_miss_deg")
            if spec.direction is None:
                row.pop("direction_miss_deg")
            if not spec.spatial:
                row.pop("tip_z_mm")
            row["seconds"] = r.seconds
            row["error"] = r.error
            rows.append(row)
        return rows

    def summary(self) -> str:
        """The scene, the target, and the table: one column per controller, one line per
        channel (A), the power, the tip in the real field, the miss and the solves."""
        scene, spec = self.scene, self.scene.control
        L = scene.rod.length
        names = self.channels
        target = f"({', '.join(_num(1e3 * v) for v in spec.target)}) mm"
        if spec.angle is not None:
            target += f", tip angle {_num(math.degrees(spec.angle))} deg"
        if spec.direction is not None:
            target += f", tip direction ({', '.join(f'{v:.4g}' for v in spec.direction)})"
        lines = [
            f"scene: {scene.name}",
            f"robot: L = {1e3 * L:g} mm, {scene.rod.magnetization!r}",
            f"system: {spec.system}, {len(names)} channel{'s' if len(names) > 1 else ''}; "
            f"target tip {target}",
        ]
        heads = [r.model + ("*" if r.error and r.result is not None else "") for r in self.runs]
        rows: list[tuple[str, list[str], str]] = []

        def add(label, fn, unit="", extra=""):
            cells = []
            for r in self.runs:
                out = r.result
                cells.append("-" if out is None else fn(out, r))
            rows.append((f"{label}{f' ({unit})' if unit else ''}", cells, extra))

        for j, name in enumerate(names):
            add(name, lambda o, r, j=j: f"{o.currents[j]:.4f}", "A", f"{spec.max_current[j]:g}")
        add("power", lambda o, r: "n/a" if not math.isfinite(o.power) else f"{o.power:.4g}", "W")
        add("real-field tip x", lambda o, r: f"{1e3 * o.tip[0]:.4f}", "mm")
        add("real-field tip y", lambda o, r: f"{1e3 * o.tip[1]:.4f}", "mm")
        if spec.spatial:
            add("real-field tip z", lambda o, r: f"{1e3 * o.tip[2]:.4f}", "mm")
        else:
            add("tip angle", lambda o, r: f"{math.degrees(o.tip_angle):.3f}", "deg")
        add("miss", lambda o, r: f"{1e3 * o.miss:.4g}", "mm")
        add("miss", lambda o, r: f"{100 * o.miss / L:.3g}", "% of L")
        if spec.angle is not None:
            add("angle miss", lambda o, r: f"{math.degrees(o.angle_miss):.3g}", "deg")
        if spec.direction is not None:
            add("direction miss", lambda o, r: f"{math.degrees(o.direction_miss):.3g}", "deg")
        add("solves (+ start)", lambda o, r: f"{o.solves} + {o.start_solves}")
        width = max(len(label) for label, _, _ in rows)
        cols = [max(10, len(h), *(len(c[k]) for _, c, _ in rows)) for k, h in enumerate(heads)]
        lines.append(
            "  "
            + " " * width
            + "".join(f"  {h:>{w}s}" for h, w in zip(heads, cols, strict=True))
            + "  limit (A)"
        )
        for label, cells, extra in rows:
            body = "".join(f"  {c:>{w}s}" for c, w in zip(cells, cols, strict=True))
            lines.append(f"  {label:<{width}s}{body}  {extra:>9s}".rstrip())
        for r in self.runs:
            what = f"  {r.model}: "
            if r.error:
                closest = " (* the closest found)" if r.result is not None else ""
                lines.append(f"{what}FAILED{closest}: {r.error} [{r.seconds:.2f} s]")
            elif r.model == "ideal":
                lines.append(
                    f"{what}ok [{r.seconds:.2f} s]: in its own model (the centre field) the tip "
                    f"is on the target; in the real field its currents put it "
                    f"{1e3 * r.result.miss:.4g} mm ({100 * r.result.miss / L:.3g} % of L) away"
                )
            else:
                lines.append(f"{what}ok [{r.seconds:.2f} s]: the tip is on the target")
        return "\n".join(lines)

    def write(self, out_dir: str | Path) -> list[Path]:
        """Write ``control.csv`` (the table), ``control.json`` (everything, with the
        iteration history) and ``control.png`` (the shapes and the target), as the scene's
        outputs request.

        Raises
        ------
        SceneError
            If ``out_dir`` is a file or cannot be created or written (one line).
        """
        out = prepare_output_dir(out_dir, key="output folder")
        written = []
        if self.scene.outputs.get("tables", True):
            rows = self.table()
            written.append(write_rows(out / "control.csv", rows))
            path = out / "control.json"
            write_json(path, self._json())
            written.append(path)
        if self.scene.outputs.get("figures", True):
            import matplotlib.pyplot as plt

            from .figures import plot_control_shapes

            ax = _plot_3d(self) if self.scene.control.spatial else plot_control_shapes(self)
            path = out / "control.png"
            try:
                save_figure(ax.figure, path)
            finally:
                plt.close(ax.figure)
            written.append(path)
        return written

    def _json(self) -> dict:
        spec = self.scene.control
        runs = []
        for r, row in zip(self.runs, self.table(), strict=True):
            out = r.result
            entry = {
                "model": r.model,
                "ok": row["ok"],
                "closest": row["closest"],
                "currents_A": None if out is None else out.currents.tolist(),
                **{k: row[k] for k in row if k not in ("model", "ok", "closest")},
                "history_mm": None if out is None else [1e3 * h for h in out.history],
            }
            for name in self.channels:
                entry.pop(_column(name))
            runs.append(entry)
        return {
            "scene": self.scene.name,
            "system": spec.system,
            "channels": list(self.channels),
            "max_current_A": spec.max_current.tolist(),
            "length_mm": 1e3 * self.scene.rod.length,
            "target_mm": (1e3 * spec.target).tolist(),
            "target_angle_deg": None if spec.angle is None else math.degrees(spec.angle),
            "target_direction": None if spec.direction is None else spec.direction.tolist(),
            "load_steps": spec.steps,
            "plan": list(self.plan.decisions),
            "runs": runs,
        }


def _unmet(out: ControlResult, spec, rod) -> str:
    """Why ``out`` does not meet the target in its controller's own model ("" if it does)."""
    L = rod.length
    if out.model == "ideal":
        own = float(min(out.history))
        if own <= MET * L:
            return ""
        if out.status in ("max_solves", "stalled", "branch_edge"):  # stopped, not the limits
            why = (
                f"in its own model (the centre field) its search stopped ({out.status}, after "
                f"{out.solves} solves) before the target, not at a current limit"
            )
        else:
            why = "even in its own model (the centre field) within the current limits"
        return (
            f"the ideal controller cannot put the tip on the target {why}: the closest it "
            f"finds there is {1e3 * own:.4g} mm away; in the real field its currents put the "
            "tip at "
            f"({', '.join(f'{1e3 * v:.4g}' for v in out.tip[: spec.target.size])}) mm, "
            f"{1e3 * out.miss:.4g} mm "
            f"({100 * out.miss / L:.3g} % of L) from the target"
        )
    angle_off = out.angle_miss is not None and out.angle_miss > MET
    direction_off = out.direction_miss is not None and out.direction_miss > MET
    if out.miss <= MET * L and not angle_off and not direction_off:
        return ""
    tip = out.tip[: spec.target.size]
    text = (
        f"the target pose is not reachable: the closest the currents make puts the tip at "
        f"({', '.join(f'{1e3 * v:.4g}' for v in tip)}) mm, {1e3 * out.miss:.4g} mm "
        f"({100 * out.miss / L:.3g} % of L) from the target position"
    )
    if out.angle_miss is not None:
        text += f" and {math.degrees(out.angle_miss):.3g} deg from the target angle"
    if out.direction_miss is not None:
        text += f" and {math.degrees(out.direction_miss):.3g} deg from the target direction"
    return text + " (the least-squares compromise within the current limits)"


def _plot_3d(result):
    """A 3D-target control scene's shapes in the real field, one per controller (solid: the
    real-field controller; dashed: the ideal one), in two views -- x-y (top) and x-z (side) --
    with the target and its tip direction marked.  Returns the x-y Axes (both on its figure)."""
    import matplotlib.pyplot as plt

    from .figures import _CONTROL_STYLE

    scene, spec = result.scene, result.scene.control
    L = scene.rod.length
    fig, axes = plt.subplots(1, 2, figsize=(10, 5))
    target = 1e3 * spec.target
    for ax, (i, j), name in zip(axes, ((0, 1), (0, 2)), ("x-y (top)", "x-z (side)"), strict=True):
        for r in result.runs:
            if r.result is None:
                continue
            c = 1e3 * r.result.result.centerline(-1)
            style, color = _CONTROL_STYLE.get(r.model, (":", "k"))
            state = " (closest found)" if r.error else ""
            miss = f"miss {1e3 * r.result.miss:.3g} mm"
            if r.result.direction_miss is not None:
                miss += f", {math.degrees(r.result.direction_miss):.3g} deg"
            ax.plot(c[:, i], c[:, j], style, color=color, lw=2, label=f"{r.model}{state}, {miss}")
        ax.plot([0, 1e3 * L], [0, 0], color="0.6", lw=1, label="undeformed")
        ax.plot(0, 0, "ks", ms=6)
        ax.plot(target[i], target[j], "kx", ms=10, mew=2, label="target")
        if spec.direction is not None:
            d = 0.15 * 1e3 * L * spec.direction
            ax.annotate(
                "",
                xy=(target[i] + d[i], target[j] + d[j]),
                xytext=(target[i], target[j]),
                arrowprops={"arrowstyle": "->", "color": "k"},
            )
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel(f"{'xyz'[i]} (mm)")
        ax.set_ylabel(f"{'xyz'[j]} (mm)")
        ax.set_title(name, fontsize=9)
    axes[0].legend(fontsize=7, loc="best")
    fig.suptitle(scene.name, fontsize=10)
    return axes[0]


def _column(name: str) -> str:
    return "current_" + "_".join(name.split()) + "_A"


def _num(x: float) -> str:
    return f"{x:.6g}"


def run_control(scene: Scene, *, plan: Plan | None = None, log=None) -> ControlSceneResult:
    """Run every controller of the control scene ``scene``.

    Parameters
    ----------
    scene : Scene
        A validated scene with a ``control`` table.
    plan : Plan, optional
        From :func:`coilrod.scene.planner.plan_scene` (made here if not given).
    log : callable, optional
        Receives one-line progress messages.

    Returns
    -------
    ControlSceneResult
    """
    plan = plan_scene(scene) if plan is None else plan
    spec = scene.control
    system = scene.fields["coils"]
    result = ControlSceneResult(scene, plan)
    for model in spec.models:
        if log:
            log(f"finding the currents ({model} controller) ...")
        t0 = time.perf_counter()
        try:
            out = solve_currents(
                scene.rod,
                system,
                spec.target,
                max_current=spec.max_current,
                model=model,
                angle=spec.angle,
                direction=spec.direction,
                steps=spec.steps,
                nodes=scene.rod_options.get("nodes"),
            )
            seconds = time.perf_counter() - t0
            result.runs.append(ControlRun(model, out, seconds, _unmet(out, spec, scene.rod)))
        except ConvergenceError as exc:
            closest = getattr(exc, "result", None)
            closest = closest if isinstance(closest, ControlResult) else None
            message = " ".join(str(exc).split())
            result.runs.append(ControlRun(model, closest, time.perf_counter() - t0, message))
    return result
