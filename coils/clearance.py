"""Exact clearance between boxes or segments and coil windings.

A coaxial coil group (:class:`~coils.coaxial.CoaxialCoils`: a coil, a pair) holds, in its local
frame (``axis`` = local z, centred on ``center``):

* winding cross-sections, rows ``(z0, radius, width, height)``, each the closed solid of
  revolution ``|z - z0| <= width/2, |rho - radius| <= height/2`` (``rho`` = distance from the
  axis), where the filament model does not hold;
* filaments, rows ``(z0, radius, current)``: circles on which the field is singular; the field
  is refused within ``ON_WIRE_TOL * radius`` of one.

This module decides, without sampling, whether a closed convex shape -- an axis-aligned
:class:`Box` (possibly flat) or a :class:`Segment` -- meets a winding, and how far it is from
each filament.  A box is clear of the windings of a field iff :func:`winding_contacts` finds
nothing; then the field can be evaluated at every point of the box (the converse holds up to the
boundary: the windings are taken closed, the direct field refuses only their interior).

Method
------
*Winding*: in the coil frame, the shape cut by the slab ``|z - z0| <= width/2`` is a convex
polytope whose vertices are the shape's vertices inside the slab and the crossings of its edges
with the two slab planes.  ``rho`` is convex and the polytope connected, so ``rho`` takes every
value between its minimum and maximum there: the maximum is at a vertex, the minimum is the
distance from the axis to the convex hull of the vertices projected on the local xy-plane (zero
if the hull holds the axis).  The shape meets the winding iff the cut is not empty and
``[min rho, max rho]`` meets ``[radius - height/2, radius + height/2]``.

*Filament*: along the circle ``q(phi)``, ``f(phi) = dist(q(phi), shape)^2`` is continuously
differentiable (the shape is convex).  Where ``f > 0`` at its minimum, ``f`` equals there the
squared distance to the affine hull of the shape's face holding the nearest point (a vertex, an
edge, a facet), a trigonometric polynomial of degree 2 in ``phi`` whose stationary points are
the roots of a quartic in ``exp(i phi)``; where ``f = 0`` (the circle enters a box) the circle
crosses a facet plane (or lies wholly inside).  The exact distance is the smallest true distance
over all these candidate angles (polished by Newton steps); a candidate can only overestimate,
never underestimate it.

Both tests are exact up to rounding, i.e. to a few ulp of the coordinates: a box touching a
winding meets it, a box a few ulp clear of it is clear.  For coil axes along x, y or z the coil
frame is a signed permutation, which adds no rounding of its own.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ._validate import as_vector, nonnegative
from .coaxial import ON_WIRE_TOL, coaxial_parts
from .field import Field, FieldSum, as_field

__all__ = [
    "Box",
    "Segment",
    "WindingContact",
    "meets_windings",
    "filament_distances",
    "winding_contacts",
    "check_clear",
]

_EPS = np.finfo(float).eps


# -- convex shapes --------------------------------------------------------------------------------
class Box:
    """A closed axis-aligned box (flat or a point if ``lower == upper`` on some axes).

    Parameters
    ----------
    lower, upper : array-like, shape (3,)
        Opposite corners, m, ``lower <= upper`` on every axis.
    """

    def __init__(self, lower, upper):
        self.lower = as_vector(lower, "lower")
        self.upper = as_vector(upper, "upper")
        if np.any(self.lower > self.upper):
            raise ValueError(
                f"lower must not exceed upper on any axis; got lower={self.lower.tolist()}, "
                f"upper={self.upper.tolist()}"
            )
        corners = np.array(list(itertools.product((0, 1), repeat=3)))  # (8, 3), vertex 4i+2j+k
        #: Vertices (8, 3), m.
        self.vertices = np.where(corners == 1, self.upper, self.lower)
        #: Edges (12, 2): vertex pairs differing on one axis.
        self.edges = np.array(
            [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]
        )

    def faces(self, low: np.ndarray, high: np.ndarray):
        """Affine hulls of the 27 faces (vertices, edges, facets, interior).

        Parameters
        ----------
        low, high : ndarray, shape (f, 3)
            Bounding boxes of f curves, m.

        Returns
        -------
        point : ndarray, shape (27, 3)
            A point of each face's affine hull, m.
        projector : ndarray, shape (27, 3, 3)
            Projector onto the directions normal to it.
        reachable : ndarray of bool, shape (f, 27)
            False where no point of the curve's bounding box has its nearest box point in the
            face's relative interior (the face cannot be the nearest one).
        """
        status = np.array(list(itertools.product((0, 1, 2), repeat=3)))  # 0 lower, 1 upper, 2 free
        point = np.where(status == 1, self.upper, self.lower)
        projector = np.zeros((27, 3, 3))
        idx = np.arange(3)
        projector[:, idx, idx] = status != 2
        lo, hi = low[:, None, :], high[:, None, :]
        ok = np.where(
            status == 0,
            lo <= self.lower,
            np.where(status == 1, hi >= self.upper, (lo <= self.upper) & (hi >= self.lower)),
        )
        return point, projector, ok.all(axis=2)

    def planes(self) -> tuple[np.ndarray, np.ndarray]:
        """Facet planes ``normal . x = level``: normals (6, 3) and levels (6,)."""
        normals = np.vstack([np.eye(3), np.eye(3)])
        return normals, np.concatenate([self.lower, self.upper])

    def squared_distance(self, q: np.ndarray) -> np.ndarray:
        """Squared distance (m^2) from points ``q`` (..., 3) to the box."""
        d = q - np.clip(q, self.lower, self.upper)
        return np.einsum("...i,...i->...", d, d)

    def __repr__(self):
        return f"Box(lower={self.lower.tolist()}, upper={self.upper.tolist()})"

    def describe(self) -> str:
        return f"box lower={self.lower.tolist()} m, upper={self.upper.tolist()} m"


class Segment:
    """A closed straight segment (a point if ``start == end``).

    Parameters
    ----------
    start, end : array-like, shape (3,)
        End points, m.
    """

    def __init__(self, start, end):
        self.start = as_vector(start, "start")
        self.end = as_vector(end, "end")
        self.vertices = np.vstack([self.start, self.end])
        self.edges = np.array([[0, 1]])
        self._d = self.end - self.start
        self._dd = float(self._d @ self._d)

    def faces(self, low: np.ndarray, high: np.ndarray):
        """Affine hulls of the faces (the two ends, the line): a point (3, 3) of each, the
        projector (3, 3, 3) onto the directions normal to it, and (f, 3) True (every face is
        reachable from f curves with bounding boxes ``low``, ``high``; see :meth:`Box.faces`)."""
        projector = np.broadcast_to(np.eye(3), (3, 3, 3)).copy()
        if self._dd > 0:
            projector[2] -= np.outer(self._d, self._d) / self._dd
        point = np.vstack([self.start, self.end, self.start])
        return point, projector, np.ones((len(low), 3), dtype=bool)

    def planes(self) -> tuple[np.ndarray, np.ndarray]:
        """Where the nearest point reaches an end: ``d . x = d . start`` and ``d . end``."""
        return np.vstack([self._d, self._d]), np.array([self._d @ self.start, self._d @ self.end])

    def squared_distance(self, q: np.ndarray) -> np.ndarray:
        """Squared distance (m^2) from points ``q`` (..., 3) to the segment."""
        rel = q - self.start
        if self._dd > 0:
            t = np.clip(np.einsum("...i,i->...", rel, self._d) / self._dd, 0.0, 1.0)
            rel = rel - t[..., None] * self._d
        return np.einsum("...i,...i->...", rel, rel)

    def __repr__(self):
        return f"Segment(start={self.start.tolist()}, end={self.end.tolist()})"

    def describe(self) -> str:
        return f"segment from {self.start.tolist()} m to {self.end.tolist()} m"


# -- windings -------------------------------------------------------------------------------------
def _slab_cut(vertices: np.ndarray, edges: np.ndarray, zl: float, zu: float) -> np.ndarray:
    """Vertices (k, 3) of the convex polytope conv(vertices) cut by the slab ``zl <= z <= zu``."""
    z = vertices[:, 2]
    parts = [vertices[(z >= zl) & (z <= zu)]]
    pa, pb = vertices[edges[:, 0]], vertices[edges[:, 1]]
    za, zb = pa[:, 2], pb[:, 2]
    for c in {zl, zu}:
        cross = (np.minimum(za, zb) < c) & (np.maximum(za, zb) > c)
        if np.any(cross):
            a, b = pa[cross], pb[cross]
            t = (c - a[:, 2]) / (b[:, 2] - a[:, 2])
            pts = a + t[:, None] * (b - a)
            pts[:, 2] = c
            parts.append(pts)
    return np.vstack(parts)


def _distance_from_origin_to_hull(p: np.ndarray) -> float:
    """Distance from the origin to the convex hull of 2D points ``p`` (k, 2), k >= 1.

    Outside the hull the nearest point lies on a hull edge, i.e. on a segment between two of the
    points, and every such segment lies in the hull: the distance is the smallest distance to the
    segments between all pairs, provided its nearest point ``c`` supports the hull
    (``p . c >= |c|^2`` for every point); otherwise the origin is inside and the distance is 0.
    """
    i, j = np.triu_indices(len(p))  # i == j: the points themselves
    a, d = p[i], p[j] - p[i]
    dd = np.einsum("ij,ij->i", d, d)
    safe = np.where(dd > 0, dd, 1.0)
    t = np.where(dd > 0, np.clip(-np.einsum("ij,ij->i", a, d) / safe, 0.0, 1.0), 0.0)
    c = a + t[:, None] * d
    dist = np.hypot(c[:, 0], c[:, 1])
    k = int(np.argmin(dist))
    if dist[k] == 0.0:
        return 0.0
    support = p @ c[k] - dist[k] ** 2
    slack = 16 * _EPS * float(np.abs(p).max()) * dist[k]
    return float(dist[k]) if np.all(support >= -slack) else 0.0


def meets_windings(part, shape) -> np.ndarray:
    """Which winding cross-sections of a coaxial group the closed ``shape`` meets.

    Parameters
    ----------
    part : CoaxialCoils
        A coil or pair (anything with ``windings`` rows ``(z0, radius, width, height)`` in m
        and ``to_local``).
    shape : Box or Segment
        The closed shape, m.

    Returns
    -------
    ndarray of bool, shape (w,)
        True where the shape has a point in the closed cross-section swept about the axis.

    Examples
    --------
    >>> from coils import Coil
    >>> coil = Coil(0.1, 100, 1.0, axis="z", winding=(0.01, 0.01))  # rho 95..105, z -5..5 mm
    >>> meets_windings(coil, Box((0.105, -0.01, 0.0), (0.2, 0.01, 0.01))).tolist()  # touches
    [True]
    >>> meets_windings(coil, Box((0.106, -0.01, 0.0), (0.2, 0.01, 0.01))).tolist()
    [False]
    """
    sections = np.asarray(part.windings, dtype=float).reshape(-1, 4)
    out = np.zeros(len(sections), dtype=bool)
    if not len(sections):
        return out
    local = part.to_local(shape.vertices)
    for k, (z0, a, w, h) in enumerate(sections):
        cut = _slab_cut(local, shape.edges, z0 - 0.5 * w, z0 + 0.5 * w)
        if not len(cut):
            continue
        xy = cut[:, :2]
        rho_max = float(np.hypot(xy[:, 0], xy[:, 1]).max())
        rho_min = _distance_from_origin_to_hull(xy)
        out[k] = rho_min <= a + 0.5 * h and rho_max >= a - 0.5 * h
    return out


# -- filaments ------------------------------------------------------------------------------------
def _quartic_angles(coef: np.ndarray) -> np.ndarray:
    """Arguments of the roots (n, 6) of ``c4 z^4 + c3 z^3 + c1 z + c0`` (coef (n, 4) complex,
    highest first, no z^2 term): the four roots where ``c4 != 0`` and the two of the quadratic
    ``c3 z^2 + c1`` (the limit ``c4 -> 0``); absent roots are 0."""
    n = coef.shape[0]
    c4, c3, c1, c0 = coef.T
    out = np.zeros((n, 6))
    scale = np.abs(coef).max(axis=1)
    quartic = np.abs(c4) > _EPS**2 * scale  # else the companion overflows; the quadratic holds
    if np.any(quartic):
        lead = c4[quartic]
        companion = np.zeros((int(quartic.sum()), 4, 4), dtype=complex)
        companion[:, 0, 0] = -c3[quartic] / lead
        companion[:, 0, 2] = -c1[quartic] / lead
        companion[:, 0, 3] = -c0[quartic] / lead
        companion[:, [1, 2, 3], [0, 1, 2]] = 1.0
        out[quartic, :4] = np.angle(np.linalg.eigvals(companion))
    quad = c3 != 0
    root = np.sqrt(-c1[quad] / c3[quad])
    out[quad, 4] = np.angle(root)
    out[quad, 5] = np.angle(-root)
    return out


def filament_distances(part, shape) -> np.ndarray:
    """Exact distance from the closed ``shape`` to each filament circle of a coaxial group.

    Parameters
    ----------
    part : CoaxialCoils
        A coil or pair (``filaments`` rows ``(z0, radius, current)``, ``center``, ``rotation``).
    shape : Box or Segment
        The closed shape, m.

    Returns
    -------
    ndarray, shape (f,)
        Distances, m (0 where the circle meets the shape).

    Examples
    --------
    >>> from coils import Coil
    >>> coil = Coil(0.1, 1, 1.0, axis="z")
    >>> float(filament_distances(coil, Segment((0.13, 0, -1), (0.13, 0, 1)))[0])  # m
    0.03
    >>> strip = Box((-0.06, 0.0, 0.03), (0.06, 0.0, 0.1))  # nearest: (0.06, 0, 0.03), 3-4-5
    >>> round(float(filament_distances(coil, strip)[0]), 15)
    0.05
    """
    fil = np.asarray(part.filaments, dtype=float).reshape(-1, 3)
    R = np.asarray(part.rotation, dtype=float)
    U, V, n = R[:, 0], R[:, 1], R[:, 2]
    centres = part.center + fil[:, :1] * n  # (f, 3)
    radius = fil[:, 1]
    nf = len(fil)
    reach = radius[:, None] * np.hypot(U, V) * (1 + 1e-12) + 1e-12 * np.abs(centres)
    point, M, reachable = shape.faces(centres - reach, centres + reach)
    # 1. stationary points of the squared distance to the affine hull of each face the circle
    #    can have its nearest point on (see the module docstring), Newton-polished
    jf, jface = np.nonzero(reachable)
    a = radius[jf]
    Mw = np.einsum("kab,kb->ka", M[jface], centres[jf] - point[jface])
    P, Q = Mw @ V, Mw @ U
    aS = a * np.einsum("a,kab,b->k", U, M, V)[jface]
    aT = a * (np.einsum("a,kab,b->k", V, M, V) - np.einsum("a,kab,b->k", U, M, U))[jface]
    coef = np.column_stack([aS - 0.5j * aT, P + 1j * Q, P - 1j * Q, aS + 0.5j * aT])
    phi = _quartic_angles(coef)  # (pairs, 6)
    trig = [c[:, None] for c in (P, Q, aS, aT)]
    polished = _newton(phi, lambda t: _trig_g(t, *trig), lambda t: _trig_dg(t, *trig), 3)
    face_angles = np.concatenate([phi, polished], axis=1)
    d2 = np.full(nf, np.inf)
    np.minimum.at(d2, jf, _squared_distance_on_circle(shape, centres[jf], a, U, V, face_angles))
    # 2. where the nearest point changes face: the circle crosses a plane normal . x = level
    #    (this also finds the circle entering a box, where the distance is 0)
    normals, levels = shape.planes()
    offset = levels - centres @ normals.T  # (f, L)
    ac = radius[:, None] * (normals @ U)
    as_ = radius[:, None] * (normals @ V)
    amp = np.hypot(ac, as_)
    psi = np.arctan2(as_, ac)
    with np.errstate(over="ignore"):
        half = np.arccos(np.clip(offset / np.where(amp > 0, amp, 1.0), -1.0, 1.0))
    cross = np.concatenate([psi + half, psi - half], axis=1)  # (f, 2L)
    amp, psi, offset = (np.concatenate([x, x], axis=1) for x in (amp, psi, offset))
    polished = _newton(
        cross, lambda t: amp * np.cos(t - psi) - offset, lambda t: -amp * np.sin(t - psi), 2
    )
    fixed = np.broadcast_to(np.arange(4) * (np.pi / 2), (nf, 4))
    angles = np.concatenate([cross, polished, fixed], axis=1)
    d2 = np.minimum(d2, _squared_distance_on_circle(shape, centres, radius, U, V, angles))
    return np.sqrt(d2)


def _squared_distance_on_circle(shape, centres, radius, U, V, angles) -> np.ndarray:
    """Smallest squared distance (m^2) from ``shape`` to the points at ``angles`` (k, c) on k
    circles (centres (k, 3), radius (k,), in-plane axes U, V): shape (k,)."""
    angles = np.where(np.isfinite(angles), angles, 0.0)
    q = centres[:, None, :] + radius[:, None, None] * (
        np.cos(angles)[..., None] * U + np.sin(angles)[..., None] * V
    )
    return shape.squared_distance(q).min(axis=1, initial=np.inf)


def _trig_g(phi, P, Q, aS, aT):
    return P * np.cos(phi) - Q * np.sin(phi) + aS * np.cos(2 * phi) + 0.5 * aT * np.sin(2 * phi)


def _trig_dg(phi, P, Q, aS, aT):
    return -P * np.sin(phi) - Q * np.cos(phi) - 2 * aS * np.sin(2 * phi) + aT * np.cos(2 * phi)


def _newton(phi: np.ndarray, g, dg, steps: int) -> np.ndarray:
    """``steps`` Newton steps on ``g(phi) = 0`` (elementwise), each at most 1 rad; a zero slope
    leaves the angle where it is."""
    for _ in range(steps):
        slope = dg(phi)
        with np.errstate(over="ignore", invalid="ignore"):
            step = np.where(slope != 0, g(phi) / np.where(slope != 0, slope, 1.0), 0.0)
        phi = phi - np.clip(np.nan_to_num(step), -1.0, 1.0)
    return phi


# -- over a whole field ---------------------------------------------------------------------------
@dataclass(frozen=True)
class WindingContact:
    """A winding cross-section or filament that a shape meets.

    Attributes
    ----------
    part : Field
        The coaxial group (coil or pair) it belongs to.
    kind : {"winding", "filament"}
        What is met.
    index : int
        Row in ``part.windings`` or ``part.filaments``.
    z0, radius : float
        Axial position in the group's frame and mean radius, m.
    width, height : float
        Cross-section, m (0 for a filament).
    distance : float
        Distance from the shape to the filament, m (0 for a winding: the shape meets it).
    """

    part: Field
    kind: str
    index: int
    z0: float
    radius: float
    width: float = 0.0
    height: float = 0.0
    distance: float = 0.0

    def __str__(self) -> str:
        mm = 1e3
        where = f"{mm * self.z0:+.6g} mm along the axis {np.round(self.part.axis, 6).tolist()}"
        if self.kind == "winding":
            what = (
                f"winding {self.index} ({mm * self.width:.6g} mm x {mm * self.height:.6g} mm "
                f"section at radius {mm * self.radius:.6g} mm, {where})"
            )
        else:
            what = (
                f"filament {self.index} (radius {mm * self.radius:.6g} mm, {where}; "
                f"{self.distance:.3g} m away)"
            )
        return f"{what} of {self.part!r}"


def _groups(field: Field):
    """Coaxial groups of ``field``: :func:`~coils.coaxial.coaxial_parts`, which walks sums and
    scalings, extended to any wrapper holding its source as ``.field`` -- a gridded cache
    evaluates its wrapped field outside its own (clear) box."""
    if isinstance(field, FieldSum):
        for p in field.parts:
            yield from _groups(p)
    elif isinstance(getattr(field, "field", None), Field):  # ScaledField, GriddedField
        yield from _groups(field.field)
    else:
        yield from coaxial_parts(field)


def winding_contacts(field: Field, shape, margin: float = ON_WIRE_TOL) -> list[WindingContact]:
    """Every winding cross-section the closed ``shape`` meets and every filament within
    ``margin`` x its radius of it, over all coaxial groups of ``field`` (sums, scalings).

    Parameters
    ----------
    field : Field
        A coil, pair, system, sum or scaled field (other sources have no windings).
    shape : Box or Segment
        The closed shape, m.
    margin : float
        Clearance demanded from the filaments, as a fraction of their radius (>= 0); the default
        is the distance within which the direct field refuses to evaluate.

    Returns
    -------
    list of WindingContact
        Windings first, then filaments, group by group; empty if the shape is clear.
    """
    field = as_field(field)
    margin = nonnegative(margin, "margin")
    if not isinstance(shape, Box | Segment):
        raise ValueError(f"shape must be a Box or a Segment; got {type(shape).__name__}")
    contacts = []
    for part in _groups(field):
        sections = np.asarray(part.windings, dtype=float).reshape(-1, 4)
        for k in np.flatnonzero(meets_windings(part, shape)):
            contacts.append(WindingContact(part, "winding", int(k), *map(float, sections[k])))
        fil = np.asarray(part.filaments, dtype=float).reshape(-1, 3)
        dist = filament_distances(part, shape)
        for k in np.flatnonzero(dist <= margin * fil[:, 1]):
            z0, a, _ = fil[k]
            contacts.append(
                WindingContact(part, "filament", int(k), float(z0), float(a), distance=dist[k])
            )
    return contacts


def check_clear(field: Field, shape, what: str = "the box", margin: float = ON_WIRE_TOL) -> None:
    """Raise ``ValueError`` naming the first winding or filament ``shape`` meets (see
    :func:`winding_contacts`); return None if it is clear.

    Parameters
    ----------
    field : Field
    shape : Box or Segment
    what : str
        How the message names the shape, e.g. "the grid box".
    margin : float
        Clearance from the filaments, fraction of their radius.
    """
    contacts = winding_contacts(field, shape, margin)
    if not contacts:
        return
    first = contacts[0]
    more = f" (and {len(contacts) - 1} more windings/filaments)" if len(contacts) > 1 else ""
    if first.kind == "winding":
        reason = "the filament model does not hold inside a winding"
    else:
        reason = f"the field is singular within {margin:g} x radius of a filament"
    raise ValueError(
        f"{what} ({shape.describe()}) meets {first}{more}: {reason}; shrink or move it to keep "
        f"it clear of the windings"
    )
