"""How far a real field departs from its ideal (linearised) counterpart, and where it stays close.

For a uniform-field source (Helmholtz) the deviation at x is ``|B(x) - B0| / |B0|``; for a
gradient source (Maxwell, zero centre field) it is ``||G(x) - G0||_F / ||G0||_F``, where B0 and G0
are the field and gradient at the centre (``coil.ideal()``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

from ._validate import as_axis, as_choice, as_count, as_points, as_vector, positive
from .coaxial import coaxial_parts
from .field import Field, as_field
from .ideal import LinearField, linearize

__all__ = ["deviation", "uniformity", "UniformityReport"]


def _pick_quantity(quantity: str, ideal: LinearField) -> str:
    quantity = as_choice(quantity, "quantity", ("B", "gradient", "auto"))
    if quantity == "auto":
        b = np.linalg.norm(ideal.B0)
        return "gradient" if b == 0.0 and np.any(ideal.G) else "B"
    return quantity


def deviation(
    field: Field, points, ideal: LinearField | None = None, quantity: str = "auto"
) -> np.ndarray:
    """Relative deviation of ``field`` from ``ideal`` at ``points``.

    Parameters
    ----------
    field : Field
        The real field.
    points : array-like, shape (n, 3)
        Positions, m.
    ideal : LinearField, optional
        The reference; default ``field.ideal()``.
    quantity : {"auto", "B", "gradient"}
        "B": ``|B - B_ideal(x)| / |B0|``; "gradient": ``||G - G0||_F / ||G0||_F``; "auto" picks
        "gradient" when the ideal centre field is zero.

    Returns
    -------
    ndarray, shape (n,)
        Dimensionless relative deviation.
    """
    field = as_field(field)
    pts = as_points(points)
    if ideal is None:
        if not hasattr(field, "ideal"):
            raise ValueError(
                f"field ({type(field).__name__}) has no ideal() to compare with; pass "
                f"ideal=LinearField(...)"
            )
        ideal = field.ideal()
    elif not isinstance(ideal, LinearField):
        raise ValueError(f"ideal must be a coils LinearField; got {type(ideal).__name__}")
    quantity = _pick_quantity(quantity, ideal)
    if quantity == "B":
        ref = np.linalg.norm(ideal.B0)
        if ref == 0:
            raise ValueError("the ideal field is zero at its origin: use quantity='gradient'")
        return np.linalg.norm(field.B(pts) - ideal.B(pts), axis=1) / ref
    ref = np.linalg.norm(ideal.G)
    if ref == 0:
        raise ValueError("the ideal gradient is zero: use quantity='B'")
    return np.linalg.norm(field.gradient(pts) - ideal.G, axis=(1, 2)) / ref


def _fibonacci_directions(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    return np.column_stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)])


@dataclass
class UniformityReport:
    """Extent of the region where a field stays within ``tol`` of its ideal counterpart.

    Attributes
    ----------
    quantity : str
        "B" or "gradient" (see :func:`deviation`).
    tol : float
        Relative tolerance.
    axial : float
        Distance (m) from the centre along the axis (both senses) within tol.
    radial : float
        Distance (m) from the centre in the mid-plane (all sampled directions) within tol.
    sphere : float
        Radius (m) of the largest centred sphere within tol (over sampled directions).
    max_deviation : float or None
        Largest deviation over ``points`` (e.g. the robot's reach), if points were given.
    points, deviations : ndarray or None
        The points (n, 3) m examined and their deviations (n,).
    """

    quantity: str
    tol: float
    axial: float
    radial: float
    sphere: float
    max_deviation: float | None = None
    points: np.ndarray | None = field(default=None, repr=False)
    deviations: np.ndarray | None = field(default=None, repr=False)

    @property
    def within_tol(self) -> bool | None:
        """True if every examined point is within tol (None if no points were given)."""
        return None if self.max_deviation is None else bool(self.max_deviation <= self.tol)

    def __str__(self) -> str:
        lines = [
            f"{self.quantity} within {100 * self.tol:g}% of ideal: axial {1e3 * self.axial:.3g} mm,"
            f" mid-plane {1e3 * self.radial:.3g} mm, sphere {1e3 * self.sphere:.3g} mm"
        ]
        if self.max_deviation is not None:
            verdict = "inside" if self.within_tol else "OUTSIDE"
            lines.append(
                f"max deviation over {len(self.deviations)} points: "
                f"{100 * self.max_deviation:.3g}% ({verdict} tolerance)"
            )
        return "\n".join(lines)


def _ray_extent(dev_fn, direction, r_max, samples) -> float:
    """First radius along ``direction`` where the deviation reaches tol (dev_fn returns dev-tol)."""
    r = np.linspace(0.0, r_max, samples)
    vals = dev_fn(r[:, None] * direction)
    above = np.nonzero(vals >= 0)[0]
    if above.size == 0:
        return float(r_max)
    k = int(above[0])
    if k == 0:
        return 0.0
    return float(
        brentq(lambda t: dev_fn((t * direction)[None, :])[0], r[k - 1], r[k], xtol=1e-12 * r_max)
    )


def _distance_to_windings(part, point: np.ndarray) -> float:
    """Distance (m) from ``point`` to the nearest filament or winding cross-section of a
    coaxial group (measured in the meridian plane, which is the 3D distance)."""
    local = part.to_local(point[None, :])[0]
    rho0, z = np.hypot(local[0], local[1]), local[2]
    d = np.hypot(part.filaments[:, 1] - rho0, part.filaments[:, 0] - z)
    best = float(d.min())
    for z0, a, w, h in part.windings:
        dr = max(a - h / 2 - rho0, 0.0, rho0 - a - h / 2)
        dz = max(z0 - w / 2 - z, 0.0, z - z0 - w / 2)
        best = min(best, float(np.hypot(dr, dz)))
    return best


def uniformity(
    field: Field,
    tol: float = 0.01,
    *,
    center=None,
    axis=None,
    quantity: str = "auto",
    points=None,
    max_radius: float | None = None,
    directions: int = 64,
    samples: int = 400,
) -> UniformityReport:
    """Report where ``field`` stays within ``tol`` of its linearisation at ``center``.

    Parameters
    ----------
    field : Field
        A coil, pair or system (anything with ``B``/``gradient``).
    tol : float
        Relative tolerance (0.01 = 1%).
    center : array-like, shape (3,), optional
        Working point, m; default ``field.center``.
    axis : str or array-like, optional
        Axis of the arrangement; default ``field.axis`` (or z).
    quantity : {"auto", "B", "gradient"}
        See :func:`deviation`.
    points : array-like, shape (n, 3), optional
        Points to examine as well, e.g. the robot's reach (m).
    max_radius : float, optional
        Search radius, m; default: 0.95 x the distance from the centre to the nearest winding
        (a calibrated :class:`coils.MPEM`: to its nearest source, at most to the nearest face of
        its workspace).
    directions : int
        Directions sampled for the sphere (and the mid-plane) radius (>= 1).
    samples : int
        Samples along each ray before the crossing is refined with Brent's method (>= 2: the
        centre and ``max_radius``).

    Returns
    -------
    UniformityReport

    Examples
    --------
    >>> from coils import HelmholtzPair
    >>> from coils import uniformity
    >>> rep = uniformity(HelmholtzPair(radius=1.0, turns=1, current=1.0, axis="z"))
    >>> round(rep.axial, 3), round(rep.radial, 3)
    (0.314, 0.378)
    """
    field = as_field(field)
    tol = positive(tol, "tol")
    directions = as_count(directions, "directions")
    samples = as_count(samples, "samples", 2)
    c = as_vector(center if center is not None else getattr(field, "center", np.zeros(3)), "center")
    n = as_axis(axis if axis is not None else getattr(field, "axis", "z"), "axis")
    ideal = linearize(field, c)
    quantity = _pick_quantity(quantity, ideal)
    if max_radius is None:
        parts = list(coaxial_parts(field))
        if parts:
            max_radius = 0.95 * min(_distance_to_windings(p, c) for p in parts)
        else:
            max_radius = field.length_scale
        box = getattr(field, "workspace", None)  # a calibrated model (coils.MPEM): its box
        inside = np.inf if box is None else min(np.min(c - box[:, 0]), np.min(box[:, 1] - c))
        if 0 < inside < max_radius:
            max_radius = inside
    max_radius = positive(max_radius, "max_radius")

    def dev_minus_tol(p):
        return deviation(field, c + p, ideal, quantity) - tol

    axial = min(_ray_extent(dev_minus_tol, s * n, max_radius, samples) for s in (1.0, -1.0))
    # mid-plane directions perpendicular to the axis
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    angles = np.linspace(0, 2 * np.pi, max(4, directions // 4), endpoint=False)
    radial = min(
        _ray_extent(dev_minus_tol, np.cos(a) * u + np.sin(a) * v, max_radius, samples)
        for a in angles
    )
    sphere = min(
        [axial, radial]
        + [
            _ray_extent(dev_minus_tol, d, max_radius, samples)
            for d in _fibonacci_directions(directions)
        ]
    )
    report = UniformityReport(quantity, tol, axial, radial, sphere)
    if points is not None:
        pts = as_points(points)
        dev = deviation(field, pts, ideal, quantity)
        report.points, report.deviations = pts, dev
        report.max_deviation = float(dev.max())
    return report
