"""Vessel centrelines as lists of exact primitive pieces: line segments (and the half-lines
that continue an open end), circular arcs and cubic polynomials (the pieces of a C2 spline).

A piece is a curve ``c(u)`` over a parameter interval ``[lo, hi]`` (``lo = -inf`` or ``hi = inf``
for a half-line).  The parameter is the arc length for lines and arcs and the spline parameter
(the arc length at the spline's knots, see :func:`spline_pieces`) for cubics.  Every kernel here
is vectorised over arrays of (piece index, parameter) and checks nothing: the validated entry
point is :class:`coilrod.contact.Vessel`.

Kernels
-------
:meth:`Pieces.curve`
    ``c``, ``dc/du`` and ``d2c/du2`` at pairs (piece, u).
:meth:`Pieces.start_guess`
    The nearest point's parameter in closed form (lines: projection, also onto a round cone;
    arcs: the clipped polar angle) or the projection onto the chord (cubics), the start of the
    Newton iteration of :mod:`coilrod.contact.vessel` where that is needed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "LINE",
    "ARC",
    "CUBIC",
    "Pieces",
    "line_pieces",
    "polyline_pieces",
    "arc_piece",
    "fit_spline",
    "spline_pieces",
    "split_lines",
    "piece_lengths",
]

LINE, ARC, CUBIC = 0, 1, 2
TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class Pieces:
    """Primitive pieces of a centreline, one row per piece.

    Attributes
    ----------
    kind : ndarray of int, shape (m,)
        ``LINE``, ``ARC`` or ``CUBIC``.
    lo, hi : ndarray, shape (m,)
        Parameter interval (m); ``-inf``/``inf`` at a half-line's open side.
    ref : ndarray, shape (m,)
        Parameter of the piece's local origin: the point ``a`` of a line, the angle 0 of an arc,
        the knot of a cubic.
    a, b, c, e : ndarray, shape (m, 3)
        Line: point ``a`` at ``ref``, unit tangent ``b``.  Arc: centre ``a``, unit vectors ``b``
        (centre -> point at angle 0) and ``c`` (tangent at angle 0).  Cubic:
        ``x(u) = a + b t + c t^2 + e t^3`` with ``t = u - ref``.
    rho : ndarray, shape (m,)
        Arc radius (m); 0 for other kinds.
    """

    kind: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    ref: np.ndarray
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    e: np.ndarray
    rho: np.ndarray

    def __len__(self) -> int:
        return len(self.kind)

    @staticmethod
    def concat(parts: list[Pieces]) -> Pieces:
        return Pieces(
            *(
                np.concatenate([getattr(p, f) for p in parts])
                for f in ("kind", "lo", "hi", "ref", "a", "b", "c", "e", "rho")
            )
        )

    def take(self, index) -> Pieces:
        return Pieces(
            *(
                getattr(self, f)[index]
                for f in ("kind", "lo", "hi", "ref", "a", "b", "c", "e", "rho")
            )
        )

    # -- evaluation -----------------------------------------------------------------------------
    def curve(self, j: np.ndarray, u: np.ndarray, order: int = 2):
        """Position and parameter derivatives at pairs (piece ``j``, parameter ``u``).

        Parameters
        ----------
        j : ndarray of int, shape (...)
        u : ndarray, shape (...), m
        order : int
            0: position only; 1: and ``dc/du``; 2: and ``d2c/du2``.

        Returns
        -------
        list of ndarray, each shape (..., 3)
            ``[c]``, ``[c, c_u]`` or ``[c, c_u, c_uu]``.
        """
        out = [np.empty(u.shape + (3,)) for _ in range(order + 1)]
        kinds = self.kind[j]
        for kind in np.unique(kinds):
            mask = kinds == kind
            jj, uu = j[mask], u[mask]
            a, b, c = self.a[jj], self.b[jj], self.c[jj]
            t = (uu - self.ref[jj])[:, None]
            if kind == LINE:
                vals = [a + b * t, b, np.zeros_like(b)]
            elif kind == ARC:
                rho = self.rho[jj][:, None]
                phi = t / rho
                cos, sin = np.cos(phi), np.sin(phi)
                radial = cos * b + sin * c
                vals = [a + rho * radial, cos * c - sin * b, -radial / rho]
            else:
                e = self.e[jj]
                vals = [
                    a + t * (b + t * (c + t * e)),
                    b + t * (2.0 * c + 3.0 * t * e),
                    2.0 * c + 6.0 * t * e,
                ]
            for k in range(order + 1):
                out[k][mask] = vals[k]
        return out

    def start_guess(
        self, p: np.ndarray, j: np.ndarray, slope: np.ndarray, x0: np.ndarray, x1: np.ndarray
    ) -> np.ndarray:
        """Parameter of the nearest point of each piece, in closed form where there is one.

        Parameters
        ----------
        p : ndarray, shape (n, 3)
            Points, m.
        j : ndarray of int, shape (n,)
            The piece paired with each point.
        slope : ndarray, shape (n,)
            Slope ``d rho / du`` (|slope| < 1) of a linear ball radius on line pieces; the
            maximiser of ``rho(u) - |p - c(u)|`` on a line is then in closed form (a round
            cone).  Ignored for other kinds.
        x0, x1 : ndarray, shape (n, 3)
            Ends of each piece's chord (used for cubics).

        Returns
        -------
        ndarray, shape (n,)
            Exact maximiser for lines (any linear ball radius) and arcs (constant radius);
            the projection onto the chord for cubics (a start for Newton).
        """
        u = np.empty(len(j))
        kinds = self.kind[j]
        for kind in np.unique(kinds):
            mask = kinds == kind
            jj = j[mask]
            lo, hi, ref = self.lo[jj], self.hi[jj], self.ref[jj]
            if kind == LINE:
                q = p[mask] - self.a[jj]
                b = self.b[jj]
                along = np.einsum("ij,ij->i", q, b)
                k = slope[mask]
                if np.any(k):
                    across = np.linalg.norm(q - along[:, None] * b, axis=1)
                    along = along + k * across / np.sqrt(1.0 - k * k)
                u[mask] = np.clip(ref + along, lo, hi)
            elif kind == ARC:
                q = p[mask] - self.a[jj]
                x1_ = np.einsum("ij,ij->i", q, self.b[jj])
                x2_ = np.einsum("ij,ij->i", q, self.c[jj])
                rho = self.rho[jj]
                phi = np.mod(np.arctan2(x2_, x1_), TWO_PI)
                span = (hi - lo) / rho
                beyond = phi > span
                # outside the arc's angles: the end nearer along the circle
                to_start = TWO_PI - phi < phi - span
                phi = np.where(beyond, np.where(to_start, 0.0, span), phi)
                u[mask] = np.clip(lo + rho * phi, lo, hi)
            else:
                a, chord = x0[mask], x1[mask] - x0[mask]
                frac = np.einsum("ij,ij->i", p[mask] - a, chord) / np.einsum(
                    "ij,ij->i", chord, chord
                )
                u[mask] = lo + np.clip(frac, 0.0, 1.0) * (hi - lo)
        return u

    def boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """Exact axis-aligned boxes (m, 3) lower and upper of the finite pieces' curves."""
        lo_u = np.where(np.isfinite(self.lo), self.lo, self.hi)
        hi_u = np.where(np.isfinite(self.hi), self.hi, self.lo)
        m = len(self)
        idx = np.arange(m)
        cand = [self.curve(idx, lo_u, 0)[0], self.curve(idx, hi_u, 0)[0]]
        lower = np.minimum(cand[0], cand[1])
        upper = np.maximum(cand[0], cand[1])
        for axis in range(3):
            us = []
            arc = self.kind == ARC
            if arc.any():
                # extremes of b_i cos(phi) + c_i sin(phi): phi = atan2(c_i, b_i) (+ pi)
                phi0 = np.arctan2(self.c[:, axis], self.b[:, axis])
                for shift in (0.0, np.pi):
                    phi = np.mod(phi0 + shift, TWO_PI)
                    us.append(np.where(arc, self.lo + self.rho * phi, np.nan))
            cub = self.kind == CUBIC
            if cub.any():
                # roots of 3 e t^2 + 2 c t + b = 0
                qa, qb, qc = 3.0 * self.e[:, axis], 2.0 * self.c[:, axis], self.b[:, axis]
                disc = qb * qb - 4.0 * qa * qc
                with np.errstate(invalid="ignore", divide="ignore"):
                    root = np.sqrt(np.where(disc >= 0, disc, np.nan))
                    big = np.abs(qa) > 1e-300
                    t1 = np.where(big, (-qb + root) / (2 * qa), -qc / qb)
                    t2 = np.where(big, (-qb - root) / (2 * qa), np.nan)
                us.extend(np.where(cub, self.ref + t, np.nan) for t in (t1, t2))
            for uu in us:
                ok = np.isfinite(uu) & (uu > lo_u) & (uu < hi_u)
                if ok.any():
                    x = self.curve(idx[ok], uu[ok], 0)[0][:, axis]
                    lower[ok, axis] = np.minimum(lower[ok, axis], x)
                    upper[ok, axis] = np.maximum(upper[ok, axis], x)
        return lower, upper


# -- constructors -------------------------------------------------------------------------------
def _empty(m: int) -> dict:
    return {
        "kind": np.zeros(m, dtype=np.int8),
        "lo": np.zeros(m),
        "hi": np.zeros(m),
        "ref": np.zeros(m),
        "a": np.zeros((m, 3)),
        "b": np.zeros((m, 3)),
        "c": np.zeros((m, 3)),
        "e": np.zeros((m, 3)),
        "rho": np.zeros(m),
    }


def line_pieces(start: np.ndarray, tangent: np.ndarray, lo, hi, ref) -> Pieces:
    """Line pieces ``c(u) = start + tangent (u - ref)`` over ``[lo, hi]`` (arrays (m, 3), (m,))."""
    start = np.atleast_2d(start)
    d = _empty(len(start))
    d["kind"][:] = LINE
    d["lo"][:], d["hi"][:], d["ref"][:] = lo, hi, ref
    d["a"][:], d["b"][:] = start, tangent
    return Pieces(**d)


def polyline_pieces(points: np.ndarray) -> tuple[Pieces, np.ndarray]:
    """Segments of a polyline; returns the pieces and the arc length at each point (n,)."""
    seg = np.diff(points, axis=0)
    length = np.linalg.norm(seg, axis=1)
    s = np.concatenate([[0.0], np.cumsum(length)])
    return line_pieces(points[:-1], seg / length[:, None], s[:-1], s[1:], s[:-1]), s


def arc_piece(center, e1, e2, rho: float, lo: float, angle: float) -> Pieces:
    """A circular arc of radius ``rho`` about ``center``, from ``center + rho e1`` turning
    towards ``e2`` by ``angle`` (rad), starting at parameter ``lo``."""
    d = _empty(1)
    d["kind"][:] = ARC
    d["lo"][:], d["hi"][:], d["ref"][:] = lo, lo + rho * angle, lo
    d["a"][:], d["b"][:], d["c"][:] = center, e1, e2
    d["rho"][:] = rho
    return Pieces(**d)


def _gauss_lengths(spline, knots: np.ndarray, nodes: int = 12, parts: int = 4) -> np.ndarray:
    """Arc length of each interval of a parametric spline (Gauss-Legendre, ``parts`` panels of
    ``nodes`` nodes per interval: exact to rounding for the smooth speeds met here)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    edges = knots[:-1, None] + (knots[1:] - knots[:-1])[:, None] * np.linspace(0, 1, parts + 1)
    a, b = edges[:, :-1], edges[:, 1:]
    u = 0.5 * (a + b)[..., None] + 0.5 * (b - a)[..., None] * x
    speed = np.linalg.norm(spline(u, 1), axis=-1)
    return (0.5 * (b - a) * np.einsum("ijk,k->ij", speed, w)).sum(axis=1)


def fit_spline(points: np.ndarray):
    """A C2 cubic spline through ``points`` (n, 3) parametrised by arc length.

    The spline is ``scipy.interpolate.CubicSpline`` (not-a-knot ends; 2 points give the line,
    3 a parabola) with the knots at their arc length along the spline itself.  Starting from
    the chord lengths, the knots are moved to the arc lengths of the previous spline until they
    agree to 1e-13 of the length (a few iterations for points spaced finely along a smooth
    path); between the knots the parameter then differs from the arc length by a fraction of
    the knot spacing times the squared turning per interval (``|dc/du|`` stays within about
    1e-3 of 1 for a spline turning by 0.1 rad per interval).

    For sparse points with sharp turns this iteration need not converge (a longer interval
    swings wider and grows further).  The chord-length spline through the points is then
    sampled finely (at least 16 samples per interval, 2048 overall), its arc length computed
    at the samples (Gauss-Legendre), and the spline through the samples in arc length is
    used: it passes through the points, is C2 and is parametrised by arc length to about
    1e-6 (the speed's deviation from 1).

    Returns
    -------
    spline : scipy.interpolate.CubicSpline
    knots : ndarray, shape (n,)
        Arc length of each point, m.
    """
    from scipy.interpolate import CubicSpline

    chords = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    knots, change = chords, np.inf
    for _ in range(30):
        spline = CubicSpline(knots, points, axis=0)
        new = np.concatenate([[0.0], np.cumsum(_gauss_lengths(spline, knots))])
        step = float(np.max(np.abs(new - knots)))
        if not step < 0.9 * change and step > 1e-13 * new[-1]:
            break  # not contracting: use the resampled spline below
        change, knots = step, new
        if step <= 1e-13 * new[-1]:
            return CubicSpline(knots, points, axis=0), knots
    chord_spline = CubicSpline(chords, points, axis=0)
    parts = np.maximum(16, np.ceil(2048 * np.diff(chords) / chords[-1])).astype(int)
    u = np.concatenate(
        [
            np.linspace(a, b, k, endpoint=False)
            for a, b, k in zip(chords[:-1], chords[1:], parts, strict=True)
        ]
        + [chords[-1:]]
    )
    s = np.concatenate([[0.0], np.cumsum(_gauss_lengths(chord_spline, u))])
    spline = CubicSpline(s, chord_spline(u), axis=0)
    at = np.concatenate([[0], np.cumsum(parts)])
    return spline, s[at]


def spline_pieces(spline, knots: np.ndarray, max_piece: float, max_turn: float = 0.2) -> Pieces:
    """The spline cut into cubic pieces: every knot interval split into equal parts no longer
    than ``max_piece`` (m) and turning by at most ``max_turn`` (rad)."""
    ints = len(knots) - 1
    fine = knots[:-1, None] + np.diff(knots)[:, None] * np.linspace(0, 1, 17)
    tang = spline(fine, 1)
    tang /= np.linalg.norm(tang, axis=-1, keepdims=True)
    turn = np.arccos(np.clip(np.einsum("ijk,ijk->ij", tang[:, 1:], tang[:, :-1]), -1, 1)).sum(1)
    count = np.maximum(np.ceil(np.diff(knots) / max_piece), np.ceil(turn / max_turn))
    count = np.clip(count, 1, None).astype(int)
    interval = np.repeat(np.arange(ints), count)
    first = np.repeat(np.cumsum(count) - count, count)
    part = np.arange(count.sum()) - first
    width = np.diff(knots)[interval] / count[interval]
    lo = knots[interval] + part * width
    hi = np.where(part == count[interval] - 1, knots[interval + 1], lo + width)
    coef = spline.c  # (4, intervals, 3): x = c0 t^3 + c1 t^2 + c2 t + c3
    d = _empty(len(lo))
    d["kind"][:] = CUBIC
    d["lo"][:], d["hi"][:], d["ref"][:] = lo, hi, knots[interval]
    d["a"][:], d["b"][:] = coef[3][interval], coef[2][interval]
    d["c"][:], d["e"][:] = coef[1][interval], coef[0][interval]
    return Pieces(**d)


def split_lines(pieces: Pieces, max_piece: float) -> Pieces:
    """Line pieces cut into equal parts no longer than ``max_piece`` (m)."""
    count = np.clip(np.ceil((pieces.hi - pieces.lo) / max_piece), 1, None).astype(int)
    idx = np.repeat(np.arange(len(pieces)), count)
    part = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    out = pieces.take(idx)
    width = (out.hi - out.lo) / count[idx]
    lo = out.lo + part * width
    hi = np.where(part == count[idx] - 1, out.hi, lo + width)
    return Pieces(out.kind, lo, hi, *(getattr(out, f) for f in ("ref", "a", "b", "c", "e", "rho")))


def piece_lengths(pieces: Pieces, j: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Arc length of piece ``j`` between parameters ``a`` and ``b`` (16-node Gauss-Legendre;
    exact for lines and arcs, to rounding for the short cubic pieces)."""
    x, w = np.polynomial.legendre.leggauss(16)
    u = 0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * x
    jj = np.broadcast_to(j[:, None], u.shape)
    speed = np.linalg.norm(pieces.curve(jj, u, 1)[1], axis=-1)
    return 0.5 * (b - a) * (speed @ w)
