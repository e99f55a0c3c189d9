"""Scene files (TOML): the robot, the field, the load path, the models to run and the outputs.

A scene is validated completely before anything runs; every problem is reported as a
:class:`SceneError` naming the key and the reason, e.g.
``robot.length: must be positive; got -40 mm`` or ``field.coil[0].radius: missing unit``.

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

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import coils

from ..robot import presets
from ..robot.magnetization import Magnetization
from ..robot.rod import Rod
from ..robot.sections import Circle, Rectangle
from .units import EXAMPLES, UnitError, parse_quantity

__all__ = ["Scene", "SceneError", "load_scene", "parse_scene", "MODELS", "PRESETS"]

#: Models a scene can request.
MODELS = ("rod", "fem2d", "fem3d")
#: Magnetization presets (see :mod:`coilrod.presets`).
PRESETS = ("M1", "M2a", "M2b", "M3", "M4.1", "M4.2")


class SceneError(ValueError):
    """A scene file is invalid; the message names the key and the reason."""


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


# -- small validation helpers --------------------------------------------------------------------
def _table(data: Any, key: str) -> dict:
    if not isinstance(data, dict):
        raise SceneError(f"{key}: expected a table; got {type(data).__name__}")
    return data


def _check_keys(data: dict, key: str, allowed: set[str], required: set[str] = frozenset()):
    unknown = sorted(set(data) - allowed)
    if unknown:
        where = f"{key}." if key else ""
        raise SceneError(
            f"{where}{unknown[0]}: unknown key (allowed here: {', '.join(sorted(allowed))})"
        )
    missing = sorted(required - set(data))
    if missing:
        where = f"{key}." if key else ""
        raise SceneError(f"{where}{missing[0]}: missing required key")


def _quantity(
    data: dict, name: str, dimension: str, key: str, *, positive: bool = False, default=None
) -> float:
    full = f"{key}.{name}"
    if name not in data:
        if default is None:
            raise SceneError(
                f"{full}: missing required key ({dimension}, e.g. '{EXAMPLES[dimension]}')"
            )
        return default
    value = _si(data[name], dimension, full)
    if positive and value <= 0:
        raise SceneError(f"{full}: must be positive; got {data[name]}")
    return value


def _number(
    data: dict,
    name: str,
    key: str,
    *,
    positive: bool = False,
    integer: bool = False,
    default=None,
    low=None,
    high=None,
) -> float:
    full = f"{key}.{name}"
    if name not in data:
        if default is None:
            raise SceneError(f"{full}: missing required key")
        return default
    value = data[name]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise SceneError(f"{full}: expected a number; got {value!r}")
    if not math.isfinite(value):
        raise SceneError(f"{full}: must be finite; got {value!r}")
    if integer and int(value) != value:
        raise SceneError(f"{full}: expected an integer; got {value!r}")
    if positive and value <= 0:
        raise SceneError(f"{full}: must be positive; got {value!r}")
    if low is not None and value < low:
        raise SceneError(f"{full}: must be at least {low}; got {value!r}")
    if high is not None and value > high:
        raise SceneError(f"{full}: must be at most {high}; got {value!r}")
    return int(value) if integer else float(value)


def _axis(value, key: str) -> np.ndarray:
    try:
        from coils._validate import as_axis

        return as_axis(value, key)
    except (ValueError, TypeError):
        raise SceneError(
            f"{key}: expected 'x', 'y', 'z' (optionally signed, e.g. '-x') or a list of 3 "
            f"numbers; got {value!r}"
        ) from None


def _si(value, dimension: str, key: str) -> float:
    """``parse_quantity`` with its UnitError reported as a SceneError (same message)."""
    try:
        return parse_quantity(value, dimension, key)
    except UnitError as exc:
        raise SceneError(str(exc)) from None


def _vector(value, dimension: str, key: str) -> np.ndarray:
    if not isinstance(value, list) or len(value) != 3:
        raise SceneError(
            f"{key}: expected a list of 3 quantities, e.g. ['0 mm', '0 mm', '0 mm']; got {value!r}"
        )
    return np.array([_si(v, dimension, f"{key}[{i}]") for i, v in enumerate(value)])


# -- sections of the scene ---------------------------------------------------------------------
def _parse_magnetization(data, length: float, key: str) -> Magnetization:
    data = _table(data, key)
    _check_keys(
        data,
        key,
        {
            "preset",
            "M0",
            "phi",
            "magnitude",
            "angle",
            "segments",
            "slope",
            "segment",
            "segment_angle",
        },
    )
    if "preset" in data:
        preset = data["preset"]
        if preset not in PRESETS:
            raise SceneError(
                f"{key}.preset: unknown preset {preset!r} (one of {', '.join(PRESETS)})"
            )
        M0 = _quantity(data, "M0", "magnetization", key, positive=True, default=presets.SEED_M0)
        if preset in ("M1", "M2a", "M2b"):
            phi = _number(data, "phi", key, positive=True, default=0.2, high=1.0)
            if preset == "M1":
                return presets.M1(M0=M0, phi=phi)
            return presets.M2(length, variant=preset[-1], M0=M0, phi=phi)
        if preset == "M3":
            slope = _number(data, "slope", key, positive=True, default=0.4, high=1.0)
            return presets.M3(length, M0=M0, slope=slope)
        if preset == "M4.1":
            return presets.M41(length, M0=M0)
        segment = _number(data, "segment", key, integer=True, default=-1)
        n_seg = len(presets.EXAMPLE_M41_LAYOUT["fractions"])
        if not -n_seg <= segment < n_seg:
            raise SceneError(
                f"{key}.segment: the M(4.x) layout has {n_seg} segments (index 0 at the clamp, "
                f"-1 at the tip); got {segment}"
            )
        angle = _quantity(data, "segment_angle", "angle", key, default=-math.pi / 4)
        return presets.M42(length, M0=M0, segment=segment, angle=angle)
    if "segments" in data:
        segs = data["segments"]
        if not isinstance(segs, list) or not segs:
            raise SceneError(
                f"{key}.segments: expected a non-empty list of tables "
                "{ length = '10 mm', magnitude = '64 kA/m', angle = '0 deg' }"
            )
        lengths, mags, angles = [], [], []
        for i, seg in enumerate(segs):
            sk = f"{key}.segments[{i}]"
            seg = _table(seg, sk)
            _check_keys(seg, sk, {"length", "magnitude", "angle"}, {"length", "magnitude"})
            lengths.append(_quantity(seg, "length", "length", sk, positive=True))
            mags.append(_quantity(seg, "magnitude", "magnetization", sk))
            angles.append(_quantity(seg, "angle", "angle", sk, default=0.0))
        total = sum(lengths)
        if abs(total - length) > 1e-9 * length:
            raise SceneError(
                f"{key}.segments: lengths add up to {1e3 * total:g} mm; the robot "
                f"is {1e3 * length:g} mm long"
            )
        return Magnetization.segments(lengths, mags, angles, label="custom segments")
    magnitude = _quantity(data, "magnitude", "magnetization", key)
    angle = _quantity(data, "angle", "angle", key, default=0.0)
    return Magnetization(magnitude, angle, label=f"uniform {magnitude:g} A/m")


def _parse_robot(data) -> tuple[Rod, float | None]:
    key = "robot"
    data = _table(data, key)
    _check_keys(
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
        {"length", "youngs_modulus", "magnetization"},
    )
    length = _quantity(data, "length", "length", key, positive=True)
    E = _quantity(data, "youngs_modulus", "pressure", key, positive=True)
    if "diameter" in data:
        if "width" in data or "thickness" in data:
            raise SceneError(
                "robot.diameter: give either diameter (circle) or width and "
                "thickness (rectangle), not both"
            )
        section = Circle(_quantity(data, "diameter", "length", key, positive=True))
    elif "width" in data or "thickness" in data:
        section = Rectangle(
            _quantity(data, "width", "length", key, positive=True),
            _quantity(data, "thickness", "length", key, positive=True),
        )
    else:
        raise SceneError(
            "robot.diameter: missing required key (or width and thickness for a "
            "rectangular section)"
        )
    nu = None
    if "poisson_ratio" in data:
        nu = _number(data, "poisson_ratio", key, low=-0.99, high=0.4999999)
    mag = _parse_magnetization(data["magnetization"], length, f"{key}.magnetization")
    return Rod(length, E, section, mag), nu


def _parse_coil(data, key: str) -> coils.Field:
    data = _table(data, key)
    _check_keys(
        data,
        key,
        {
            "type",
            "radius",
            "turns",
            "current",
            "B",
            "gradient",
            "axis",
            "center",
            "spacing",
            "winding",
            "filaments",
        },
        {"type", "radius", "turns"},
    )
    kind = data["type"]
    classes = {"helmholtz": coils.HelmholtzPair, "maxwell": coils.MaxwellPair, "coil": coils.Coil}
    if not isinstance(kind, str) or kind not in classes:
        raise SceneError(f"{key}.type: unknown coil type {kind!r} (one of {', '.join(classes)})")
    radius = _quantity(data, "radius", "length", key, positive=True)
    turns = _number(data, "turns", key, positive=True)
    axis = _axis(data.get("axis", "y"), f"{key}.axis")
    center = _vector(data["center"], "length", f"{key}.center") if "center" in data else np.zeros(3)
    kwargs: dict[str, Any] = {"axis": axis, "center": center}
    if "spacing" in data:
        if kind == "coil":
            raise SceneError(f"{key}.spacing: a single coil has no spacing")
        kwargs["spacing"] = _quantity(data, "spacing", "length", key, positive=True)
    if "winding" in data:
        w = data["winding"]
        if not isinstance(w, list) or len(w) != 2:
            raise SceneError(
                f"{key}.winding: expected ['width', 'height'], e.g. ['10 mm', '10 mm']"
            )
        kwargs["winding"] = tuple(_si(v, "length", f"{key}.winding[{i}]") for i, v in enumerate(w))
        if "filaments" in data:
            f = data["filaments"]
            if (
                not isinstance(f, list)
                or len(f) != 2
                or not all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in f)
            ):
                raise SceneError(
                    f"{key}.filaments: expected two positive integers (axial, radial), "
                    f"e.g. [3, 3]; got {f!r}"
                )
            kwargs["filaments"] = tuple(f)
    elif "filaments" in data:
        raise SceneError(f"{key}.filaments: filaments model a finite winding; give winding too")
    given = [k for k in ("current", "B", "gradient") if k in data]
    if len(given) != 1:
        raise SceneError(
            f"{key}: give exactly one of current, B (target centre field) or "
            f"gradient (target centre gradient); got {given or 'none'}"
        )
    try:
        unit = classes[kind](radius, turns, 1.0, **kwargs)
        if "current" in data:
            current = _quantity(data, "current", "current", key)
        elif "B" in data:
            from coils.design import current_for_field

            current = current_for_field(unit, _quantity(data, "B", "flux density", key))
        else:
            from coils.design import current_for_gradient

            current = current_for_gradient(unit, _quantity(data, "gradient", "gradient", key))
        return classes[kind](radius, turns, current, **kwargs)
    except SceneError:
        raise  # already names its key
    except ValueError as exc:  # from the coil classes and design helpers
        raise SceneError(f"{key}: {exc}") from None


def _parse_field(data, rod: Rod) -> tuple[dict[str, coils.Field], str]:
    key = "field"
    data = _table(data, key)
    kind = data.get("type")
    if kind == "uniform":
        _check_keys(data, key, {"type", "B", "direction"}, {"B"})
        B = _quantity(data, "B", "flux density", key)
        direction = _axis(data.get("direction", "y"), f"{key}.direction")
        return {"ideal": coils.UniformField(B * direction)}, "uniform"
    if kind == "gradient":
        _check_keys(data, key, {"type", "gradient", "axis", "B0", "origin"}, {"gradient"})
        g = _quantity(data, "gradient", "gradient", key)
        axis = _axis(data.get("axis", "y"), f"{key}.axis")
        G = g * (np.outer(axis, axis) - 0.5 * (np.eye(3) - np.outer(axis, axis)))
        B0 = _vector(data["B0"], "flux density", f"{key}.B0") if "B0" in data else np.zeros(3)
        origin = (
            _vector(data["origin"], "length", f"{key}.origin") if "origin" in data else np.zeros(3)
        )
        return {"ideal": coils.LinearField(B0, G, origin)}, "gradient"
    if kind == "coils":
        _check_keys(data, key, {"type", "coil", "compare_ideal"}, {"coil"})
        parts = data["coil"]
        if not isinstance(parts, list) or not parts:
            raise SceneError(f"{key}.coil: expected a non-empty list of coil tables")
        built = [_parse_coil(c, f"{key}.coil[{i}]") for i, c in enumerate(parts)]
        real = built[0] if len(built) == 1 else coils.CoilSystem(built)
        fields = {"coils": real}
        compare = data.get("compare_ideal", True)
        if not isinstance(compare, bool):
            raise SceneError(f"{key}.compare_ideal: expected true or false; got {compare!r}")
        if compare:
            fields["ideal"] = real.ideal()
        return fields, "coils"
    raise SceneError(f"{key}.type: expected 'uniform', 'gradient' or 'coils'; got {kind!r}")


def _parse_load(data) -> np.ndarray:
    key = "load"
    data = _table(data, key)
    _check_keys(data, key, {"steps", "scales", "max_scale"})
    if "scales" in data:
        if "steps" in data:
            raise SceneError("load.scales: give either scales or steps, not both")
        sc = data["scales"]
        if (
            not isinstance(sc, list)
            or not sc
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in sc)
        ):
            raise SceneError("load.scales: expected a non-empty list of numbers")
        scales = np.array(sc, dtype=float)
        if not np.all(np.isfinite(scales)):
            raise SceneError("load.scales: must be finite")
        return scales
    steps = _number(data, "steps", key, integer=True, positive=True, default=10)
    top = _number(data, "max_scale", key, default=1.0)
    return top * np.arange(1, steps + 1) / steps


def parse_scene(data: dict, source: str = "<embedded>") -> Scene:
    """Validate a scene given as a dict (as read from TOML) and build its objects.

    Raises
    ------
    SceneError
        Naming the first invalid key and the reason.
    """
    data = _table(data, "scene")
    _check_keys(
        data,
        "",
        {"name", "description", "robot", "field", "load", "models", "rod", "fem", "output"},
        {"robot", "field"},
    )
    name = data.get("name", Path(source).stem)
    rod, nu = _parse_robot(data["robot"])
    fields, kind = _parse_field(data["field"], rod)
    scales = _parse_load(data.get("load", {}))
    models_tbl = _table(data.get("models", {"run": ["rod"]}), "models")
    _check_keys(models_tbl, "models", {"run"}, {"run"})
    run = models_tbl["run"]
    if not isinstance(run, list) or not run:
        raise SceneError(f"models.run: expected a non-empty list from {list(MODELS)}")
    for m in run:
        if m not in MODELS:
            raise SceneError(f"models.run: unknown model {m!r} (one of {', '.join(MODELS)})")
    rod_opts = _table(data.get("rod", {}), "rod")
    _check_keys(rod_opts, "rod", {"nodes"})
    rod_options = {}
    if "nodes" in rod_opts:
        rod_options["nodes"] = _number(rod_opts, "nodes", "rod", integer=True, low=4)
    fem_opts = _table(data.get("fem", {}), "fem")
    _check_keys(fem_opts, "fem", {"order", "elements2d", "elements3d"})
    fem_options: dict[str, Any] = {}
    if "order" in fem_opts:
        fem_options["order"] = _number(fem_opts, "order", "fem", integer=True, low=1, high=2)
    for k in ("elements2d", "elements3d"):
        if k in fem_opts:
            v = fem_opts[k]
            n = 2 if k == "elements2d" else 3
            if (
                not isinstance(v, list)
                or len(v) != n
                or not all(isinstance(x, int) and not isinstance(x, bool) and x > 0 for x in v)
            ):
                raise SceneError(f"fem.{k}: expected {n} positive integers; got {v!r}")
            fem_options[k] = tuple(v)
    out = _table(data.get("output", {}), "output")
    _check_keys(out, "output", {"figures", "tables"})
    outputs = {"figures": bool(out.get("figures", True)), "tables": bool(out.get("tables", True))}
    return Scene(
        name=str(name),
        rod=rod,
        fields=fields,
        field_kind=kind,
        scales=scales,
        models=tuple(dict.fromkeys(run)),
        rod_options=rod_options,
        fem_options=fem_options,
        outputs=outputs,
        description=str(data.get("description", "")),
        source=source,
        poisson_ratio=nu,
    )


def load_scene(path: str | Path) -> Scene:
    """Read and validate a TOML scene file.

    Raises
    ------
    SceneError
        If the file is missing, is not valid TOML, or fails validation.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise SceneError(f"{path}: cannot read the scene file ({exc.strerror})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: not valid TOML ({exc})") from None
    return parse_scene(data, source=str(path))
