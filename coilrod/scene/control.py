"""Control scenes: a coil system under current control and the tip target its currents must meet.

A control scene drives a coil system (``[field] type = "system"``) and says where the tip
should go (``[control]``)::

    [field]
    type = "system"
    preset = "three_axis_helmholtz"      # a preset of coils.presets, and/or
    coil = [ { type = "maxwell", radius = "240 mm", turns = 500, axis = "y" } ]

    [control]
    target = ["20 mm", "30 mm"]          # tip (x, y) in the bending plane, or (x, y, z)
    angle = "60 deg"                     # optional: the tip angle too (a target (x, y))
    direction = [0, 0.6, 0.8]            # optional: the tip direction (a target (x, y, z))
    model = "both"                       # "real", "ideal" or "both" (default)
    max_current = "5 A"                  # optional: one limit, or one per channel

Every channel -- each pair or coil of the preset, each listed coil or pair -- carries one
current, and the currents are what the scene finds (:func:`coilrod.solve_currents`): a coil of
a system therefore has no ``current``, ``B`` or ``gradient`` (an error says so), and may give
``wire_diameter`` (copper: its resistance weighs the minimum-power currents and gives the
power).  The preset's own arguments (``radii``, ``turns``, ``max_current``, ...) may follow the
preset, with units, as they follow a magnetization preset.  Limits: a preset's channels are
rated (its ``max_current``); ``control.max_current`` may lower them, not raise them, and is
required when listed coils (which have no rating) are driven.

A 3D target (x, y, z) -- for a system whose channels make every field direction at its
centre (three-axis Helmholtz, the eight-coil hemisphere, the eMNS presets) -- is steered on
the spatial rod; ``direction`` (three plain numbers: a vector along the wanted tip tangent,
normalised, so ``[0, 1, 1]`` is fine) adds the tip direction to it.  A 3D target with a
system that makes no B_z at its centre (e.g. helmholtz_maxwell), a direction with a target
(x, y), an angle with a target (x, y, z), or a direction that is not three finite numbers
with a non-zero length is an error naming the key.

``model = "real"`` finds the currents in the real (Biot-Savart) field; ``"ideal"`` is the usual
controller, which takes the system's field and gradient at its centre for the field over the
robot, and whose currents are then applied to the real field (its miss says how far off that
puts the tip); ``"both"`` runs the two.  The load path of each forward solve ramps the currents
from zero in ``load.steps`` equal steps; ``rod.nodes`` sets the rod mesh.  The rod model is the
only one used: FEM models (``models.run``) are an error in a control scene.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

import coils

from .tables import (
    _BAD,
    _MISSING,
    SceneError,
    _axis,
    _Coil,
    _coil_list_problem,
    _FieldInfo,
    _mm,
    _ok,
    _parse_coil,
    _plain,
    _Problems,
    _show,
    _table,
    _unknown_keys,
    _value,
    _vector,
)

__all__ = ["ControlSpec", "SYSTEM_PRESETS", "CONTROL_MODELS", "parse_system", "parse_control"]

#: The coil-system presets of :mod:`coils.presets` a scene may name, with the parameters each
#: takes (besides ``preset``), as in the preset functions.
SYSTEM_PRESETS = {
    "three_axis_helmholtz": (
        "radii",
        "turns",
        "max_current",
        "wire_diameter",
        "winding",
        "center",
    ),
    "helmholtz_maxwell": (
        "radii",
        "turns",
        "max_current",
        "maxwell_radius",
        "maxwell_turns",
        "maxwell_max_current",
        "maxwell_axis",
        "wire_diameter",
        "winding",
        "center",
    ),
    "eight_coil_hemisphere": (
        "distance",
        "radius",
        "turns",
        "max_current",
        "wire_diameter",
        "winding",
        "center",
    ),
    # calibrated eMNS models (coils.MPEM): their own coils' limits only
    "cardiomag": ("max_current",),
    "navion": ("max_current",),
    "octomag": ("max_current",),
}
#: The presets that are calibrated eMNS models (:class:`coils.MPEM`: point-dipole sources, no
#: windings; no listed coils may join them).
EMNS_PRESETS = ("cardiomag", "navion", "octomag")
_PRESET_ARGS = tuple(dict.fromkeys(a for args in SYSTEM_PRESETS.values() for a in args))
#: Channels of each preset (the length of a per-channel list such as ``max_current``).
_PRESET_CHANNELS = {
    "three_axis_helmholtz": 3,
    "helmholtz_maxwell": 3,
    "eight_coil_hemisphere": 8,
    "cardiomag": 8,
    "navion": 3,
    "octomag": 8,
}
#: ``control.model`` -> the controllers run.
CONTROL_MODELS = {"real": ("real",), "ideal": ("ideal",), "both": ("real", "ideal")}


@dataclass
class ControlSpec:
    """The ``[control]`` table of a validated scene.

    Attributes
    ----------
    target : ndarray, shape (2,) or (3,)
        Target tip position (x, y) in the bending plane, or (x, y, z), m.
    angle : float or None
        Target tip angle, rad (None: the position only; a target (x, y) only).
    models : tuple of str
        The controllers to run, from ("real", "ideal").
    max_current : ndarray, shape (m,)
        Current limit of each channel, A (finite).
    steps : int
        Load steps of each forward solve (the currents ramped from zero).
    system : str
        What the coil system is, in words (for the plan and the summary).
    direction : ndarray, shape (3,), or None
        Target unit tip tangent (a target (x, y, z) only; None: the position only).
    """

    target: np.ndarray
    angle: float | None
    models: tuple[str, ...]
    max_current: np.ndarray
    steps: int
    system: str
    direction: np.ndarray | None = None

    @property
    def spatial(self) -> bool:
        """A 3D target (x, y, z): the spatial rod."""
        return self.target.size == 3


# -- the coil system ([field] type = "system") ---------------------------------------------------
def _length(raw, full, kind="coil size"):
    return _value(raw, "length", full, kind=kind, positive=True)


def _turns(raw, full):
    return _plain(raw, full, integer=True, positive=True, high=1e6, what="turns of one coil")


def _current(raw, full):
    return _value(raw, "current", full, kind="current", positive=True)


def _one_or_list(raw, full: str, one, n: int, what: str):
    """One value (applies to every entry) or a list of ``n``, each read by ``one(raw, key)``."""
    if isinstance(raw, list):
        if len(raw) != n:
            raise SceneError(
                f"{full}: expected one value or a list of {n} ({what}); got a list of {len(raw)}"
            )
        return _each(raw, full, one)
    return one(raw, full)


def _each(items: list, full: str, one) -> tuple:
    """Every entry of ``items`` read by ``one(raw, key)``; all problems reported together."""
    p = _Problems()
    out = [p.take(one, v, f"{full}[{i}]") for i, v in enumerate(items)]
    if p.lines:
        raise SceneError(p.lines)
    return tuple(out)


def _winding(raw, full):
    if not isinstance(raw, list) or len(raw) != 2:
        raise SceneError(
            f"{full}: expected ['width', 'height'], e.g. ['28 mm', '28 mm']; got {_show(raw)}"
        )
    return _each(raw, full, _length)


def _preset_argument(name: str, raw, full: str, preset: str):
    n = _PRESET_CHANNELS[preset]
    pairs = preset in ("three_axis_helmholtz", "helmholtz_maxwell")
    per = "x, y, z pairs" if pairs else f"one per coil, {n} coils"
    if name == "radii":
        return _one_or_list(raw, full, _length, 3, "radius of the x, y, z pairs")
    if name == "turns":
        if preset == "eight_coil_hemisphere":
            return _turns(raw, full)
        return _one_or_list(raw, full, _turns, 3, "turns of the x, y, z pairs")
    if name == "max_current":
        return _one_or_list(raw, full, _current, n, per)
    if name in ("maxwell_radius", "distance", "radius", "wire_diameter"):
        return _length(raw, full)
    if name == "maxwell_turns":
        return _turns(raw, full)
    if name == "maxwell_max_current":
        return _current(raw, full)
    if name == "maxwell_axis":
        return _axis(raw, full)
    if name == "winding":
        return _winding(raw, full)
    if name == "center":
        return _vector(raw, "length", full, "position")
    raise AssertionError(name)  # pragma: no cover - SYSTEM_PRESETS lists only these


def _preset_geometry(preset: str, args: dict, p: _Problems) -> bool:
    """The preset's own geometric conditions, in the scene's words (True: they hold)."""
    if preset == "helmholtz_maxwell" and "maxwell_radius" in args:
        radii = args.get("radii", (0.100, 0.140, 0.180))
        largest = max(radii) if isinstance(radii, tuple) else radii
        if args["maxwell_radius"] <= largest:
            p.add(
                f"field.maxwell_radius: must exceed the largest Helmholtz radius "
                f"({_mm(largest)}): the Maxwell coils sit outside the pairs; got "
                f"{_mm(args['maxwell_radius'])}"
            )
            return False
    if preset == "eight_coil_hemisphere":
        distance, radius = args.get("distance", 0.200), args.get("radius", 0.060)
        if radius >= distance:
            key = "radius" if "radius" in args else "distance"
            p.add(
                f"field.{key}: the coil radius ({_mm(radius)}) must be below the distance of "
                f"the coils from the centre ({_mm(distance)})"
            )
            return False
    return True


def _build_preset(preset: str, args: dict, p: _Problems):
    fn = getattr(coils.presets, preset)
    try:
        return fn(**args)
    except ValueError as exc:  # the preset's own checks: name the argument they are about
        text = str(exc)
        name = next(
            (a for a in sorted(args, key=len, reverse=True) if re.match(rf"{a}\b", text)),
            None,
        )
        p.add(f"field.{name or 'preset'}: {text}")
        return _BAD


def _channel_label(i: int, kind: str, coil) -> str:
    axis = np.asarray(coil.axis, float)
    for k, letter in enumerate("xyz"):
        if abs(axis[k]) == 1.0:
            return f"coil[{i}] {kind} {'+' if axis[k] > 0 else '-'}{letter}"
    return f"coil[{i}] {kind} ({', '.join(f'{v:.3g}' for v in axis)})"


def _emns_system(preset: str, args: dict, built: list, p: _Problems):
    """The _FieldInfo of a calibrated eMNS preset (:class:`coils.MPEM`), or _BAD: no listed
    coils join it (its channels are a fitted model's, not windings), and a model without a
    rating of its own (octomag) needs ``max_current``.  No clearance entries: the model has
    no windings (its sources lie outside the calibrated workspace; a point on one is refused
    when the field is evaluated)."""
    if built:
        p.add(
            f"field.coil: the preset {preset} is a calibrated eMNS model (coils.MPEM: fitted "
            "point-dipole sources, no windings); listed coils cannot join its channels -- "
            "remove the coil list or use an air-coil preset"
        )
        return _BAD
    if preset == "octomag" and "max_current" not in args:
        p.add(
            "field.max_current: missing required key: the preset octomag is a model, not a "
            "built system, and has no current rating; give one for every coil (e.g. '20 A') "
            "or a list of 8"
        )
        return _BAD
    if isinstance(args.get("max_current"), tuple):
        args = args | {"max_current": np.asarray(args["max_current"], float)}
    system = _build_preset(preset, args, p)
    if system is _BAD:
        return _BAD
    info = _FieldInfo({"coils": system}, "system", [], "field.preset")
    info.label = f"preset {preset} (calibrated eMNS model, {len(system.channels)} coils)"
    return info


def parse_system(data: dict, p: _Problems):
    """The coil system of ``[field] type = "system"`` (a preset and/or a coil list), as the
    _FieldInfo of :func:`coilrod.scene.parse.parse_scene` (``fields = {"coils": system}``, one
    clearance entry per channel); _BAD if invalid (the problems are in ``p``)."""
    key = "field"
    preset = data.get("preset", _MISSING)
    if preset is not _MISSING and not (isinstance(preset, str) and preset in SYSTEM_PRESETS):
        p.add(
            f"{key}.preset: unknown coil-system preset {_show(preset)} (one of "
            f"{', '.join(SYSTEM_PRESETS)})"
        )
        preset = _BAD
    params = SYSTEM_PRESETS.get(preset, ()) if _ok(preset) and preset is not _MISSING else ()
    p.take(_unknown_keys, data, key, {"type", "preset", "coil", *params, *_PRESET_ARGS})
    args: dict[str, Any] = {}
    for name in _PRESET_ARGS:
        if name not in data:
            continue
        if preset is _MISSING:
            p.add(
                f"{key}.{name}: only used with a preset (one of {', '.join(SYSTEM_PRESETS)}); "
                "remove it or give the preset"
            )
            args[name] = _BAD  # the system is not what the scene meant: no checks against it
        elif _ok(preset) and name not in params:
            p.add(
                f"{key}.{name}: not a parameter of preset {preset} (its parameters: "
                f"{', '.join(params)})"
            )
            args[name] = _BAD
        elif _ok(preset):
            args[name] = p.take(_preset_argument, name, data[name], f"{key}.{name}", preset)
    parts = data.get("coil", _MISSING)
    built = []
    if parts is _MISSING:
        if preset is _MISSING:
            p.add(
                f"{key}.preset: missing required key: a coil system is a preset (one of "
                f"{', '.join(SYSTEM_PRESETS)}) and/or a coil list (coil = [...])"
            )
            return _BAD
    elif (problem := _coil_list_problem(parts, key)) is not None:
        p.add(problem)
        return _BAD
    else:
        built = [
            p.take(_parse_coil, c, f"{key}.coil[{i}]", p, control=True) for i, c in enumerate(parts)
        ]
    if not _ok(preset, *args.values(), *built):
        return _BAD
    if preset in EMNS_PRESETS:
        return _emns_system(preset, args, built, p)
    channels, names, keys, what = [], [], [], []
    system = None
    if preset is not _MISSING:
        if not _preset_geometry(preset, args, p):
            return _BAD
        system = _build_preset(preset, args, p)
        if system is _BAD:
            return _BAD
        channels.append(system)
        names += system.names
        keys += [
            _Coil("field.preset", ch, "field.preset", what=f"channel '{nm}' of the preset")
            for ch, nm in zip(system.channels, system.names, strict=True)
        ]
        what.append(f"preset {preset}")
    for i, (b, table) in enumerate(zip(built, parts if built else [], strict=True)):
        channels.append(b.coil)
        names.append(_channel_label(i, table["type"], b.coil))
        keys.append(b)
    if built:
        what.append(f"{len(built)} listed coil{'s' if len(built) > 1 else ''}")
    if system is None or built:
        center = system.center if system is not None else None
        try:
            system = coils.CoilSystem(channels, center=center, names=names)
        except ValueError as exc:  # pragma: no cover - the parts were validated one by one
            p.add(f"{key}: {exc}")
            return _BAD
    strength_key = f"{key}.preset" if preset is not _MISSING and not built else f"{key}.coil"
    info = _FieldInfo({"coils": system}, "system", keys, strength_key)
    info.label = " and ".join(what)
    return info


# -- the [control] table ----------------------------------------------------------------------
def _target(raw, full: str) -> np.ndarray:
    if not isinstance(raw, list) or len(raw) not in (2, 3):
        raise SceneError(
            f"{full}: expected a list of 2 lengths (the tip's x and y in the bending plane), "
            f"e.g. ['20 mm', '30 mm'], or of 3 (x, y, z), e.g. ['20 mm', '25 mm', '10 mm']; "
            f"got {_show(raw)}"
        )
    p = _Problems()
    out = [p.take(_value, v, "length", f"{full}[{i}]", kind="position") for i, v in enumerate(raw)]
    if p.lines:
        raise SceneError(p.lines)
    return np.array(out, dtype=float)


def _direction(raw, full: str) -> np.ndarray:
    """control.direction: three plain numbers along the tip tangent, normalised (not zero)."""
    if not isinstance(raw, list) or len(raw) != 3:
        raise SceneError(
            f"{full}: expected a list of 3 numbers (a vector along the tip tangent, x, y, z; "
            f"normalised), e.g. [0, 0.6, 0.8]; got {_show(raw)}"
        )
    p = _Problems()
    out = [p.take(_plain, v, f"{full}[{i}]") for i, v in enumerate(raw)]
    if p.lines:
        raise SceneError(p.lines)
    v = np.array(out, dtype=float)
    norm = float(np.linalg.norm(v))
    if not norm > 0.0 or not math.isfinite(norm):
        raise SceneError(f"{full}: must have a non-zero length (a direction); got {_show(raw)}")
    return v / norm


def _makes_3d(system) -> int | None:
    """Rank of the system's centre field per ampere (3: every field direction), or None if
    it cannot be evaluated there (the checks report a centre on a winding)."""
    try:
        B, _ = system.unit_fields(np.asarray(system.center, float)[None])
    except ValueError:
        return None
    B = B[0]
    if not np.all(np.isfinite(B)):
        return None
    return int(np.linalg.matrix_rank(B, tol=1e-12 * max(float(np.abs(B).max()), 1e-300)))


def _limits(raw, info, m: int):
    """control.max_current: one limit or one per channel (A), at most each channel's rating."""
    full = "control.max_current"
    if isinstance(raw, list):
        if len(raw) != m:
            raise SceneError(
                f"{full}: expected one current or a list of {m} (one per channel: "
                f"{', '.join(info.fields['coils'].names)}); got a list of {len(raw)}"
            )
        p = _Problems()
        values = [p.take(_current, v, f"{full}[{j}]") for j, v in enumerate(raw)]
        if p.lines:
            raise SceneError(p.lines)
        keys = [f"{full}[{j}]" for j in range(m)]
        shown = list(raw)
    else:
        values = [_current(raw, full)] * m
        keys = [full] * m
        shown = [raw] * m
    system = info.fields["coils"]
    rating = system.max_current
    over: dict[str, list[int]] = {}  # key -> the channels whose rating it exceeds
    for j in range(m):
        if values[j] > rating[j] * (1 + 1e-12):
            over.setdefault(keys[j], []).append(j)
    problems = []
    for k, channels in over.items():
        which = ", ".join(system.names[j] for j in channels)
        ratings = ", ".join(f"{rating[j]:g}" for j in channels)
        plural = "s" if len(channels) > 1 else ""
        problems.append(
            f"{k}: {shown[channels[0]]} is above the rating of the channel{plural} {which} "
            f"({ratings} A; the preset's max_current): a scene may lower a limit, not raise it"
        )
    if problems:
        raise SceneError(problems)
    return np.array(values, dtype=float)


def parse_control(data, robot, info, steps, p: _Problems):
    """The ControlSpec of the ``[control]`` table, or _BAD (problems in ``p``).

    ``robot`` ((Rod, nu) or _BAD), ``info`` (the field's _FieldInfo or _BAD) and ``steps`` (the
    load steps or _BAD) are those parsed before; checks that need an invalid one are skipped.
    """
    key = "control"
    data = _table(data, key)
    p.take(_unknown_keys, data, key, {"target", "angle", "direction", "model", "max_current"})
    if "target" in data:
        target = p.take(_target, data["target"], f"{key}.target")
    else:
        p.add(
            f"{key}.target: missing required key (the tip's x and y in the bending plane, e.g. "
            "['20 mm', '30 mm'], or x, y, z)"
        )
        target = _BAD
    angle = None
    if "angle" in data:
        angle = p.take(_value, data["angle"], "angle", f"{key}.angle", kind="angle")
    direction = None
    if "direction" in data:
        direction = p.take(_direction, data["direction"], f"{key}.direction")
    if _ok(target):
        if target.size == 3 and "angle" in data:
            p.add(
                f"{key}.angle: a tip angle is for a target (x, y) in the bending plane; the "
                "target is (x, y, z): give direction (the tip tangent) instead"
            )
            angle = _BAD
        if target.size == 2 and "direction" in data:
            p.add(
                f"{key}.direction: a tip direction is for a target (x, y, z); the target is "
                "(x, y) in the bending plane: give angle instead, or the target's z"
            )
            direction = _BAD
    model = data.get("model", "both")
    if not isinstance(model, str) or model not in CONTROL_MODELS:
        p.add(f"{key}.model: expected 'real', 'ideal' or 'both'; got {_show(model)}")
        model = _BAD
    system_ok = _ok(info) and info.kind == "system"
    if _ok(info) and info.kind != "system":
        p.add(
            f"field.type: a control scene drives a coil system: give type = 'system' (a preset "
            f"and/or a coil list whose currents [control] finds); got {_show(info.kind)}"
        )
    limit = _BAD
    if system_ok:
        system = info.fields["coils"]
        m = system.currents.size
        if "max_current" in data:
            limit = p.take(_limits, data["max_current"], info, m)
        elif not np.all(np.isfinite(system.max_current)):
            rated = zip(system.names, system.max_current, strict=True)
            unrated = [name for name, r in rated if r == np.inf]
            p.add(
                f"{key}.max_current: missing required key: the channels {', '.join(unrated)} "
                "have no current limit of their own; give one for every channel (e.g. "
                f"'10 A') or a list of {m}"
            )
        else:
            limit = system.max_current
        if _ok(target) and target.size == 3 and (rank := _makes_3d(system)) is not None:
            if rank < 3:
                p.add(
                    f"{key}.target: a 3D target (x, y, z) needs a system whose channels make "
                    f"every field direction at its centre; the centre field per ampere of "
                    f"{info.label} has rank {rank} (a planar-only system) -- give the target "
                    "(x, y) in the bending plane, or a system such as three_axis_helmholtz"
                )
                target = _BAD
    if _ok(target, robot):
        L = robot[0].length
        d = math.hypot(*target)
        if d > L * (1 + 1e-12):
            p.add(
                f"{key}.target: ({', '.join(_mm(v) for v in target)}) is {_mm(d)} from the "
                f"clamp, beyond the robot's length ({_mm(L)}, robot.length): no tip reaches it"
            )
            target = _BAD
    if not _ok(target, angle, direction, model, limit, steps) or not system_ok:
        return _BAD
    return ControlSpec(
        target=target,
        angle=angle,
        models=CONTROL_MODELS[model],
        max_current=np.asarray(limit, dtype=float),
        steps=int(steps),
        system=info.label,
        direction=direction,
    )
