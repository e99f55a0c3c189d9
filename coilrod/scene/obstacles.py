"""The ``[obstacles]`` table of a scene: walls, vessel presets, mesh files and centrelines.

.. code-block:: toml

    [obstacles]
    friction = 0.0                       # Coulomb mu >= 0 of every obstacle's wall
    [[obstacles.wall]]
    point = ["0 mm", "8 mm", "0 mm"]
    normal = [0, -1, 0]
    [[obstacles.vessel]]
    preset = "bend"                      # straight, bend, aneurysm, branch
    bend_radius = "20 mm"
    angle = "90 deg"
    radius = "3 mm"
    [[obstacles.mesh]]
    file = "lumen.stl"                   # relative to the scene file
    units = "mm"
    translate = ["-2 mm", "0 mm", "0 mm"]  # optional: moves the mesh (the clamp is the origin)
    fix_normals = false                  # optional: true turns inward-facing normals round
    [[obstacles.centerline]]
    file = "centerline.csv"              # VMTK: x, y, z, MaximumInscribedSphereRadius
    units = "mm"

The obstacles are passed to ``solve_rod(..., obstacles=...)`` (rod runs only); the clamp
must lie in every lumen.  :func:`parse_obstacles` returns the list or raises a
:class:`~coilrod.scene.parse.SceneError` naming every bad key.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .tables import (
    SceneError,
    _axis,
    _plain,
    _Problems,
    _show,
    _table,
    _unknown_keys,
    _value,
    _vector,
)

__all__ = ["parse_obstacles"]

_KINDS = ("wall", "vessel", "mesh", "centerline")
_PRESET_KEYS = {
    "straight": {"length": "length", "radius": "length", "ends": None},
    "bend": {
        "bend_radius": "length",
        "angle": "angle",
        "radius": "length",
        "straight_before": "length",
        "straight_after": "length",
        "ends": None,
    },
    "aneurysm": {
        "length": "length",
        "radius": "length",
        "bulge_radius": "length",
        "bulge_center": "length",
        "bulge_width": "length",
        "ends": None,
    },
    "branch": {
        "length": "length",
        "radius": "length",
        "branch_length": "length",
        "branch_radius": "length",
        "branch_angle": "angle",
        "branch_at": "length",
        "ends": None,
    },
}
_COMMON = {"start", "direction", "plane_normal"}


def _list(data: dict, name: str) -> list:
    items = data.get(name, [])
    if isinstance(items, dict):
        items = [items]
    if not isinstance(items, list):
        raise SceneError(f"obstacles.{name}: expected tables ([[obstacles.{name}]])")
    return items


def _wall(item, key):
    from ..contact import Wall

    item = _table(item, key)
    _unknown_keys(item, key, {"point", "normal"})
    p = _Problems()
    if "point" not in item or "normal" not in item:
        raise SceneError(f"{key}: needs point (e.g. ['0 mm', '8 mm', '0 mm']) and normal")
    point = p.take(_vector, item["point"], "length", f"{key}.point", "position")
    normal = p.take(_axis, item["normal"], f"{key}.normal")
    if p.lines:
        raise SceneError(p.lines)
    return Wall(point, normal)


def _vessel(item, key):
    from ..contact import presets

    item = _table(item, key)
    preset = item.get("preset")
    if preset not in _PRESET_KEYS:
        raise SceneError(f"{key}.preset: expected one of {list(_PRESET_KEYS)}; got {_show(preset)}")
    keys = _PRESET_KEYS[preset]
    allowed = {"preset", *keys, *_COMMON} - (
        set() if preset in ("bend", "branch") else {"plane_normal"}
    )
    _unknown_keys(item, key, allowed)
    p = _Problems()
    kwargs = {}
    for name, dim in keys.items():
        if name not in item:
            continue
        full = f"{key}.{name}"
        if dim is None:
            kwargs[name] = item[name]
        else:
            kind = "angle" if dim == "angle" else "position"
            kwargs[name] = p.take(_value, item[name], dim, full, kind=kind)
    if "start" in item:
        kwargs["start"] = p.take(_vector, item["start"], "length", f"{key}.start", "position")
    for name in ("direction", "plane_normal"):
        if name in item:
            kwargs[name] = p.take(_axis, item[name], f"{key}.{name}")
    if p.lines:
        raise SceneError(p.lines)
    try:
        return getattr(presets, preset)(**kwargs)
    except (TypeError, ValueError) as exc:
        raise SceneError(f"{key}: {exc}") from None


def _file_obstacle(item, key, base: Path, kind: str, friction: float = 0.0):
    from ..contact import MeshVessel, Vessel

    item = _table(item, key)
    _unknown_keys(
        item,
        key,
        {"file", "units", "translate", "fix_normals"} if kind == "mesh" else {"file", "units"},
    )
    name = item.get("file")
    if not isinstance(name, str) or not name:
        raise SceneError(f"{key}.file: expected a file name; got {_show(name)}")
    units = item.get("units", "m")
    if units not in ("m", "mm"):
        raise SceneError(f"{key}.units: expected 'm' or 'mm'; got {_show(units)}")
    shift = None
    if "translate" in item:
        shift = _vector(item["translate"], "length", f"{key}.translate", "position")
    fix = item.get("fix_normals", False)
    if not isinstance(fix, bool):
        raise SceneError(f"{key}.fix_normals: expected true or false; got {_show(fix)}")
    path = Path(name) if Path(name).is_absolute() else base / name
    try:
        if kind == "mesh":
            mesh = MeshVessel.from_file(path, units=units, friction=friction, fix_normals=fix)
            if shift is None:
                return mesh
            return MeshVessel(mesh.vertices + np.asarray(shift), mesh.faces, source=mesh.source,
                              friction=friction)  # fmt: skip
        return Vessel.from_centerline_file(path, units=units)
    except ValueError as exc:
        raise SceneError(f"{key}.file: {exc}") from None


def _with_friction(ob, mu: float):
    """The obstacle with the wall's Coulomb coefficient ``mu`` (``obstacles.friction``), by
    its ``with_friction`` (obstacles without it are frictionless)."""
    if mu == 0.0 or getattr(ob, "friction", 0.0) == mu:
        return ob
    with_friction = getattr(ob, "with_friction", None)
    return ob if with_friction is None else with_friction(mu)


def _narrowest(ob) -> float | None:
    """The smallest lumen radius of a vessel or network of vessels (None for walls, meshes)."""
    radii = [getattr(m, "min_radius", None) for m in getattr(ob, "vessels", [ob])]
    radii = [r for r in radii if r is not None]
    return min(radii) if radii else None


def parse_obstacles(data, source: str = "<embedded>", length=None, thickness=None, tangent=None):
    """The obstacles of a scene's ``[obstacles]`` table.

    Parameters
    ----------
    data : dict
        The table.
    source : str
        The scene's path: mesh and centreline files are relative to its folder.
    length : float, optional
        The robot's length (m): its straight starting state along ``tangent`` from the clamp
        at the origin is checked to lie in every obstacle's admissible region (the clamp alone if
        None).
    thickness : float, optional
        The robot's largest half-width (m): a vessel narrower than it is a problem.
    tangent : array-like, shape (3,), optional
        The straight robot's unit direction from the clamp (default +x; the first column of
        ``rod.clamp_rotation`` for a rotated clamp).

    Returns
    -------
    obstacles : list of Obstacle
    friction : float
        The ``friction`` key (mu >= 0, default 0).

    Raises
    ------
    SceneError
        One line per problem (``obstacles.vessel[0].radius: ...``).
    """
    data = _table(data, "obstacles")
    p = _Problems()
    p.take(_unknown_keys, data, "obstacles", {"friction", *_KINDS})
    friction = 0.0
    if isinstance(data.get("friction"), str):  # "0.1 mm", "0.1": a coefficient has no unit
        p.add(
            "obstacles.friction: expected a plain number, the Coulomb coefficient mu >= 0 "
            f"(no unit, no quotes: friction = 0.1); got {_show(data['friction'])}"
        )
        friction = None
    elif "friction" in data:
        friction = p.take(_plain, data["friction"], "obstacles.friction", low=0.0)
    xs = [0.0] if length is None else np.linspace(0.0, float(length), 33)
    t = np.array([1.0, 0.0, 0.0]) if tangent is None else np.asarray(tangent, float)
    start = np.outer(xs, t / np.linalg.norm(t))
    base = Path(source).parent if source != "<embedded>" else Path.cwd()
    out = []
    for kind in _KINDS:
        items = p.take(_list, data, kind)
        if not isinstance(items, list):
            continue
        for i, item in enumerate(items):
            key = f"obstacles.{kind}[{i}]"
            if kind == "wall":
                ob = p.take(_wall, item, key)
            elif kind == "vessel":
                ob = p.take(_vessel, item, key)
            else:
                mu = friction if isinstance(friction, float) else 0.0
                ob = p.take(_file_obstacle, item, key, base, kind, mu)
            if not hasattr(ob, "gap"):  # its problems are recorded
                continue
            if isinstance(friction, float):
                ob = _with_friction(ob, friction)
            narrow = _narrowest(ob)
            if thickness is not None and narrow is not None and narrow <= thickness:
                p.add(
                    f"{key}: the robot ({1e3 * thickness:.4g} mm from its axis to its surface) "
                    f"is thicker than the lumen (radius {1e3 * narrow:.4g} mm at its narrowest)"
                )
            gap = ob.gap(start)
            if gap[0] < 0:
                p.add(f"{key}: the clamp lies {1e3 * -gap[0]:.4g} mm outside it")
            elif np.any(gap < 0):
                k = int(np.flatnonzero(gap < 0)[0])
                p.add(
                    f"{key}: the straight robot leaves it {1e3 * xs[k]:.4g} mm from the "
                    "clamp (the solve starts from the straight robot; lengthen the straight part)"
                )
            out.append(ob)
    if not out and not p.lines:
        p.add(f"obstacles: no obstacle given (tables {', '.join(_KINDS)})")
    if p.lines:
        raise SceneError(p.lines)
    return out, float(friction)
