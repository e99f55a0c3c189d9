"""The ``[insertion]`` table of a scene: feed the robot into its vessel (``coilrod run``).

.. code-block:: toml

    [insertion]
    lengths = ["6 mm", "40 mm"]   # first and last free length out of the introducer
    steps = 18                    # insertion steps from the first to the last length
    withdraw = true               # then back to the first length by the same steps
    nodes = 32                    # segments of each step's rod (default 32)

The introducer is the scene's clamp (the origin, the robot along +x or ``rod.clamp_rotation``)
and the lumen is the scene's one ``[obstacles]`` entry (a vessel preset, a mesh or a
centreline; ``obstacles.friction`` is its wall's Coulomb coefficient).  At every step the
field is the scene's at its largest load scale.  :func:`run_navigation` runs
:func:`coilrod.insert` once per field of the plan (the ideal field and the coils') and
returns a :class:`NavigationSceneResult`: a table per step (free length, tip, total wall
force -- the size of the vector sum of the contact forces, less than the largest contact's
when the rod touches the wall on two sides --, the largest contact's force, push force at the
introducer, contact points), a summary and the figure
``navigation.png`` (the shapes in the vessel with the contact points and forces, and the
push and wall forces against the inserted length).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConvergenceError
from .tables import SceneError, _Problems, _table, _unknown_keys, _value

__all__ = [
    "parse_insertion",
    "push_force",
    "contact_patch_forces",
    "run_navigation",
    "NavigationSceneResult",
]

_KEYS = {"lengths", "steps", "withdraw", "nodes"}


def parse_insertion(data, robot_length=None) -> dict:
    """The ``[insertion]`` table: ``{"lengths": (m,) free lengths in m (insertion, then
    withdrawal if asked), "nodes": int, "withdraw": bool, "steps": int}``.

    Raises
    ------
    SceneError
        One line per bad key (``insertion.lengths: ...``).
    """
    data = _table(data, "insertion")
    p = _Problems()
    p.take(_unknown_keys, data, "insertion", _KEYS)
    first = last = None
    raw = data.get("lengths")
    if not isinstance(raw, list) or len(raw) != 2:
        p.add(
            "insertion.lengths: expected the first and the last free length, e.g. "
            f"['6 mm', '40 mm']; got {raw!r}"
        )
    else:
        first = p.take(_value, raw[0], "length", "insertion.lengths[0]", kind="position")
        last = p.take(_value, raw[1], "length", "insertion.lengths[1]", kind="position")
    steps = data.get("steps", 10)
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 2:
        p.add(f"insertion.steps: expected a whole number >= 2; got {steps!r}")
    nodes = data.get("nodes", 32)
    if isinstance(nodes, bool) or not isinstance(nodes, int) or not 8 <= nodes <= 512:
        p.add(f"insertion.nodes: expected a whole number in [8, 512]; got {nodes!r}")
    withdraw = data.get("withdraw", False)
    if not isinstance(withdraw, bool):
        p.add(f"insertion.withdraw: expected true or false; got {withdraw!r}")
    if isinstance(first, float) and isinstance(last, float):
        if not 0 < first < last:
            p.add(
                f"insertion.lengths: need 0 < first < last; got {1e3 * first:.4g} mm, "
                f"{1e3 * last:.4g} mm"
            )
        elif robot_length is not None and last > robot_length * (1 + 1e-12):
            p.add(
                f"insertion.lengths: the last free length {1e3 * last:.4g} mm exceeds the "
                f"robot's length {1e3 * robot_length:.4g} mm"
            )
    if p.lines:
        raise SceneError(p.lines)
    lengths = np.linspace(first, last, steps)
    if withdraw:
        lengths = np.concatenate([lengths, lengths[-2::-1]])
    return {"lengths": lengths, "nodes": nodes, "withdraw": withdraw, "steps": steps}


def push_force(ins, axis=(1.0, 0.0, 0.0)) -> np.ndarray:
    """Push force at the introducer per step, shape (m,), N (> 0 pushes the robot in).

    ``ins.push_force`` where the insertion reports it (with friction); otherwise the axial
    component of the clamp's force from the equilibrium of the free part,
    ``wall_force . axis``: the wall's forces on the rod are ``-wall_force`` and the clamp
    balances them (exact without friction in a uniform field, which exerts no net force).
    """
    given = getattr(ins, "push_force", None)
    if given is not None and len(given) == len(ins):
        return np.asarray(given, dtype=float)
    return np.asarray(ins.wall_force, dtype=float) @ np.asarray(axis, dtype=float)


def contact_patch_forces(ins, k: int) -> np.ndarray:
    """Forces of the wall on the rod at step ``k``, one per contact patch, shape (m, 3), N.

    A contact point's force is its force per length (``ins.contact_force(k)``) times its
    weight (a corner's segment length; half the last segment for the last corner and for the
    tip), and a patch is a run of consecutive points in contact.  The patches' forces sum to
    minus ``ins.wall_force[k]`` and converge with the grid whether the contact is distributed
    or at a point (the force per length of a point contact grows as 1/h: the largest per
    length is no measure of the force on the wall).
    """
    f = ins.contact_force(k)
    h = np.diff(ins.s(k))
    w = np.empty(len(f))
    w[:-2], w[-2:] = h[:-1], 0.5 * h[-1]
    on = np.flatnonzero(np.asarray(ins.contact_nodes[k], bool))
    if on.size == 0:
        return np.zeros((0, 3))
    force = f * w[:, None]
    runs = np.split(on, np.flatnonzero(np.diff(on) > 1) + 1)
    return np.array([force[r].sum(axis=0) for r in runs])


def _largest_contact(ins, k: int) -> float:
    """The largest contact patch force of step ``k`` (N; 0 without contact)."""
    return float(np.max(np.linalg.norm(contact_patch_forces(ins, k), axis=1), initial=0.0))


@dataclass
class NavigationRun:
    """One insertion (in one field): the :class:`~coilrod.contact.Insertion` or the error."""

    field_label: str
    seconds: float
    result: object = None
    error: str = ""


@dataclass
class NavigationSceneResult:
    """The insertions of a navigation scene, with their table, summary, files and figure."""

    scene: object
    plan: object
    runs: list[NavigationRun] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True if every insertion reached its last step."""
        return all(not r.error for r in self.runs)

    @property
    def axis(self) -> np.ndarray:
        """The introducer's axis (the clamp's tangent)."""
        R0 = self.scene.rod_options.get("clamp_rotation")
        return np.eye(3)[:, 0] if R0 is None else np.asarray(R0, float)[:, 0]

    def table(self) -> list[dict]:
        """One row per (field, step): free length (mm), tip (mm), total wall force (the size
        of the contact forces' vector sum), the largest contact's force
        (:func:`contact_patch_forces`) and push force (mN), contact points in contact."""
        rows = []
        for r in self.runs:
            ins = r.result
            if ins is None:
                continue
            push = push_force(ins, self.axis)
            for k in range(len(ins)):
                rows.append(
                    {
                        "field": r.field_label,
                        "step": k,
                        "free_length_mm": 1e3 * float(ins.lengths[k]),
                        "tip_x_mm": 1e3 * float(ins.tip[k, 0]),
                        "tip_y_mm": 1e3 * float(ins.tip[k, 1]),
                        "tip_z_mm": 1e3 * float(ins.tip[k, 2]),
                        "wall_force_mN": 1e3 * float(ins.wall_force_magnitude[k]),
                        "largest_contact_mN": 1e3 * _largest_contact(ins, k),
                        "push_force_mN": 1e3 * float(push[k]),
                        "contacts": int(np.count_nonzero(ins.contact_nodes[k])),
                        "min_gap_mm": 1e3 * float(ins.min_gap[k]),
                    }
                )
        return rows

    def summary(self) -> str:
        """A short account of each insertion."""
        spec = self.scene.rod_options["insertion"]
        a, b = 1e3 * spec["lengths"][0], 1e3 * spec["lengths"].max()
        how = " and back" if spec["withdraw"] else ""
        lines = [
            f"scene: {self.scene.name}",
            f"insertion: free length {a:g} -> {b:g} mm{how} in {spec['steps'] - 1} steps, "
            f"{spec['nodes']} segments",
        ]
        for r in self.runs:
            ins = r.result
            status = "ok" if not r.error else f"FAILED: {r.error}"
            if ins is None:
                lines.append(f"  {r.field_label:6s} [{status}]")
                continue
            push = push_force(ins, self.axis)
            tip = 1e3 * ins.tip[-1]
            most = max(_largest_contact(ins, k) for k in range(len(ins)))
            lines.append(
                f"  {r.field_label:6s} tip ({tip[0]:7.3f}, {tip[1]:7.3f}, {tip[2]:7.3f}) mm "
                f"at {1e3 * ins.lengths[-1]:g} mm; total wall force max "
                f"{1e3 * ins.wall_force_magnitude.max():.4g} mN (largest contact "
                f"{1e3 * most:.4g} mN), push force "
                f"{1e3 * push.min():.4g} .. {1e3 * push.max():.4g} mN  "
                f"[{r.seconds:.2f} s, {status}]"
            )
        return "\n".join(lines)

    def write(self, out_dir) -> list:
        """Write ``insertion.csv``, ``summary.json`` and ``navigation.png`` (as the scene's
        outputs ask) to ``out_dir``; returns the paths."""
        from .outputs import prepare_output_dir, save_figure, write_json, write_rows

        out = prepare_output_dir(out_dir, key="output folder")
        written = []
        if self.scene.outputs.get("tables", True):
            rows = self.table()
            written.append(write_rows(out / "insertion.csv", rows))
            path = out / "summary.json"
            runs = []
            for r in self.runs:
                ins = r.result
                runs.append(
                    {
                        "field": r.field_label,
                        "seconds": r.seconds,
                        "error": r.error,
                        "steps_reached": 0 if ins is None else len(ins),
                        "tip_mm": None if ins is None else (1e3 * ins.tip[-1]).tolist(),
                        "max_wall_force_mN": None
                        if ins is None
                        else 1e3 * float(ins.wall_force_magnitude.max()),
                        "max_contact_force_mN": None
                        if ins is None
                        else 1e3 * max(_largest_contact(ins, k) for k in range(len(ins))),
                    }
                )
            write_json(path, {"scene": self.scene.name, "runs": runs})
            written.append(path)
        if self.scene.outputs.get("figures", True):
            import matplotlib.pyplot as plt

            fig = plot_navigation(self)
            path = out / "navigation.png"
            try:
                save_figure(fig, path)
            finally:
                plt.close(fig)
            written.append(path)
        return written


def plot_navigation(result, steps: int = 6):
    """The insertion's shapes in the vessel (x-y, mm; about ``steps`` of them per run, the
    contact points in contact marked, the contact forces of the step with the largest wall
    force as arrows) and the
    push force at the introducer and the total wall force against the free length (mN).
    Returns the figure."""
    import matplotlib.pyplot as plt
    from matplotlib.transforms import Affine2D

    scene = result.scene
    fig, (ax, axf) = plt.subplots(1, 2, figsize=(11, 4.8), layout="constrained")
    to_mm = Affine2D().scale(1e3) + ax.transData
    for ob in scene.rod_options.get("obstacles") or []:
        ob._draw(ax, color="0.35", linewidth=1, transform=to_mm)
    styles = {"ideal": "--", "coils": "-"}
    cmap = plt.get_cmap("viridis")
    for r in result.runs:
        ins = r.result
        if ins is None:
            continue
        ls = styles.get(r.field_label, "-")
        m = len(ins)
        shown = np.unique(np.linspace(0, m - 1, min(steps, m)).astype(int))
        for i, k in enumerate(shown):
            x = 1e3 * ins.centerline(k)
            color = cmap(i / max(len(shown) - 1, 1))
            label = f"{r.field_label} {1e3 * ins.lengths[k]:.0f} mm"
            ax.plot(x[:, 0], x[:, 1], ls, color=color, lw=1.2, label=label)
            on = np.asarray(ins.contact_nodes[k], bool)
            p = 1e3 * ins.contact_points(k)
            ax.plot(p[on, 0], p[on, 1], "o", color="crimson", ms=3)
        k = int(np.argmax(ins.wall_force_magnitude))  # the step pressing hardest
        f = ins.contact_force(k)
        size = np.linalg.norm(f, axis=1)
        on = size > 1e-9 * max(size.max(), 1e-300)
        if ins.wall_force_magnitude[k] > 0 and np.any(on):
            p = 1e3 * ins.contact_points(k)
            scale = 0.1 * 1e3 * scene.rod.length / np.max(np.linalg.norm(f[on], axis=1))
            # (the largest contact's force, not the largest per length: a point contact's
            # force per length is its force over a segment, growing as the grid is refined)
            most = _largest_contact(ins, k)
            ax.quiver(p[on, 0], p[on, 1], scale * f[on, 0], scale * f[on, 1], angles="xy",
                      scale_units="xy", scale=1, color="tab:red", width=0.004,
                      label=f"wall on rod at {1e3 * ins.lengths[k]:.0f} mm ({r.field_label}; "
                      f"largest contact {1e3 * most:.3g} mN)")  # fmt: skip
        lengths = 1e3 * ins.lengths
        axf.plot(lengths, 1e3 * push_force(ins, result.axis), ls + "o", ms=3, color="tab:blue",
                 label=f"push force ({r.field_label})")  # fmt: skip
        axf.plot(lengths, 1e3 * ins.wall_force_magnitude, ls + "s", ms=3, color="tab:red",
                 label=f"total wall force ({r.field_label})")  # fmt: skip
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(scene.name, fontsize=10)
    axf.axhline(0.0, color="0.7", lw=0.8)
    axf.set_xlabel("free length (mm)")
    axf.set_ylabel("force (mN)")
    if any(r.result is not None for r in result.runs):  # (every run failed: nothing to name)
        ax.legend(fontsize=6, loc="best")
        axf.legend(fontsize=7)
    return fig


def run_navigation(scene, plan, progress: bool = False, log=None) -> NavigationSceneResult:
    """Insert the scene's robot into its vessel in each field of ``plan`` (see the module)."""
    from ..contact import insert

    spec = scene.rod_options["insertion"]
    (vessel,) = scene.rod_options["obstacles"]
    R0 = scene.rod_options.get("clamp_rotation")
    top = float(np.max(scene.scales))
    result = NavigationSceneResult(scene, plan)
    for job in plan.jobs:
        if log:
            log(f"inserting the robot in the {job.field_label} field ...")
        f = job.field * top if top != 1.0 else job.field
        t0 = time.perf_counter()
        try:
            ins = insert(
                scene.rod,
                vessel,
                spec["lengths"],
                f,
                clamp_position=(0.0, 0.0, 0.0),
                clamp_rotation=np.eye(3) if R0 is None else R0,
                nodes=spec["nodes"],
                progress=progress,
            )
            run = NavigationRun(job.field_label, time.perf_counter() - t0, ins)
        except (ConvergenceError, ValueError) as exc:  # (a failed run is reported, no traceback)
            run = NavigationRun(
                job.field_label, time.perf_counter() - t0, getattr(exc, "result", None), str(exc)
            )
        result.runs.append(run)
    return result


def check_insertion(data: dict, robot, rod_options, models) -> dict:
    """Parse a scene's ``[insertion]`` table against the rest of the scene: it needs one
    obstacle (the lumen) and the rod model alone; returns ``rod_options`` with the parsed
    table under ``"insertion"`` (raises SceneError with one line per problem)."""
    lines = []
    length = getattr(robot[0], "length", None) if isinstance(robot, tuple) else None
    try:
        spec = parse_insertion(data["insertion"], length)
    except SceneError as exc:
        lines += exc.problems
        spec = None
    if "obstacles" not in data:
        lines.append("insertion: needs the lumen to insert into ([[obstacles.vessel]], "
                     "[[obstacles.mesh]] or [[obstacles.centerline]])")  # fmt: skip
    elif isinstance(rod_options, dict) and "obstacles" in rod_options:
        obstacles = rod_options["obstacles"]
        if len(obstacles) != 1:
            lines.append(f"insertion: needs exactly one obstacle (the lumen); got {len(obstacles)}")
        elif type(obstacles[0]).__name__ == "Wall":
            lines.append("insertion: the obstacle must be a lumen (vessel, mesh or centreline), "
                         "not a wall")  # fmt: skip
        elif spec is not None and isinstance(robot, tuple):
            lines += _straight_surface(obstacles[0], robot[0], rod_options, spec["lengths"][0])
    if isinstance(models, list | tuple) and [m for m in models if m != "rod"]:
        lines.append("insertion: insertion is modelled by the rod only -- run the rod alone")
    if isinstance(rod_options, dict) and rod_options.get("model") == "planar":
        lines.append("insertion: needs the spatial rod (rod.model = 'spatial')")
    if lines:
        raise SceneError(lines)
    if not isinstance(rod_options, dict):  # its problems are listed already
        return rod_options
    return {**rod_options, "insertion": spec}


def _straight_surface(lumen, rod, rod_options, length: float) -> list[str]:
    """The problem (a line, or none) of a first free length whose straight surface reaches
    the lumen's wall (its centreline is checked by :func:`~coilrod.scene.obstacles.
    parse_obstacles`): the insertion's first step starts from it."""
    from ..rod.model import clamp_frame

    sec = rod.section  # (a circle's radius, a rectangle's smaller half-side: as insert)
    half = sec.diameter / 2 if hasattr(sec, "diameter") else min(sec.width, sec.thickness) / 2
    tangent = clamp_frame(0.0, rod_options.get("clamp_rotation"))[:, 0]
    s = np.linspace(0.0, length, 65)
    gap = np.asarray(lumen.gap(np.outer(s, tangent)), float) - half
    bad = np.flatnonzero(gap < -1e-12 * length)
    if bad.size == 0:
        return []
    if bad[0] == 0:  # no room at the clamp (a lumen narrower than the robot: said by
        from .obstacles import _narrowest  # parse_obstacles for vessels, not for meshes)

        narrow = _narrowest(lumen)
        widest = half if hasattr(sec, "diameter") else 0.5 * np.hypot(sec.width, sec.thickness)
        if narrow is not None and narrow <= widest:
            return []
        return [
            f"insertion: the robot's surface ({1e3 * half:.4g} mm from its axis) reaches the "
            f"lumen's wall at the clamp (the introducer; by {1e3 * -gap[0]:.3g} mm): the lumen "
            "is narrower than the robot there, or the clamp is too close to its wall"
        ]
    return [
        f"insertion.lengths[0]: the robot starts straight at its first free length "
        f"{1e3 * length:.4g} mm, and its surface ({1e3 * half:.4g} mm from its axis) reaches "
        f"the lumen's wall {1e3 * s[bad[0]]:.4g} mm from the clamp (by {1e3 * -gap.min():.3g} "
        "mm); start with a shorter first length"
    ]


def first_length(data) -> float | None:
    """The first free length of a scene's ``[insertion]`` table (m), None if it is invalid:
    the straight robot that must start inside the lumen is that long."""
    try:
        return float(parse_insertion(data)["lengths"][0])
    except (SceneError, TypeError, ValueError):
        return None
