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
import io
import os
import warnings
import xml.etree.ElementTree as ET

import numpy as np

from coils._files import input_path, read_text
from coils._validate import as_choice

from ..errors import UnitsWarning

__all__ = ["read_table"]

_UNITS = {"m": 1.0, "mm": 1e-3}
#: Radii (m) outside which a file's units are doubted (coilrod.UnitsWarning): wider than an
#: aorta's 15 mm with a margin, narrower than a capillary's 5 um.
MAX_RADIUS, MIN_RADIUS = 0.05, 2e-6
_RADIUS_NAMES = ("maximuminscribedsphereradius", "radius", "r")


def _at_least_two(label: str, n: int) -> None:
    """ValueError unless a centreline (its file, or its first line) has n >= 2 points."""
    if n < 2:
        raise ValueError(f"{label} has {n} point{'' if n == 1 else 's'}; at least 2 needed")


def _read_csv(path: str):
    text = read_text(path, "centreline file")
    try:
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:  # e.g. a NUL byte
        raise ValueError(f"centreline file {path!r} is not a CSV table: {exc}") from None
    if not rows:
        raise ValueError(f"centreline file {path!r} is empty")
    head = [h.strip().lower() for h in rows[0]]
    twice = sorted({h for h in head if h and head.count(h) > 1})
    if twice:
        raise ValueError(f"centreline file {path!r}: column(s) {twice} appear more than once")
    try:
        cols = [head.index(c) for c in ("x", "y", "z")]
    except ValueError:
        raise ValueError(f"centreline file {path!r} needs columns x, y, z; got {rows[0]}") from None
    radii = [n for n in _RADIUS_NAMES if n in head]
    if not radii:
        raise ValueError(
            f"centreline file {path!r} needs a radius column (MaximumInscribedSphereRadius or "
            f"radius); got {rows[0]}"
        )
    if len(radii) > 1:
        raise ValueError(
            f"centreline file {path!r} has {len(radii)} radius columns "
            f"({', '.join(rows[0][head.index(n)] for n in radii)}); keep one"
        )
    rcol = head.index(radii[0])
    data = []
    for line, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        if len(row) != len(head):
            raise ValueError(
                f"centreline file {path!r}: line {line} has {len(row)} cells, the header "
                f"{len(head)}"
            )
        try:
            data.append([float(row[c]) for c in [*cols, rcol]])
        except ValueError as exc:
            raise ValueError(f"centreline file {path!r}: line {line}: {exc}") from None
    if not data:
        raise ValueError(f"centreline file {path!r} has a header but no points")
    data = np.array(data, float)
    return data[:, :3], data[:, 3]


def _read_vtp(path: str):
    text = read_text(path, "centreline file")
    try:
        root = ET.fromstring(text)
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

    pts = array(piece.find("./Points/DataArray"), "Points")
    if pts.size % 3:
        raise ValueError(
            f"centreline file {path!r}: Points holds {pts.size} numbers, not 3 per point"
        )
    pts = pts.reshape(-1, 3)
    _at_least_two(f"centreline file {path!r}", len(pts))  # (before its lines' offsets)
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
        c = array(conn, "line connectivity")
        o = array(offs, "line offsets")
        if not (np.all(c == np.round(c)) and np.all(o == np.round(o))):
            raise ValueError(f"centreline file {path!r}: line indices must be whole numbers")
        c, o = c.astype(np.int64), o.astype(np.int64)
        if len(o):
            if o[0] == 1:
                _at_least_two(f"centreline file {path!r}: its first line", 1)
            if not 2 <= o[0] <= len(c):
                raise ValueError(
                    f"centreline file {path!r}: the first line's offset is {o[0]}; it must be "
                    f"from 2 to the {len(c)} connectivity entries"
                )
            order = c[: o[0]]
            if order.min() < 0 or order.max() >= len(pts):
                raise ValueError(f"centreline file {path!r}: line indices out of range")
            pts, radius = pts[order], radius[order]
    return pts, radius


def read_table(path, units: str = "m"):
    """Points (n, 3) and radii (n,) in m of a centreline file, and the file's label for
    messages; see :func:`coilrod.contact.read_centerline`."""
    units = as_choice(units, "units", tuple(_UNITS))
    path = input_path(path, "centreline file")
    label = f"centreline file {path!r}"
    ext = os.path.splitext(path)[1].lower()
    if ext == ".csv":
        pts, radius = _read_csv(path)
    elif ext == ".vtp":
        pts, radius = _read_vtp(path)
    else:
        raise ValueError(f"{label}: the format must be .csv or .vtp")
    _at_least_two(label, len(pts))
    if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(radius))):
        raise ValueError(f"{label} has non-finite values")
    if np.any(radius <= 0):
        k = int(np.flatnonzero(radius <= 0)[0])
        raise ValueError(f"{label}: radius of point {k} is {radius[k]} (<= 0)")
    scale = _UNITS[units]
    r_min, r_max = scale * float(radius.min()), scale * float(radius.max())
    if r_max > MAX_RADIUS or r_min < MIN_RADIUS:
        other = "mm" if units == "m" else "m"
        warnings.warn(
            f"{label}: radii from {r_min:.3g} m to {r_max:.3g} m with units={units!r}: no blood "
            f"vessel is that {'wide' if r_max > MAX_RADIUS else 'narrow'}; is the file in "
            f"{other} (units={other!r})?",
            UnitsWarning,
            stacklevel=3,
        )
    return pts * scale, radius * scale, label
