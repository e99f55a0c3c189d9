"""A rigid tube around a centreline: the lumen of a blood vessel or a catheter guide.

What the vessel is
------------------
The lumen is the union of the balls ``B(c(u), rho(u))`` centred on the centreline ``c``
(:mod:`coilrod.contact.profile` relates the ball radius ``rho`` to the cross-section radius
``R`` the user gives; ``rho = R`` for a constant radius), and

    gap(p) = max_u  rho(u) - |p - c(u)|,

maximised over the whole centreline.  For a constant radius this is ``R - dist(p, centreline)``.
It is the exact signed distance to the wall for every point outside the lumen (the penetration
depth), and for points inside wherever the wall does not fold, which construction checks (see
*Validation*).  The centreline is a list of exact primitive pieces (:mod:`.centerline`): line
segments (a polyline; the tube is then the union of capsules, or of round cones for a radius
varying linearly between the points), circular arcs (presets) and the cubic pieces of a C2
spline (``smooth=True``).

Distances, per piece
--------------------
========================  ===============================================  ================
piece, radius             nearest point                                    accuracy
========================  ===============================================  ================
line, constant or linear  projection (a round cone: closed form)           exact
arc, constant             polar angle, clipped to the arc                  exact
spline piece, any         Newton on the spline parameter from the chord    to rounding (1)
any piece, smooth radius  Newton from the closed form                      to rounding (1)
========================  ===============================================  ================

(1) Newton is safeguarded (ascent steps, clamped to the piece, end points compared) and
converges to the maximiser of ``rho(u) - |p - c(u)|`` on the piece when this is unimodal, which
holds for every point nearer to the centreline than its radius of curvature (every point in
the lumen, and outside up to ``1/kappa - R``): the pieces are cut short (at most one radius
long, turning by at most 0.2 rad) for this.  The spline itself is exact (no sampling): the
distance is to the C2 curve, not to a polyline through samples of it.

Varying radius
--------------
The balls' radius ``rho`` reproduces the user's cross-section radius ``R`` exactly on straight
pieces (round cones for a linear ``R``, the inscribed balls of the surface of revolution for a
smooth one, to ``radius_error``).  Approximations, all of order ``R (dR/ds)^2`` or smaller:
within about one radius of a polyline point where the slope of ``R`` changes, and of an
extended end where ``dR/ds != 0`` (the neighbouring cone's or the extension's end ball), the
section is larger than ``R`` by up to ``R (dR/ds)^2 / 2``; on a curved centreline the balls
fitted as if it were straight give a section off by ``O(R |dR/ds| kappa R)``.

Corners and ends
----------------
* **Convex side of a polyline corner** (outside of the turn): the nearest centreline point is
  the vertex, the wall a sphere about it; the gap is C1 there (the hessian jumps from the
  cylinder's to the sphere's).
* **Concave side** (inside of the turn): the two segments' cylinders meet in a crease.  The
  gap is the larger of the two segments' gaps -- the distance to the nearer segment -- and so
  is continuous, with a gradient that jumps across the bisecting plane of the corner.  Outside
  the lumen this is the exact penetration depth (and the normal points to the nearest
  admissible point); inside, near the crease, it is a lower bound of the distance to the wall
  (conservative).  Where two pieces tie, one whose nearest point is interior to it is taken
  (so G1 joints, as in the bend preset, get the smooth side's hessian).
* **The centreline itself** is where the gap has its cone point: the hessian grows like
  ``1/d`` at distance ``d``; below ``1e-15 R`` (where the normal is rounding noise) it is
  capped there, and exactly on the centreline the gradient is some unit normal.
* **Ends**: ``ends="extend"`` (default) continues each end by a straight half-line along its
  end tangent with the end's cross-section radius: the vessel is infinitely long beyond its
  ends and a rod passing an end meets no wall there.  ``ends="round"`` closes it with the
  hemispherical cap of the end ball (a blind end; used for a branch's root inside its parent).

Validation
----------
``ValueError`` naming the argument for: fewer than two points, NaN or infinite coordinates,
repeated consecutive points, radii that are not positive, a radius array of the wrong length,
and geometry whose wall would fold or intersect itself:

* a polyline corner turning by ``theta`` cuts ``R tan(theta / 2)`` off each adjacent segment
  (where the inner walls cross); two corners must not need more than the segment between them;
* an arc or a spline whose radius of curvature is not larger than the tube radius;
* a smooth radius bulge sharper than the balls that fill it (``R (-R'') >= 1 + R'^2``);
* the centreline (with its extensions) coming back within the sum of the two radii of itself:
  pairs of centreline samples (spacing ``R/4``, coarser only beyond 2e5 samples) that are local
  minima of their mutual
  distance (double normals, so a corner's two legs do not count) and closer than the sum of
  their radii; folds within about one sample spacing of touching can pass.  Straight
  extensions are checked for the vessel's extent (plus two radii) beyond its ends: farther
  crossings of the two extensions (e.g. of a U-turn whose ends converge slightly) concern no
  point near the vessel and are ignored.
"""

from __future__ import annotations

import math

import numpy as np

from coils._immutable import kernel_input
from coils._memo import remember
from coils._validate import as_bool, as_choice, as_points

from ._lumens import _draw_lumens
from .centerline import (
    ARC,
    CUBIC,
    LINE,
    TWO_PI,
    Pieces,
    fit_spline,
    line_pieces,
    piece_lengths,
    polyline_pieces,
    spline_pieces,
    split_lines,
)
from .centerline_file import read_table
from .obstacle import Obstacle, _mm, _point_mm, as_friction
from .profile import BallProfile, section_from

__all__ = ["Vessel"]

EPS = np.finfo(float).eps
#: Above this many finite pieces the candidate pieces of a point come from a KD-tree.
BRUTE_MAX = 24
#: Points x candidate pieces evaluated at once (memory bound).
PAIR_CHUNK = 1 << 19
#: Largest number of centreline samples for the self-intersection check.
CHECK_SAMPLES = 200_000
#: Below this distance (m) a point is taken to lie on the centreline itself.
ON_LINE = 1e-300


def _as_ends(ends) -> tuple[str, str]:
    choices = ("extend", "round")
    if isinstance(ends, str):
        one = as_choice(ends, "ends", choices)
        return one, one
    if isinstance(ends, tuple | list) and len(ends) == 2:
        return tuple(as_choice(e, "ends", choices) for e in ends)
    raise ValueError(f"ends must be 'extend', 'round' or a pair of them (start, end); got {ends!r}")


def _unit_normal_to(v: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to each row of ``v`` (n, 3)."""
    axis = np.zeros_like(v)
    axis[np.arange(len(v)), np.argmin(np.abs(v), axis=1)] = 1.0
    w = np.cross(v, axis)
    return w / np.linalg.norm(w, axis=1, keepdims=True)


_COMPILED = []


def _compiled():
    """:mod:`coilrod.contact._compiled_search` (imports numba), imported at the first
    all-pairs evaluation."""
    if not _COMPILED:
        from . import _compiled_search

        _COMPILED.append(_compiled_search)
    return _COMPILED[0]


#: Point sets whose nearest-point search a vessel remembers (:meth:`Vessel._located`).
_LOCATED_KEPT = 4
_EYE3 = np.eye(3)
#: The compiled search's derivative outputs at order 0 (empty: never written).
_NO_GRAD, _NO_HESS = np.empty((0, 3)), np.empty((0, 3, 3))


class Vessel(Obstacle):
    """Rigid tube of radius ``radius`` around the 3D curve ``centerline``.

    Parameters
    ----------
    centerline : array-like, shape (n, 3)
        Points of the centreline, m (n >= 2, consecutive points distinct).
    radius : float, array-like of shape (n,), or callable
        Cross-section radius, m: a constant; one value per centreline point, linear in arc
        length between them; or a callable of arc length ``s`` (ndarray, m) returning radii (m),
        sampled finely and interpolated by a C2 spline (see ``radius_error``).
    smooth : bool
        False (default): the centreline is the polyline through the points.  True: the C2
        cubic spline through them (``scipy.interpolate.CubicSpline``, not-a-knot, parametrised
        by arc length), with exact distances to the spline (Newton on its parameter).
    ends : {"extend", "round"} or (str, str)
        How the tube continues beyond its first and last point: straight half-lines
        (``"extend"``, the vessel is infinitely long) or hemispherical caps (``"round"``).
    friction : float
        Coulomb friction coefficient mu >= 0 of the wall (0, the default: frictionless;
        presets: ``Vessel.bend(...).with_friction(mu)``).

    Attributes
    ----------
    length : float
        Arc length of the centreline from its first to its last point, m.
    ends : tuple of str
    radius_error : float
        For a smooth radius (callable, aneurysm): the largest mismatch (m) of the spline fits of
        the radius and of the ball radius (about 1e-9 of the radius or less); 0 otherwise.
    points : ndarray, shape (n, 3)
        The centreline points given (presets: the ends of their pieces), m; read-only.

    Notes
    -----
    The module docstring (:mod:`coilrod.contact.vessel`) states what is exact and how corners,
    ends and varying radii are treated.  Evaluation is vectorised over points: a point's
    candidate pieces are all pieces (up to 24), or its nearest pieces by a KD-tree over the
    pieces' bounding balls, widened until no other piece can have a larger gap.

    Examples
    --------
    >>> tube = Vessel([[0, 0, 0], [0.04, 0, 0]], radius=1e-3)
    >>> tube.gap([[0.02, 0.0005, 0.0], [0.02, 0.0015, 0.0]]).round(6).tolist()
    [0.0005, -0.0005]
    >>> tube.gap_gradient([0.02, 0.0005, 0.0]).round(12).tolist()
    [[-0.0, -1.0, -0.0]]
    """

    _outside = "outside the vessel"
    _immutable = True
    _caches = ("_located_memo", "_search_data")

    def __init__(self, centerline, radius, *, smooth: bool = False, ends="extend", friction=0.0):
        self.friction = as_friction(friction)
        pts = as_points(centerline, "centerline")
        if len(pts) < 2:
            raise ValueError(f"centerline must have at least 2 points; got {len(pts)}")
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        extent = float(np.max(np.ptp(pts, axis=0)))
        rep = np.flatnonzero(seg <= 1e-12 * extent)
        if rep.size:
            k = int(rep[0])
            raise ValueError(
                f"centerline points {k} and {k + 1} coincide at {_point_mm(pts[k])}; "
                "consecutive points must differ"
            )
        smooth = as_bool(smooth, "smooth")
        ends = _as_ends(ends)
        if smooth:
            spline, knots = fit_spline(pts)
            section = section_from(radius, knots)
            # cut at the spline's own breakpoints: the points' knots, or (a resampled spline,
            # sparse points with sharp turns) its samples -- cubic pieces taken per point
            # interval from a resampled spline's first coefficients were another curve
            pieces = spline_pieces(spline, spline.x, max_piece=section.minimum)
        else:
            pieces, knots = polyline_pieces(pts)
            section = section_from(radius, knots)
            if section.kind == "smooth":
                pieces = split_lines(pieces, section.minimum)
        self.points = pts.copy()
        self._setup(pieces, section, ends, corners=None if smooth else pts)

    @classmethod
    def _from_pieces(cls, pieces: Pieces, section, ends, points) -> Vessel:
        """A vessel from ordered finite pieces (presets); validated like any other."""
        self = cls.__new__(cls)
        self.points = np.array(points, dtype=float)
        self._setup(pieces, section, _as_ends(ends), corners=None)
        self._seal(None)  # the preset records its parameters (remembers_recipe)
        return self

    @classmethod
    def from_centerline_file(cls, path, units: str = "m", smooth: bool = False) -> Vessel:
        """The vessel of a VMTK centreline with maximum inscribed sphere radii (CSV or ASCII
        VTP), radii linear in arc length between the points; see
        :func:`coilrod.contact.read_centerline` (the same)."""
        smooth = as_bool(smooth, "smooth")
        points, radii, label = read_table(path, units)
        try:
            return cls(points, radii, smooth=smooth)
        except ValueError as exc:
            raise ValueError(f"{label}: {exc}") from None

    # the presets Vessel.straight, .bend, .aneurysm, .branch are attached by
    # coilrod.contact.presets (so that this module does not import it)

    # -- construction ---------------------------------------------------------------------------
    def _setup(self, finite: Pieces, section, ends, corners) -> None:
        if section.kind == "smooth":
            section.check()
        self.ends = ends
        self._section = section
        m = len(finite)
        self._m = m
        self.length = float(finite.hi[-1])
        idx = np.array([0, m - 1])
        x, xu = finite.curve(idx, np.array([0.0, self.length]), 1)[:2]
        tu = xu / np.linalg.norm(xu, axis=1, keepdims=True)
        halves = line_pieces(x, tu, [-np.inf, self.length], [0.0, np.inf], [0.0, self.length])
        self._pieces = Pieces.concat([finite, halves])
        r_end = section(np.array([0.0, self.length]))
        ball = section.ball(finite.lo, finite.hi, self.length)
        self._ball = ball.concat(BallProfile(np.array([0.0, self.length]), r_end, np.zeros(2)))
        self._extra = np.array([m + k for k in range(2) if ends[k] == "extend"], dtype=np.intp)
        self.radius_error = float(
            max(getattr(section, "error", 0.0), getattr(section, "ball_error", 0.0))
        )
        pcs, ball = self._pieces, self._ball
        self._needs_newton = (
            (pcs.kind == CUBIC) | ball.smooth_mask | ((pcs.kind == ARC) & (ball.slope != 0))
        )
        # closed-form round cones on lines whose ball radius is linear
        self._cone_slope = np.where((pcs.kind == LINE) & ~ball.smooth_mask, ball.slope, 0.0)
        self._bounding()
        # the all-pairs closed-form search applies (few pieces, all lines or constant arcs)
        self._closed_form = self._tree is None and not bool(self._needs_newton.any())
        self._check_geometry(corners)

    def _bounding(self) -> None:
        """Bounding balls, chords and radius bounds of the finite pieces; the KD-tree."""
        m, pcs = self._m, self._pieces
        j = np.arange(m)
        lo, hi = pcs.lo[:m], pcs.hi[:m]
        mid = 0.5 * (lo + hi)
        self._piece_length = piece_lengths(pcs, j, lo, hi)
        half = np.maximum(piece_lengths(pcs, j, lo, mid), piece_lengths(pcs, j, mid, hi))
        self._center = pcs.curve(j, mid, 0)[0]
        self._half = half * (1 + 1e-9) + 1e-300
        # chords of the finite pieces (the two half-lines get rows of zeros: never used)
        self._x0 = np.zeros((len(pcs), 3))
        self._x1 = np.zeros((len(pcs), 3))
        self._x0[:m] = pcs.curve(j, lo, 0)[0]
        self._x1[:m] = pcs.curve(j, hi, 0)[0]
        # deviation of each piece from its chord (bounds the gap on the piece from above)
        dev = np.zeros(m)
        arc = pcs.kind[:m] == ARC
        if arc.any():
            angle = (hi - lo)[arc] / pcs.rho[:m][arc]
            sag = pcs.rho[:m][arc] * (1 - np.cos(0.5 * angle))
            dev[arc] = np.where(angle <= np.pi, sag, self._half[arc])
        cub = np.flatnonzero(pcs.kind[:m] == CUBIC)
        if cub.size:
            t = np.linspace(0.0, 1.0, 33)
            uu = lo[cub, None] + (hi - lo)[cub, None] * t
            jj = np.broadcast_to(cub[:, None], uu.shape)
            xs = pcs.curve(jj, uu, 0)[0]
            x0, x1 = self._x0[cub, None], self._x1[cub, None]
            far = _segment_distance(xs, x0, x1).max(axis=1)
            curv = np.maximum(
                *(np.linalg.norm(pcs.curve(cub, u, 2)[2], axis=1) for u in (lo[cub], hi[cub]))
            )
            dev[cub] = far + curv * ((hi - lo)[cub] / 32) ** 2 / 8
        self._dev = dev * (1 + 1e-9)
        # largest ball radius on each piece
        ends_rho = np.maximum(self._ball(j, lo, 0)[0], self._ball(j, hi, 0)[0])
        smooth = self._ball.smooth_mask[:m]
        if smooth.any():
            t = np.linspace(0.0, 1.0, 17)
            ss = np.flatnonzero(smooth)
            uu = lo[ss, None] + (hi - lo)[ss, None] * t
            vals = self._ball(np.broadcast_to(ss[:, None], uu.shape), uu, 1)
            margin = np.abs(vals[1]).max(axis=1) * (hi - lo)[ss] / 32
            ends_rho[ss] = vals[0].max(axis=1) + margin
        self._rho_max = ends_rho
        self._hmax = float(np.max(self._rho_max + self._half))
        self._rho_scale = float(np.max(self._rho_max))
        self._tree = None
        if m > BRUTE_MAX:
            from scipy.spatial import cKDTree

            self._tree = cKDTree(self._center)
        lower, upper = pcs.take(np.arange(m)).boxes()
        grow = self._section.maximum
        self._bounds = np.array([lower.min(axis=0) - grow, upper.max(axis=0) + grow])

    # -- validation of the geometry -------------------------------------------------------------
    def _check_geometry(self, corners) -> None:
        section = self._section
        if corners is not None and len(corners) > 2:
            _check_corners(corners, section)
        s, x, radius, seq = self._samples()
        pcs, m = self._pieces, self._m
        # curvature of arcs and splines against the tube radius
        curved = np.flatnonzero(pcs.kind[:m] != LINE)
        if curved.size:
            t = np.linspace(0.0, 1.0, 9)
            lo, hi = pcs.lo[curved], pcs.hi[curved]
            uu = (lo[:, None] + (hi - lo)[:, None] * t).ravel()
            jj = np.repeat(curved, len(t))
            _, xu, xuu = pcs.curve(jj, uu, 2)
            speed = np.linalg.norm(xu, axis=1)
            kappa = np.linalg.norm(np.cross(xu, xuu), axis=1) / speed**3
            ratio = kappa * section(uu)
            if ratio.max() >= 1.0:
                k = int(np.argmax(ratio))
                what = "arc" if pcs.kind[jj[k]] == ARC else "smooth (spline) centerline"
                raise ValueError(
                    f"centerline: the {what} bends with a radius of curvature of "
                    f"{_mm(1 / kappa[k])} at s = {_mm(uu[k])}, "
                    f"{_point_mm(pcs.curve(jj[k : k + 1], uu[k : k + 1], 0)[0][0])}, not more "
                    f"than the tube radius {_mm(section(uu[k : k + 1])[0])} there: the inner "
                    "wall would fold; bend more gently, lower the radius or add points"
                )
        _check_self_approach(s, x, radius, seq, self.ends)

    def _samples(self):
        """Centreline samples for the checks: arc length, position, cross-section radius and
        which part they are on (-1 start extension, 0 centreline, 1 end extension)."""
        pcs, m = self._pieces, self._m
        section = self._section
        h = section.minimum / 4.0
        extent = float(np.linalg.norm(self._bounds[1] - self._bounds[0]))
        ext_len = extent + 2.0 * section.maximum
        lens = self._piece_length
        n_ext = [ext_len / h if e == "extend" else 0.0 for e in self.ends]
        total = float(np.sum(np.ceil(lens / h))) + sum(n_ext) + m
        if total > CHECK_SAMPLES:
            h *= total / CHECK_SAMPLES
        count = np.clip(np.ceil(lens / h), 1, None).astype(int)
        parts_s, parts_j = [], []
        for k in range(m):
            u = np.linspace(pcs.lo[k], pcs.hi[k], count[k] + 1)
            parts_s.append(u if k == 0 else u[1:])
            parts_j.append(np.full(len(parts_s[-1]), k))
        s = np.concatenate(parts_s)
        j = np.concatenate(parts_j)
        x = pcs.curve(j, s, 0)[0]
        seq = np.zeros(len(s), dtype=int)
        if self.ends[0] == "extend":
            se = -np.arange(math.ceil(ext_len / h), 0, -1) * h
            s = np.concatenate([se, s])
            x = np.concatenate([pcs.curve(np.full(len(se), m), se, 0)[0], x])
            seq = np.concatenate([np.full(len(se), -1), seq])
        if self.ends[1] == "extend":
            se = self.length + np.arange(1, math.ceil(ext_len / h) + 1) * h
            s = np.concatenate([s, se])
            x = np.concatenate([x, pcs.curve(np.full(len(se), m + 1), se, 0)[0]])
            seq = np.concatenate([seq, np.full(len(se), 1)])
        return s, x, section(s), seq

    # -- the gap --------------------------------------------------------------------------------
    def _gap_pairs(self, p: np.ndarray, j: np.ndarray, u: np.ndarray) -> np.ndarray:
        x = self._pieces.curve(j, u, 0)[0]
        return self._ball(j, u, 0)[0] - np.linalg.norm(p - x, axis=-1)

    def _terms(self, p, j, u):
        """``g``, ``dg/du``, ``d2g/du2`` of ``g(u) = rho(u) - |p - c(u)|`` at pairs."""
        x, xu, xuu = self._pieces.curve(j, u, 2)
        rho, rho_u, rho_uu = self._ball(j, u, 2)
        r = p - x
        d = np.linalg.norm(r, axis=-1)
        ds = np.maximum(d, ON_LINE)
        rh = r / ds[..., None]
        along = np.einsum("...i,...i->...", rh, xu)
        gu = rho_u + along
        guu = (
            rho_uu
            - (np.einsum("...i,...i->...", xu, xu) - along * along) / ds
            + np.einsum("...i,...i->...", rh, xuu)
        )
        return rho - d, gu, guu

    def _newton(self, p, j, u):
        """Maximise ``g(u)`` on each pair's piece from ``u`` (safeguarded Newton); returns the
        maximiser and ``g`` there, the piece's end points included in the comparison."""
        pcs = self._pieces
        lo, hi = pcs.lo[j], pcs.hi[j]
        span = hi - lo
        g, gu, guu = self._terms(p, j, u)
        u = u.copy()
        active = np.arange(len(u))
        for _ in range(60):
            if active.size == 0:
                break
            pa, ja, ua, ga = p[active], j[active], u[active], g[active]
            gua, guua, sp = gu[active], guu[active], span[active]
            tol = 16 * EPS * (np.abs(ga) + self._rho_scale)
            step = np.where(guua < 0, -gua / np.where(guua < 0, guua, -1.0), np.sign(gua) * sp)
            step = np.clip(step, -0.25 * sp, 0.25 * sp)
            for _ in range(50):
                ut = np.clip(ua + step, lo[active], hi[active])
                gt, gut, guut = self._terms(pa, ja, ut)
                worse = gt < ga - tol
                if not worse.any():
                    break
                step = np.where(worse, 0.5 * step, step)
            keep = gt < ga - tol
            ut = np.where(keep, ua, ut)
            moved = np.abs(ut - ua)
            u[active] = ut
            g[active] = np.where(keep, ga, gt)
            gu[active] = np.where(keep, gua, gut)
            guu[active] = np.where(keep, guua, guut)
            # converged: no move, or a derivative that is zero to rounding (|dc/du| ~ 1)
            done = (moved <= 1e-14 * sp + 4 * EPS * np.abs(ut)) | (np.abs(gu[active]) <= 32 * EPS)
            active = active[~done]
        for end in (lo, hi):
            ge = self._gap_pairs(p, j, end)
            better = ge > g
            u = np.where(better, end, u)
            g = np.where(better, ge, g)
        return u, g

    def _solve_pairs(self, p: np.ndarray, j: np.ndarray):
        """Maximiser ``u`` and maximum ``g`` of ``rho(u) - |p - c(u)|`` on piece ``j`` for
        flat pairs (closed form, or Newton from the closed-form start)."""
        u = self._pieces.start_guess(p, j, self._cone_slope[j], self._x0[j], self._x1[j])
        need = self._needs_newton[j]
        if need.all():
            return self._newton(p, j, u)
        g = self._gap_pairs(p, j, u)
        if need.any():
            u[need], g[need] = self._newton(p[need], j[need], u[need])
        return u, g

    def _best(self, p: np.ndarray, J: np.ndarray):
        """Gap, piece and parameter of each point's best piece among the candidates ``J``
        (n, k), preferring (within rounding) a piece whose maximiser is interior.

        Pieces in closed form are evaluated for every pair.  Pieces that need Newton are
        ranked by an upper bound of their gap (from the distance to their chord); the most
        promising one per point is solved first, then only those whose bound can beat the
        best gap found.
        """
        g = np.full(J.shape, -np.inf)
        u = np.zeros(J.shape)
        need = self._needs_newton[J]
        easy = ~need
        if easy.any():
            ri, ci = np.nonzero(easy)
            u[ri, ci], g[ri, ci] = self._solve_pairs(p[ri], J[ri, ci])
        if need.any():
            ri, ci = np.nonzero(need)
            jj = J[ri, ci]
            chord = _segment_distance(p[ri], self._x0[jj], self._x1[jj])
            bound = np.full(J.shape, -np.inf)
            bound[ri, ci] = self._rho_max[jj] - np.maximum(chord - self._dev[jj], 0.0)
            rows = np.flatnonzero(need.any(axis=1))
            first = np.argmax(bound[rows], axis=1)
            u[rows, first], g[rows, first] = self._solve_pairs(p[rows], J[rows, first])
            lower = g.max(axis=1)
            tol = 64 * EPS * (np.abs(lower) + self._rho_scale + np.abs(p).max(axis=1))
            rest = need & (bound >= (lower - tol)[:, None])
            rest[rows, first] = False
            if rest.any():
                ri, ci = np.nonzero(rest)
                u[ri, ci], g[ri, ci] = self._solve_pairs(p[ri], J[ri, ci])
        best = g.max(axis=1)
        pcs = self._pieces
        inside = (u > pcs.lo[J]) & (u < pcs.hi[J])
        tol = 64 * EPS * (np.abs(best) + self._rho_scale + np.abs(p).max(axis=1))
        tie = inside & (g >= (best - tol)[:, None])
        col = np.where(
            tie.any(axis=1),
            np.argmax(np.where(tie, g, -np.inf), axis=1),
            np.argmax(g, axis=1),
        )
        rows = np.arange(len(p))
        return g[rows, col], J[rows, col], u[rows, col]

    def _locate(self, p: np.ndarray):
        """(gap, piece, parameter) of the best piece for every point."""
        n, m = len(p), self._m
        g, j, u = np.empty(n), np.empty(n, dtype=np.intp), np.empty(n)
        everything = np.concatenate([np.arange(m), self._extra])

        def brute(rows):
            step = max(1, PAIR_CHUNK // len(everything))
            for a in range(0, len(rows), step):
                r = rows[a : a + step]
                J = np.broadcast_to(everything, (len(r), len(everything)))
                g[r], j[r], u[r] = self._best(p[r], J)

        if self._tree is None:
            brute(np.arange(n))
            return g, j, u
        todo, k = np.arange(n), min(8, m)
        while todo.size:
            if k >= m:
                brute(todo)
                break
            step = max(1, PAIR_CHUNK // (k + len(self._extra)))
            left = []
            for a in range(0, len(todo), step):
                r = todo[a : a + step]
                dist, idx = self._tree.query(p[r], k=k)
                J = np.concatenate(
                    [idx, np.broadcast_to(self._extra, (len(r), len(self._extra)))], 1
                )
                gr, jr, ur = self._best(p[r], J)
                # no piece beyond the k-th nearest centre can have a larger gap
                ok = self._hmax - dist[:, -1] <= gr
                g[r[ok]], j[r[ok]], u[r[ok]] = gr[ok], jr[ok], ur[ok]
                left.append(r[~ok])
            todo = np.concatenate(left)
            k = min(4 * k, m)
        return g, j, u

    def _closed_form_groups(self):
        """The candidate pieces of every point when all are in closed form and few (no
        KD-tree), cached (state-independent): ``(everything, groups, lo, hi, rho, back)`` --
        the candidates, their fields by kind (with a flag for a sloped ball) in kind order
        (lines, then arcs: each kind's columns one contiguous slice), their parameter ranges
        and ball radii where those are constant (else None) in that order, and ``back``, the
        candidates' columns in kind order (the search ranks them in the candidates' order)."""
        groups = self.__dict__.get("_groups_cache")
        if groups is None:
            pcs, ball = self._pieces, self._ball
            everything = np.concatenate([np.arange(self._m), self._extra])
            order = np.concatenate(
                [np.flatnonzero(pcs.kind[everything] == kind) for kind in (LINE, ARC)]
            )
            kinds, start = [], 0
            for kind in (LINE, ARC):
                count = int(np.count_nonzero(pcs.kind[everything] == kind))
                jj = everything[order[start : start + count]]
                fields = (pcs.lo, pcs.hi, pcs.ref, pcs.a, pcs.b, pcs.c, pcs.rho, self._cone_slope)
                sloped = bool(np.any(self._cone_slope[jj]))
                kinds.append((kind, slice(start, start + count), sloped, *(f[jj] for f in fields)))
                start += count
            smooth = ball.smooth is not None and bool(np.any(ball.smooth_mask[everything]))
            # a constant ball: value + 0 * (u - anchor) is the value exactly
            rho = None if smooth or np.any(ball.slope[everything]) else ball.value[everything]
            back = np.argsort(order)  # kind-order column of each candidate
            groups = (everything, kinds, pcs.lo[everything], pcs.hi[everything], rho, order, back)
            self.__dict__["_groups_cache"] = groups
        return groups

    def _locate_closed_form(self, p: np.ndarray):
        """:meth:`_locate` and the centreline's point and derivatives at the best pieces, all
        pairs at once when every candidate piece is a line or an arc in closed form (the
        formulas of :meth:`Pieces.start_guess` and :meth:`Pieces.curve`): (gap, piece,
        parameter, c, c_u, c_uu).  The pairs are formed kind by kind in contiguous columns
        (kind order); the gaps and parameters are then ranked in the candidates' own order,
        and the centreline's point and derivatives gathered at the chosen pair alone."""
        everything, kinds, lo_all, hi_all, rho_all, order, back = self._closed_form_groups()
        n, K = len(p), len(everything)
        U = np.empty((n, K))
        X = np.empty((n, K, 3))
        XU = np.empty((n, K, 3))
        XUU = np.zeros((n, K, 3))
        for kind, col, sloped, lo, hi, ref, a, b, c, rho, slope in kinds:
            if col.start == col.stop:
                continue
            q = p[:, None, :] - a  # (n, k, 3)
            if kind == LINE:
                along = np.einsum("nkj,kj->nk", q, b)
                if sloped:
                    across = np.linalg.norm(q - along[..., None] * b, axis=2)
                    along = along + slope * across / np.sqrt(1.0 - slope * slope)
                u = np.minimum(np.maximum(ref + along, lo), hi)
                X[:, col] = a + b * (u - ref)[..., None]
                XU[:, col] = b
            else:
                x1_ = np.einsum("nkj,kj->nk", q, b)
                x2_ = np.einsum("nkj,kj->nk", q, c)
                phi = np.arctan2(x2_, x1_)
                phi = phi + TWO_PI * (phi < 0.0)  # np.mod(phi, 2 pi), bitwise on [-pi, pi]
                span = (hi - lo) / rho
                beyond = phi > span
                if beyond.any():
                    to_start = TWO_PI - phi < phi - span
                    phi = np.where(beyond, np.where(to_start, 0.0, span), phi)
                u = np.minimum(np.maximum(lo + rho * phi, lo), hi)
                ang = ((u - ref) / rho)[..., None]
                cos, sin = np.cos(ang), np.sin(ang)
                radial = cos * b + sin * c
                X[:, col] = a + rho[:, None] * radial
                XU[:, col] = cos * c - sin * b
                XUU[:, col] = -radial / rho[:, None]
            U[:, col] = u
        # back to the candidates' order (the ranking's ties go to the first column)
        U = U[:, back]
        if rho_all is None:
            rho_all = self._ball(np.broadcast_to(everything, (n, K)), U, 0)[0]
        q = p[:, None, :] - X[:, back]
        G = rho_all - np.sqrt(np.add.reduce(q * q, axis=-1))  # np.linalg.norm's own sum
        # the choice of _best: a piece whose maximiser is interior, within rounding
        best = G.max(axis=1)
        inside = (U > lo_all) & (U < hi_all)
        tol = 64 * EPS * (np.abs(best) + self._rho_scale + np.abs(p).max(axis=1))
        tie = inside & (G >= (best - tol)[:, None])
        col = np.where(
            tie.any(axis=1), np.argmax(np.where(tie, G, -np.inf), axis=1), np.argmax(G, axis=1)
        )
        rows = np.arange(n)
        kcol = back[col]
        return (
            G[rows, col],
            everything[col],
            U[rows, col],
            X[rows, kcol],
            XU[rows, kcol],
            XUU[rows, kcol],
        )

    def _located(self, points: np.ndarray):
        """The nearest-point search of ``points`` (gap, piece, parameter, and the centreline's
        point and derivatives there or None), remembered for the last
        :data:`_LOCATED_KEPT` point sets: a contact solve asks for the same points again (the
        gaps of a state, then its linearization; a prediction's start and its events), and
        the search is most of an evaluation.  The geometry never changes after
        construction, so a remembered search is the search (the key is the points' bytes)."""
        key = points.tobytes()
        memo = self._memo()
        hit = memo.get(key)
        if hit is None or len(hit) != 6:  # (not the compiled search's)
            if self._all_pairs(len(points)):
                hit = self._locate_closed_form(points)
            else:
                hit = (*self._locate(points), None, None, None)
        return remember(memo, key, hit, _LOCATED_KEPT)

    def _memo(self) -> dict:
        memo = self.__dict__.get("_located_memo")
        if memo is None:  # (a cache: a pickled or evolved copy starts without it)
            memo = {}
            self._set_cache("_located_memo", memo)
        return memo

    def _all_pairs(self, n: int) -> bool:
        """Whether the search of ``n`` points is the all-pairs closed form (few pieces, no
        KD-tree, every piece a line or an arc in closed form)."""
        return self._closed_form and n * (self._m + len(self._extra)) <= PAIR_CHUNK

    def _search_inputs(self):
        """The candidate pieces (in the candidates' order) and the compiled search's inputs
        describing them (read-only, C-contiguous: one compiled version), cached."""
        data = self.__dict__.get("_search_data")
        if data is None:
            pcs, ball = self._pieces, self._ball
            j = np.concatenate([np.arange(self._m), self._extra])
            # the columns of _compiled_search.geom: LO, HI, REF, A, B, C, ARC, CONE, VALUE, ...
            fields = (pcs.lo, pcs.hi, pcs.ref, pcs.a, pcs.b, pcs.c, pcs.rho, self._cone_slope)
            fields += (ball.value, ball.slope, ball.anchor)
            geom = np.column_stack([f[j] for f in fields])
            data = (j, kernel_input(pcs.kind[j], np.int64), kernel_input(geom))
            self._set_cache("_search_data", data)
        return data

    def _evaluate_compiled(self, points: np.ndarray, order: int):
        """:meth:`_evaluate` by the compiled all-pairs search and evaluation
        (:mod:`coilrod.contact._compiled_search`; the numpy search is its twin), remembered
        like :meth:`_located`'s: (gap, piece, parameter, gradient, hessian), the last two
        None after an order-0 call (the gaps alone; an order >= 1 call then searches anew)."""
        key = points.tobytes()
        memo = self._memo()
        hit = memo.get(key)
        # (not the numpy search's; an order-0 search's has no derivatives: searched anew)
        if hit is None or len(hit) != 5 or (order >= 1 and hit[3] is None):
            j, kind, geom = self._search_inputs()
            n = len(points)
            g, col, u = np.empty(n), np.empty(n, dtype=np.int64), np.empty(n)
            if order == 0:  # the gaps alone (the same numbers: the derivatives come after)
                grad, hess = _NO_GRAD, _NO_HESS
            else:
                grad, hess = np.empty((n, 3)), np.empty((n, 3, 3))
            _compiled().closed_form_search(
                kernel_input(points), 0 if order == 0 else 2, kind, geom, self._rho_scale,
                ON_LINE, g, col, u, grad, hess,
            )  # fmt: skip
            hit = (g, j[col], u) + ((None, None) if order == 0 else (grad, hess))
        remember(memo, key, hit, _LOCATED_KEPT)
        return (
            hit[0].copy(),
            hit[3].copy() if order >= 1 else None,
            hit[4].copy() if order >= 2 else None,
        )

    def _evaluate(self, points: np.ndarray, order: int):
        """Gap, gradient and hessian (up to ``order``) of validated points: by the compiled
        all-pairs search (:meth:`_evaluate_compiled`) where it applies and compiling has paid
        (:func:`coilrod.contact._compiled_search.search_pays`), else by numpy."""
        if self._all_pairs(len(points)) and _compiled().search_pays(
            len(points), self._m + len(self._extra)
        ):
            return self._evaluate_compiled(points, order)
        return self._evaluate_numpy(points, order)

    def _evaluate_numpy(self, points: np.ndarray, order: int):
        """:meth:`_evaluate` by the numpy search (:meth:`_located`) and derivatives: the
        compiled evaluation's twin, and the search of every vessel the compiled one does not
        cover (many pieces, splines, smooth radii)."""
        g, j, u, x, xu, xuu = self._located(points)
        g = g.copy()  # (the remembered search stays the caller's to keep)
        if order == 0:
            return g, None, None
        if x is None:
            x, xu, xuu = self._pieces.curve(j, u, 2)
        r = points - x
        d = np.sqrt(np.add.reduce(r * r, axis=1))  # (np.linalg.norm's sum, bitwise)
        zero = d < ON_LINE
        on_line = zero.any()
        rh = r / (np.where(zero, 1.0, d) if on_line else d)[:, None]
        if on_line:  # on the centreline: any normal is a (sub)gradient
            rh[zero] = _unit_normal_to(xu[zero])
        grad = -rh
        if order == 1:
            return g, grad, None
        rho, rho_u, rho_uu = self._ball(j, u, 2)
        # the hessian grows like 1/d towards the centreline (where the gap has a cone point);
        # below 1e-15 of the radius, where the normal is rounding noise, it is capped there
        ds = np.maximum(d, 1e-15 * rho)
        proj = _EYE3 - rh[:, :, None] * rh[:, None, :]
        hess = -proj / ds[:, None, None]
        pcs = self._pieces
        inside = (u > pcs.lo[j]) & (u < pcs.hi[j])
        w = np.einsum("nij,nj->ni", proj, xu)
        # d * d2g/du2 (finite as d -> 0)
        dguu = ds * (rho_uu + np.einsum("ni,ni->n", rh, xuu)) - np.einsum("ni,ni->n", xu, w)
        use = inside & (dguu < 0)
        if use.any():
            hess[use] -= (w[use, :, None] * w[use, None, :]) / (ds[use] * dguu[use])[:, None, None]
        return g, grad, hess

    # -- queries --------------------------------------------------------------------------------
    def closest(self, points) -> np.ndarray:
        """Arc length (m) of the centreline point whose ball is nearest to each point
        (for a constant radius: the nearest centreline point), shape (n,); beyond an extended
        end it continues along the extension (< 0 or > ``length``)."""
        pts = as_points(points)
        if len(pts) == 0:
            return np.zeros(0)
        return self._locate(pts)[2]

    def _piece_at(self, s: np.ndarray) -> np.ndarray:
        m = self._m
        j = np.clip(np.searchsorted(self._pieces.hi[:m], s), 0, m - 1)
        j = np.where(s < 0, m, j)
        return np.where(s > self.length, m + 1, j)

    def position(self, s) -> np.ndarray:
        """Centreline points at arc lengths ``s`` (m, any shape; beyond the ends along the
        straight extensions), shape ``s.shape + (3,)``, m."""
        s = np.asarray(s, dtype=float)
        return self._pieces.curve(self._piece_at(s), s, 0)[0]

    def tangent(self, s) -> np.ndarray:
        """Unit centreline tangents at arc lengths ``s``, shape ``s.shape + (3,)``."""
        s = np.asarray(s, dtype=float)
        t = self._pieces.curve(self._piece_at(s), s, 1)[1]
        return t / np.linalg.norm(t, axis=-1, keepdims=True)

    def radius_at(self, s) -> np.ndarray:
        """Cross-section radius at arc lengths ``s`` (m; the end values beyond the ends)."""
        return self._section(np.asarray(s, dtype=float))

    @property
    def min_radius(self) -> float:
        """The smallest cross-section radius, m (a device thicker than twice this cannot pass)."""
        return float(self._section.minimum)

    @property
    def bounds(self) -> np.ndarray:
        """Box (2, 3) of the tube between its end cross-sections, m: the centreline's exact
        box grown by the largest radius (the straight extensions of open ends are not
        included)."""
        return self._bounds.copy()

    def __repr__(self) -> str:
        sec = self._section
        if sec.kind == "constant":
            rad = _mm(sec.value)
        else:
            rad = f"{_mm(sec.minimum)}..{_mm(sec.maximum)}"
        return (
            f"Vessel(length={_mm(self.length)}, radius={rad}, pieces={self._m}, ends={self.ends})"
        )

    # -- drawing --------------------------------------------------------------------------------
    def _shadow(self):
        """The lumen's projection on the x-y plane as a shapely polygon (union of the balls'
        disks along the centreline; open ends drawn 3 radii long) and the disks cutting the
        drawn open ends off the outline."""
        import shapely

        pcs, m = self._pieces, self._m
        h = self._section.minimum / 2.0
        count = np.clip(np.ceil(self._piece_length / h), 1, 400).astype(int)
        count = np.where((pcs.kind[:m] == LINE) & ~self._ball.smooth_mask[:m], 1, count)
        ss, js = [], []
        for k in range(m):
            u = np.linspace(pcs.lo[k], pcs.hi[k], count[k] + 1)
            ss.append(u)
            js.append(np.full(len(u), k))
        cuts = []
        for e, end in enumerate(self.ends):
            if end == "extend":
                jj = m + e
                r = self._ball.value[jj]
                tip = (-3.0 * r) if e == 0 else self.length + 3.0 * r
                u = np.array([0.0, tip]) if e == 0 else np.array([self.length, tip])
                ss.append(u)
                js.append(np.full(2, jj))
                cuts.append((pcs.curve(np.array([jj]), np.array([tip]), 0)[0][0, :2], r))
        polys = []
        for u, j in zip(ss, js, strict=True):
            x = pcs.curve(j, u, 0)[0][:, :2]
            rho = self._ball(j, u, 0)[0]
            disks = shapely.buffer(shapely.points(x), rho, quad_segs=16)
            if len(disks) > 1:
                pairs = shapely.convex_hull(shapely.union(disks[:-1], disks[1:]))
                polys.append(shapely.union_all(pairs))
            else:
                polys.append(disks[0])
        return shapely.union_all(polys), cuts

    def _centerline_xy(self):
        pcs, m = self._pieces, self._m
        count = np.where(pcs.kind[:m] == LINE, 1, 64)
        xs = [
            pcs.curve(np.full(c + 1, k), np.linspace(pcs.lo[k], pcs.hi[k], c + 1), 0)[0]
            for k, c in enumerate(count)
        ]
        return np.concatenate(xs)[:, :2]

    def _draw(self, ax, **kwargs):
        _draw_lumens(ax, [self], **kwargs)


# -- geometric helpers --------------------------------------------------------------------------
def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points ``p`` to segments ``[a, b]`` (broadcast, (..., 3))."""
    ab = b - a
    t = np.einsum("...i,...i->...", p - a, ab) / np.maximum(
        np.einsum("...i,...i->...", ab, ab), 1e-300
    )
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(p - a - t[..., None] * ab, axis=-1)


def _check_corners(points: np.ndarray, section) -> None:
    """A polyline corner turning by theta needs ``R tan(theta/2)`` of each adjacent segment
    (where the inner walls of the two segments cross); the segment between two corners must
    hold both."""
    seg = np.diff(points, axis=0)
    length = np.linalg.norm(seg, axis=1)
    t = seg / length[:, None]
    cos = np.clip(np.einsum("ij,ij->i", t[:-1], t[1:]), -1.0, 1.0)
    turn = np.arccos(cos)
    knots = np.concatenate([[0.0], np.cumsum(length)])
    radius = section(knots[1:-1])
    with np.errstate(divide="ignore", over="ignore"):
        setback = np.where(turn < np.pi * (1 - 1e-12), radius * np.tan(0.5 * turn), np.inf)
    need = np.concatenate([[0.0], setback]) + np.concatenate([setback, [0.0]])
    bad = np.flatnonzero(need > length)
    if bad.size == 0:
        return
    k = int(bad[np.argmax((need - length)[bad])])
    turns = [
        f"{math.degrees(turn[v - 1]):.4g} deg at point {v}"
        for v in (k, k + 1)
        if 1 <= v <= len(points) - 2
    ]
    what = f"turns of {' and '.join(turns)} need" if len(turns) > 1 else f"turn of {turns[0]} needs"
    raise ValueError(
        f"centerline: the inner wall folds between points {k} and {k + 1}: the {what} "
        f"{_mm(need[k]) if np.isfinite(need[k]) else 'more than all'} of the "
        f"{_mm(length[k])} segment between them (R tan(turn/2) at each corner); lengthen the "
        "segment, turn less at each point, lower the radius or use smooth=True"
    )


def _check_self_approach(s, x, radius, seq, ends) -> None:
    """ValueError where the centreline (with its extensions) comes back within the sum of the
    radii of itself: sample pairs closer than that which are local minima of their distance."""
    from scipy.spatial import cKDTree

    n = len(s)
    reach = 2.0 * float(radius.max())
    pairs = cKDTree(x).query_pairs(reach, output_type="ndarray")
    if len(pairs) == 0:
        return
    i, j = pairs[:, 0], pairs[:, 1]
    far = np.abs(j - i) > 2
    i, j = i[far], j[far]
    d = np.linalg.norm(x[i] - x[j], axis=1)
    close = d < radius[i] + radius[j]
    i, j, d = i[close], j[close], d[close]
    if i.size == 0:
        return

    def dist(a, b):
        ok = (a >= 0) & (a < n) & (b >= 0) & (b < n)
        out = np.full(len(a), np.inf)
        out[ok] = np.linalg.norm(x[a[ok]] - x[b[ok]], axis=1)
        return out

    slack = 1e-12 * (d + reach)
    local = (
        (d <= dist(i - 1, j) + slack)
        & (d <= dist(i + 1, j) + slack)
        & (d <= dist(i, j - 1) + slack)
        & (d <= dist(i, j + 1) + slack)
    )
    i, j, d = i[local], j[local], d[local]
    if i.size == 0:
        return
    k = int(np.argmin(d - radius[i] - radius[j]))
    a, b = int(i[k]), int(j[k])
    where = {
        -1: "the straight extension before the first point",
        1: "the straight extension beyond the last point",
        0: "the centerline",
    }

    def place(q):
        return f"{where[int(seq[q])]} at s = {_mm(s[q])}, {_point_mm(x[q])}"

    hint = "; use ends='round'" if seq[a] or seq[b] else ""
    raise ValueError(
        f"centerline: the tube intersects itself: {place(a)}, and {place(b)}, are "
        f"{_mm(d[k])} apart, less than the sum of the radii there, "
        f"{_mm(radius[a] + radius[b])}{hint}"
    )


def read_centerline(path, units: str = "m", smooth: bool = False) -> Vessel:
    """The vessel of a centreline with per-point radii (VMTK's table, CSV or ASCII VTP).

    Parameters
    ----------
    path : str or os.PathLike
        ``.csv`` (header ``x, y, z, MaximumInscribedSphereRadius``; ``radius`` accepted) or
        ``.vtp`` (ASCII; point data ``MaximumInscribedSphereRadius``).
    units : {"m", "mm"}
        Length unit of the file (points and radii), converted to m.
    smooth : bool
        The centreline as the C2 spline through the points.

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
    return Vessel.from_centerline_file(path, units, smooth)
