"""Radius of a vessel along its centreline: the cross-section radius the user gives, and the
radius of the balls whose union is the lumen.

A vessel's lumen is the union of the balls ``B(c(u), rho(u))`` centred on the centreline (a
canal surface): its gap ``max_u rho(u) - |p - c(u)|`` is the exact signed distance to the wall
outside the lumen, and inside it wherever the wall does not fold.  For a constant radius
``rho = R``.  For a varying cross-section radius ``R(s)`` (the radius of the lumen's section
perpendicular to the centreline), ``rho`` is the radius of the largest ball centred at
``c(s)`` that fits in the straight tube of section ``R``:

* linear ``R`` on a straight piece (a cone of half-angle ``alpha = atan(dR/ds)``):
  ``rho = R cos(alpha)``, linear in ``s`` with slope ``sin(alpha)``; the union of the balls is
  the round cone whose section is exactly ``R``;
* smooth ``R``: ``rho(s) = min_x sqrt((x - s)^2 + R(x)^2)`` (the distance from the axis point to
  the wall's meridian), computed at construction on a fine grid by Newton (strictly convex when
  ``R (-R'') < 1 + R'^2``, which is also the condition for the balls to reach every wall point)
  and interpolated by a C2 cubic spline; the section of the union of the balls is then ``R`` up
  to the interpolation error (reported as ``Vessel.radius_error``).

On a curved centreline the same ``rho`` is used (the balls are fitted as if the centreline
were straight over one radius): the section differs from ``R`` by ``O(R |dR/ds| kappa R)``.
"""

from __future__ import annotations

import numpy as np

from coils._validate import as_array, positive

__all__ = ["ConstantSection", "LinearSection", "SmoothSection", "BallProfile", "section_from"]

#: Grid size limits for sampling a callable radius and fitting the ball radius.
MIN_SAMPLES, MAX_SAMPLES = 257, 200_001
EPS = np.finfo(float).eps


def _mm(x: float) -> str:
    return f"{1e3 * x:.4g} mm"


class Smooth:
    """A C2 function of arc length on ``[s0, s1]`` from its value and two derivatives,
    continued by its end values (derivatives 0) outside."""

    def __init__(self, f, df, d2f, s0: float, s1: float):
        self.f, self.df, self.d2f, self.s0, self.s1 = f, df, d2f, s0, s1

    def __call__(self, s: np.ndarray, order: int = 2) -> list[np.ndarray]:
        s = np.asarray(s, dtype=float)
        inside = (s >= self.s0) & (s <= self.s1)
        sc = np.clip(s, self.s0, self.s1)
        out = [np.asarray(self.f(sc), dtype=float)]
        if order >= 1:
            out.append(np.where(inside, self.df(sc), 0.0))
        if order >= 2:
            out.append(np.where(inside, self.d2f(sc), 0.0))
        return out

    @classmethod
    def spline(cls, s: np.ndarray, values: np.ndarray) -> Smooth:
        from scipy.interpolate import CubicSpline

        spl = CubicSpline(s, values)
        return cls(spl, spl.derivative(1), spl.derivative(2), float(s[0]), float(s[-1]))


class ConstantSection:
    """Constant cross-section radius ``value`` (m)."""

    kind = "constant"

    def __init__(self, value: float):
        self.value = value
        self.minimum = self.maximum = value

    def __call__(self, s: np.ndarray) -> np.ndarray:
        return np.full(np.shape(s), self.value)

    def ball(self, piece_lo: np.ndarray, piece_hi: np.ndarray, length: float) -> BallProfile:
        m = len(piece_lo)
        return BallProfile(np.zeros(m), np.full(m, self.value), np.zeros(m))


class LinearSection:
    """Cross-section radius given at the knots ``s`` (m) and linear in arc length between."""

    kind = "linear"

    def __init__(self, knots: np.ndarray, values: np.ndarray):
        self.knots, self.values = knots, values
        self.minimum, self.maximum = float(values.min()), float(values.max())

    def __call__(self, s: np.ndarray) -> np.ndarray:
        return np.interp(s, self.knots, self.values)

    def ball(self, piece_lo: np.ndarray, piece_hi: np.ndarray, length: float) -> BallProfile:
        """Round cones: on the knot interval of each piece, ``rho = R cos(alpha)``."""
        mid = 0.5 * (piece_lo + piece_hi)
        k = np.clip(np.searchsorted(self.knots, mid) - 1, 0, len(self.knots) - 2)
        s0 = self.knots[k]
        slope = (self.values[k + 1] - self.values[k]) / (self.knots[k + 1] - s0)
        cos = 1.0 / np.hypot(1.0, slope)
        return BallProfile(s0, self.values[k] * cos, slope * cos)


class SmoothSection:
    """A smooth cross-section radius ``R(s)`` with its derivatives on ``[0, length]``."""

    kind = "smooth"

    def __init__(self, smooth: Smooth, length: float, error: float = 0.0):
        self.smooth, self.length, self.error = smooth, length, error
        grid = np.linspace(0.0, length, 4097)
        vals = smooth(grid, 0)[0]
        self.minimum, self.maximum = float(vals.min()), float(vals.max())

    def __call__(self, s: np.ndarray) -> np.ndarray:
        return self.smooth(s, 0)[0]

    @classmethod
    def from_callable(cls, radius, length: float) -> SmoothSection:
        """Sample ``radius(s)`` (a callable of arc length, m -> m) and interpolate it by a C2
        cubic spline, refining until the spline matches the midpoints to 1e-9 of the radius
        (or the grid reaches ``MAX_SAMPLES``); ``error`` is the largest midpoint mismatch."""
        count = MIN_SAMPLES
        first = True
        while True:
            s = np.linspace(0.0, length, count)
            vals = _call_radius(radius, s)
            if first:
                first = False
                need = int(np.ceil(8.0 * length / vals.min())) + 1
                if need > count:
                    count = min(need, MAX_SAMPLES)
                    continue
            mids = 0.5 * (s[1:] + s[:-1])
            smooth = Smooth.spline(s, vals)
            error = float(np.max(np.abs(smooth(mids, 0)[0] - _call_radius(radius, mids))))
            if error <= 1e-9 * vals.max() or count >= MAX_SAMPLES:
                return cls(smooth, length, error)
            count = min(2 * count - 1, MAX_SAMPLES)

    def check(self, name: str = "radius") -> None:
        """ValueError where a concave bulge is sharper than the balls that fill it:
        ``R (-R'') >= 1 + R'^2`` (the wall's radius of curvature is below its distance to the
        centreline along its normal)."""
        s = np.linspace(0.0, self.length, 8193)
        R, dR, d2R = self.smooth(s)
        bad = R * -d2R >= 1.0 + dR * dR
        if bad.any():
            k = int(np.argmax(R * -d2R - dR * dR))
            raise ValueError(
                f"{name}: the bulge at s = {_mm(s[k])} is too sharp for a tube of radius "
                f"{_mm(R[k])} (R d2R/ds2 = {R[k] * d2R[k]:.3g}, the wall curves more tightly "
                "than the lumen is wide); make it wider or lower"
            )

    def ball(self, piece_lo: np.ndarray, piece_hi: np.ndarray, length: float) -> BallProfile:
        """The radius of the largest ball about the axis of the straight tube of section R,
        interpolated by a C2 spline on a grid refined until it matches the midpoints to 1e-9
        of the radius (``ball_error``: the largest mismatch, not counting two radii at each
        end)."""
        count = int(np.clip(np.ceil(16.0 * length / self.minimum) + 1, MIN_SAMPLES, MAX_SAMPLES))
        while True:
            s = np.linspace(0.0, length, count)
            ball = Smooth.spline(s, inscribed_radius(self.smooth, s))
            mids = 0.5 * (s[1:] + s[:-1])
            # within two radii of an end the ends' kink in R (continued by its end value)
            # makes rho less smooth; the end's own O(R R'^2) approximation dominates there
            margin = 2.0 * self.maximum if length > 8.0 * self.maximum else 0.0
            mids = mids[(mids >= margin) & (mids <= length - margin)]
            error = np.abs(ball(mids, 0)[0] - inscribed_radius(self.smooth, mids))
            self.ball_error = float(error.max())
            if self.ball_error <= 1e-9 * self.maximum or count >= MAX_SAMPLES:
                break
            count = min(2 * count - 1, MAX_SAMPLES)
        m = len(piece_lo)
        return BallProfile(
            np.zeros(m), np.zeros(m), np.zeros(m), smooth=ball, smooth_mask=np.ones(m, bool)
        )


def inscribed_radius(section: Smooth, s: np.ndarray) -> np.ndarray:
    """``min_x sqrt((x - s)^2 + R(x)^2)`` for each ``s``.

    ``f(x) = (x - s)^2 + R(x)^2`` is strictly convex where ``R (-R'') < 1 + R'^2`` and its
    minimiser lies within ``R(s)`` of ``s`` (``f(s) = R(s)^2``): Newton safeguarded by
    bisection on the sign of ``f'`` in that bracket, to 1e-9 of the radius in ``x`` (``f`` is
    flat there, so ``rho`` is then exact to rounding).
    """
    s = np.asarray(s, dtype=float)
    r0 = section(s, 0)[0]
    lo, hi = s - r0, s + r0
    x = s.copy()
    tol = 1e-9 * float(np.max(r0))
    active = np.arange(len(s))
    for _ in range(200):
        if active.size == 0:
            break
        xa, sa = x[active], s[active]
        R, dR, d2R = section(xa)
        grad = (xa - sa) + R * dR
        curv = 1.0 + dR * dR + R * d2R
        up = grad > 0
        hi[active] = np.where(up, xa, hi[active])
        lo[active] = np.where(up, lo[active], xa)
        a, b = lo[active], hi[active]
        with np.errstate(divide="ignore", invalid="ignore"):
            newton = xa - grad / curv
        inside = (curv > 0) & (newton > a) & (newton < b)
        xn = np.where(grad == 0, xa, np.where(inside, newton, 0.5 * (a + b)))
        x[active] = xn
        done = (np.abs(xn - xa) <= tol) | (b - a <= tol) | (grad == 0)
        active = active[~done]
    R = section(x, 0)[0]
    return np.sqrt((x - s) ** 2 + R * R)


class BallProfile:
    """Ball radius ``rho`` on each piece: linear ``value + slope (u - anchor)`` per piece, or
    a global smooth function of ``u`` on the pieces flagged in ``smooth_mask``."""

    def __init__(self, anchor, value, slope, smooth: Smooth | None = None, smooth_mask=None):
        self.anchor, self.value, self.slope = anchor, value, slope
        self.smooth = smooth
        self.smooth_mask = np.zeros(len(anchor), bool) if smooth_mask is None else smooth_mask

    def concat(self, other: BallProfile) -> BallProfile:
        return BallProfile(
            np.concatenate([self.anchor, other.anchor]),
            np.concatenate([self.value, other.value]),
            np.concatenate([self.slope, other.slope]),
            self.smooth if self.smooth is not None else other.smooth,
            np.concatenate([self.smooth_mask, other.smooth_mask]),
        )

    def __call__(self, j: np.ndarray, u: np.ndarray, order: int = 2) -> list[np.ndarray]:
        """``[rho, rho_u, rho_uu][: order + 1]`` at pairs (piece ``j``, parameter ``u``)."""
        slope = self.slope[j]
        rho = self.value[j] + slope * (u - self.anchor[j])
        out = [rho, slope, np.zeros_like(rho)][: order + 1]
        if self.smooth is not None:
            mask = self.smooth_mask[j]
            if mask.any():
                vals = self.smooth(u[mask], order)
                for k in range(order + 1):
                    out[k][mask] = vals[k]
        return out


def _call_radius(radius, s: np.ndarray) -> np.ndarray:
    try:
        vals = radius(s.copy())
        vals = np.broadcast_to(np.asarray(vals, dtype=float), s.shape)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"radius must be a callable mapping arc length (ndarray, m) to radii (m); "
            f"calling it with shape {s.shape} failed: {exc}"
        ) from exc
    bad = ~np.isfinite(vals)
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(f"radius(s) must be finite; got {vals[k]} at s = {_mm(s[k])}")
    if np.any(vals <= 0):
        k = int(np.argmin(vals))
        raise ValueError(
            f"radius(s) must be positive along the centerline; got {vals[k]:.4g} m at "
            f"s = {_mm(s[k])}"
        )
    return np.array(vals)


def section_from(radius, knots: np.ndarray):
    """The cross-section radius from the user's ``radius``: a positive scalar, one positive
    value per centreline point (``knots`` their arc lengths) or a callable of arc length."""
    n = len(knots)
    if callable(radius) and not isinstance(radius, np.ndarray):
        return SmoothSection.from_callable(radius, float(knots[-1]))
    try:
        arr = as_array(radius, "radius")
    except ValueError as exc:
        if "finite" in str(exc):
            raise
        raise ValueError(
            "radius must be a positive number, one per centerline point or a callable of arc "
            f"length; got {radius!r}"[:200]
        ) from None
    if arr.ndim == 0:
        return ConstantSection(positive(float(arr), "radius"))
    if arr.shape != (n,):
        raise ValueError(
            f"radius must be a scalar, a callable of arc length or have shape ({n},) (one per "
            f"centerline point); got shape {arr.shape}"
        )
    for k, v in enumerate(arr):
        if not v > 0:
            raise ValueError(f"radius[{k}] must be positive; got {v}")
    if np.all(arr == arr[0]):
        return ConstantSection(float(arr[0]))
    return LinearSection(knots.copy(), arr.astype(float).copy())
