"""Run a planned scene: solve each model in each field, collect tables, figures and a summary."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ConvergenceError
from .figures import leaves_plane, plot_scene_shapes, plot_scene_shapes_3d, plot_tip_vs_field
from .outputs import prepare_output_dir, save_figure, write_json, write_rows
from .parse import Scene
from .planner import Plan, plan_scene
from .strength import field_strength

__all__ = ["ModelRun", "SceneResult", "run_scene", "field_strength"]


@dataclass
class ModelRun:
    """The outcome of one job (a model in one field).

    Attributes
    ----------
    model, field_label : str
    scales : ndarray, shape (k,)
        Scales reached (all requested ones on success).
    tip : ndarray, shape (k, 3)
        Tip positions, m (rod: centreline end; FEM: centroid of the free end face).
    tip_angle : ndarray, shape (k,)
        Tip tangent angle, rad (FEM: the normal of the deformed end face).
    seconds : float
        Wall time of the solve.
    error : str
        Empty on success, else the solver's message.
    result : object
        The solver's own result object (RodResult or FEMResult), or None.
    """

    model: str
    field_label: str
    scales: np.ndarray
    tip: np.ndarray
    tip_angle: np.ndarray
    seconds: float
    error: str = ""
    result: object = None

    @property
    def stable(self) -> np.ndarray:
        """Stability flag per reached scale, shape (k,) (True where the model does not say)."""
        flags = getattr(self.result, "stable", None)
        return np.ones(len(self.scales), bool) if flags is None else np.asarray(flags, bool)


@dataclass
class SceneResult:
    """All runs of a scene, with tables, the real-vs-ideal shift, figures and a summary."""

    scene: Scene
    plan: Plan
    runs: list[ModelRun] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True if every job reached every scale."""
        return all(not r.error for r in self.runs)

    def run(self, model: str, field_label: str) -> ModelRun | None:
        """The run of ``model`` in the field labelled ``field_label`` (None if absent)."""
        for r in self.runs:
            if r.model == model and r.field_label == field_label:
                return r
        return None

    def table(self) -> list[dict]:
        """One row per (model, field, scale): tip (x, y, z) in mm, angle in degrees, lambda."""
        value, kind, number = field_strength(self.scene)
        L = self.scene.rod.length
        rows = []
        for r in self.runs:
            for k, s in enumerate(r.scales):
                rows.append(
                    {
                        "model": r.model,
                        "field": r.field_label,
                        "scale": float(s),
                        ("B_mT" if kind == "B" else "gradient_T_per_m"): float(
                            s * value * (1e3 if kind == "B" else 1.0)
                        ),
                        ("lambda" if kind == "B" else "gamma"): float(s * number),
                        "tip_x_mm": 1e3 * float(r.tip[k, 0]),
                        "tip_y_mm": 1e3 * float(r.tip[k, 1]),
                        "tip_z_mm": 1e3 * float(r.tip[k, 2]),
                        "tip_deflection_over_L": float(r.tip[k, 1] / L),
                        "tip_angle_deg": float(np.degrees(r.tip_angle[k])),
                        "stable": bool(r.stable[k]),
                    }
                )
        return rows

    def shift(self) -> list[dict]:
        """Per model: how far the coil field moves the tip from the ideal-field prediction.

        Reports the shift at the largest common scale and the maximum over scales, in mm, in
        percent of L and (where defined) in degrees of tip angle.
        """
        L = self.scene.rod.length
        out = []
        for model in self.scene.models:
            real, ideal = self.run(model, "coils"), self.run(model, "ideal")
            if real is None or ideal is None or len(real.scales) == 0 or len(ideal.scales) == 0:
                continue
            n = min(len(real.scales), len(ideal.scales))
            d = np.linalg.norm(real.tip[:n] - ideal.tip[:n], axis=1)
            da = np.degrees(real.tip_angle[:n] - ideal.tip_angle[:n])
            out.append(
                {
                    "model": model,
                    "scale": float(real.scales[n - 1]),
                    "tip_shift_mm": 1e3 * float(d[-1]),
                    "tip_shift_percent_L": 100 * float(d[-1] / L),
                    "max_tip_shift_mm": 1e3 * float(d.max()),
                    "tip_angle_shift_deg": float(da[-1]),
                    "ideal_tip_mm": (1e3 * ideal.tip[n - 1, :3]).tolist(),
                    "coil_tip_mm": (1e3 * real.tip[n - 1, :3]).tolist(),
                }
            )
        return out

    def summary(self) -> str:
        """A short human-readable account of the runs and of the shift."""
        value, kind, number = field_strength(self.scene)
        unit = f"{1e3 * value:.3g} mT" if kind == "B" else f"{value:.3g} T/m"
        sym = "lambda" if kind == "B" else "gamma"
        top = float(np.max(self.scene.scales))
        lines = [
            f"scene: {self.scene.name}",
            f"robot: L = {1e3 * self.scene.rod.length:g} mm, {self.scene.rod.magnetization!r}",
            f"field at scale 1: {unit} ({sym} = {number:.3g}); load to scale {top:g} "
            f"({sym} = {top * number:.3g})",
        ]
        for r in self.runs:
            status = "ok" if not r.error else f"FAILED: {r.error}"
            if not r.error and not r.stable.all():
                status += f", UNSTABLE at {np.count_nonzero(~r.stable)} scale(s)"
            if len(r.scales):
                tip = 1e3 * r.tip[-1]
                lines.append(
                    f"  {r.model:6s} {r.field_label:6s} tip ({tip[0]:7.3f}, "
                    f"{tip[1]:7.3f}, {tip[2]:7.3f}) mm at scale {r.scales[-1]:.3g}  "
                    f"[{r.seconds:.2f} s, {status}]"
                )
            else:
                lines.append(f"  {r.model:6s} {r.field_label:6s} [{status}]")
        for s in self.shift():
            lines.append(
                f"shift ({s['model']}): real coils move the tip by "
                f"{s['tip_shift_mm']:.3f} mm = {s['tip_shift_percent_L']:.2f}% of L "
                f"(tip angle {s['tip_angle_shift_deg']:+.2f} deg) vs the ideal field; "
                f"max over the path {s['max_tip_shift_mm']:.3f} mm"
            )
        return "\n".join(lines)

    def write(self, out_dir: str | Path) -> list[Path]:
        """Write tables (CSV, JSON) and figures (PNG) as the scene's outputs request.

        Parameters
        ----------
        out_dir : str or Path
            The folder (created if missing).

        Returns
        -------
        list of Path
            The files written.

        Raises
        ------
        SceneError
            If ``out_dir`` is a file or cannot be created or written (one line).
        """
        out = prepare_output_dir(out_dir, key="output folder")
        written = []
        if self.scene.outputs.get("tables", True):
            rows = self.table()
            written.append(write_rows(out / "tip_path.csv", rows))
            path = out / "summary.json"
            value, kind, number = field_strength(self.scene)
            write_json(
                path,
                {
                    "scene": self.scene.name,
                    "field_kind": self.scene.field_kind,
                    "reference": {kind: value, "number": number},
                    "plan": [str(d) for d in self.plan.decisions],
                    "runs": [
                        {
                            "model": r.model,
                            "field": r.field_label,
                            "seconds": r.seconds,
                            "error": r.error,
                            "scales_reached": len(r.scales),
                            "tip_mm": (1e3 * r.tip[-1, :3]).tolist() if len(r.scales) else None,
                        }
                        for r in self.runs
                    ],
                    "shift": self.shift(),
                },
            )
            written.append(path)
        if self.scene.outputs.get("vtk", False):
            from ..rod.export import write_vtk

            for r in self.runs:
                if r.model != "rod" or r.result is None or not len(r.scales):
                    continue
                label = "".join(ch if ch.isalnum() else "_" for ch in r.field_label)
                written += write_vtk(r.result, out / f"rod_{label}.vtu")
        if self.scene.outputs.get("figures", True):
            import matplotlib.pyplot as plt

            figures = [("tip_vs_field.png", plot_tip_vs_field), ("shapes.png", plot_scene_shapes)]
            if leaves_plane(self):
                figures.append(("shapes_3d.png", plot_scene_shapes_3d))
            for name, fn in figures:
                ax = fn(self)
                path = out / name
                try:
                    save_figure(ax.figure, path)
                finally:
                    plt.close(ax.figure)
                written.append(path)
        return written


def _solve(job, scene: Scene, field_obj, progress: bool):
    scales = scene.scales
    if job.model == "rod":
        from ..rod import solve_rod

        res = solve_rod(scene.rod, field_obj, scales, progress=progress, **scene.rod_options)
        return res.scales, res.tip, res.tip_angle, res
    from ..fem import solve_fem

    dim = 2 if job.model == "fem2d" else 3
    opts = {"order": scene.fem_options.get("order", 2)}
    key = "elements2d" if dim == 2 else "elements3d"
    if key in scene.fem_options:
        opts["elements"] = scene.fem_options[key]
    if scene.poisson_ratio is not None:
        opts["poisson_ratio"] = scene.poisson_ratio
    res = solve_fem(scene.rod, field_obj, scales, dim=dim, progress=progress, **opts)
    return res.scales, res.tip, res.tip_angle, res


def scene_with_scales(scene: Scene, scales) -> Scene:
    """A copy of ``scene`` with another load path."""
    import dataclasses

    return dataclasses.replace(scene, scales=np.asarray(scales, dtype=float))


def _field_cache(scene, plan, result, log):
    """The gridded field cache of the coils over the plan's box (None without a box, or, noted
    in the plan's decisions, when the grid cannot reach its tolerance)."""
    if plan.cache_box is None:
        return None
    from coils.grid import GriddedField

    t0 = time.perf_counter()
    try:
        cached = GriddedField(
            scene.fields["coils"],
            plan.cache_box[0],
            plan.cache_box[1],
            tol=1e-7,
            tol_gradient=1e-5,
        )
    except ValueError as exc:  # the grid cannot reach the tolerance within its cell limit
        note = f"no field cache after all, direct evaluation: {exc}"
        result.plan.decisions.append(note)
        if log:
            log(note)
        return None
    if log:
        log(
            f"field cache: {cached.cells.tolist()} cells, estimated error B "
            f"{cached.error_B:.1e}, gradient {cached.error_gradient:.1e} "
            f"({time.perf_counter() - t0:.2f} s)"
        )
    return cached


def _failed_run(job, t0: float, error: str) -> ModelRun:
    """A run of ``job`` that reached no state, holding ``error`` (started at ``t0``, s)."""
    return ModelRun(
        job.model,
        job.field_label,
        np.zeros(0),
        np.zeros((0, 3)),
        np.zeros(0),
        time.perf_counter() - t0,
        error=error,
    )


def _run_job(job, scene, field_obj, progress) -> ModelRun:
    """One model in one field along the scene's scales; on a ConvergenceError the run holds the
    error and the part of the path that was reached, on a ValueError of the solver (an input
    the scene parser does not refuse, e.g. a FEM Poisson ratio within 1e-10 of 0.5) the
    error alone."""
    t0 = time.perf_counter()
    try:
        scales, tip, angle, res = _solve(job, scene, field_obj, progress)
        return ModelRun(
            job.model,
            job.field_label,
            np.asarray(scales),
            tip,
            np.asarray(angle),
            time.perf_counter() - t0,
            result=res,
        )
    except ValueError as exc:  # an input the scene parser lets through but the solver refuses
        return _failed_run(job, t0, f"{job.model}: {exc}")
    except ConvergenceError as exc:
        run = _failed_run(job, t0, str(exc))
        partial = getattr(exc, "result", None)
        if partial is not None and len(getattr(partial, "scales", ())):
            # the solver handed over the states it reached
            run.scales = np.asarray(partial.scales)
            run.tip = np.asarray(partial.tip)
            run.tip_angle = np.asarray(partial.tip_angle)
            run.result = partial
            return run
        # keep the part of the path that was reached (cheap for the rod: solve it again)
        reachable = scene.scales[scene.scales <= exc.reached]
        if job.model == "rod" and reachable.size and np.all(np.diff(scene.scales) > 0):
            partial = scene_with_scales(scene, reachable)
            try:
                scales, tip, angle, res = _solve(job, partial, field_obj, progress)
                run.scales, run.tip, run.tip_angle, run.result = scales, tip, angle, res
            except ConvergenceError:  # pragma: no cover - the reached scales converged
                pass
        return run


def run_scene(
    scene: Scene, *, plan: Plan | None = None, progress: bool | None = None, log=None
) -> SceneResult:
    """Plan (unless given) and run every job of ``scene``.

    A job that cannot reach its load is recorded with the solver's message (and whatever it
    reached); the other jobs still run.  A control scene (``scene.control``) runs its
    controllers instead and returns a
    :class:`~coilrod.scene.control_runner.ControlSceneResult` (same ``ok``, ``summary`` and
    ``write``), a navigation scene (``[insertion]``) inserts the robot into its vessel and
    returns a :class:`~coilrod.scene.navigation.NavigationSceneResult`.  ``progress`` shows
    tqdm bars (default: when stderr is a terminal); ``log`` is a callable for one-line
    messages (default: none).
    """
    if scene.control is not None:  # a control scene: the currents for its target
        from .control_runner import run_control

        return run_control(scene, plan=plan, log=log)
    plan = plan_scene(scene) if plan is None else plan
    progress = sys.stderr.isatty() if progress is None else progress
    if "insertion" in scene.rod_options:  # a navigation scene: insert the robot
        from .navigation import run_navigation

        return run_navigation(scene, plan, progress=progress, log=log)
    result = SceneResult(scene, plan)
    cached = _field_cache(scene, plan, result, log)
    for job in plan.jobs:
        field_obj = cached if (cached is not None and job.field_label == "coils") else job.field
        if log:
            log(f"solving {job.model} in the {job.field_label} field ...")
        result.runs.append(_run_job(job, scene, field_obj, progress))
    return result
