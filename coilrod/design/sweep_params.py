"""Sweep parameters: scene keys and their values, read from ``"START:STOP:N"`` (with units) or
sequences, and checked against the scene before anything is solved.

A key names one value of the scene's TOML data (:mod:`coilrod.scene.keys`); its values are
converted to SI with the scene's units (:mod:`coilrod.scene.units`) and must be of the kind the
scene has there (a length for a length).  A key the scene does not set is tried at the first
grid point: the scene parser must know it.
"""

from __future__ import annotations

import copy
import math
import numbers
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..scene import limits
from ..scene.keys import MISSING, assign, lookup, spell_key, split_key
from ..scene.parse import Scene, SceneError, parse_scene
from ..scene.units import SI_UNITS, UnitError, read_quantity

__all__ = ["Parameter", "sweep_parameters", "point_data"]

#: Column-name suffix of a parameter's SI unit.
_UNIT_SUFFIX = {
    "length": "m",
    "flux density": "T",
    "gradient": "T_per_m",
    "magnetization": "A_per_m",
    "pressure": "Pa",
    "current": "A",
    "angle": "rad",
}
_INTEGER = re.compile(r"^\s*[-+]?\d+\s*$")


@dataclass(frozen=True)
class Parameter:
    """One swept scene key and its values.

    Attributes
    ----------
    key : str
        The key, dotted (``field.coil.0.radius``, also when given as ``field.coil[0].radius``).
    parts : tuple of str and int
        The key's path in the scene data.
    values : tuple of float or int
        The values, in SI units (m, T, T/m, A/m, Pa, A, rad) when ``dimension`` is set, else
        plain numbers.
    dimension : str or None
        "length", "pressure", ... (:data:`coilrod.scene.units.DIMENSIONS`); None for a plain
        number (``robot.magnetization.phi``, ``field.coil.0.turns``).
    """

    key: str
    parts: tuple
    values: tuple
    dimension: str | None

    @property
    def column(self) -> str:
        """The CSV column: the key and its SI unit, e.g. ``field.coil.0.radius_m``."""
        return self.key + (f"_{_UNIT_SUFFIX[self.dimension]}" if self.dimension else "")

    def scene_value(self, value):
        """``value`` as the scene file spells it: SI with its unit, e.g. ``"0.06 m"``."""
        if self.dimension is None:
            return value
        return f"{float(value)!r} {SI_UNITS[self.dimension]}"


def _label(key) -> str:
    return f"sweep parameter {key}"


def _about(key, parts, line: str) -> str:
    """A scene problem ``line`` as a problem of the parameter ``key`` (its key said once)."""
    own = f"{spell_key(parts)}: "
    return f"{_label(key)}: {line.removeprefix(own)}"


def _number_values(items, label: str):
    """(values, dimension, plain_kind) of a sequence of numbers and quantity strings."""
    values, dims = [], set()
    for i, item in enumerate(items):
        if isinstance(item, str):
            value, dim = read_quantity(item, f"{label}[{i}]")
            values.append(value)
            dims.add(dim)
        elif isinstance(item, numbers.Real) and not isinstance(item, bool | np.bool_):
            if not math.isfinite(item):
                raise SceneError(f"{label}[{i}]: must be finite; got {item!r}")
            values.append(int(item) if isinstance(item, numbers.Integral) else float(item))
            dims.add("SI")
        else:
            raise SceneError(f"{label}[{i}]: expected a number or a quantity such as '60 mm'")
    units = dims - {None, "SI"}
    if len(units) > 1:
        raise SceneError(f"{label}: values of different kinds ({', '.join(sorted(units))})")
    if units and None in dims:
        raise SceneError(f"{label}: some values have a unit and some do not")
    return values, (units.pop() if units else None), ("SI" if "SI" in dims else None)


def _range(spec: str, label: str):
    """(values, dimension, plain) of ``"START:STOP:N"``."""
    example = "e.g. '60 mm:120 mm:4' (4 values from 60 mm to 120 mm)"
    pieces = spec.split(":")
    if len(pieces) != 3 or not all(p.strip() for p in pieces):
        raise SceneError(f"{label}: expected START:STOP:N, {example}; got {spec!r}")
    start_s, stop_s, n_s = (p.strip() for p in pieces)
    if not _INTEGER.match(n_s):
        raise SceneError(f"{label}: N must be a whole number of values, {example}; got {n_s!r}")
    n = int(n_s)
    if n < 1:
        raise SceneError(f"{label}: N must be at least 1 (the number of values); got {n}")
    if n > limits.MAX_SWEEP_POINTS:
        raise SceneError(f"{label}: at most {limits.MAX_SWEEP_POINTS} values; got {n}")
    start, d0 = read_quantity(start_s, f"{label} START")
    stop, d1 = read_quantity(stop_s, f"{label} STOP")
    if d0 != d1:
        what = [f"a {d}" if d else "a plain number" for d in (d0, d1)]
        raise SceneError(
            f"{label}: START {start_s!r} is {what[0]} but STOP {stop_s!r} is {what[1]}; give "
            f"both with units, {example}"
        )
    values = np.linspace(start, stop, n).tolist()
    if d0 is None and _INTEGER.match(start_s) and _INTEGER.match(stop_s):
        if all(float(v).is_integer() for v in values):
            values = [int(v) for v in values]
    return values, d0, None


def _parameter(key, spec, data: dict) -> Parameter:
    label = _label(key)
    try:
        parts = split_key(key)
    except SceneError as exc:
        raise SceneError(f"{label}: {exc.problems[0].removeprefix(f'{key!r}: ')}") from None
    try:
        current = lookup(data, parts)
    except SceneError as exc:
        raise SceneError(_about(key, parts, exc.problems[0])) from None
    try:
        if isinstance(spec, str):
            values, dim, plain = _range(spec, label)
        elif isinstance(spec, Sequence | np.ndarray) and not isinstance(spec, bytes):
            items = np.asarray(spec).tolist() if isinstance(spec, np.ndarray) else list(spec)
            if not items:
                raise SceneError(f"{label}: no values (an empty sequence)")
            if len(items) > limits.MAX_SWEEP_POINTS:
                raise SceneError(f"{label}: at most {limits.MAX_SWEEP_POINTS} values")
            values, dim, plain = _number_values(items, label)
        else:
            raise SceneError(
                f"{label}: expected 'START:STOP:N' (e.g. '60 mm:120 mm:4') or a sequence of "
                f"values; got {spec!r}"
            )
    except UnitError as exc:
        raise SceneError(str(exc)) from None
    here = spell_key(parts)
    if isinstance(current, bool):
        raise SceneError(f"{label}: is a boolean in the scene; only numbers are swept")
    scene_dim = None
    if isinstance(current, str):
        try:
            _, scene_dim = read_quantity(current, here)
        except UnitError:
            raise SceneError(
                f"{label}: is {current!r} in the scene, not a number; only numbers are swept"
            ) from None
    plain_in_scene = current is not MISSING and scene_dim is None
    if dim == "angle" and plain_in_scene and current == 0:
        plain_in_scene = False  # scenes may write a zero angle without a unit
    if dim is not None and plain_in_scene:
        raise SceneError(
            f"{label}: is a plain number in the scene ({current!r}); got a {dim} ({spec!r})"
        )
    if dim is not None and scene_dim is not None and dim != scene_dim:
        raise SceneError(
            f"{label}: is a {scene_dim} in the scene ({current!r}); got a {dim} ({spec!r})"
        )
    if dim is None and scene_dim is not None:
        if plain != "SI":  # "START:STOP:N" without units
            raise SceneError(
                f"{label}: missing unit in {spec!r}; it is a {scene_dim} (the scene has "
                f"{current!r}): give START and STOP with units"
            )
        dim = scene_dim  # numbers in a sequence are SI
    if dim is not None:
        values = [float(v) for v in values]
    return Parameter(key=_dotted(parts), parts=parts, values=tuple(values), dimension=dim)


def _dotted(parts) -> str:
    return ".".join(str(p) for p in parts)


def sweep_parameters(params: Mapping, scene: Scene) -> list[Parameter]:
    """Check the parameters of a sweep of ``scene`` and read their values.

    Parameters
    ----------
    params : mapping
        Scene key -> ``"START:STOP:N"`` (units on START and STOP, e.g. ``"60 mm:120 mm:4"``;
        N evenly spaced values, START alone for N = 1) or a sequence of values (numbers in SI,
        or strings with units such as ``"60 mm"``).
    scene : Scene
        A scene with its TOML data (:attr:`Scene.data`).

    Returns
    -------
    list of Parameter

    Raises
    ------
    SceneError
        Every problem, one line each: a key the scene cannot have (an unknown key, an index past
        the end of a list), a malformed or empty range, a value of the wrong kind (a length for
        a pressure), a key given twice, a grid of more than
        :data:`coilrod.scene.limits.MAX_SWEEP_POINTS` points.
    """
    if not isinstance(params, Mapping) or not params:
        raise SceneError(
            "sweep parameters: expected at least one scene key and its values, e.g. "
            "{'field.coil.0.radius': '60 mm:120 mm:4'}"
        )
    problems: dict[str, list[str]] = {}  # by key, reported in the order given
    found: list[Parameter] = []
    seen: dict[tuple, str] = {}
    for key, spec in params.items():
        problems[key] = []
        try:
            p = _parameter(key, spec, scene.data)
        except SceneError as exc:
            problems[key] += exc.problems
            continue
        if p.parts in seen:
            problems[key].append(f"{_label(key)}: given twice (also as {seen[p.parts]})")
            continue
        seen[p.parts] = key
        found.append(p)
    for key, lines in _unknown_keys(found, scene).items():
        problems[key] += lines
    lines = [line for key_lines in problems.values() for line in key_lines]
    if lines:
        raise SceneError(lines)
    total = math.prod(len(p.values) for p in found)
    if total > limits.MAX_SWEEP_POINTS:
        raise SceneError(
            f"sweep parameters: {total} points, more than the {limits.MAX_SWEEP_POINTS} allowed; "
            "sweep fewer values"
        )
    return found


def _unknown_keys(found: list[Parameter], scene: Scene) -> dict[str, list[str]]:
    """The parser's "unknown key" and unit problems of each parameter the scene does not set.

    Such a key is put in (at the first grid point, and again with every plain-number parameter
    at its first non-zero value, since a plain 0 passes for an angle): the parser must know it
    and take its values' kind (a plain number where the scene needs a unit, ``elevation =
    0.5``), else it is an error of the sweep, not of every row.
    """
    fresh = [p for p in found if lookup(scene.data, p.parts) is MISSING]
    if not fresh:
        return {}
    first = [p.values[0] for p in fresh]
    points = [first]
    nonzero = [
        next((v for v in p.values if v != 0), p.values[0]) if p.dimension is None else v0
        for p, v0 in zip(fresh, first, strict=True)
    ]
    if nonzero != first:
        points.append(nonzero)
    out: dict[str, list[str]] = {}
    for values in points:
        try:
            parse_scene(point_data(scene.data, fresh, values), scene.source)
        except SceneError as exc:
            for p in fresh:
                n = len(p.parts)
                prefixes = [f"{spell_key(p.parts[:i])}: unknown key" for i in range(1, n + 1)]
                own = f"{spell_key(p.parts)}: "
                lines = [
                    line
                    for line in exc.problems
                    if line.startswith(tuple(prefixes)) or (line.startswith(own) and "unit" in line)
                ]
                for line in lines:
                    about = _about(p.key, p.parts, line)
                    if about not in out.setdefault(p.key, []):
                        out[p.key].append(about)
    return {key: lines for key, lines in out.items() if lines}


def point_data(base: dict, parameters: list[Parameter], values) -> dict:
    data = copy.deepcopy(base)
    for p, v in zip(parameters, values, strict=True):
        assign(data, p.parts, p.scene_value(v))
    return data
