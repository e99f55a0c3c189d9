"""Vessel presets: a straight tube, a bend (straight - circular arc - straight) with the arc
treated exactly, an aneurysm (or a stenosis: a smooth local change of radius) and a
side-branch junction.  Also available as ``Vessel.straight``, ``Vessel.bend``,
``Vessel.aneurysm`` and ``Vessel.branch``.

A preset's vessel remembers how it was built: ``vessel.replace(**changes)`` calls the preset
again with the changes (``presets.bend(0.02, 1.2, 1e-3).replace(angle=0.6)``).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from coils._immutable import remembers_recipe
from coils._validate import as_axis, as_vector, finite_scalar, nonnegative, positive

from .centerline import Pieces, arc_piece, line_pieces, split_lines
from .network import VesselNetwork
from .obstacle import _mm
from .profile import Smooth, SmoothSection
from .vessel import Vessel, _as_ends

__all__ = ["straight", "bend", "aneurysm", "branch"]


def _frame(direction, plane_normal) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit direction d, the plane's unit normal n (made perpendicular to d) and q = n x d,
    the direction a positive turn about n heads to."""
    d = as_axis(direction, "direction")
    n = as_axis(plane_normal, "plane_normal")
    n = n - (n @ d) * d
    size = float(np.linalg.norm(n))
    if size < 1e-9:
        raise ValueError(
            f"plane_normal must not be parallel to direction; got {np.round(n + (n @ d) * d, 6)}"
        )
    n = n / size
    return d, n, np.cross(n, d)


@remembers_recipe
def straight(length, radius, start=(0.0, 0.0, 0.0), direction=(1.0, 0.0, 0.0), ends="extend"):
    """A straight tube of constant ``radius`` from ``start`` along ``direction``.

    Parameters
    ----------
    length : float
        m.
    radius : float
        m.
    start : array-like, shape (3,)
        First centreline point, m.
    direction : array-like, shape (3,), or str
        Axis direction (normalised), or ``"x"``, ``"-y"``.
    ends : {"extend", "round"} or (str, str)
        See :class:`~coilrod.contact.Vessel`.

    Returns
    -------
    Vessel

    Examples
    --------
    >>> v = straight(0.05, 2e-3)
    >>> float(v.gap([0.01, 0.0, 0.0])[0]), float(v.gap([0.1, 0.0, 0.0])[0])
    (0.002, 0.002)
    """
    length = positive(length, "length")
    start = as_vector(start, "start")
    d = as_axis(direction, "direction")
    return Vessel(np.array([start, start + length * d]), radius, ends=ends)


@remembers_recipe
def bend(
    bend_radius,
    angle,
    radius,
    straight_before=0.0,
    straight_after=0.0,
    start=(0.0, 0.0, 0.0),
    direction=(1.0, 0.0, 0.0),
    plane_normal=(0.0, 0.0, 1.0),
    ends="extend",
):
    """A straight piece, a circular arc and a straight piece, tangent-continuous (G1).

    The arc is an exact primitive (no sampling): the gap inside the bend is ``R - |p - c|`` with
    ``c`` the nearest point of the true circle.  The curvature jumps at the two joints, so the
    hessian jumps across their normal planes; gap and gradient are continuous.

    Parameters
    ----------
    bend_radius : float
        Radius of the arc of the centreline, m; must exceed ``radius``.
    angle : float
        Turning angle, rad, in (0, 2 pi); the centreline turns counterclockwise about
        ``plane_normal``.
    radius : float
        Tube radius, m.
    straight_before, straight_after : float
        Lengths of the straight pieces, m (0: none; the ends still extend if ``ends`` says so).
    start : array-like, shape (3,)
        First centreline point, m.
    direction : array-like, shape (3,), or str
        Initial direction.
    plane_normal : array-like, shape (3,), or str
        Normal of the bend plane (its component along ``direction`` is removed).
    ends : {"extend", "round"} or (str, str)

    Returns
    -------
    Vessel

    Examples
    --------
    A quarter bend of centreline radius 10 mm: a point 9 mm from the centre of curvature, in
    the plane, is 1 mm from the centreline.

    >>> v = bend(0.01, np.pi / 2, 2e-3)
    >>> centre = np.array([0.0, 0.01, 0.0])
    >>> p = centre + 0.009 * np.array([np.sin(0.3), -np.cos(0.3), 0.0])
    >>> round(float(v.gap(p)[0]), 12)
    0.001
    """
    rho = positive(bend_radius, "bend_radius")
    angle = finite_scalar(angle, "angle")
    if not 0.0 < angle < 2.0 * math.pi:
        raise ValueError(f"angle must be in (0, 2 pi) rad; got {angle}")
    radius = positive(radius, "radius")
    if rho <= radius:
        raise ValueError(
            f"bend_radius must exceed radius (the inner wall of the bend folds otherwise); got "
            f"bend_radius {_mm(rho)}, radius {_mm(radius)}"
        )
    before = nonnegative(straight_before, "straight_before")
    after = nonnegative(straight_after, "straight_after")
    start = as_vector(start, "start")
    d, _, q = _frame(direction, plane_normal)
    parts: list[Pieces] = []
    s = 0.0
    p1 = start + before * d
    if before > 0:
        parts.append(line_pieces(start, d, [0.0], [before], [0.0]))
        s = before
    center = p1 + rho * q
    parts.append(arc_piece(center, -q, d, rho, s, angle))
    s += rho * angle
    p2 = center + rho * (-math.cos(angle) * q + math.sin(angle) * d)
    t2 = math.cos(angle) * d + math.sin(angle) * q
    if after > 0:
        parts.append(line_pieces(p2, t2, [s], [s + after], [s]))
    from .profile import ConstantSection

    points = [start, p1, p2, p2 + after * t2]
    return Vessel._from_pieces(Pieces.concat(parts), ConstantSection(radius), ends, points)


@remembers_recipe
def aneurysm(
    length,
    radius,
    bulge_radius,
    bulge_center=None,
    bulge_width=None,
    start=(0.0, 0.0, 0.0),
    direction=(1.0, 0.0, 0.0),
    ends="extend",
):
    """A straight tube whose radius swells smoothly (a fusiform aneurysm) or narrows (a
    stenosis, ``bulge_radius < radius``) about one point.

    The cross-section radius is Gaussian in arc length,
    ``R(s) = radius + (bulge_radius - radius) exp(-4 ln2 (s - bulge_center)^2 / bulge_width^2)``
    (``bulge_width`` is the full width at half the excess).  The lumen is the union of the
    largest balls on the axis (:mod:`coilrod.contact.profile`), whose section matches ``R`` to
    ``Vessel.radius_error`` (about 1e-12 m for millimetre vessels); the gap is exact to that.

    Parameters
    ----------
    length : float
        Centreline length, m.
    radius : float
        Radius away from the bulge, m.
    bulge_radius : float
        Radius at the bulge's centre, m.
    bulge_center : float, optional
        Arc length of the bulge's centre, m; default ``length / 2``.
    bulge_width : float, optional
        Full width at half maximum of the radius excess, m; default ``2 * bulge_radius``.
    start, direction, ends
        As for :func:`straight`.

    Returns
    -------
    Vessel

    Examples
    --------
    >>> v = aneurysm(0.04, 1e-3, 2e-3)
    >>> round(float(v.radius_at(0.02)), 9), round(float(v.gap([0.02, 0.0, 0.0])[0]), 9)
    (0.002, 0.002)
    """
    length = positive(length, "length")
    radius = positive(radius, "radius")
    bulge = positive(bulge_radius, "bulge_radius")
    center = 0.5 * length if bulge_center is None else finite_scalar(bulge_center, "bulge_center")
    width = 2.0 * bulge if bulge_width is None else positive(bulge_width, "bulge_width")
    start = as_vector(start, "start")
    d = as_axis(direction, "direction")
    amp = bulge - radius
    a = 4.0 * math.log(2.0) / width**2

    def f(s):
        return radius + amp * np.exp(-a * (s - center) ** 2)

    def df(s):
        return -2.0 * a * (s - center) * amp * np.exp(-a * (s - center) ** 2)

    def d2f(s):
        x2 = a * (s - center) ** 2
        return 2.0 * a * amp * (2.0 * x2 - 1.0) * np.exp(-x2)

    section = SmoothSection(Smooth(f, df, d2f, 0.0, length), length)
    pieces = split_lines(line_pieces(start, d, [0.0], [length], [0.0]), section.minimum)
    try:
        return Vessel._from_pieces(pieces, section, ends, [start, start + length * d])
    except ValueError as exc:
        if str(exc).startswith("radius:"):
            raise ValueError("bulge_width" + str(exc)[len("radius") :]) from None
        raise


@remembers_recipe
def branch(
    length,
    radius,
    branch_length,
    branch_radius=None,
    branch_angle=math.pi / 2,
    branch_at=None,
    start=(0.0, 0.0, 0.0),
    direction=(1.0, 0.0, 0.0),
    plane_normal=(0.0, 0.0, 1.0),
    ends="extend",
):
    """A straight main vessel with a straight side branch (a T or Y junction): the union of
    two tubes, :class:`~coilrod.contact.VesselNetwork`.

    The branch leaves the main centreline at arc length ``branch_at``, turned by
    ``branch_angle`` from ``direction`` about ``plane_normal``; its root is a round end inside
    the main vessel (so it adds nothing behind the junction), its far end follows ``ends[1]``.

    Parameters
    ----------
    length, radius : float
        Main vessel, m.
    branch_length : float
        Branch centreline length from the main centreline, m (longer than ``radius``).
    branch_radius : float, optional
        m; default ``radius``; at most ``radius``.
    branch_angle : float
        Angle between the main direction and the branch, rad, in (0, pi): pi/2 a T junction,
        smaller a Y.
    branch_at : float, optional
        Arc length of the junction on the main centreline, m; default ``length / 2``.
    start, direction, plane_normal
        As for :func:`bend`.
    ends : {"extend", "round"} or (str, str)
        Ends of the main vessel; the branch's far end takes the second.

    Returns
    -------
    VesselNetwork

    Examples
    --------
    >>> net = branch(0.04, 1e-3, 0.02)
    >>> net.contains([[0.02, 0.015, 0.0], [0.01, 0.015, 0.0]]).tolist()
    [True, False]
    """
    length = positive(length, "length")
    radius = positive(radius, "radius")
    blen = positive(branch_length, "branch_length")
    brad = radius if branch_radius is None else positive(branch_radius, "branch_radius")
    if brad > radius:
        raise ValueError(
            f"branch_radius must not exceed radius (the branch's round root would poke out of "
            f"the main vessel); got {_mm(brad)} > {_mm(radius)}"
        )
    if blen <= radius:
        raise ValueError(
            f"branch_length must exceed radius (the branch would end inside the main vessel); "
            f"got {_mm(blen)}"
        )
    angle = finite_scalar(branch_angle, "branch_angle")
    if not 0.0 < angle < math.pi:
        raise ValueError(f"branch_angle must be in (0, pi) rad; got {angle}")
    at = 0.5 * length if branch_at is None else finite_scalar(branch_at, "branch_at")
    if not 0.0 <= at <= length:
        raise ValueError(f"branch_at must lie in [0, length] = [0, {_mm(length)}]; got {_mm(at)}")
    start = as_vector(start, "start")
    d, _, q = _frame(direction, plane_normal)

    main_ends = _as_ends(ends)
    main = Vessel(np.array([start, start + length * d]), radius, ends=main_ends)
    root = start + at * d
    tip = root + blen * (math.cos(angle) * d + math.sin(angle) * q)
    side = Vessel(np.array([root, tip]), brad, ends=("round", main_ends[1]))
    return VesselNetwork([main, side])


def _as_classmethod(func):
    """``Vessel.<name>(...)``: the preset ``func`` as a class method of Vessel (attached here,
    so that vessel.py does not import this module)."""

    @functools.wraps(func)
    def method(cls, *args, **kwargs):
        return func(*args, **kwargs)

    method.__doc__ = (
        f"{func.__doc__.splitlines()[0]} See :func:`coilrod.contact.presets.{func.__name__}`."
    )
    return classmethod(method)


for _preset in (straight, bend, aneurysm, branch):
    setattr(Vessel, _preset.__name__, _as_classmethod(_preset))
del _preset
