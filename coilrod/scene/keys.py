"""Scene keys: a dotted path to one value of a scene's TOML data, to read or replace it.

``field.coil.0.radius`` and ``field.coil[0].radius`` name the same value (the radius of the
first coil); :func:`spell_key` gives the spelling of the scene's error messages, so that a
problem the parser reports about a key can be matched to it.
"""

from __future__ import annotations

import re
from typing import Any

from .parse import SceneError

__all__ = ["split_key", "spell_key", "lookup", "assign", "MISSING"]

#: Returned by :func:`lookup` for a key the scene does not set (but could).
MISSING = object()

_PART = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$|^\d+$")


def split_key(key: str) -> tuple[str | int, ...]:
    """The parts of a dotted key: names (str) and list indices (int).

    Parameters
    ----------
    key : str
        E.g. ``"robot.youngs_modulus"``, ``"field.coil.0.radius"`` or
        ``"field.coil[0].radius"``.

    Returns
    -------
    tuple of str and int

    Raises
    ------
    SceneError
        If ``key`` is not a dotted path of names and indices.

    Examples
    --------
    >>> split_key("field.coil[0].radius")
    ('field', 'coil', 0, 'radius')
    >>> split_key("field.coil.0.radius")
    ('field', 'coil', 0, 'radius')
    """
    if not isinstance(key, str):
        raise SceneError(f"expected a scene key such as 'robot.length'; got {key!r}")
    text = re.sub(r"\[\s*(\d+)\s*\]", r".\1", key.strip())
    parts = text.split(".")
    if not text or not all(_PART.match(p) for p in parts) or parts[0].isdigit():
        raise SceneError(
            f"{key!r}: not a scene key (names and list indices joined by dots, e.g. "
            "'robot.youngs_modulus' or 'field.coil.0.radius')"
        )
    return tuple(int(p) if p.isdigit() else p for p in parts)


def spell_key(parts: tuple[str | int, ...]) -> str:
    """The key as the scene's error messages spell it, e.g. ``field.coil[0].radius``.

    Examples
    --------
    >>> spell_key(("robot", "magnetization", "segments", 1, "length"))
    'robot.magnetization.segments[1].length'
    """
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else p)
    return out


def _kind(value) -> str:
    return "a table" if isinstance(value, dict) else ("a list" if isinstance(value, list) else "")


def _step(node, part, parts, i):
    """The child ``part`` of ``node`` (MISSING for an absent table key); raises SceneError."""
    key = spell_key(parts)
    where = spell_key(parts[:i]) or "the scene"
    if isinstance(node, dict):
        if isinstance(part, int):
            raise SceneError(f"{key}: {where} is a table, not a list (no index {part})")
        return node.get(part, MISSING)
    if isinstance(node, list):
        n = len(node)
        if not isinstance(part, int):
            raise SceneError(f"{key}: {where} is a list; give an index from 0 to {n - 1}")
        if part >= n:
            raise SceneError(
                f"{key}: {where} has {n} {'entry' if n == 1 else 'entries'} (indices 0 to {n - 1})"
            )
        return node[part]
    raise SceneError(f"{key}: {where} is a value ({node!r}), not a table or a list")


def lookup(data: dict, parts: tuple[str | int, ...]) -> Any:
    """The value at ``parts`` in the scene data, or :data:`MISSING` if a table does not set it.

    Parameters
    ----------
    data : dict
        The scene as read from TOML.
    parts : tuple
        From :func:`split_key`.

    Returns
    -------
    object
        The value (str, number, bool), or MISSING when the key or one of its tables is absent.

    Raises
    ------
    SceneError
        If the path cannot exist: an index past the end of a list, an index into a table, a name
        into a list or a value, or a key that names a whole table or list.

    Examples
    --------
    >>> data = {"field": {"coil": [{"radius": "80 mm"}]}}
    >>> lookup(data, ("field", "coil", 0, "radius"))
    '80 mm'
    >>> lookup(data, ("rod", "nodes")) is MISSING
    True
    """
    node: Any = data
    for i, part in enumerate(parts):
        node = _step(node, part, parts, i)
        if node is MISSING:
            if any(isinstance(p, int) for p in parts[i + 1 :]):
                raise SceneError(
                    f"{spell_key(parts)}: the scene has no {spell_key(parts[: i + 1])} to index"
                )
            return MISSING
    if isinstance(node, dict | list):
        raise SceneError(
            f"{spell_key(parts)}: is {_kind(node)}; name one value in it "
            f"(e.g. {spell_key(parts)}{'.<key>' if isinstance(node, dict) else '[0]'})"
        )
    return node


def assign(data: dict, parts: tuple[str | int, ...], value) -> None:
    """Set the value at ``parts`` in ``data`` (in place), creating absent tables.

    The path must be valid for :func:`lookup`.

    Examples
    --------
    >>> data = {"robot": {"length": "40 mm"}}
    >>> assign(data, ("rod", "nodes"), 32)
    >>> data["rod"]
    {'nodes': 32}
    """
    node: Any = data
    for part in parts[:-1]:
        if isinstance(node, dict) and part not in node:
            node[part] = {}
        node = node[part]
    node[parts[-1]] = value
