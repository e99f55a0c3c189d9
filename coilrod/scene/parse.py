"""Scene files (TOML): the robot, the field, the load path, the models to run and the outputs.

A scene is validated completely before anything runs, and every problem is reported at once:
a :class:`SceneError` lists one line per problem, each naming the key and the reason, e.g.
``robot.length: must be positive; got -40 mm`` or ``field.coil[0].radius: missing unit``.
Nothing is read loosely: booleans must be TOML booleans, integers integers, quantities carry
their unit, keys that do not apply (a ``magnitude`` next to a ``preset``) are errors, and every
number must lie in the ranges of :mod:`coilrod.scene.limits`.  Once the scene is well formed,
:mod:`coilrod.scene.checks` makes sure it can be solved (a field that is not zero, a robot
clear of the coil windings, FEM meshes that resolve the magnetization and fit in memory).
A control scene -- a coil system as its field (``type = "system"``) and a ``[control]`` table
with the tip target whose currents the scene finds -- is read by :mod:`coilrod.scene.control`.

Example (``coilrod/scene/examples/helmholtz_vs_ideal.toml``)::

    name = "Helmholtz pair vs ideal uniform field, M(1)"

    [robot]
    length = "40 mm"
    diameter = "2 mm"
    youngs_modulus = "1 MPa"
    magnetization = { preset = "M1", M0 = "640 kA/m", phi = 0.2 }

    [field]
    type = "coils"
    compare_ideal = true
    coil = [ { type = "helmholtz", radius = "80 mm", turns = 200, B = "15 mT", axis = "y" } ]

    [load]
    steps = 15

    [models]
    run = ["rod"]
"""

from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

import coils
from coils._files import read_utf8

from ..robot import presets
from ..robot.magnetization import Magnetization
from ..robot.rod import Rod
from ..robot.sections import Circle, Rectangle
from . import limits
from .tables import (  # noqa: F401 -- re-exported: other modules import them from here
    _AXES,
    _AXIS_RE,
    _BAD,
    _COIL_NAMES,
    _COIL_TYPES,
    _MAX_LINE,
    _MISSING,
    SceneError,
    _axis,
    _Bad,
    _boolean,
    _Coil,
    _coil_current,
    _coil_geometry,
    _coil_kind,
    _coil_list_problem,
    _coil_strength,
    _coil_winding,
    _controlled_coil,
    _counts,
    _FieldInfo,
    _in_range,
    _mm,
    _number,
    _ok,
    _parse_coil,
    _plain,
    _Problems,
    _quantity,
    _show,
    _si,
    _table,
    _text,
    _unknown_keys,
    _value,
    _vector,
)

if TYPE_CHECKING:
    from .control import ControlSpec

__all__ = ["Scene", "SceneError", "load_scene", "parse_scene", "MODELS", "PRESETS"]

#: Models a scene can request.
MODELS = ("rod", "fem2d", "fem3d")
#: Magnetization presets (see :mod:`coilrod.presets`).
PRESETS = ("M1", "M2a", "M2b", "M3", "M4.1", "M4.2")
#: The parameters each preset takes (besides ``preset``).
PRESET_PARAMETERS = {
    "M1": ("M0", "phi"),
    "M2a": ("M0", "phi"),
    "M2b": ("M0", "phi"),
    "M3": ("M0", "slope"),
    "M4.1": ("M0",),
    "M4.2": ("M0", "segment", "segment_angle"),
}
_PRESET_KEYS = ("M0", "phi", "slope", "segment", "segment_angle")
_FIELD_TYPES = "'uniform', 'gradient', 'coils' or 'system'"


@dataclass
class Scene:
    """A validated scene.

    Attributes
    ----------
    name : str
    rod : Rod
    fields : dict[str, coils.Field]
        The fields to compare, by label: ``{"coils": real, "ideal": ideal}`` for coil scenes,
        ``{"ideal": field}`` for ideal-field scenes.  Each is multiplied by every load scale.
    field_kind : str
        "uniform", "gradient" or "coils".
    scales : ndarray, shape (k,)
        Load scales (fractions of the field at scale 1), increasing from near 0.
    models : tuple of str
        Subset of :data:`MODELS`.
    rod_options, fem_options : dict
        Keyword arguments for ``solve_rod`` / ``solve_fem``.
    outputs : dict
        ``figures`` and ``tables`` booleans.
    source : str
        Where the scene came from (path or "<embedded>").
    poisson_ratio : float or None
        ``robot.poisson_ratio`` if the scene gives it (also in ``rod.poisson_ratio``, and the
        FEM's; which cannot take 0.5), else None (the Rod's default 0.5 and the FEM's own).
    data : dict or None
        A copy of the TOML data the scene was parsed from (what :func:`coilrod.sweep` varies).
    control : ControlSpec or None
        The ``[control]`` table of a control scene (:mod:`coilrod.scene.control`): then
        ``field_kind`` is "system", ``fields`` is ``{"coils": system}`` (the coil system at
        0 A) and ``scales`` the load path of each forward solve.
    """

    name: str
    rod: Rod
    fields: dict[str, coils.Field]
    field_kind: str
    scales: np.ndarray
    models: tuple[str, ...]
    rod_options: dict = field(default_factory=dict)
    fem_options: dict = field(default_factory=dict)
    outputs: dict = field(default_factory=lambda: {"figures": True, "tables": True})
    description: str = ""
    source: str = "<embedded>"
    poisson_ratio: float | None = None
    data: dict | None = field(default=None, repr=False, compare=False)
    control: ControlSpec | None = None


def _parse_magnetization(data, length, key: str, p: _Problems):
    """The Magnetization of ``robot.magnetization`` (``length`` may be _BAD: then the checks
    that need it are skipped)."""
    data = _table(data, key)
    p.take(
        _unknown_keys,
        data,
        key,
        {"preset", "magnitude", "angle", "elevation", "segments", *_PRESET_KEYS},
    )
    if "preset" in data:
        return _parse_preset(data, length, key, p)
    if "segments" in data:
        for k in ("magnitude", "angle", "elevation", *_PRESET_KEYS):
            if k in data:
                why = (
                    "each segment has its own magnitude, angle and elevation"
                    if k in ("magnitude", "angle", "elevation")
                    else "it is a parameter of the presets"
                )
                p.add(f"{key}.{k}: not used with segments ({why}); remove it")
        return _parse_segments(data["segments"], length, f"{key}.segments", p)
    for k in _PRESET_KEYS:
        if k in data:
            p.add(
                f"{key}.{k}: only used with a preset (one of {', '.join(PRESETS)}); "
                "remove it or give the preset"
            )
    if "magnitude" not in data:
        p.add(
            f"{key}.magnitude: missing required key (a magnetization such as '128 kA/m'; or "
            f"give a preset, one of {', '.join(PRESETS)}, or segments)"
        )
        return _BAD
    magnitude = p.take(_quantity, data, "magnitude", "magnetization", key, kind="magnetization")
    angle = p.take(_quantity, data, "angle", "angle", key, kind="angle", default=0.0)
    elevation = p.take(_quantity, data, "elevation", "angle", key, kind="angle", default=0.0)
    if magnitude is not _BAD and magnitude == 0:
        p.add(
            f"{key}.magnitude: is zero: a rod without magnetization feels no field (nothing "
            "to solve)"
        )
        return _BAD
    if not _ok(magnitude, angle, elevation):
        return _BAD
    return Magnetization(magnitude, angle, elevation, label=f"uniform {magnitude:g} A/m")


def _parse_preset(data: dict, length, key: str, p: _Problems):
    preset = data["preset"]
    for k in ("magnitude", "angle", "elevation", "segments"):
        if k in data:
            p.add(
                f"{key}.{k}: not used with a preset (the preset sets the magnetization, in the "
                "bending plane); give either a preset or magnitude and angle (and elevation) "
                "or segments"
            )
    if not isinstance(preset, str) or preset not in PRESETS:
        p.add(f"{key}.preset: unknown preset {_show(preset)} (one of {', '.join(PRESETS)})")
        return _BAD
    params = PRESET_PARAMETERS[preset]
    for k in _PRESET_KEYS:
        if k in data and k not in params:
            p.add(
                f"{key}.{k}: not a parameter of preset {preset} (its parameters: "
                f"{', '.join(params)})"
            )
    M0 = p.take(
        _quantity,
        data,
        "M0",
        "magnetization",
        key,
        kind="magnetization",
        positive=True,
        default=presets.SEED_M0,
    )
    values: dict[str, Any] = {"M0": M0}
    if "phi" in params:
        values["phi"] = p.take(
            _number,
            data,
            "phi",
            key,
            positive=True,
            high=1.0,
            default=0.2,
            what="a particle volume fraction",
        )
    if "slope" in params:
        values["slope"] = p.take(
            _number,
            data,
            "slope",
            key,
            positive=True,
            high=1.0,
            default=0.4,
            what="the particle fraction at the tip",
        )
    if "segment" in params:
        n_seg = len(presets.EXAMPLE_M41_LAYOUT["fractions"])
        values["segment"] = p.take(
            _number,
            data,
            "segment",
            key,
            integer=True,
            default=-1,
            low=-n_seg,
            high=n_seg - 1,
            what=f"the M(4.x) layout has {n_seg} segments: 0 at the clamp, -1 at the tip",
        )
        values["segment_angle"] = p.take(
            _quantity, data, "segment_angle", "angle", key, kind="angle", default=-math.pi / 4
        )
    if not _ok(*values.values()) or length is _BAD:
        return _BAD
    if preset == "M1":
        return presets.M1(M0=M0, phi=values["phi"])
    if preset in ("M2a", "M2b"):
        return presets.M2(length, variant=preset[-1], M0=M0, phi=values["phi"])
    if preset == "M3":
        return presets.M3(length, M0=M0, slope=values["slope"])
    if preset == "M4.1":
        return presets.M41(length, M0=M0)
    return presets.M42(length, M0=M0, segment=values["segment"], angle=values["segment_angle"])


def _parse_segments(segs, length, key: str, p: _Problems):
    if not isinstance(segs, list) or not segs:
        p.add(
            f"{key}: expected a non-empty list of tables "
            "{ length = '10 mm', magnitude = '64 kA/m', angle = '0 deg', elevation = '0 deg' }"
        )
        return _BAD
    if len(segs) > limits.MAX_SEGMENTS:
        p.add(f"{key}: at most {limits.MAX_SEGMENTS} segments; got {len(segs)}")
        return _BAD
    lengths, mags, angles, elevations = [], [], [], []
    for i, seg in enumerate(segs):
        sk = f"{key}[{i}]"
        seg = p.take(_table, seg, sk)
        if seg is _BAD:
            lengths.append(_BAD)
            continue
        p.take(_unknown_keys, seg, sk, {"length", "magnitude", "angle", "elevation"})
        lengths.append(
            p.take(_quantity, seg, "length", "length", sk, kind="robot length", positive=True)
        )
        mags.append(p.take(_quantity, seg, "magnitude", "magnetization", sk, kind="magnetization"))
        angles.append(p.take(_quantity, seg, "angle", "angle", sk, kind="angle", default=0.0))
        elevations.append(
            p.take(_quantity, seg, "elevation", "angle", sk, kind="angle", default=0.0)
        )
    if not _ok(*lengths, *mags, *angles, *elevations):
        return _BAD
    if length is not _BAD:
        # exact to rounding: each length carries at most two roundings (decimal, unit factor)
        total = math.fsum(lengths)
        if abs(total - length) > 8 * (len(lengths) + 1) * np.finfo(float).eps * length:
            p.add(
                f"{key}: lengths add up to {_mm(total)}; the robot is {_mm(length)} long "
                "(robot.length)"
            )
            return _BAD
    if not any(mags):
        p.add(
            f"{key}: every segment has zero magnitude: a rod without magnetization feels no "
            "field (nothing to solve)"
        )
        return _BAD
    return Magnetization.segments(lengths, mags, angles, elevations, label="custom segments")


def _parse_robot(data, p: _Problems):
    """(Rod, poisson ratio or None), or _BAD."""
    key = "robot"
    data = _table(data, key)
    p.take(
        _unknown_keys,
        data,
        key,
        {
            "length",
            "diameter",
            "width",
            "thickness",
            "youngs_modulus",
            "poisson_ratio",
            "magnetization",
        },
    )
    length = p.take(_quantity, data, "length", "length", key, kind="robot length", positive=True)
    E = p.take(
        _quantity, data, "youngs_modulus", "pressure", key, kind="youngs_modulus", positive=True
    )

    def size(name):
        value = p.take(_quantity, data, name, "length", key, kind="section", positive=True)
        if _ok(value, length) and value >= length:
            p.add(
                f"{key}.{name}: must be smaller than robot.length ({_mm(length)}) for a rod; "
                f"got {data[name]}"
            )
            return _BAD
        return value

    section = _BAD
    if "diameter" in data:
        if "width" in data or "thickness" in data:
            p.add(
                "robot.diameter: give either diameter (circle) or width and "
                "thickness (rectangle), not both"
            )
        else:
            d = size("diameter")
            section = Circle(d) if _ok(d) else _BAD
    elif "width" in data or "thickness" in data:
        w, t = size("width"), size("thickness")
        section = Rectangle(w, t) if _ok(w, t) else _BAD
    else:
        p.add(
            "robot.diameter: missing required key (or width and thickness for a "
            "rectangular section)"
        )
    nu = None
    if "poisson_ratio" in data:
        nu = p.take(
            _number,
            data,
            "poisson_ratio",
            key,
            low=-0.99,
            high=0.5,
            what="0.5 is incompressible",
        )
    if "magnetization" in data:
        mag = p.take(_parse_magnetization, data["magnetization"], length, f"{key}.magnetization", p)
    else:
        p.add(
            "robot.magnetization: missing required key (e.g. { preset = 'M1' } or "
            "{ magnitude = '128 kA/m', angle = '0 deg' })"
        )
        mag = _BAD
    if not _ok(length, E, section, nu, mag):
        return _BAD
    try:
        given = {} if nu is None else {"poisson_ratio": nu}  # else the Rod's default
        return Rod(length, E, section, mag, **given), nu
    except ValueError as exc:  # the library's own checks (e.g. segments spanning the rod)
        p.add(f"{key}: {exc}")
        return _BAD


def _parse_field(data, p: _Problems):
    key = "field"
    data = _table(data, key)
    kind = data.get("type", _MISSING)
    if kind == "uniform":
        p.take(_unknown_keys, data, key, {"type", "B", "direction"})
        B = p.take(_quantity, data, "B", "flux density", key, kind="flux density")
        direction = p.take(_axis, data.get("direction", "y"), f"{key}.direction")
        if not _ok(B, direction):
            return _BAD
        return _FieldInfo({"ideal": coils.UniformField(B * direction)}, "uniform", [], "field.B")
    if kind == "gradient":
        p.take(_unknown_keys, data, key, {"type", "gradient", "axis", "B0", "origin"})
        g = p.take(_quantity, data, "gradient", "gradient", key, kind="gradient")
        axis = p.take(_axis, data.get("axis", "y"), f"{key}.axis")
        B0 = (
            p.take(_vector, data["B0"], "flux density", f"{key}.B0", "flux density")
            if "B0" in data
            else np.zeros(3)
        )
        origin = (
            p.take(_vector, data["origin"], "length", f"{key}.origin", "position")
            if "origin" in data
            else np.zeros(3)
        )
        if not _ok(g, axis, B0, origin):
            return _BAD
        G = g * (np.outer(axis, axis) - 0.5 * (np.eye(3) - np.outer(axis, axis)))
        return _FieldInfo(
            {"ideal": coils.LinearField(B0, G, origin)}, "gradient", [], "field.gradient"
        )
    if kind == "coils":
        p.take(_unknown_keys, data, key, {"type", "coil", "compare_ideal"})
        compare = p.take(_boolean, data, "compare_ideal", key, True)
        parts = data.get("coil", _MISSING)
        if parts is _MISSING:
            p.add(f"{key}.coil: missing required key (a list of coil tables)")
            return _BAD
        problem = _coil_list_problem(parts, key)
        if problem is not None:
            p.add(problem)
            return _BAD
        built = [p.take(_parse_coil, c, f"{key}.coil[{i}]", p) for i, c in enumerate(parts)]
        if not _ok(compare, *built):
            return _BAD
        real = built[0].coil if len(built) == 1 else coils.CoilSystem([b.coil for b in built])
        try:  # the reference strength (and the ideal field) is taken at the coils' centre
            ideal = real.ideal()
        except ValueError as exc:
            p.add(
                f"{key}.coil: the coils' centre ({', '.join(_mm(c) for c in real.center)}), "
                f"where their ideal field is taken, lies on a winding ({exc}); move the coils"
            )
            return _BAD
        fields = {"coils": real}
        if compare:
            fields["ideal"] = ideal
        strength_key = built[0].strength_key if len(built) == 1 else f"{key}.coil"
        return _FieldInfo(fields, "coils", built, strength_key)
    if kind == "system":
        from .control import parse_system

        return parse_system(data, p)
    if kind is _MISSING:
        raise SceneError(f"{key}.type: missing required key ({_FIELD_TYPES})")
    raise SceneError(f"{key}.type: expected {_FIELD_TYPES}; got {_show(kind)}")


def _parse_load(data, p: _Problems):
    key = "load"
    data = _table(data, key)
    p.take(_unknown_keys, data, key, {"steps", "scales", "max_scale"})
    if "scales" in data:
        for k in ("steps", "max_scale"):
            if k in data:
                p.add(f"load.{k}: give either scales or steps and max_scale, not both")
        sc = data["scales"]
        if not isinstance(sc, list) or not sc:
            p.add(f"load.scales: expected a non-empty list of numbers; got {_show(sc)}")
            return _BAD
        if len(sc) > limits.MAX_STEPS:
            p.add(
                f"load.scales: at most {limits.MAX_STEPS} load steps (more would take hours); "
                f"got {len(sc)}"
            )
            return _BAD
        values = [
            p.take(
                _plain,
                v,
                f"load.scales[{i}]",
                low=-limits.MAX_SCALE,
                high=limits.MAX_SCALE,
                what="multiples of the scene's field",
            )
            for i, v in enumerate(sc)
        ]
        if not _ok(*values):
            return _BAD
        if not any(values):
            p.add("load.scales: every scale is 0: the field is never applied (nothing to solve)")
            return _BAD
        return np.array(values, dtype=float)
    steps = p.take(
        _number,
        data,
        "steps",
        key,
        integer=True,
        positive=True,
        default=10,
        low=1,
        high=limits.MAX_STEPS,
        what="load steps; more would take hours",
    )
    top = p.take(
        _number,
        data,
        "max_scale",
        key,
        positive=True,
        default=1.0,
        low=0,
        high=limits.MAX_SCALE,
        what="a multiple of the scene's field",
    )
    if not _ok(steps, top):
        return _BAD
    return top * np.arange(1, steps + 1) / steps


def _parse_models(data, p: _Problems):
    data = _table(data, "models")
    p.take(_unknown_keys, data, "models", {"run"})
    if "run" not in data:
        p.add(f"models.run: missing required key (a list from {list(MODELS)})")
        return _BAD
    run = data["run"]
    if not isinstance(run, list) or not run:
        p.add(f"models.run: expected a non-empty list from {list(MODELS)}; got {_show(run)}")
        return _BAD
    ok = True
    for i, m in enumerate(run):
        if not isinstance(m, str) or m not in MODELS:
            p.add(f"models.run[{i}]: unknown model {_show(m)} (one of {', '.join(MODELS)})")
            ok = False
        elif m in run[:i]:
            p.add(f"models.run[{i}]: {m!r} is listed twice")
            ok = False
    return tuple(run) if ok else _BAD


def _parse_rod_options(data, p: _Problems):
    data = _table(data, "rod")
    p.take(_unknown_keys, data, "rod", {"nodes", "model", "clamp_rotation"})
    out: dict[str, Any] = {}
    if "nodes" in data:
        out["nodes"] = p.take(
            _number,
            data,
            "nodes",
            "rod",
            integer=True,
            low=limits.MIN_NODES,
            high=limits.MAX_NODES,
            what="segments of the rod mesh",
        )
    if "model" in data:
        from ..rod.model import MODELS

        model = data["model"]
        if not isinstance(model, str) or model not in MODELS:
            p.add(f"rod.model: expected one of {list(MODELS)}; got {_show(model)}")
            out["model"] = _BAD
        else:
            out["model"] = model
    if "clamp_rotation" in data:
        out["clamp_rotation"] = p.take(_clamp_rotation, data["clamp_rotation"])
    return out if _ok(*out.values()) else _BAD


def _clamp_rotation(value) -> np.ndarray:
    """``{ axis = [x, y, z], angle = "30 deg" }``: the clamp frame as a rotation matrix."""
    key = "rod.clamp_rotation"
    if not isinstance(value, dict) or set(value) != {"axis", "angle"}:
        raise SceneError(
            f'{key}: expected a table {{ axis = [0, 0, 1], angle = "30 deg" }}; got {_show(value)}'
        )
    axis = value["axis"]
    if (
        not isinstance(axis, list)
        or len(axis) != 3
        or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in axis)
    ):
        raise SceneError(f"{key}.axis: expected 3 numbers, e.g. [0, 0, 1]; got {_show(axis)}")
    axis = np.array(axis, float)
    norm = float(np.linalg.norm(axis))
    if not np.isfinite(norm) or norm == 0.0:
        shown = _show(value["axis"])
        raise SceneError(f"{key}.axis: must be a finite non-zero vector; got {shown}")
    angle = _value(value["angle"], "angle", f"{key}.angle", kind="angle")
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(angle * axis / norm).as_matrix()


def _parse_fem_options(data, p: _Problems):
    data = _table(data, "fem")
    p.take(_unknown_keys, data, "fem", {"order", "elements2d", "elements3d"})
    out: dict[str, Any] = {}
    if "order" in data:
        out["order"] = p.take(
            _number,
            data,
            "order",
            "fem",
            integer=True,
            low=1,
            high=2,
            what="linear or quadratic elements",
        )
    high = max(limits.MAX_FEM_ELEMENTS.values())
    if "elements2d" in data:
        out["elements2d"] = p.take(
            _counts, data["elements2d"], "fem.elements2d", 2, high, "[40, 2]"
        )
    if "elements3d" in data:
        out["elements3d"] = p.take(
            _counts, data["elements3d"], "fem.elements3d", 3, high, "[40, 2, 1]"
        )
    return out if _ok(*out.values()) else _BAD


def _parse_outputs(data, p: _Problems):
    data = _table(data, "output")
    p.take(_unknown_keys, data, "output", {"figures", "tables", "vtk"})
    figures = p.take(_boolean, data, "figures", "output", True)
    tables = p.take(_boolean, data, "tables", "output", True)
    vtk = p.take(_boolean, data, "vtk", "output", False)
    if not _ok(figures, tables, vtk):
        return _BAD
    return {"figures": figures, "tables": tables, "vtk": vtk}


def _parse_control_scene(data: dict, robot, info, scales, models, p: _Problems):
    """The ControlSpec of a control scene, and the keys that do not apply to one."""
    from .control import parse_control

    load = data.get("load", {})
    for k in ("scales", "max_scale"):
        if isinstance(load, dict) and k in load:
            p.add(
                f"load.{k}: not used in a control scene (each forward solve ramps the currents "
                "from zero in load.steps equal steps); give load.steps only"
            )
            scales = _BAD
    if _ok(models):
        for i, m in enumerate(models):
            if m != "rod":
                p.add(
                    f"models.run[{i}]: {m!r} is not used for control (the currents are found "
                    "with the rod model); remove it"
                )
    steps = len(scales) if _ok(scales) else _BAD
    return parse_control(data["control"], robot, info, steps, p)


def _rod_obstacles(data: dict, source: str, robot, models, rod_options, p: _Problems):
    """The rod options checked against the models (a rotated clamp is the rod's alone) with
    the scene's ``[[obstacles]]`` parsed into them (for the straight robot at its first free
    length, its section's half width, along its clamp's tangent); ``_BAD`` where invalid."""
    if _ok(rod_options, models) and "clamp_rotation" in rod_options:
        fem = [m for m in models if m != "rod"]
        if fem:
            p.add(
                f"rod.clamp_rotation: the continuum models ({', '.join(fem)}) clamp the robot "
                "along +x; a rotated clamp applies to rod runs only -- run the rod alone"
            )
            rod_options = _BAD
    if "obstacles" in data and _ok(rod_options, models):
        from .obstacles import parse_obstacles

        if [m for m in models if m != "rod"]:
            p.add("obstacles: contact is modelled by the rod only -- run the rod alone")
        length = robot[0].length if _ok(robot) else None
        if "insertion" in data:  # the robot starts straight at its first free length
            from .navigation import first_length

            length = first_length(data["insertion"]) or length
        half = None
        if _ok(robot):
            sec = robot[0].section
            half = sec.diameter / 2 if hasattr(sec, "diameter") else None
            if hasattr(sec, "width"):
                half = 0.5 * float(np.hypot(sec.width, sec.thickness))
        tangent = None  # the straight robot's direction: +x or the rotated clamp's
        if _ok(rod_options) and "clamp_rotation" in rod_options:
            tangent = np.asarray(rod_options["clamp_rotation"])[:, 0]
        found = p.take(parse_obstacles, data["obstacles"], source, length, half, tangent)
        if _ok(found):
            rod_options = {**rod_options, "obstacles": found[0]}
    return rod_options


def parse_scene(data: dict, source: str = "<embedded>") -> Scene:
    """Validate a scene given as a dict (as read from TOML) and build its objects.

    Every key is checked (type, unit, range, and whether it applies), then the scene as a
    whole (:func:`coilrod.scene.checks.scene_problems`: a non-zero field, a robot clear of the
    coil windings, FEM meshes that resolve the magnetization and fit the limits).

    Parameters
    ----------
    data : dict
        The scene, as :func:`tomllib.loads` returns it.
    source : str
        Where the scene came from (a path, or "<embedded>"); its stem is the default name.

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        Listing every problem found, one line each (``problems``).

    Examples
    --------
    >>> scene = parse_scene({
    ...     "robot": {"length": "40 mm", "diameter": "2 mm", "youngs_modulus": "1 MPa",
    ...               "magnetization": {"preset": "M1"}},
    ...     "field": {"type": "uniform", "B": "5 mT"},
    ...     "load": {"steps": 4}})
    >>> scene.scales.tolist(), scene.models
    ([0.25, 0.5, 0.75, 1.0], ('rod',))
    >>> try:
    ...     parse_scene({"robot": {"length": "-40 mm"}, "field": {"type": "uniform"}})
    ... except SceneError as exc:
    ...     print(exc)
    robot.length: must be positive; got -40 mm
    robot.youngs_modulus: missing required key (pressure, e.g. '1 MPa')
    robot.diameter: missing required key (or width and thickness for a rectangular section)
    robot.magnetization: missing required key (e.g. { preset = 'M1' } or { magnitude = '128 kA/m', angle = '0 deg' })
    field.B: missing required key (flux density, e.g. '5 mT')
    """  # noqa: E501
    p = _Problems()
    data = _table(data, "scene")
    p.take(
        _unknown_keys,
        data,
        "",
        {
            "name",
            "description",
            "robot",
            "field",
            "load",
            "models",
            "rod",
            "fem",
            "output",
            "control",
            "obstacles",
            "insertion",
        },
    )
    name = p.take(_text, data, "name", "", Path(source).stem)
    description = p.take(_text, data, "description", "", "")
    robot = _BAD
    if "robot" in data:
        robot = p.take(_parse_robot, data["robot"], p)
    else:
        p.add("robot: missing required table (length, diameter, youngs_modulus, magnetization)")
    info = _BAD
    if "field" in data:
        info = p.take(_parse_field, data["field"], p)
    else:
        p.add(f"field: missing required table (type = {_FIELD_TYPES})")
    scales = p.take(_parse_load, data.get("load", {}), p)
    models = p.take(_parse_models, data.get("models", {"run": ["rod"]}), p)
    rod_options = p.take(_parse_rod_options, data.get("rod", {}), p)
    rod_options = _rod_obstacles(data, source, robot, models, rod_options, p)
    if "insertion" in data:
        from .navigation import check_insertion

        rod_options = p.take(check_insertion, data, robot, rod_options, models)
    fem_options = p.take(_parse_fem_options, data.get("fem", {}), p)
    outputs = p.take(_parse_outputs, data.get("output", {}), p)
    control = None
    if "control" in data:
        control = p.take(_parse_control_scene, data, robot, info, scales, models, p)
    elif _ok(info) and info.kind == "system":
        p.add(
            "control: missing required table (e.g. target = ['20 mm', '30 mm']): a coil system "
            "(field.type = 'system') has no currents until [control] finds them for a target"
        )
    if p.lines or not _ok(robot, info, scales, models, rod_options, fem_options, outputs, control):
        raise SceneError(p.lines or ["scene: invalid"])
    rod, nu = robot
    scene = Scene(
        name=name,
        rod=rod,
        fields=info.fields,
        field_kind=info.kind,
        scales=scales,
        models=models,
        rod_options=rod_options,
        fem_options=fem_options,
        outputs=outputs,
        description=description,
        source=source,
        poisson_ratio=nu,
        data=copy.deepcopy(data),
        control=control,
    )
    from .checks import scene_problems

    problems = scene_problems(scene, coil_keys=info.coils, strength_key=info.strength_key)
    if problems:
        raise SceneError(problems)
    return scene


def load_scene(path: str | Path) -> Scene:
    """Read and validate a TOML scene file.

    Parameters
    ----------
    path : str or Path
        A UTF-8 TOML file.

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        If the file cannot be read (missing, a directory, no permission, not UTF-8), is not
        valid TOML, or fails validation; one line per problem, each naming the file or the key
        (a validation error's ``source`` is the file, and its message ends with a line naming
        it).
    """
    path = Path(path)
    if path.is_dir():
        raise SceneError(f"{path}: is a directory, not a scene file (give a .toml file)")
    text = read_utf8(
        path,
        unreadable="{path}: cannot read the scene file ({reason})",
        not_utf8="{path}: not UTF-8 text (byte {byte} on line {line}); save the scene file as "
        "UTF-8",
        unreadable_error=SceneError,
        not_utf8_error=SceneError,
    )
    try:
        data = tomllib.loads(text)
    except ValueError as exc:  # TOMLDecodeError, or an integer too long for Python
        raise SceneError(f"{path}: not valid TOML ({exc})") from None
    if not data:
        raise SceneError(
            f"{path}: the scene file is empty (no keys); see 'coilrod scenes --show NAME' for "
            "a complete one"
        )
    try:
        return parse_scene(data, source=str(path))
    except SceneError as exc:  # name the file (the key of each problem is relative to it)
        raise SceneError(exc.problems, source=str(path)) from None
