"""Figures of a scene's results: tip deflection against field strength, deformed shapes over
the field map (with the uniformity contour of the real coils), and a control scene's shapes in
the real field with the target."""

from __future__ import annotations

import numpy as np

from .strength import field_strength

__all__ = [
    "plot_tip_vs_field",
    "plot_scene_shapes",
    "plot_scene_shapes_3d",
    "plot_control_shapes",
    "centerline_of",
    "leaves_plane",
]

_STYLE = {"coils": "-", "ideal": "--"}
_COLOR = {"rod": "tab:blue", "fem2d": "tab:orange", "fem3d": "tab:green"}
#: The rod's curves are drawn thin and on top, the FEM's wide, translucent and below: the two
#: models agree to ~1 % of L, so curves of one width would hide each other.
_WIDTH = {"rod": 1.4}
_FEM = {"lw": 3.5, "alpha": 0.55, "zorder": 2}


def _line_style(model: str, lw: float | None = None) -> dict:
    """Width, transparency and drawing order of a model's curve (see :data:`_WIDTH`)."""
    if model == "rod":
        return {"lw": _WIDTH["rod"] if lw is None else lw, "zorder": 4}
    return dict(_FEM)


def _title(text: str, width: int = 52) -> str:
    """A scene name wrapped to the width of one panel."""
    import textwrap

    return textwrap.fill(text, width)


def centerline_of(run, k: int = -1) -> np.ndarray:
    """Deformed centreline (n, 3) in m of state ``k`` of a run (rod or FEM)."""
    res = run.result
    k = k % len(run.scales)
    if hasattr(res, "centerline"):
        return res.centerline(k)
    p = np.asarray(res.nodes)
    u = np.asarray(res.displacement(k))
    dim = p.shape[0]
    off = np.abs(p[1]) + (np.abs(p[2]) if dim == 3 else 0.0)
    sel = off <= off.min() + 1e-9 * max(1.0, np.ptp(p[0]))
    order = np.argsort(p[0, sel])
    x = (p + u)[:, sel][:, order]
    pts = np.zeros((x.shape[1], 3))
    pts[:, :dim] = x.T
    return pts


def plot_tip_vs_field(result, ax=None):
    """Tip deflection y/L against the magneto-elastic number, every model in every field.

    Solid lines: real coils; dashed: the ideal field.  Returns the Axes.
    """
    import matplotlib.pyplot as plt

    value, kind, number = field_strength(result.scene)
    pairs = [
        (result.run(m, "coils"), result.run(m, "ideal"))
        for m in result.scene.models
        if result.run(m, "coils") is not None and result.run(m, "ideal") is not None
    ]
    shift_ax = None
    if ax is None:
        if pairs:
            _, (ax, shift_ax) = plt.subplots(
                2, 1, figsize=(6, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 2]}
            )
        else:
            _, ax = plt.subplots(figsize=(6, 4.2))
    L = result.scene.rod.length
    for r in result.runs:
        if len(r.scales) == 0:
            continue
        x = np.concatenate([[0.0], r.scales * number])
        y = np.concatenate([[0.0], r.tip[:, 1] / L])
        ax.plot(
            x,
            y,
            _STYLE.get(r.field_label, ":"),
            color=_COLOR.get(r.model, "k"),
            marker="o" if r.model != "rod" else None,
            ms=3,
            label=f"{r.model}, {r.field_label} field",
            **_line_style(r.model),
        )
    sym = r"$\lambda$" if kind == "B" else r"$\gamma$"
    unit = f"{1e3 * value:.3g} mT" if kind == "B" else f"{value:.3g} T/m"
    ax.set_xlabel(f"{sym} (scale 1 = {unit})")
    ax.set_ylabel("tip deflection $y_{tip}/L$")
    ax.set_title(_title(result.scene.name), fontsize=10)
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8)
    if shift_ax is not None:
        for real, ideal in pairs:
            n = min(len(real.scales), len(ideal.scales))
            if n == 0:
                continue
            shift = np.linalg.norm(real.tip[:n] - ideal.tip[:n], axis=1) / L
            shift_ax.plot(
                np.concatenate([[0.0], real.scales[:n] * number]),
                np.concatenate([[0.0], 100 * shift]),
                "-",
                color=_COLOR.get(real.model, "k"),
                marker="o" if real.model != "rod" else None,
                ms=3,
                label=real.model,
                **_line_style(real.model),
            )
        # the norm of a vector: where the real field's excess over the ideal one changes sign
        # along the tip's path, the shift dips to zero and rises again (see the README)
        shift_ax.set_ylabel("|tip(coils) - tip(ideal)| (% of L)")
        shift_ax.set_xlabel(ax.get_xlabel())
        ax.set_xlabel("")
        shift_ax.grid(alpha=0.3)
        if shift_ax.get_legend_handles_labels()[0]:
            shift_ax.legend(fontsize=8)
    return ax


def plot_scene_shapes(result, ax=None, k: int = -1):
    """Deformed shapes at load state ``k`` (default: the last), real vs ideal, over a map of the
    real field's deviation from ideal with its 1% contour (coil scenes)."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(6, 5))
    scene = result.scene
    L = scene.rod.length
    shapes = [
        (r, centerline_of(r, k)) for r in result.runs if len(r.scales) and r.result is not None
    ]
    pts = np.vstack([c for _, c in shapes] + [np.array([[0.0, 0.0, 0.0], [L, 0.0, 0.0]])])
    lo, hi = pts[:, :2].min(axis=0), pts[:, :2].max(axis=0)
    center = np.array([*(0.5 * (lo + hi)), 0.0])
    half = 0.5 * float(np.max(hi - lo)) + 0.1 * L
    real = scene.fields.get("coils")
    if real is not None:
        from coils.plot import plot_field_map

        plot_field_map(real, "xy", center=center, half_width=half, n=81, ax=ax, streamlines=True)
    else:
        ax.set_xlim(1e3 * (center[0] - half), 1e3 * (center[0] + half))
        ax.set_ylim(1e3 * (center[1] - half), 1e3 * (center[1] + half))
    for r, c in shapes:
        ax.plot(
            1e3 * c[:, 0],
            1e3 * c[:, 1],
            _STYLE.get(r.field_label, ":"),
            color=_COLOR.get(r.model, "k"),
            label=f"{r.model}, {r.field_label} (scale {r.scales[k]:.3g})",
            **_line_style(r.model, lw=2),
        )
    ax.plot([0, 1e3 * L], [0, 0], color="0.6", lw=1, label="undeformed", zorder=1.5)
    ax.plot(0, 0, "ks", ms=6)
    _draw_contacts(ax, scene, shapes, k)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.legend(fontsize=7, loc="best")
    ax.set_title(_title(scene.name), fontsize=10)
    return ax


def _draw_contacts(ax, scene, shapes, k: int) -> None:
    """The scene's obstacles (x-y outlines, in mm) and, for rod runs, the contact nodes with
    their contact forces per length (arrows, scaled to a tenth of the robot length)."""
    from matplotlib.transforms import Affine2D

    obstacles = scene.rod_options.get("obstacles") or []
    if not obstacles:
        return
    to_mm = Affine2D().scale(1e3) + ax.transData
    for ob in obstacles:
        ob._draw(ax, color="0.35", linewidth=1, transform=to_mm)
    for r, c in shapes:
        res = r.result
        if not hasattr(res, "contact_force"):
            continue
        f = res.contact_force(k)
        on = np.linalg.norm(f, axis=1) > 0
        if not np.any(on) or len(f) != len(c):
            continue
        scale = 0.1 * scene.rod.length / np.max(np.linalg.norm(f[on], axis=1))
        ax.quiver(
            1e3 * c[on, 0],
            1e3 * c[on, 1],
            1e3 * scale * f[on, 0],
            1e3 * scale * f[on, 1],
            angles="xy",
            scale_units="xy",
            scale=1,
            color="tab:red",
            width=0.004,
            label=f"contact force (max {np.max(np.linalg.norm(f, axis=1)):.3g} N/m)",
        )


def leaves_plane(result, tol: float = 1e-9) -> bool:
    """True if a rod shape of the scene result leaves the plane z = 0 by more than ``tol`` L."""
    L = result.scene.rod.length
    for r in result.runs:
        if r.result is None or not len(r.scales):
            continue
        c = centerline_of(r, -1)
        if np.max(np.abs(c[:, 2] - c[0, 2])) > tol * L:
            return True
    return False


def plot_scene_shapes_3d(result, k: int = -1):
    """The last shapes of a scene whose rod leaves its plane: two projections (x-y and x-z,
    mm) side by side; returns the first axis."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8), layout="constrained")
    L = result.scene.rod.length
    z_extent = 0.0
    for r in result.runs:
        if r.result is None or not len(r.scales):
            continue
        c = 1e3 * centerline_of(r, k)
        style = dict(color=_COLOR.get(r.model, "k"), **_line_style(r.model, lw=2))
        label = f"{r.model}, {r.field_label} (scale {r.scales[k]:.3g})"
        axes[0].plot(c[:, 0], c[:, 1], _STYLE.get(r.field_label, ":"), label=label, **style)
        axes[1].plot(c[:, 0], c[:, 2], _STYLE.get(r.field_label, ":"), label=label, **style)
        z_extent = max(z_extent, float(np.ptp(c[:, 2])))
    for ax, (a, b) in zip(axes, (("x", "y"), ("x", "z")), strict=True):
        ax.plot([0, 1e3 * L], [0, 0], color="0.6", lw=1, zorder=1.5)
        ax.plot(0, 0, "ks", ms=6)
        ax.set_xlabel(f"{a} (mm)")
        ax.set_ylabel(f"{b} (mm)")
        ax.legend(fontsize=7, loc="best")
        ax.grid(alpha=0.3)
    axes[0].set_aspect("equal")
    # equal axes would make the x-z view a thin strip when the rod leaves its plane a little:
    # the out-of-plane axis is stretched instead, and says so
    if z_extent < 0.25 * 1e3 * L:
        axes[1].set_title("x-z (z exaggerated)", fontsize=9)
    else:
        axes[1].set_aspect("equal")
    name = result.scene.name
    suffix = "" if "leaves its plane" in name else ": the rod leaves its plane"
    fig.suptitle(_title(name + suffix, 110), fontsize=10)
    return axes[0]


_CONTROL_STYLE = {"real": ("-", "tab:blue"), "ideal": ("--", "tab:red")}


def plot_control_shapes(result, ax=None):
    """A control scene's shapes in the real field, one per controller (solid: the real-field
    controller; dashed: the ideal one, its currents applied to the real field), with the target
    (and its tip angle) marked, over the map of the real field made by the first controller's
    currents (its deviation from ideal, with the 1% contour).  Returns the Axes."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(6, 5))
    scene, spec = result.scene, result.scene.control
    L = scene.rod.length
    target = np.asarray(spec.target, float)
    shapes = [(r, r.result.result.centerline(-1)) for r in result.runs if r.result is not None]
    pts = np.vstack(
        [c[:, :2] for _, c in shapes] + [np.array([[0.0, 0.0], [L, 0.0]]), target[None]]
    )
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    center = np.array([*(0.5 * (lo + hi)), 0.0])
    half = 0.5 * float(np.max(hi - lo)) + 0.1 * L
    currents = shapes[0][0].result.currents if shapes else None
    if currents is not None and np.any(currents):
        from coils.plot import plot_field_map

        real = scene.fields["coils"].with_currents(currents)
        plot_field_map(real, "xy", center=center, half_width=half, n=81, ax=ax, streamlines=True)
    else:
        ax.set_xlim(1e3 * (center[0] - half), 1e3 * (center[0] + half))
        ax.set_ylim(1e3 * (center[1] - half), 1e3 * (center[1] + half))
    for r, c in shapes:
        style, color = _CONTROL_STYLE.get(r.model, (":", "k"))
        state = " (closest found)" if r.error else ""
        ax.plot(
            1e3 * c[:, 0],
            1e3 * c[:, 1],
            style,
            color=color,
            lw=2,
            label=f"{r.model} controller{state}, miss {1e3 * r.result.miss:.3g} mm",
        )
    ax.plot([0, 1e3 * L], [0, 0], color="0.6", lw=1, label="undeformed")
    ax.plot(0, 0, "ks", ms=6)
    ax.plot(*(1e3 * target), "kx", ms=10, mew=2, label="target")
    if spec.angle is not None:
        d = 0.15 * L * np.array([np.cos(spec.angle), np.sin(spec.angle)])
        ax.annotate(
            "",
            xy=1e3 * (target + d),
            xytext=1e3 * target,
            arrowprops={"arrowstyle": "->", "color": "k"},
        )
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.legend(fontsize=7, loc="best")
    ax.set_title(scene.name, fontsize=10)
    return ax
