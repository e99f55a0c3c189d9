"""The building blocks of scene parsing: SceneError, the problem collector, the small value
validators (each raises a SceneError naming its key) and the coil tables.

Shared by :mod:`coilrod.scene.parse` (which re-exports what it always has) and the parsers of
the scene's optional tables (:mod:`~coilrod.scene.control`,
:mod:`~coilrod.scene.obstacles`), which import from here, not from ``parse``: ``parse``
calls them, so they must not import it (no import circle).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

import coils

from . import limits
from .units import EXAMPLES, UnitError, parse_quantity, short_int

#: Longest problem line (a value pasted by mistake is cut, not printed in full).
_MAX_LINE = 400


class SceneError(ValueError):
    """A scene is invalid.

    Parameters
    ----------
    problems : str or list of str
        One problem (``"key: reason"``) or several; each is kept on one line (whitespace runs
        become single spaces, lines beyond 400 characters are cut).
    source : str, optional
        The scene file the problems are in (:func:`~coilrod.scene.load_scene` gives it).

    Attributes
    ----------
    problems : list of str
        Every problem found, one line each, in the order of the scene.
    source : str or None
        The scene file, when the scene was read from one.
    lines : list of str
        ``problems`` and, when ``source`` is known, a last line naming the file
        (``"scene.toml: the scene file with the 2 problems above"``).  The message is these
        lines joined by newlines; the CLI prints each as one error line.

    Examples
    --------
    >>> err = SceneError(["robot.length: must be positive; got -40 mm", "load.steps: ..."])
    >>> err.problems[0]
    'robot.length: must be positive; got -40 mm'
    >>> len(str(err).splitlines())
    2
    >>> SceneError("robot.length: must be positive; got -40 mm", source="bad.toml").lines[-1]
    'bad.toml: the scene file with the problem above'
    """

    def __init__(self, problems: str | list[str], source: str | None = None):
        if isinstance(problems, str):
            problems = [problems]
        lines = [" ".join(str(p).split()) for p in problems]
        lines = [ln if len(ln) <= _MAX_LINE else ln[: _MAX_LINE - 6] + " [...]" for ln in lines]
        self.problems = list(dict.fromkeys(line for line in lines if line))
        self.source = None if source is None else str(source)
        self.lines = list(self.problems)
        if self.source is not None:
            n = len(self.problems)
            what = "the problem" if n == 1 else f"the {n} problems"
            self.lines.append(f"{self.source}: the scene file with {what} above")
        super().__init__("\n".join(self.lines))

    def __reduce__(self):
        return (type(self), (self.problems, self.source))


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
_COIL_TYPES = {"helmholtz": coils.HelmholtzPair, "maxwell": coils.MaxwellPair, "coil": coils.Coil}
_COIL_NAMES = {"helmholtz": "Helmholtz pair", "maxwell": "Maxwell pair", "coil": "single coil"}


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
