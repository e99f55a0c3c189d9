"""Checks of a well-formed scene as a whole: can it be solved, and within the limits?

Everything a run would trip over is found here, before any solve, so that ``coilrod check``
and ``coilrod run`` stop at the same problems (:func:`coilrod.scene.parse_scene` calls
:func:`scene_problems` last):

- the field is not zero, and the planar models (fem2d, a rod with model "planar") see some of
  it in their plane and nothing out of it (B_z, dB_z/dx, dB_z/dy over the robot's reach: the
  planar rod's criterion, :func:`coilrod.rod.model.planar_reasons`);
- the magneto-elastic number at the top load stays within :data:`limits.MAX_MAGNETOELASTIC`;
- the clamp and the undeformed robot keep clear of every coil winding, and the real field is
  finite on the undeformed centreline (the problem names the coil);
- FEM meshes resolve the magnetization segments and stay within the element limits;
- a magnetization with an out-of-plane elevation is not given to a planar model (fem2d, a rod
  with model "planar"), and the FEM is not given the incompressible
  ``robot.poisson_ratio = 0.5``;
- a coil system under control (``field.type = "system"``) can make every in-plane field at its
  centre, where the ideal controller takes its field, and that centre is off the windings.
"""

from __future__ import annotations

import math

import numpy as np

from coils.coaxial import coaxial_parts

from ..fem.mesh import DEFAULT_ELEMENTS as FEM_DEFAULT_ELEMENTS
from ..fem.mesh import (
    clamp_layer,
    default_elements,
    element_count,
    length_layers,
    linear_circle_problem,
)
from ..fem.solve import NU_GAP as FEM_NU_GAP
from ..robot.sections import Circle
from . import limits
from .strength import field_strength

__all__ = ["scene_problems", "centerline_points", "body_radius", "FEM_DEFAULT_ELEMENTS"]

#: Points sampled along the undeformed centreline (the closest approach is then refined).
CENTERLINE_SAMPLES = 2001
#: Points of the undeformed centreline where the field itself is evaluated.
FIELD_SAMPLES = 201


def centerline_points(length: float, n: int = CENTERLINE_SAMPLES, tangent=(1.0, 0.0, 0.0)):
    """Points (n, 3) in m of the undeformed centreline, from the clamp (origin) along the unit
    ``tangent`` (default +x; the clamp frame's first column for a rotated clamp)."""
    return np.outer(np.linspace(0.0, length, n), np.asarray(tangent, float))


def clamp_tangent(scene) -> np.ndarray:
    """The unit tangent (3,) of the undeformed robot at the clamp: +x, or the first column of
    ``rod.clamp_rotation`` (rod runs only; the continuum models clamp along +x)."""
    from ..rod.model import clamp_frame

    return clamp_frame(0.0, scene.rod_options.get("clamp_rotation"))[:, 0]


def body_radius(rod) -> float:
    """Radius (m) of the smallest cylinder about the centreline containing the rod's body."""
    sec = rod.section
    if isinstance(sec, Circle):
        return 0.5 * sec.diameter
    return 0.5 * math.hypot(sec.width, sec.thickness)


def _mm(x: float) -> str:
    return f"{1e3 * x:.4g} mm"


def _fem_elements(scene, dim: int) -> tuple[tuple[int, ...], bool]:
    """(elements, given): the scene's FEM elements for ``dim`` or solve_fem's default."""
    given = scene.fem_options.get(f"elements{dim}d")
    if given is not None:
        return tuple(given), True
    return default_elements(scene.rod, dim), False


def fem_cells(scene, dim: int, elements) -> int:
    """Number of elements of the FEM mesh ``elements`` builds (:func:`coilrod.fem.rod_mesh`):
    its layers along the length by the builder's own rule (:func:`~coilrod.fem.length_layers`:
    one piece per magnetization segment at least, and in 3D the layers graded at the clamp to
    :func:`~coilrod.fem.mesh.clamp_layer`, a few more for a thin rod) times the section's
    (:func:`~coilrod.fem.mesh.element_count`)."""
    rod = scene.rod
    clamp = clamp_layer(rod.section) if dim == 3 else None
    layers = length_layers(rod.length, elements[0], rod.magnetization.breakpoints, clamp).size - 1
    return element_count(rod.section, dim, (layers, *elements[1:]))


# -- the checks ---------------------------------------------------------------------------------
def _zero_field(scene, coil_keys, strength_key) -> list[str]:
    if scene.field_kind == "coils":
        if all(c.coil.current == 0 for c in coil_keys):
            what = "the coil carries" if len(coil_keys) == 1 else "every coil carries"
            return [f"{strength_key}: {what} no current: the field is zero (nothing to solve)"]
        return []
    ideal = scene.fields["ideal"]
    if not np.any(ideal.B0) and not np.any(ideal.G):
        if scene.field_kind == "uniform":
            return [f"{strength_key}: the field is zero (nothing to solve); give e.g. '5 mT'"]
        return [
            f"{strength_key}: the gradient is zero and there is no B0: the field is zero "
            "(nothing to solve)"
        ]
    return []


def _in_plane(scene, strength_key) -> list[str]:
    """The planar models (fem2d; the rod when ``rod.model = "planar"``) see only B_x, B_y and
    their x-y derivatives: a scene in which no field has any of them along the robot gives them
    nothing to solve.  (The rod's default model takes the spatial rod for such a field.)"""
    planar = ["fem2d"] if "fem2d" in scene.models else []
    if "rod" in scene.models and scene.rod_options.get("model") == "planar":
        planar.insert(0, "rod")
    if not planar:
        return []
    pts = centerline_points(scene.rod.length, FIELD_SAMPLES, clamp_tangent(scene))
    L = scene.rod.length
    for fld in scene.fields.values():
        try:
            B, G = fld.B_and_gradient(pts)
        except ValueError:  # on a winding: reported by the clearance check
            return []
        total = np.abs(B).max() + L * np.abs(G).max()
        plane = np.abs(B[:, :2]).max() + L * np.abs(G[:, :2, :2]).max()
        if plane > 1e-12 * total:
            return []  # this field bends the rod in its plane
    key = {"uniform": "field.direction", "gradient": "field.axis"}.get(
        scene.field_kind, strength_key
    )
    return [
        f"{key}: the field has no component in the bending plane (x-y) along the robot, so the "
        f"planar models ({', '.join(planar)}) would see no load; turn the field into the x-y "
        "plane or run fem3d only"
    ]


def _out_of_plane(scene, strength_key) -> list[str]:
    """The planar models (fem2d; the rod when ``rod.model = "planar"``) refuse a field that
    would push the robot out of its plane, by :func:`coilrod.rod.model.planar_reasons` (the
    magnetization's elevation is reported by :func:`_planar_and_incompressible`)."""
    from ..rod.model import CLAMP_REASON, MAGNETIZATION_REASON, clamp_frame, planar_reasons

    planar = {"fem2d": None} if "fem2d" in scene.models else {}
    if "rod" in scene.models and scene.rod_options.get("model") == "planar":
        planar["rod"] = scene.rod_options.get("clamp_rotation")
    key = {"uniform": "field.direction", "gradient": "field.axis"}.get(
        scene.field_kind, strength_key
    )
    problems = []
    for model, rotation in planar.items():
        R0 = clamp_frame(0.0, rotation)
        for label, fld in scene.fields.items():
            for reason in planar_reasons(scene.rod, fld, np.zeros(3), R0):
                if reason == MAGNETIZATION_REASON:
                    continue
                where = "rod.clamp_rotation" if reason == CLAMP_REASON else key
                fix = "run fem3d" if model == "fem2d" else "drop rod.model = 'planar'"
                problems.append(
                    f"{where}: {reason} ({label} field), which the planar {model} model would "
                    f"drop; turn it into the x-y plane or {fix}"
                )
    return list(dict.fromkeys(problems))


def _magnetoelastic(scene, strength_key) -> list[str]:
    _, label, number = field_strength(scene)
    top = float(np.max(np.abs(scene.scales))) * number
    if not top <= limits.MAX_MAGNETOELASTIC:
        sym = "lambda = |M| |B| A L^2 / (E I)" if label == "B" else "gamma = |M| g A L^3 / (E I)"
        return [
            f"{strength_key}: at the top load the magneto-elastic number {sym} is {top:.3g}, "
            f"more than the {limits.MAX_MAGNETOELASTIC:g} coilrod solves (the rod would just "
            "line up with the field); lower the field, the magnetization or the load"
        ]
    return []


def _closest(dist, length: float) -> tuple[float, float]:
    """(s, d): the arc length in [0, length] where ``dist(s)`` (vectorised) is smallest."""
    from scipy.optimize import minimize_scalar

    s = np.linspace(0.0, length, CENTERLINE_SAMPLES)
    d = dist(s)
    k = int(np.argmin(d))
    best = (float(s[k]), float(d[k]))
    lo, hi = s[max(k - 1, 0)], s[min(k + 1, len(s) - 1)]
    if hi > lo:
        res = minimize_scalar(
            lambda x: float(dist(np.array([x]))[0]),
            bounds=(lo, hi),
            method="bounded",
            options={"xatol": 1e-12 * length},
        )
        if res.fun < best[1]:
            best = (float(res.x), float(res.fun))
    return best


def _clearance(scene, coil_keys) -> list[str]:
    """The clamp and the undeformed body (along the clamp's tangent, :func:`clamp_tangent`)
    against every filament and winding of every coil."""
    problems = []
    L = scene.rod.length
    r = body_radius(scene.rod)
    tangent = clamp_tangent(scene)
    for c in coil_keys:
        worst = None  # (gap, s)
        for part in coaxial_parts(c.coil):

            def local(s, part=part):
                loc = part.to_local(np.outer(s, tangent))
                return np.hypot(loc[:, 0], loc[:, 1]), loc[:, 2]

            # a finite winding's section (rho, z) holds its filaments; else the filaments
            boxes = [tuple(b) for b in part.windings] or [
                (z0, a, 0.0, 0.0) for z0, a, _ in part.filaments
            ]
            for z0, a, w, h in boxes:

                def dist(s, z0=z0, a=a, w=w, h=h):
                    rho, z = local(s)
                    dr = np.maximum(np.abs(rho - a) - 0.5 * h, 0.0)
                    dz = np.maximum(np.abs(z - z0) - 0.5 * w, 0.0)
                    return np.hypot(dr, dz)

                s, d = _closest(dist, L)
                if worst is None or d - r < worst[0]:
                    worst = (d - r, s)
        if worst is not None and worst[0] <= 0:
            s = worst[1]
            where = (
                "the clamp (the robot's base, at the origin)"
                if s <= 1e-9 * L
                else f"the undeformed robot, at s = {_mm(s)} from the clamp,"
            )
            rotated = "clamp_rotation" in scene.rod_options
            along = " along the rotated clamp's tangent" if rotated else ""
            problems.append(
                f"{c.key}: {where}{along} touches the winding of {c.what} (the robot's body "
                f"reaches {_mm(r)} from its centreline); move the coil (center, radius, "
                f"spacing) or change the robot{' or rod.clamp_rotation' if rotated else ''}"
            )
            continue
        # the real field on the undeformed centreline, as the solvers will first evaluate it
        try:
            B, G = c.coil.B_and_gradient(centerline_points(L, FIELD_SAMPLES, tangent))
        except ValueError as exc:
            problems.append(f"{c.key}: the field cannot be evaluated on the robot ({exc})")
            continue
        if not (np.all(np.isfinite(B)) and np.all(np.isfinite(G))):
            problems.append(f"{c.key}: the field is not finite on the undeformed robot")
    return problems


def _fem(scene) -> list[str]:
    problems = []
    steps = len(scene.scales)
    L = scene.rod.length
    edges = getattr(scene.rod.magnetization, "segment_edges", None)
    for model in scene.models:
        if not model.startswith("fem"):
            continue
        dim = 2 if model == "fem2d" else 3
        key = f"fem.elements{dim}d"
        elements, given = _fem_elements(scene, dim)
        what = f"{list(elements)}" if given else f"the default {list(elements)} of {model}"
        linear = linear_circle_problem(
            scene.rod.section, dim, scene.fem_options.get("order", 2), elements
        )
        if linear:
            problems.append(f"{key}: {linear} (fem.order = 1)")
        cells = fem_cells(scene, dim, elements)
        if cells > limits.MAX_FEM_ELEMENTS[dim]:
            problems.append(
                f"{key}: {what} makes {cells} elements; at most "
                f"{limits.MAX_FEM_ELEMENTS[dim]} in {dim}D (about 2 GB of memory)"
            )
        elif cells * steps > limits.MAX_FEM_ELEMENT_STEPS[dim]:
            problems.append(
                f"{key}: {what} makes {cells} elements, times {steps} load steps "
                f"= {cells * steps} element-steps; at most {limits.MAX_FEM_ELEMENT_STEPS[dim]} "
                f"in {dim}D (about 20 minutes per field): use fewer elements or load steps"
            )
        if edges is not None:
            shortest = float(np.min(np.diff(edges)))
            n = elements[0]
            if L / n > shortest * (1 + 1e-9):
                need = math.ceil(L / shortest * (1 - 1e-9))
                fix = (
                    f"use at least {need}"
                    if given
                    else f"give {key} = [{need}, {', '.join(map(str, elements[1:]))}]"
                )
                problems.append(
                    f"{key}[0]: {what}: {n} elements along the robot are {_mm(L / n)} long, "
                    f"longer than its shortest magnetization segment ({_mm(shortest)}), "
                    f"which the mesh cannot resolve; {fix}"
                )
    return problems


def _planar_and_incompressible(scene) -> list[str]:
    """A non-planar magnetization given to a planar model; nu = 0.5 given to the FEM."""
    problems = []
    planar = ["fem2d"] if "fem2d" in scene.models else []
    if "rod" in scene.models and scene.rod_options.get("model") == "planar":
        planar.append("rod (rod.model = 'planar')")
    if not scene.rod.magnetization.is_planar:
        problems += [
            f"robot.magnetization: has an out-of-plane elevation; the planar {what} supports "
            "only planar magnetizations (elevation 0)"
            for what in planar
        ]
    fem = [m for m in scene.models if m.startswith("fem")]
    nu = scene.poisson_ratio
    if nu == 0.5 and fem:
        problems.append(
            "robot.poisson_ratio: 0.5 is incompressible, which the FEM "
            f"({', '.join(fem)}) cannot take (infinite bulk modulus); give e.g. 0.4995"
        )
    elif nu is not None and nu > 0.5 - FEM_NU_GAP and fem:
        problems.append(
            f"robot.poisson_ratio: {nu!r} is within {FEM_NU_GAP:g} of 0.5, beyond what the FEM "
            f"({', '.join(fem)}) solves in float64; 0.4999999 gives the same tips to 1e-8"
        )
    return problems


def _control_system(scene, key) -> list[str]:
    """A coil system under control: its centre off the windings, every in-plane field there."""
    system = scene.fields["coils"]
    where = ", ".join(_mm(c) for c in system.center)
    try:
        Bu, _ = system.unit_fields(np.asarray(system.center, float)[None])
    except ValueError as exc:
        return [
            f"{key}: the system's centre ({where}), where the ideal controller takes its "
            f"field, lies on a winding ({exc}); move the coils"
        ]
    plane = Bu[0, :2]
    rank = int(np.linalg.matrix_rank(plane, tol=1e-12 * max(np.abs(Bu).max(), 1e-300)))
    if rank < 2:
        return [
            f"{key}: the channels cannot make every in-plane field (B_x, B_y) at the system's "
            f"centre ({where}): rank {rank} of 2, so no currents bend the robot every way; add "
            "a coil or pair with its axis along x or y"
        ]
    return []


def scene_problems(scene, coil_keys=(), strength_key: str = "field") -> list[str]:
    """Every reason a well-formed ``scene`` cannot be solved (empty: it can).

    Parameters
    ----------
    scene : Scene
        A scene whose keys are valid one by one.
    coil_keys : sequence
        The parsed coils with their scene keys (``key``, ``coil``, ``strength_key``).
    strength_key : str
        The key that sets the field's strength (``field.B``, ``field.coil[0].current``, ...).

    Returns
    -------
    list of str
        One line per problem, each starting with the key to change.
    """
    if scene.field_kind == "system":  # the currents are to be found: no field strength yet
        problems = _planar_and_incompressible(scene) + _clearance(scene, list(coil_keys))
        return problems or _control_system(scene, strength_key)
    zero = _zero_field(scene, list(coil_keys), strength_key)
    if zero:
        return zero
    problems = _clearance(scene, list(coil_keys))
    if not problems:  # the field along the robot is known only once it is clear of the coils
        problems += _in_plane(scene, strength_key) or _out_of_plane(scene, strength_key)
    problems += _magnetoelastic(scene, strength_key)
    problems += _fem(scene)
    problems += _planar_and_incompressible(scene)
    return problems
