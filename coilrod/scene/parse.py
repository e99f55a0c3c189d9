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
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

import coils

from ..robot import presets
from ..robot.magnetization import Magnetization
from ..robot.rod import Rod
from ..robot.sections import Circle, Rectangle
from . import limits
from .units import EXAMPLES, UnitError, parse_quantity, short_int

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
_COIL_TYPES = {"helmholtz": coils.HelmholtzPair, "maxwell": coils.MaxwellPair, "coil": coils.Coil}
_COIL_NAMES = {"helmholtz": "Helmholtz pair", "maxwell": "Maxwell pair", "coil": "single coil"}
_FIELD_TYPES = "'uniform', 'gradient', 'coils' or 'system'"


#: Longest problem line (a value pasted by mistake is cut, not printed in full).
_MAX_LINE = 400


class SceneError(ValueError):
    """A scene is invalid.

    Parameters
    ----------
    problems : str or list of str
        One problem (``"key: reason"``) or several; each is kept on one line (whitespace runs
        become single spaces, lines beyond 400 characters are cut).

    Attributes
    ----------
    problems : list of str
        Every problem found, one line each, in the order of the scene.  The message is these
        lines joined by newlines.

    Examples
    --------
    >>> err = SceneError(["robot.length: must be positive; got -40 mm", "load.steps: ..."])
    >>> err.problems[0]
    'robot.length: must be positive; got -40 mm'
    >>> len(str(err).splitlines())
    2
    """

    def __init__(self, problems: str | list[str]):
        if isinstance(problems, str):
            problems = [problems]
        lines = [" ".join(str(p).split()) for p in problems]
        lines = [ln if len(ln) <= _MAX_LINE else ln[: _MAX_LINE - 6] + " [...]" for ln in lines]
        self.problems = list(dict.fromkeys(line for line in lines if line))
        super().__init__("\n".join(self.problems))

    def __reduce__(self):
        return (type(self), (self.problems,))


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


# -- collecting problems -------------------------------------------------------------------------
class _Bad:
    """Marks a value that failed validation (its problem is already recorded)."""

    def __repr__(self):
        return "<invalid>"


_BAD = _Bad()
_MISSING = object()


def _ok(*values) -> bool:
    return not any(v is _BAD for v in values)


class _Problems:
    """The problems found so far; ``take`` runs a validator and records its SceneError."""

    def __init__(self):
        self.lines: list[str] = []

    def add(self, line: str) -> None:
        self.lines.append(line)

    def take(self, fn, *args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except SceneError as exc:
            self.lines.extend(exc.problems)
            return _BAD


# -- small validators (each raises a SceneError naming the key) ----------------------------------
def _table(data: Any, key: str) -> dict:
    if not isinstance(data, dict):
        raise SceneError(f"{key}: expected a table; got {_show(data)}")
    return data


def _unknown_keys(data: dict, key: str, allowed) -> None:
    unknown = sorted(set(data) - set(allowed), key=str)
    if unknown:
        where = f"{key}." if key else ""
        raise SceneError(
            [
                f"{where}{u}: unknown key (allowed here: {', '.join(sorted(allowed))})"
                for u in unknown
            ]
        )


def _show(value) -> str:
    """A value as the user wrote it, for messages (TOML spelling of booleans, long integers
    shortened)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, int) and abs(value) >= 10**15:
        return short_int(value)
    return repr(value)


def _in_range(value: float, kind: str, full: str, raw) -> float:
    rng = limits.RANGES[kind]
    size = abs(value)
    if size > rng.high or (rng.low > 0 and size < rng.low):
        raise SceneError(f"{full}: must be {rng.text} ({rng.why}); got {raw}")
    return value


def _quantity(
    data: dict,
    name: str,
    dimension: str,
    key: str,
    *,
    kind: str,
    positive: bool = False,
    default=_MISSING,
) -> float:
    full = f"{key}.{name}"
    if name not in data:
        if default is _MISSING:
            raise SceneError(
                f"{full}: missing required key ({dimension}, e.g. '{EXAMPLES[dimension]}')"
            )
        return default
    return _value(data[name], dimension, full, kind=kind, positive=positive)


def _value(raw, dimension: str, full: str, *, kind: str, positive: bool = False) -> float:
    """One quantity with its unit, in SI, checked against the range of ``kind``."""
    value = _si(raw, dimension, full)
    if positive and value <= 0:
        raise SceneError(f"{full}: must be positive; got {raw}")
    return _in_range(value, kind, full, raw)


def _number(
    data: dict,
    name: str,
    key: str,
    *,
    positive: bool = False,
    integer: bool = False,
    default=_MISSING,
    low=None,
    high=None,
    what: str = "",
) -> float:
    full = f"{key}.{name}"
    if name not in data:
        if default is _MISSING:
            raise SceneError(f"{full}: missing required key")
        return default
    return _plain(
        data[name], full, positive=positive, integer=integer, low=low, high=high, what=what
    )


def _plain(value, full, *, positive=False, integer=False, low=None, high=None, what=""):
    """A plain number (no unit): type, finiteness, integrality and range."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        kind = "an integer" if integer else "a number"
        raise SceneError(f"{full}: expected {kind}; got {_show(value)}")
    if isinstance(value, float) and not math.isfinite(value):
        raise SceneError(f"{full}: must be finite; got {value!r}")
    if integer and int(value) != value:
        raise SceneError(f"{full}: expected an integer; got {value!r}")
    if positive and value <= 0:
        raise SceneError(f"{full}: must be positive; got {_show(value)}")
    if (low is not None and value < low) or (high is not None and value > high):
        lo = "" if low is None else f"{low:g}"
        hi = "" if high is None else f"{high:g}"
        span = f"from {lo} to {hi}" if lo and hi else (f"at least {lo}" if lo else f"at most {hi}")
        raise SceneError(
            f"{full}: must be {span}{f' ({what})' if what else ''}; got {_show(value)}"
        )
    return int(value) if integer else float(value)


def _boolean(data: dict, name: str, key: str, default: bool) -> bool:
    full = f"{key}.{name}"
    value = data.get(name, default)
    if not isinstance(value, bool):
        raise SceneError(
            f"{full}: expected true or false (a TOML boolean, without quotes); got {_show(value)}"
        )
    return value


def _text(data: dict, name: str, key: str, default: str) -> str:
    full = f"{key}.{name}" if key else name
    value = data.get(name, default)
    if not isinstance(value, str):
        raise SceneError(f"{full}: expected a string; got {_show(value)}")
    return value


_AXIS_RE = re.compile(r"^\s*([+-]?)\s*([xyz])\s*$", re.IGNORECASE)
_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


def _axis(value, key: str) -> np.ndarray:
    """A unit vector from 'x', 'y', 'z' with an optional sign, or a list of 3 numbers."""
    hint = "expected 'x', 'y', 'z' (optionally signed, e.g. '-x') or a list of 3 numbers"
    if isinstance(value, str):
        match = _AXIS_RE.match(value)
        if not match:
            raise SceneError(f"{key}: {hint}; got {value!r}")
        sign = -1.0 if match[1] == "-" else 1.0
        return sign * np.array(_AXES[match[2].lower()])
    if (
        isinstance(value, list)
        and len(value) == 3
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
    ):
        if any(isinstance(v, int) and abs(v) > 10**15 for v in value):
            raise SceneError(f"{key}: the components must be numbers of moderate size")
        vec = np.array(value, dtype=float)
        if not np.all(np.isfinite(vec)):
            raise SceneError(f"{key}: the components must be finite; got {value!r}")
        norm = float(np.linalg.norm(vec))
        if norm == 0:
            raise SceneError(f"{key}: a direction cannot be the zero vector")
        return vec / norm
    raise SceneError(f"{key}: {hint}; got {_show(value)}")


def _si(value, dimension: str, key: str) -> float:
    """``parse_quantity`` with its UnitError reported as a SceneError (same message)."""
    try:
        return parse_quantity(value, dimension, key)
    except UnitError as exc:
        raise SceneError(str(exc)) from None


def _vector(value, dimension: str, key: str, kind: str) -> np.ndarray:
    if not isinstance(value, list) or len(value) != 3:
        unit = EXAMPLES[dimension].split()[1]
        raise SceneError(
            f"{key}: expected a list of 3 quantities, e.g. ['0 {unit}', '0 {unit}', '0 {unit}']; "
            f"got {_show(value)}"
        )
    p = _Problems()
    out = [p.take(_value, v, dimension, f"{key}[{i}]", kind=kind) for i, v in enumerate(value)]
    if p.lines:
        raise SceneError(p.lines)
    return np.array(out)


def _counts(value, key: str, n: int, high: int, example: str) -> tuple[int, ...]:
    """A list of ``n`` positive integers, each at most ``high``."""
    if not isinstance(value, list) or len(value) != n:
        raise SceneError(
            f"{key}: expected a list of {n} positive integers, e.g. {example}; got {_show(value)}"
        )
    p = _Problems()
    out = [
        p.take(_plain, v, f"{key}[{i}]", integer=True, positive=True, high=high)
        for i, v in enumerate(value)
    ]
    if p.lines:
        raise SceneError(p.lines)
    return tuple(out)


def _mm(x: float) -> str:
    return f"{1e3 * x:.12g} mm"


# -- sections of the scene ---------------------------------------------------------------------
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


@dataclass
class _Coil:
    """A parsed coil and the scene keys that describe it (``what``: the coil in messages)."""

    key: str
    coil: coils.Field
    strength_key: str
    what: str = "this coil"


def _coil_list_problem(parts, key: str) -> str | None:
    """The problem with a ``coil = [...]`` list of ``key`` (not a non-empty list, too many
    coils), or None."""
    if not isinstance(parts, list) or not parts:
        return f"{key}.coil: expected a non-empty list of coil tables; got {_show(parts)}"
    if len(parts) > limits.MAX_COILS:
        return f"{key}.coil: at most {limits.MAX_COILS} coils; got {len(parts)}"
    return None


def _coil_kind(data, key: str, p: _Problems, control: bool):
    """Check the keys of a coil table (strengths refused under control) and return its
    ``type`` (or _BAD)."""
    strengths = ("current", "B", "gradient")
    geometry = {"type", "radius", "turns", "axis", "center", "spacing", "winding", "filaments"}
    allowed = geometry | ({"wire_diameter"} if control else set(strengths))
    if control:  # the currents are what the scene finds
        for k in strengths:
            if k in data:
                p.add(
                    f"{key}.{k}: not used in a coil system under control ([control] finds the "
                    "currents); remove it"
                )
        allowed |= set(strengths)
    p.take(_unknown_keys, data, key, allowed)
    kind = data.get("type", _MISSING)
    if kind is _MISSING:
        p.add(f"{key}.type: missing required key (one of {', '.join(_COIL_TYPES)})")
        kind = _BAD
    elif not isinstance(kind, str) or kind not in _COIL_TYPES:
        p.add(f"{key}.type: unknown coil type {_show(kind)} (one of {', '.join(_COIL_TYPES)})")
        kind = _BAD
    return kind


def _coil_winding(data, key: str, p: _Problems, kind, radius, kwargs: dict) -> None:
    """Parse a coil's ``winding`` (and ``filaments``) into ``kwargs``, checked against its
    radius and the pair's spacing (``kwargs["spacing"]`` set _BAD when it is too small)."""
    w = data["winding"]
    if not isinstance(w, list) or len(w) != 2:
        p.add(
            f"{key}.winding: expected ['width', 'height'], e.g. ['10 mm', '10 mm']; got {_show(w)}"
        )
        kwargs["winding"] = _BAD
    else:
        width, height = (
            p.take(_value, v, "length", f"{key}.winding[{i}]", kind="coil size", positive=True)
            for i, v in enumerate(w)
        )
        if _ok(height, radius) and height >= 2 * radius:
            p.add(
                f"{key}.winding[1]: the winding height {w[1]} must be below twice the "
                f"radius ({_mm(2 * radius)})"
            )
            height = _BAD
        if _ok(width, kind) and kind != "coil":
            spacing = kwargs.get("spacing")
            if spacing is None and _ok(radius):
                default = radius * _COIL_TYPES[kind].default_spacing_factor
                if width >= default:
                    p.add(
                        f"{key}.winding[0]: the winding width {w[0]} must be below the "
                        f"spacing of the pair (default {_mm(default)}); give a spacing"
                    )
                    width = _BAD
            elif _ok(spacing) and spacing is not None and width >= spacing:
                p.add(
                    f"{key}.spacing: must exceed the winding width {w[0]} (the two "
                    f"windings would overlap); got {data['spacing']}"
                )
                kwargs["spacing"] = _BAD
        kwargs["winding"] = (width, height) if _ok(width, height) else _BAD
    if "filaments" in data:
        kwargs["filaments"] = p.take(
            _counts, data["filaments"], f"{key}.filaments", 2, limits.MAX_FILAMENTS, "[3, 3]"
        )


def _coil_geometry(data, key: str, p: _Problems, kind):
    """A coil's radius, turns and the keyword arguments of its class (axis, center, spacing,
    winding, filaments), each _BAD where the table is wrong."""
    radius = p.take(_quantity, data, "radius", "length", key, kind="coil size", positive=True)
    turns = p.take(
        _number,
        data,
        "turns",
        key,
        integer=True,
        positive=True,
        high=1e6,
        what="turns of one coil",
    )
    axis = p.take(_axis, data.get("axis", "y"), f"{key}.axis")
    center = (
        p.take(_vector, data["center"], "length", f"{key}.center", "position")
        if "center" in data
        else np.zeros(3)
    )
    kwargs: dict[str, Any] = {"axis": axis, "center": center}
    if "spacing" in data:
        if kind == "coil":
            p.add(f"{key}.spacing: a single coil has no spacing")
            kwargs["spacing"] = _BAD
        else:
            kwargs["spacing"] = p.take(
                _quantity, data, "spacing", "length", key, kind="coil size", positive=True
            )
    if "winding" in data:
        _coil_winding(data, key, p, kind, radius, kwargs)
    elif "filaments" in data:
        p.add(f"{key}.filaments: filaments model a finite winding; give winding too")
    return radius, turns, kwargs


def _controlled_coil(data, key: str, p: _Problems, kind, radius, turns, kwargs):
    """A coil of a system under control: at 0 A, with an optional ``wire_diameter``."""
    if "wire_diameter" in data:
        kwargs["wire_diameter"] = p.take(
            _quantity, data, "wire_diameter", "length", key, kind="coil size", positive=True
        )
    if not _ok(kind, radius, turns, *kwargs.values()):
        return _BAD
    try:
        coil = _COIL_TYPES[kind](radius, turns, 0.0, **kwargs)
    except ValueError as exc:  # the coil classes' own checks
        p.add(f"{key}: {exc}")
        return _BAD
    return _Coil(key, coil, key)


def _coil_strength(data, key: str, p: _Problems, kind):
    """The one strength key given (``current``, ``B`` or ``gradient``; None if not exactly
    one) and its value (or _BAD), checked against what the coil type can make."""
    given = [k for k in ("current", "B", "gradient") if k in data]
    if len(given) != 1:
        p.add(
            f"{key}: give exactly one of current, B (target centre field) or "
            f"gradient (target centre gradient); got {', '.join(given) or 'none'}"
        )
        return None, _BAD
    if given == ["current"]:
        return "current", p.take(_quantity, data, "current", "current", key, kind="current")
    if given == ["B"]:
        strength = p.take(_quantity, data, "B", "flux density", key, kind="flux density")
        if _ok(kind) and kind == "maxwell":
            p.add(f"{key}.B: a Maxwell pair has no field at its centre; give its gradient")
            strength = _BAD
        return "B", strength
    strength = p.take(_quantity, data, "gradient", "gradient", key, kind="gradient")
    if _ok(kind) and kind != "maxwell":
        p.add(
            f"{key}.gradient: a {_COIL_NAMES[kind]} has no gradient at its centre (by "
            "symmetry); give its field B, or use a maxwell pair"
        )
        strength = _BAD
    return "gradient", strength


def _coil_current(data, p: _Problems, unit, given: str, strength, strength_key: str):
    """The current (A) of a coil whose strength is ``given`` ("current", "B" or "gradient"),
    ``unit`` the coil at 1 A; _BAD (the problem added) beyond the allowed current."""
    if given == "current":
        return strength
    from coils.design import current_for_field, current_for_gradient

    to_current = current_for_field if given == "B" else current_for_gradient
    try:
        current = to_current(unit, strength)
    except ValueError as exc:
        p.add(f"{strength_key}: {exc}")
        return _BAD
    high = limits.RANGES["current"].high
    if not abs(current) <= high:
        p.add(
            f"{strength_key}: needs {abs(current):.3g} A per turn in this coil, more than "
            f"the {high:g} A allowed; use more turns or another size; got {data[given]}"
        )
        return _BAD
    return current


def _parse_coil(data, key: str, p: _Problems, *, control: bool = False):
    """A coil table: at the current its ``current``, ``B`` or ``gradient`` gives; in a coil
    system under control (``control``) at 0 A, with an optional ``wire_diameter``."""
    data = _table(data, key)
    kind = _coil_kind(data, key, p, control)
    radius, turns, kwargs = _coil_geometry(data, key, p, kind)
    if control:
        return _controlled_coil(data, key, p, kind, radius, turns, kwargs)
    given, strength = _coil_strength(data, key, p, kind)
    if not _ok(kind, radius, turns, strength, *kwargs.values()):
        return _BAD
    strength_key = f"{key}.{given}"
    cls = _COIL_TYPES[kind]
    try:
        unit = cls(radius, turns, 1.0, **kwargs)
    except ValueError as exc:  # the coil classes' own checks
        p.add(f"{key}: {exc}")
        return _BAD
    current = _coil_current(data, p, unit, given, strength, strength_key)
    if not _ok(current):
        return _BAD
    return _Coil(key, cls(radius, turns, current, **kwargs), strength_key)


@dataclass
class _FieldInfo:
    """What the checks need to know about the parsed field."""

    fields: dict[str, coils.Field]
    kind: str
    coils: list[_Coil]
    strength_key: str
    label: str = ""


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
        found = p.take(parse_obstacles, data["obstacles"], source, length, half)
        if _ok(found):
            rod_options = {**rod_options, "obstacles": found[0]}
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
        valid TOML, or fails validation; one line per problem, each naming the file or the key.
    """
    path = Path(path)
    if path.is_dir():
        raise SceneError(f"{path}: is a directory, not a scene file (give a .toml file)")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise SceneError(
            f"{path}: cannot read the scene file ({exc.strerror or type(exc).__name__})"
        ) from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise SceneError(
            f"{path}: not UTF-8 text (byte 0x{raw[exc.start]:02x} on line {line}); save the "
            "scene file as UTF-8"
        ) from None
    try:
        data = tomllib.loads(text)
    except ValueError as exc:  # TOMLDecodeError, or an integer too long for Python
        raise SceneError(f"{path}: not valid TOML ({exc})") from None
    return parse_scene(data, source=str(path))
