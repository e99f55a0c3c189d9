"""Decide what a scene needs and what it can skip, before any heavy import or computation.

The plan says, in words, which solves run and why others are skipped: no Biot-Savart for ideal
fields, no gradient (force) path for uniform fields, a gridded cache when a coil field will be
queried many times over the robot's reach, no scikit-fem import for rod-only scenes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

import coils
from coils.clearance import Box, winding_contacts
from coils.coaxial import coaxial_parts

from .parse import Scene

__all__ = ["Plan", "Job", "plan_scene", "robot_reach_box", "leaves_its_plane"]

#: A coil field expected to be queried more than this many times per grid node is cached.
CACHE_QUERIES_PER_NODE = 20
#: Rough grid size of a cache over the robot's reach (nodes), for that decision.
CACHE_NODES_ESTIMATE = 20_000
#: Below this many filaments, direct evaluation by the compiled kernel is faster than the
#: interpolating cache, so no cache is built.  Measured by ``benchmarks/bench_coils.py`` part g
#: (one coaxial group, 300 and 3000 points in a robot's reach box, a single core): a direct
#: query costs ~0.03 us per filament and point, a grid query ~1.5 us per point for B + gradient
#: and ~3.8 us with the hessian, whatever the field, so the cache breaks even at ~47 filaments
#: for B + gradient and ~95 for B + gradient + hessian (the rod's Newton tangent), at both
#: sizes.  150 is 1.5 x the larger: the cache is built only where it is faster for every query
#: (1.5 x with the hessian, 3 x without), which pays for its build (1-3 s) and its
#: interpolation error.  Each further coaxial group adds a call overhead worth ~3 filaments,
#: and points beyond 4 group radii use the multipole series, whose cost does not grow with the
#: filaments; neither is counted.
CACHE_MIN_FILAMENTS = 150
#: Rough Newton iterations per load step, for the query estimate.
ITERATIONS_PER_STEP = 6


@dataclass
class Job:
    """One solve: a model in one of the scene's fields (``kind`` "solve"), or one controller of
    a control scene (``kind`` "control": ``field_label`` is the controller, "real" or
    "ideal", and ``field`` the coil system)."""

    model: str
    field_label: str
    field: coils.Field
    note: str = ""
    kind: str = "solve"


@dataclass
class Plan:
    """What will run and what is skipped (human-readable reasons in ``decisions``)."""

    jobs: list[Job] = field(default_factory=list)
    decisions: list[str] = field(default_factory=list)
    cache_box: tuple[np.ndarray, np.ndarray] | None = None

    def __str__(self) -> str:
        lines = ["plan:"]
        lines += [
            f"  run   {j.model:6s} in {j.field_label:6s} field{j.note}"
            if j.kind == "solve"
            else f"  run   {j.model:6s} currents by the {j.field_label} controller{j.note}"
            for j in self.jobs
        ]
        lines += [f"  note  {d}" for d in self.decisions]
        return "\n".join(lines)


def leaves_its_plane(scene: Scene) -> bool:
    """True if the robot can leave the plane z = 0 in some field of ``scene``: the planar rod
    model's criterion (:func:`coilrod.rod.model.planar_reasons`: an elevated magnetization, a
    clamp rotation out of the x-y plane, B_z or dB_z/dx, dB_z/dy over the reach)."""
    from ..rod.model import clamp_frame, planar_reasons

    R0 = clamp_frame(0.0, scene.rod_options.get("clamp_rotation"))
    return any(planar_reasons(scene.rod, fld, np.zeros(3), R0) for fld in scene.fields.values())


def robot_reach_box(scene: Scene, margin: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box (m) containing every point the robot can reach, with a margin: the
    ball of radius L about the clamp at the origin, thickened by the section, when the robot
    can leave its plane (:func:`leaves_its_plane`), else its disc in the plane z = 0 thickened
    by the section."""
    L = scene.rod.length
    h = scene.rod.section.height
    half = (1 + margin) * L + h
    depth = half if leaves_its_plane(scene) else max(h, getattr(scene.rod.section, "width", h))
    return np.array([-half, -half, -depth]), np.array([half, half, depth])


def _expected_queries(scene: Scene) -> int:
    steps = len(scene.scales)
    total = 0
    for model in scene.models:
        if model == "rod":
            points = 2 * (scene.rod_options.get("nodes") or 200)
        else:
            points = 27 * 200 if model == "fem3d" else 9 * 80
        total += points * steps * ITERATIONS_PER_STEP
    return total


def _box_clear_of_windings(field: coils.Field, box) -> bool:
    """True if the closed box stays out of every winding cross-section and more than 5% of the
    radius away from every filament (exact geometry, :mod:`coils.clearance`)."""
    return not winding_contacts(field, Box(*box), margin=0.05)


def _unused_options(scene: Scene) -> list[str]:
    """Notes on options the scene sets for models it does not run (they have no effect)."""
    notes = []
    if scene.rod_options and "rod" not in scene.models:
        notes.append("rod.nodes is set but the rod model is not run: it has no effect")
    for name in sorted(scene.fem_options):
        model = {"elements2d": ["fem2d"], "elements3d": ["fem3d"]}.get(name, ["fem2d", "fem3d"])
        if not any(m in scene.models for m in model):
            notes.append(f"fem.{name} is set but {' or '.join(model)} is not run: it has no effect")
    return notes


def _mm(x: float) -> str:
    return f"{1e3 * x:.6g}"


def _plan_control(scene: Scene) -> Plan:
    """The controllers of a control scene, and what each does."""
    spec = scene.control
    system = scene.fields["coils"]
    plan = Plan()
    notes = {
        "real": " (Gauss-Newton on the currents, each iteration a rod solve in the real "
        "Biot-Savart field)",
        "ideal": " (the system's field and gradient at its centre; its currents then solved "
        "in the real field: the miss)",
    }
    for model in spec.models:
        plan.jobs.append(Job("rod", model, system, notes[model], kind="control"))
    limits = ", ".join(f"{v:g}" for v in spec.max_current)
    m = len(system.names)
    plan.decisions.append(
        f"coil system: {spec.system}, {m} current channel{'s' if m > 1 else ''} "
        f"({', '.join(system.names)}), limits {limits} A"
    )
    if len(spec.target) == 3:
        target = "target: tip at ({}) mm (3D: the spatial rod)".format(
            ", ".join(_mm(v) for v in spec.target)
        )
        if spec.direction is not None:
            target += ", tip direction ({})".format(", ".join(f"{v:.6g}" for v in spec.direction))
    else:
        target = f"target: tip at ({_mm(spec.target[0])}, {_mm(spec.target[1])}) mm in the plane"
    if spec.angle is not None:
        target += (
            f", tip angle {math.degrees(spec.angle):.6g} deg (three conditions: with fewer "
            "independent in-plane controls the currents are the least-squares compromise, and "
            "the misses say how far)"
        )
    plan.decisions.append(target)
    nodes = scene.rod_options.get("nodes")
    plan.decisions.append(
        f"each rod solve ramps the currents from zero in {spec.steps} load steps"
        + (f" on {nodes} rod segments" if nodes else "")
    )
    if "real" in spec.models:
        plan.decisions.append(
            "the real controller starts from the uniform-field answer (a coarse workspace of "
            "uniform fields, then a least-squares fit) made at the centre with minimum power, "
            "and steps with the exact (adjoint) current sensitivities"
        )
    n_fil = sum(len(p.filaments) for p in coaxial_parts(system))
    plan.decisions.append(
        f"coil field: Biot-Savart of {n_fil} filaments, evaluated directly (the currents "
        "change at every iteration: no grid cache)"
    )
    plan.decisions.append(
        "control uses the rod model only: no FEM solve, scikit-fem is not imported"
    )
    plan.decisions += _unused_options(scene)
    return plan


def plan_scene(scene: Scene, *, cache: bool | None = None) -> Plan:
    """Plan the solves of ``scene``.

    Parameters
    ----------
    scene : Scene
    cache : bool, optional
        Force (True) or forbid (False) the gridded field cache; default: decided from the
        expected number of field queries.  Control scenes (``scene.control``) never cache.
    """
    if scene.control is not None:
        return _plan_control(scene)
    plan = Plan()
    if scene.field_kind in ("uniform", "gradient"):
        plan.decisions.append("ideal field: no Biot-Savart evaluation")
    if "ideal" in scene.fields:
        ideal = scene.fields["ideal"]
        if ideal.uniform:
            plan.decisions.append(
                "ideal field is uniform: force (gradient) path skipped, the "
                "magnetic load is a pure torque"
            )
    fem = [m for m in scene.models if m.startswith("fem")]
    if not fem:
        plan.decisions.append("no FEM model requested: scikit-fem is not imported")
    plan.decisions += _unused_options(scene)
    real = scene.fields.get("coils")
    if real is not None:
        n_fil = sum(len(p.filaments) for p in coaxial_parts(real))
        plan.decisions.append(
            f"coil field: Biot-Savart of {n_fil} filaments (closed form, exact gradient)"
        )
        queries = _expected_queries(scene)
        want = (
            cache
            if cache is not None
            else (
                n_fil >= CACHE_MIN_FILAMENTS
                and (queries > CACHE_QUERIES_PER_NODE * CACHE_NODES_ESTIMATE or bool(fem))
            )
        )
        if want:
            box = robot_reach_box(scene)
            if _box_clear_of_windings(real, box):
                plan.cache_box = box
                plan.decisions.append(
                    "coil field cached on a grid over the robot's reach"
                    + (" (a ball: it can leave its plane) " if leaves_its_plane(scene) else " ")
                    + f"[{1e3 * box[0][0]:.0f}, {1e3 * box[1][0]:.0f}] x "
                    f"[{1e3 * box[0][1]:.0f}, {1e3 * box[1][1]:.0f}] x "
                    f"[{1e3 * box[0][2]:.1f}, {1e3 * box[1][2]:.1f}] mm "
                    f"(~{queries:.1e} queries expected)"
                )
            else:
                plan.decisions.append(
                    "the robot's reach comes close to a winding: no field cache, direct evaluation"
                )
        else:
            why = (
                f"only {n_fil} filaments, as cheap as interpolation"
                if n_fil < CACHE_MIN_FILAMENTS
                else f"~{queries:.1e} field queries expected"
            )
            plan.decisions.append(f"direct field evaluation, no grid cache ({why})")
    for model in scene.models:
        for label, fld in scene.fields.items():
            note = ""
            if fld.uniform:
                note = " (uniform: torque only)"
            elif fld.linear:
                note = " (constant gradient)"
            plan.jobs.append(Job(model, label, fld, note))
    return plan
