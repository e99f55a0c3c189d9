"""A vessel from a centreline with radii, as VMTK writes it (``vmtkcenterlines``).

VMTK's centreline table holds the centreline points and, per point, the radius of the maximum
inscribed sphere (array ``MaximumInscribedSphereRadius``).  :func:`read_centerline` reads it
from a CSV table (columns ``x, y, z`` and ``MaximumInscribedSphereRadius`` or ``radius``) or
from an ASCII VTK PolyData file (``.vtp``; the points in their order, or in the order of the
first polyline) and returns the :class:`~coilrod.contact.Vessel` with those radii (linear in
arc length between points).
"""

from __future__ import annotations

import csv
import os
import xml.etree.ElementTree as ET

import numpy as np

from coils._validate import as_bool, as_choice

__all__ = ["read_centerline"]

_UNITS = {"m": 1.0, "mm": 1e-3}
_RADIUS_NAMES = ("maximuminscribedsphereradius", "radius", "r")


def _read_csv(path: str):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise ValueError(f"centreline file {path!r} is empty")
    head = [h.strip().lower() for h in rows[0]]
    try:
        cols = [head.index(c) for c in ("x", "y", "z")]
    except ValueError:
        raise ValueError(f"centreline file {path!r} needs columns x, y, z; got {rows[0]}") from None
    rcol = next((head.index(n) for n in _RADIUS_NAMES if n in head), None)
    if rcol is None:
        raise ValueError(
            f"centreline file {path!r} needs a radius column (MaximumInscribedSphereRadius or "
            f"radius); got {rows[0]}"
        )
    try:
        data = np.array([[float(r[c]) for c in [*cols, rcol]] for r in rows[1:] if r], float)
    except (ValueError, IndexError) as exc:
        raise ValueError(f"centreline file {path!r} has a bad row: {exc}") from None
    return data[:, :3], data[:, 3]


def _read_vtp(path: str):
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"centreline file {path!r} is not valid XML: {exc}") from None
    piece = root.find("./PolyData/Piece")
    if piece is None:
        raise ValueError(f"centreline file {path!r} holds no PolyData piece")

    def array(node, what):
        if node is None:
            raise ValueError(f"centreline file {path!r} has no {what}")
        if node.get("format", "ascii") != "ascii":
            raise ValueError(
                f"centreline file {path!r}: {what} is stored {node.get('format')!r}; only "
                "ASCII VTP is read (save it as ASCII, or export a CSV table)"
            )
        try:
            return np.array((node.text or "").split(), dtype=float)
        except ValueError as exc:
            raise ValueError(f"centreline file {path!r}: bad numbers in {what}: {exc}") from None

    pts = array(piece.find("./Points/DataArray"), "Points").reshape(-1, 3)
    rnode = None
    for node in piece.findall("./PointData/DataArray"):
        if (node.get("Name") or "").lower() in _RADIUS_NAMES:
            rnode = node
            break
    radius = array(rnode, "MaximumInscribedSphereRadius point data")
    if len(radius) != len(pts):
        raise ValueError(f"centreline file {path!r} has {len(pts)} points and {len(radius)} radii")
    conn = piece.find("./Lines/DataArray[@Name='connectivity']")
    offs = piece.find("./Lines/DataArray[@Name='offsets']")
    if conn is not None and offs is not None:
        c = array(conn, "line connectivity").astype(int)
        o = array(offs, "line offsets").astype(int)
        if len(o):
            order = c[: o[0]]
            if order.min() < 0 or order.max() >= len(pts):
                raise ValueError(f"centreline file {path!r}: line indices out of range")
            pts, radius = pts[order], radius[order]
    return pts, radius


def read_centerline(path, units: str = "m", smooth: bool = False):
    """The vessel of a centreline with per-point radii (VMTK's table, CSV or ASCII VTP).

    Parameters
    ----------
    path : str or os.PathLike
        ``.csv`` (header ``x, y, z, MaximumInscribedSphereRadius``; ``radius`` accepted) or
        ``.vtp`` (ASCII; point data ``MaximumInscribedSphereRadius``).
    units : {"m", "mm"}
        Length unit of the file (points and radii), converted to m.
    smooth : bool
        The centreline as the C2 spline through the points (:class:`~coilrod.contact.Vessel`).

    Returns
    -------
    Vessel
        Radii linear in arc length between the points.

    Raises
    ------
    ValueError
        Missing or unreadable files, missing columns or arrays, non-finite or non-positive
        radii, fewer than 2 points; every message names the file.
    """
    from .vessel import Vessel

    units = as_choice(units, "units", tuple(_UNITS))
    smooth = as_bool(smooth, "smooth")
    if not isinstance(path, str | os.PathLike):
        raise ValueError(f"path must be a file name; got {path!r}")
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ValueError(f"centreline file {path!r} does not exist")
    ext = os.path.splitext(path)[1].lower()
    if ext == ".csv":
        pts, radius = _read_csv(path)
    elif ext == ".vtp":
        pts, radius = _read_vtp(path)
    else:
        raise ValueError(f"centreline file {path!r}: the format must be .csv or .vtp")
    if len(pts) < 2:
        raise ValueError(f"centreline file {path!r} has {len(pts)} points; at least 2 needed")
    if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(radius))):
        raise ValueError(f"centreline file {path!r} has non-finite values")
    if np.any(radius <= 0):
        k = int(np.flatnonzero(radius <= 0)[0])
        raise ValueError(f"centreline file {path!r}: radius of point {k} is {radius[k]} (<= 0)")
    scale = _UNITS[units]
    try:
        return Vessel(pts * scale, radius * scale, smooth=smooth)
    except ValueError as exc:
        raise ValueError(f"centreline file {path!r}: {exc}") from None
