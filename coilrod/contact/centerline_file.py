"""A vessel from a centreline with radii, as VMTK writes it (``vmtkcenterlines``).

VMTK's centreline table holds the centreline points and, per point, the radius of the maximum
inscribed sphere (array ``MaximumInscribedSphereRadius``).  :func:`read_table` reads it
from a CSV table (columns ``x, y, z`` and ``MaximumInscribedSphereRadius`` or ``radius``) or
from an ASCII VTK PolyData file (``.vtp``; the points in their order, or in the order of the
first polyline); :meth:`Vessel.from_centerline_file` (or
:func:`~coilrod.contact.read_centerline`) builds the vessel with those radii.
"""

from __future__ import annotations

import csv
import os
import xml.etree.ElementTree as ET

import numpy as np

from coils._validate import as_choice

__all__ = ["read_table"]

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


def read_table(path, units: str = "m"):
    """Points (n, 3) and radii (n,) in m of a centreline file, and the file's label for
    messages; see :func:`coilrod.contact.read_centerline`."""
    units = as_choice(units, "units", tuple(_UNITS))
    if not isinstance(path, str | os.PathLike):
        raise ValueError(f"path must be a file name; got {path!r}")
    path = os.fspath(path)
    label = f"centreline file {path!r}"
    if not os.path.isfile(path):
        raise ValueError(f"{label} does not exist")
    ext = os.path.splitext(path)[1].lower()
    if ext == ".csv":
        pts, radius = _read_csv(path)
    elif ext == ".vtp":
        pts, radius = _read_vtp(path)
    else:
        raise ValueError(f"{label}: the format must be .csv or .vtp")
    if len(pts) < 2:
        raise ValueError(f"{label} has {len(pts)} points; at least 2 needed")
    if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(radius))):
        raise ValueError(f"{label} has non-finite values")
    if np.any(radius <= 0):
        k = int(np.flatnonzero(radius <= 0)[0])
        raise ValueError(f"{label}: radius of point {k} is {radius[k]} (<= 0)")
    scale = _UNITS[units]
    return pts * scale, radius * scale, label
