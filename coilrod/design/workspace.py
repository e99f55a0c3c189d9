"""The workspace of a magnetic rod: every tip position a bounded field can hold it at.

Definition (what :func:`workspace` approximates, with an error estimate):

* The workspace is the set of tips of the **stable** states reached quasi-statically along
  the radial field ramps ``B = s b_max (cos phi, sin phi)``, s from 0 to 1, over all in-plane
  field directions phi: the image of the field disc ``|B| <= b_max`` under the map field ->
  tip, each field's state being the one the solver's path following (:func:`coilrod.solve_rod`:
  snap-through to the stable branch at a limit point, never a state of an unstable branch)
  reaches from the straight rod along its ramp.  Stability is the solver's own figure.
* Directions are measured from the robot, not from +x: ``phi = reference + alpha``, alpha in
  (-pi, pi), ``reference`` the direction of the rod's net magnetic moment in the clamp frame
  turned by the clamp angle (:func:`reference_direction`).  Turning the clamp turns the grid
  with it, so the area is exactly invariant; turning a uniform magnetization turns its
  equilibria exactly, but the 3D stability of a tilted one differs (twist).
* **The antiparallel cut.**  Near alpha = +-pi (the field against the net moment) the rod
  buckles beyond a critical field: the two sides of the antiparallel ray land on the two
  branches of the (imperfect) bifurcation, and the map field -> tip jumps across that ray (more
  generally across any ray where neighbouring directions land on different branches).  The
  workspace is the image of the disc **cut along** those rays: both sides are reached (as
  one-sided limits), nothing in between is.  No grid direction lies on alpha = +-pi initially
  (the initial grid is ``alpha_d = -pi + 2 pi (d + 1/2) / directions``).
* Computed as a union of grid cells: the quadrilateral ``tips[d, j], tips[d, j + 1],
  tips[d + 1, j + 1], tips[d + 1, j]`` (two triangles, shapely) of neighbouring directions d,
  d + 1 (the last cell across the cut) and magnitudes j, j + 1.  A cell is left out when its
  image is not swept continuously: a corner state unstable, a snap-through along either ramp,
  or the two directions on different branches (node angles differing by more than
  ``max(0.5 rad, 2 x the direction step)``).  Cells left out whose two sides differ (a branch
  jump, one side unstable or snapping) are **bisected in direction** (``refine`` levels), so
  the lost wedge shrinks to zero on either side of the cut wherever the grid falls; so is the
  cell pair whose tips at ``b_max`` bend away from their chord by more than ``tolerance`` L.
  Magnitude steps along which the tip curves bend away from their chords by more than
  ``tolerance`` L (the sharp knee of a nearly antiparallel ramp just past buckling) are
  bisected for every direction (the grid stays a tensor grid).
* ``area_error``: the area's difference from that of the same states one resolution coarser
  in directions plus its difference from that one resolution coarser in magnitudes (the
  last bisection undone everywhere; on a stretch the refinement left alone, every other
  point of the initial grid).  Undoing both at once let the two differences cancel (at
  12 x 3 for M(1) at 6 mT: 0.55 mm^2 against a distance of 5.2 mm^2 to a refined run).

With ``system`` (a coil system with current control) each direction's field is made by the
currents that give ``b_max`` along that direction at the system centre, and the real
(Biot-Savart) field of those currents acts on the rod: the real-coil workspace.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass

import numpy as np

import coils
from coils._validate import as_count, as_vector, finite_scalar, positive

from ..errors import ConvergenceError
from ..path.corrector import NewtonOptions, newton
from ..path.events import StabilityWarning
from ..path.stepping import PathOptions, follow_load
from ..robot.rod import Rod
from ..rod.fan import UniformFan
from ..rod.solve import DEFAULT_SEGMENTS, MAX_SEGMENTS, build_problem, make_mesh, solve_rod

__all__ = ["workspace", "Workspace", "area_gradient", "reference_direction"]

#: Largest grids accepted (time and memory stay bounded: 3600 x 1000 states).
MAX_DIRECTIONS = 3600
MAX_MAGNITUDES = 1000
#: Most refinement levels of the directions.
MAX_REFINE = 20
#: Largest magnetoelastic number A |M| b_max L^2 / (E I) accepted.
MAX_LAMBDA = 1000.0

#: Node angles of neighbouring directions differing by more than this (rad, or twice the
#: direction step if larger) put the two states on different branches.
BRANCH_JUMP = 0.5


@dataclass
class Workspace:
    """Tip positions of a rod over a grid of field directions and magnitudes, and their union.

    Attributes
    ----------
    directions : ndarray, shape (D,)
        Field directions in the bending plane, rad from +x, increasing from
        ``reference - pi`` to ``reference + pi`` (the initial grid and the directions added by
        refinement).
    magnitudes : ndarray, shape (M + 1,)
        Field magnitudes at the system centre, T, increasing from ``magnitudes[0] = 0`` to
        ``b_max`` (the initial steps and their bisections).
    tips : ndarray, shape (D, M + 1, 3)
        Tip positions, m.
    stable : ndarray of bool, shape (D, M + 1)
        Stability of each state.
    snaps : ndarray of bool, shape (D, M)
        True where the rod snaps through between magnitudes j and j + 1.
    cells : ndarray of bool, shape (D, M)
        The grid cells whose images make up the workspace.
    polygon : shapely geometry
        The union of the cells' images (x, y in m).
    area : float
        Its area, m^2.
    boundary : ndarray, shape (p, 2)
        The exterior ring of the largest part of ``polygon`` (closed: first = last), m.
    events : list of dict
        Snap-throughs and bifurcations met, each with its ``direction`` (index) and the
        :class:`~coilrod.RodResult` event fields; kind "unreached" where a direction's path
        could not be followed to ``b_max`` (its tips beyond ``scale`` are NaN, left out).
    system : object or None
        The coil system, or None for ideal uniform fields.
    currents : ndarray, shape (D, m) or None
        With ``system``: the currents of each direction at ``b_max``, A.
    area_error : float
        Error estimate of ``area``, m^2: its difference from the area of the same states one
        resolution coarser in directions plus that from one resolution coarser in magnitudes
        (the last bisection of every stretch undone; where none was made, every other point
        of the initial grid).
    reference : float
        The direction the field directions are measured from (:func:`reference_direction`),
        rad from +x.
    levels : ndarray of int, shape (D,)
        Refinement level of each direction: 0 and 1 the initial grid's even and odd
        directions, ``k + 2`` a direction bisecting a step ``2 pi / directions / 2**k``.
    """

    directions: np.ndarray
    magnitudes: np.ndarray
    tips: np.ndarray
    stable: np.ndarray
    snaps: np.ndarray
    cells: np.ndarray
    polygon: object
    area: float
    boundary: np.ndarray
    events: list
    system: object = None
    currents: np.ndarray | None = None
    reference: float = 0.0
    levels: np.ndarray | None = None
    _solution: object = dataclasses.field(default=None, repr=False)
    _coarse: object = dataclasses.field(default=None, repr=False)
    _area_error: float | None = dataclasses.field(default=None, repr=False)

    @property
    def area_error(self) -> float:
        """Error estimate of :attr:`area`, m^2 (see the class docstring); computed when first
        read."""
        if self._area_error is None:
            self._area_error = 0.0 if self._coarse is None else self._coarse.area_error(self.area)
        return self._area_error

    def plot(self, ax=None, *, color="C0", label=None, grid: bool = False, unit: float = 1e-3):
        """Draw the workspace (filled union) and, with ``grid``, the tip grid.

        Parameters
        ----------
        ax : matplotlib Axes, optional
        color : str
        label : str, optional
        grid : bool
            Also draw the tips of every state (lines along directions and magnitudes).
        unit : float
            Length unit of the axes, m (default mm).

        Returns
        -------
        matplotlib Axes
        """
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(5, 5))
        geoms = getattr(self.polygon, "geoms", [self.polygon])
        first = True
        for g in geoms:
            if g.is_empty:
                continue
            x, y = np.asarray(g.exterior.coords).T / unit
            ax.fill(x, y, color=color, alpha=0.3, lw=1.5, ec=color, label=label if first else None)
            first = False
            for hole in g.interiors:
                hx, hy = np.asarray(hole.coords).T / unit
                ax.fill(hx, hy, color="white", lw=1.0, ec=color)
        if grid:
            t = self.tips[..., :2] / unit
            ax.plot(t[:, :, 0].T, t[:, :, 1].T, color=color, lw=0.4, alpha=0.6)
            ax.plot(t[:, -1, 0], t[:, -1, 1], ".", color=color, ms=2)
        ax.set_aspect("equal")
        name = {1e-3: "mm", 1.0: "m", 1e-2: "cm"}.get(unit, f"{unit:g} m")
        ax.set_xlabel(f"tip x ({name})")
        ax.set_ylabel(f"tip y ({name})")
        ax.set_title(f"workspace: {self.area / unit**2:.4g} {name}$^2$")
        return ax


# -- geometry -----------------------------------------------------------------------------------
def _triangles(tips_xy: np.ndarray, cells: np.ndarray):
    """Triangles (N, 3, 2) of the included cells and their corner indices (N, 3) into the
    flattened (D (M + 1)) tip grid."""
    D, M1 = tips_xy.shape[:2]
    d, j = np.nonzero(cells)
    dn = (d + 1) % D
    idx = lambda a, b: a * M1 + b  # noqa: E731
    a, b, c, e = idx(d, j), idx(d, j + 1), idx(dn, j + 1), idx(dn, j)
    corners = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, e], 1)])
    flat = tips_xy.reshape(-1, 2)
    return flat[corners], corners


def _union(tips_xy: np.ndarray, cells: np.ndarray, scale: float):
    """The union of the included cells' images (shapely), its area and boundary ring."""
    import shapely

    tri, _ = _triangles(tips_xy, cells)
    # a strictly convex cell is one quadrilateral (the union of its two triangles, half the
    # shapes to unite); the others stay two triangles
    N = tri.shape[0] // 2
    quad = np.concatenate([tri[:N, :3], tri[N:, 2:3]], axis=1)  # a, b, c, e
    edges = np.roll(quad, -1, axis=1) - quad
    turn = edges[..., 0] * np.roll(edges, -1, axis=1)[..., 1]
    turn -= edges[..., 1] * np.roll(edges, -1, axis=1)[..., 0]
    tiny = 1e-20 * scale**2
    convex = np.all(turn > tiny, axis=1) | np.all(turn < -tiny, axis=1)
    tri = tri[~np.r_[convex, convex]]
    # drop degenerate triangles (the cells at zero field have two equal corners)
    u, v = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area2 = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    tri = tri[area2 > 1e-24 * scale**2]
    if tri.shape[0] == 0 and not convex.any():
        return shapely.Polygon(), 0.0, np.zeros((0, 2))
    polys = np.r_[
        shapely.polygons(np.concatenate([tri, tri[:, :1]], axis=1)),
        shapely.polygons(np.concatenate([quad[convex], quad[convex][:, :1]], axis=1)),
    ]
    union = shapely.union_all(polys)
    union = shapely.orient_polygons(union) if hasattr(shapely, "orient_polygons") else union
    parts = getattr(union, "geoms", [union])
    largest = max(parts, key=lambda g: g.area)
    return union, float(union.area), np.asarray(largest.exterior.coords)


def area_gradient(ws: Workspace) -> np.ndarray:
    """d(area)/d(tip x, y) of every grid state, shape (D, M + 1, 2), m^2 per m.

    The union's boundary is made of pieces of the cells' triangle edges; moving the tips moves
    each edge (linearly along it), and the area changes by the normal velocity integrated over
    the boundary: a piece of edge (a, b) spanning edge parameters [t0, t1] and of length l
    contributes ``l n . ((1 - t) v_a + t v_b)``, ``t = (t0 + t1) / 2``, n its outward normal.
    Exact where the union's combinatorics do not change (almost everywhere)."""
    import shapely

    tips_xy = ws.tips[..., :2]
    D, M1 = tips_xy.shape[:2]
    grad = np.zeros((D * M1, 2))
    if ws.area == 0.0:
        return grad.reshape(D, M1, 2)
    tri, corners = _triangles(tips_xy, ws.cells)
    ea = np.concatenate([corners[:, 0], corners[:, 1], corners[:, 2]])
    eb = np.concatenate([corners[:, 1], corners[:, 2], corners[:, 0]])
    key = np.unique(np.sort(np.stack([ea, eb], 1), axis=1), axis=0)
    ea, eb = key[:, 0], key[:, 1]
    flat = tips_xy.reshape(-1, 2)
    pa, pb = flat[ea], flat[eb]
    ev = pb - pa
    elen2 = np.einsum("ij,ij->i", ev, ev)
    keep = elen2 > 0
    ea, eb, pa, ev, elen2 = ea[keep], eb[keep], pa[keep], ev[keep], elen2[keep]
    scale = math.sqrt(float(np.max(elen2))) if elen2.size else 1.0
    tol = 1e-9 * scale
    oriented = shapely.orient_polygons(ws.polygon) if hasattr(shapely, "orient_polygons") else None
    geom = oriented if oriented is not None else ws.polygon
    rings = []
    for g in getattr(geom, "geoms", [geom]):
        if oriented is None:
            g = shapely.geometry.polygon.orient(g, 1.0)
        rings.append(np.asarray(g.exterior.coords))
        rings += [np.asarray(r.coords) for r in g.interiors]
    for ring in rings:
        p, q = ring[:-1], ring[1:]
        seg = q - p
        slen = np.hypot(seg[:, 0], seg[:, 1])
        ok = slen > 0
        p, q, seg, slen = p[ok], q[ok], seg[ok], slen[ok]
        normal = np.stack([seg[:, 1], -seg[:, 0]], 1) / slen[:, None]  # outward (CCW ring)
        # which edge holds each piece: both ends on the edge's line, within its span
        rp = p[:, None, :] - pa[None]
        rq = q[:, None, :] - pa[None]
        cross_p = (rp[..., 0] * ev[None, :, 1] - rp[..., 1] * ev[None, :, 0]) / np.sqrt(elen2)
        cross_q = (rq[..., 0] * ev[None, :, 1] - rq[..., 1] * ev[None, :, 0]) / np.sqrt(elen2)
        tp = np.einsum("sek,ek->se", rp, ev) / elen2
        tq = np.einsum("sek,ek->se", rq, ev) / elen2
        on = (np.abs(cross_p) < tol) & (np.abs(cross_q) < tol)
        span = 1e-9
        on &= (tp > -span) & (tp < 1 + span) & (tq > -span) & (tq < 1 + span)
        s_idx, e_idx = np.nonzero(on)
        # a piece on several coincident edges moves with any of them: take the first
        first = np.unique(s_idx, return_index=True)[1]
        s_idx, e_idx = s_idx[first], e_idx[first]
        t = 0.5 * (tp[s_idx, e_idx] + tq[s_idx, e_idx])
        w = slen[s_idx][:, None] * normal[s_idx]
        np.add.at(grad, ea[e_idx], (1 - t)[:, None] * w)
        np.add.at(grad, eb[e_idx], t[:, None] * w)
    return grad.reshape(D, M1, 2)


# -- the solves -----------------------------------------------------------------------------------
@dataclass
class _Batch:
    """Directions followed together as one fan: the fan problems and states per mesh and the
    workspace indices of the fan's members (set once the directions are sorted)."""

    fans: tuple
    states: tuple
    members: np.ndarray  # positions of the fan's members in the list of solved directions
    index: np.ndarray | None = None


@dataclass
class _Solution:
    """What the workspace's sensitivities need: the fan batches, and the directions solved one
    by one (workspace index -> RodResult)."""

    rod: Rod
    batches: list = dataclasses.field(default_factory=list)
    single: dict = dataclasses.field(default_factory=dict)


def _check(rod, b_max, directions, magnitudes, nodes, clamp_position, clamp_angle, refine):
    if not isinstance(rod, Rod):
        raise ValueError(f"rod must be a coilrod.Rod; got {type(rod).__name__}")
    rod.magnetization.check_planar("workspace")
    b_max = positive(b_max, "b_max")
    lam = rod.magnetoelastic_number(b_max)
    if lam > MAX_LAMBDA:
        raise ValueError(
            f"b_max = {b_max:g} T gives a magnetoelastic number of {lam:.3g} for this rod, beyond "
            f"{MAX_LAMBDA:g}: the rod would be a boundary layer at the clamp; lower b_max"
        )
    directions = as_count(directions, "directions", 3, MAX_DIRECTIONS)
    magnitudes = as_count(magnitudes, "magnitudes", 1, MAX_MAGNITUDES)
    nodes = as_count(DEFAULT_SEGMENTS if nodes is None else nodes, "nodes", 4, MAX_SEGMENTS)
    refine = as_count(refine, "refine", 0, MAX_REFINE)
    clamp = as_vector(clamp_position, "clamp_position")
    angle = finite_scalar(clamp_angle, "clamp_angle")
    return b_max, directions, magnitudes, nodes, clamp, angle, refine


def reference_direction(rod: Rod, nodes: int | None = None, clamp_angle: float = 0.0) -> float:
    """The direction the workspace's field directions are measured from, rad from +x.

    The direction of the rod's net magnetic moment in the plane, ``sum_i w_i m_i`` over the
    mesh nodes (body-frame magnetization, quadrature weights w), turned by ``clamp_angle``: a
    property of the robot, which turns with the clamp and with a uniform magnetization.  A rod
    whose net moment vanishes (below 1e-9 of ``sum_i w_i |m_i|``) takes the clamp direction.

    Parameters
    ----------
    rod : Rod
    nodes : int, optional
        Mesh nodes (as in :func:`coilrod.solve_rod`).
    clamp_angle : float
        Clamp angle, rad.

    Returns
    -------
    float
        rad.
    """
    from ..rod.mesh import node_magnetization

    mesh = make_mesh(rod, DEFAULT_SEGMENTS if nodes is None else nodes)
    m = node_magnetization(rod.magnetization, mesh, rod.length)
    net = mesh.w @ m
    if math.hypot(*net) <= 1e-9 * float(mesh.w @ np.hypot(m[:, 0], m[:, 1])):
        return float(clamp_angle)
    return float(clamp_angle) + math.atan2(net[1], net[0])


def _direction_fields(system, b_max: float, phi: np.ndarray):
    """(fields, currents): each direction's field at scale 1 (``b_max`` along phi at the
    centre) and, with a system, its currents (D, m)."""
    B = b_max * np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], 1)
    if system is None:
        return [coils.UniformField(B=b) for b in B], None
    if not (hasattr(system, "currents_for") and hasattr(system, "with_currents")):
        raise ValueError(
            "system must be a coil system with current control (currents_for, with_currents); "
            f"got {type(system).__name__}"
        )
    currents = []
    for b, p in zip(B, phi, strict=True):
        try:
            currents.append(system.currents_for(B=b))
        except ValueError as exc:
            raise ValueError(
                f"the system cannot make b_max = {b_max:g} T along {np.degrees(p):g} deg at its "
                f"centre: {exc}"
            ) from None
    currents = np.array(currents)
    return [system.with_currents(i) for i in currents], currents


def _cells(alpha, theta, stable, snaps):
    """Included cells (D, M) and the cells left out that refinement can recover (D, M), of
    directions ``alpha`` (D,) sorted over (-pi, pi), the cell d lying between alpha[d] and
    alpha[d + 1] (the last one across the cut, alpha[0] + 2 pi)."""
    gap = np.diff(np.r_[alpha, alpha[0] + 2 * np.pi])
    ok = stable[:, :-1] & stable[:, 1:] & ~snaps  # (D, M): along each direction's ramp
    cells = ok & np.roll(ok, -1, axis=0)
    with np.errstate(invalid="ignore"):
        jump = np.max(np.abs(theta - np.roll(theta, -1, axis=0)), axis=2)  # (D, M + 1)
    same = jump <= np.maximum(BRANCH_JUMP, 2 * gap)[:, None]
    cells &= same[:, :-1] & same[:, 1:]
    # nothing to recover where both directions' ramps leave the cell out (e.g. the straight
    # rod beyond buckling on both sides): elsewhere the two sides differ
    dead = ~ok & ~np.roll(ok, -1, axis=0)
    return cells, ~cells & ~dead


def workspace(
    rod: Rod,
    b_max: float,
    directions: int = 72,
    magnitudes: int = 16,
    system=None,
    *,
    nodes: int | None = None,
    richardson: bool = True,
    clamp_position=(0.0, 0.0, 0.0),
    clamp_angle: float = 0.0,
    refine: int = 6,
    tolerance: float = 1e-3,
    reference: float | None = None,
    progress: bool = False,
) -> Workspace:
    """The workspace of ``rod``: the tip positions reached by fields up to ``b_max``.

    Parameters
    ----------
    rod : Rod
    b_max : float
        Largest field magnitude (at the system centre), T, > 0.
    directions : int
        In-plane field directions of the initial grid (>= 3), evenly spaced over the circle
        and measured from the rod's :func:`reference_direction` (see the module docstring).
    magnitudes : int
        Magnitude steps from 0 to ``b_max`` (>= 1).
    system : coil system, optional
        A coil system with current control whose channels can make any in-plane field at its
        centre (``currents_for``, ``with_currents``; e.g. two or three orthogonal Helmholtz
        pairs).  Its real field acts; ``b_max`` must be within its current limits in every
        direction.  None: ideal uniform fields.
    nodes, richardson, clamp_position, clamp_angle
        As in :func:`coilrod.solve_rod` (the clamp in m and rad).
    refine : int
        Bisection levels of the directions where neighbouring directions land on different
        branches, a snap or an unstable state (0 ... 20): the smallest direction step is
        ``2 pi / directions / 2**refine``, the smallest magnitude step
        ``b_max / magnitudes / 2**refine``.
    tolerance : float
        Largest estimated distance of the tip curves (along a direction's ramp, or across
        directions at one magnitude) from a cell's straight edge, in rod lengths (> 0): the
        directions and magnitude steps beyond it are bisected (up to ``refine`` levels).
    reference : float, optional
        The direction the field directions are measured from, rad from +x; default the rod's
        :func:`reference_direction` (give it to hold the directions fixed while the
        magnetization changes, e.g. for differences of tips).
    progress : bool
        Show a progress bar (directions solved one by one).

    Returns
    -------
    Workspace
        See the module docstring for the definition.

    Raises
    ------
    ValueError
        Bad input (naming the argument); a magnetization with an out-of-plane elevation (the
        workspace is that of the planar rod).

    Notes
    -----
    Ideal fields: all directions of a refinement level are followed together as one
    block-diagonal problem (:class:`~coilrod.rod.fan.UniformFan`); a direction whose path
    meets a fold or a bifurcation is re-solved on its own with :func:`coilrod.solve_rod` (which
    locates and reports the event).  Real coil fields: one :func:`coilrod.solve_rod` per
    direction.  Stability is the solver's (``member_stability`` of the fan, ``stable`` of
    :func:`coilrod.solve_rod`).

    Examples
    --------
    >>> from coilrod import presets, workspace
    >>> ws = workspace(presets.seed_rod(presets.M1()), 0.01, directions=12, magnitudes=4, refine=2)
    >>> ws.tips.shape == (ws.directions.size, ws.magnitudes.size, 3)
    True
    >>> bool(0 < ws.area_error < ws.area)  # two levels only: a rough area
    True
    """
    b_max, D, M, nodes, clamp, angle, refine = _check(
        rod, b_max, directions, magnitudes, nodes, clamp_position, clamp_angle, refine
    )
    tolerance = positive(tolerance, "tolerance")
    if reference is None:
        psi = reference_direction(rod, nodes, angle)
    else:
        psi = finite_scalar(reference, "reference")
    n = make_mesh(rod, nodes).n
    straight = clamp + rod.length * np.array([math.cos(angle), math.sin(angle), 0.0])
    h = tolerance * rod.length  # largest sagitta of the tip curves over a cell edge, m
    alpha = -np.pi + 2 * np.pi * (np.arange(D) + 0.5) / D  # from the reference direction
    level = np.arange(D) % 2  # the initial grid is level 1 of a grid half as fine
    scales = np.arange(1, M + 1) / M
    mlevel = np.arange(1, M + 1) % 2
    min_gap = 2 * np.pi / D / 2**refine * (1 - 1e-9)
    min_width = 1.0 / M / 2**refine * (1 - 1e-9)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(desc="workspace", unit="direction")
    args = (rod, b_max, scales, nodes, richardson, clamp, angle, system, n, straight)
    try:
        alpha, level, got, sol, events = _refine_directions(
            psi, alpha, level, args, refine, h, min_gap, bar
        )
        scales, mlevel = _refine_magnitudes(psi, alpha, got, mlevel, args, refine, h, min_width)
        # 3. every direction at the final magnitudes
        if scales.size > magnitudes:
            got, sol, events = _fresh(), _Solution(rod), []
            args = (rod, b_max, scales, nodes, richardson, clamp, angle, system, n, straight)
            _solve_directions(psi + alpha, 0, *args, got, sol, events, bar)
    finally:
        if bar is not None:
            bar.close()
    return _collect(rod, b_max, system, psi, alpha, level, scales, mlevel, got, sol, events)


def _fresh() -> dict:
    """Empty lists of what :func:`_solve_directions` gathers per direction."""
    return {"tips": [], "theta": [], "stable": [], "snaps": [], "currents": []}


def _refine_directions(psi, alpha, level, args, refine, h, min_gap, bar):
    """1. Directions: solve ``alpha`` (from the reference ``psi``), then bisect where
    neighbours land on different branches (or one on an unstable state or a snap) and where
    the tips at b_max bend away from the chords (sagitta > ``h``), ``refine`` times at most.

    Returns the directions (in the order solved), their bisection levels, and what
    :func:`_solve_directions` gathered (got, solution, events)."""
    D = alpha.size
    got, sol, events = _fresh(), _Solution(args[0]), []
    _solve_directions(psi + alpha, 0, *args, got, sol, events, bar)
    for _ in range(refine):
        a, cat = _sorted(alpha, got)
        _, recover = _cells(a, *(cat[k] for k in ("theta", "stable", "snaps")))
        gap = np.diff(np.r_[a, a[0] + 2 * np.pi])
        sag = _sagitta(cat["tips"][:, -1:, :2], axis=0, wrap=True)[:, 0]
        split = np.flatnonzero((recover.any(axis=1) | (sag > h)) & (gap > min_gap))
        if split.size == 0:
            break
        new = a[split] + gap[split] / 2
        new = np.where(new > np.pi, new - 2 * np.pi, new)
        first = alpha.size
        alpha = np.r_[alpha, new]
        depth = 2 + np.round(np.log2(2 * np.pi / D / gap[split])).astype(int)
        level = np.r_[level, depth]  # the finer the step split, the higher
        _solve_directions(psi + new, first, *args, got, sol, events, bar)
    return alpha, level, got, sol, events


def _refine_magnitudes(psi, alpha, got, mlevel, args, refine, h, min_width):
    """2. Magnitudes: bisect the steps where the ramps of the directions bounding the
    workspace (next to the cut or to a cell left out) bend away from the chords (sagitta >
    ``h``), ``refine`` times at most, the ramps probed on the coarse mesh (enough to see where
    they bend).  Returns the magnitudes (fractions of b_max) and their bisection levels."""
    scales = args[2]
    M = scales.size
    a, cat = _sorted(alpha, got)
    _, recover = _cells(a, *(cat[k] for k in ("theta", "stable", "snaps")))
    edge = np.any(_sagitta(cat["tips"][..., :2], axis=1) > h, axis=1)
    probe, tips = psi + a[edge], cat["tips"][edge]
    for _ in range(refine):
        width = np.diff(np.r_[0.0, scales])
        sag = _sagitta(tips[..., :2], axis=1)
        long = np.flatnonzero(np.any(sag > h, axis=0) & (width > min_width))
        if long.size == 0:
            break
        probe = probe[np.any(sag[:, long] > h, axis=1)]  # the ramps still bent
        scales = np.r_[scales, scales[long] - width[long] / 2]
        mlevel = np.r_[mlevel, 2 + np.round(np.log2(1.0 / M / width[long])).astype(int)]
        o = np.argsort(scales)
        scales, mlevel = scales[o], mlevel[o]
        trial = _fresh()
        # (the coarse mesh's tips: enough to see where the ramps bend)
        targs = (*args[:2], scales, args[3], False, *args[5:])
        _solve_directions(probe, 0, *targs, trial, _Solution(args[0]), [], None)
        tips = trial["tips"][0]
    return scales, mlevel


def _collect(rod, b_max, system, psi, alpha, level, scales, mlevel, got, sol, events):
    """The Workspace: the directions sorted, the cells and their union, and the area error
    (the area one bisection level coarser)."""
    order = np.argsort(alpha, kind="stable")
    where = np.empty_like(order)
    where[order] = np.arange(order.size)
    cat = {k: np.concatenate(v)[order] for k, v in got.items() if k != "currents"}
    for b in sol.batches:
        b.index = where[b.members]
    sol.single = {int(where[k]): v for k, v in sol.single.items()}
    for e in events:
        e["direction"] = int(where[e["direction"]])
    alpha, level = alpha[order], level[order]
    cells, _ = _cells(alpha, cat["theta"], cat["stable"], cat["snaps"])
    tips = cat["tips"]
    polygon, area, boundary = _union(tips[..., :2], cells, rod.length)
    # one level coarser, for area_error (computed when first read: its unions cost about as
    # much as the area's, and optimisation loops read only the area)
    coarse = _Coarse(
        alpha, level, mlevel, cat["theta"], cat["stable"], cat["snaps"], tips, rod.length
    )
    currents = None if system is None else np.concatenate(got["currents"])[order]
    return Workspace(
        directions=psi + alpha,
        magnitudes=b_max * np.r_[0.0, scales],
        tips=tips,
        stable=cat["stable"],
        snaps=cat["snaps"],
        cells=cells,
        polygon=polygon,
        area=area,
        boundary=boundary,
        events=events,
        system=system,
        currents=currents,
        reference=psi,
        levels=level,
        _solution=sol,
        _coarse=coarse,
    )


@dataclass
class _Coarse:
    """What :attr:`Workspace.area_error` needs: the grid's directions (sorted) and their
    levels, the magnitudes' levels, the states (theta, stable, snaps, tips) and L."""

    alpha: np.ndarray
    level: np.ndarray
    mlevel: np.ndarray
    theta: np.ndarray
    stable: np.ndarray
    snaps: np.ndarray
    tips: np.ndarray
    length: float

    def area_error(self, area: float) -> float:
        """``|A - A_d| + |A - A_m|`` (m^2): A_d the area with the last bisection of the
        directions undone everywhere (the leaves of the bisection trees left out; on an
        unrefined stretch, every other point of the initial grid), A_m that with the
        magnitudes' undone.  Undone together, the two differences (of either sign) could
        cancel."""
        keep = ~_leaves(self.level, cyclic=True)
        M = self.mlevel.size
        mj = np.flatnonzero(~_leaves(np.r_[0, self.mlevel], cyclic=False))
        mj = np.unique(np.r_[mj, M])
        every = np.arange(M + 1)
        error = 0.0
        for kd, km in ((keep, every), (np.ones_like(keep), mj)):
            cells, _ = _cells(
                self.alpha[kd],
                self.theta[kd][:, km],
                self.stable[kd][:, km],
                _coarse_snaps(self.snaps[kd], km),
            )
            error += abs(area - _union(self.tips[kd][:, km, :2], cells, self.length)[1])
        return error


def _leaves(level, cyclic: bool):
    """The points of a bisection hierarchy (levels in grid order) made by the last bisection
    of their stretch: finer than both neighbours (the ends of a non-cyclic grid are kept)."""
    if cyclic:
        return (level > np.roll(level, 1)) & (level > np.roll(level, -1))
    out = np.zeros(level.size, dtype=bool)
    out[1:-1] = (level[1:-1] > level[:-2]) & (level[1:-1] > level[2:])
    return out


def _sorted(alpha, got):
    """The directions sorted, and the states solved (``got``) in their order."""
    order = np.argsort(alpha, kind="stable")
    return alpha[order], {k: np.concatenate(v)[order] for k, v in got.items() if k != "currents"}


def _sagitta(xy, axis: int, wrap: bool = False):
    """Estimated distance of the tip curves from their chords, per chord: ``|chord| turn / 8``
    (the sagitta of a circular arc), ``turn`` the larger turning angle of the polyline at the
    chord's two ends, along ``axis`` of the tip grid ``xy`` (D, M + 1, 2); (D, M) along the
    magnitudes (axis 1), (D, M + 1) along the directions (axis 0, ``wrap``: closed)."""
    xy = np.moveaxis(xy, axis, 0)
    nxt = np.roll(xy, -1, axis=0) if wrap else xy[1:]
    v = nxt - (xy if wrap else xy[:-1])  # chords
    with np.errstate(invalid="ignore"):
        c = np.hypot(v[..., 0], v[..., 1])
        prev = np.roll(v, 1, axis=0)
        turn = np.abs(
            np.arctan2(
                prev[..., 0] * v[..., 1] - prev[..., 1] * v[..., 0],
                np.einsum("...k,...k->...", prev, v),
            )
        )  # at each chord's start
        if not wrap:
            turn[0] = 0.0
        end = np.roll(turn, -1, axis=0)
        if not wrap:
            end[-1] = 0.0
        sag = c * np.fmax(turn, end) / 8
    sag = np.where(np.isfinite(sag), sag, 0.0)
    return np.moveaxis(sag, 0, axis)


def _coarse_snaps(snaps, mj):
    """Snaps of the coarse magnitude steps mj[i] -> mj[i + 1]: any fine snap between."""
    c = np.concatenate([np.zeros((snaps.shape[0], 1), int), np.cumsum(snaps, axis=1)], axis=1)
    return (c[:, mj[1:]] - c[:, mj[:-1]]) > 0


def _solve_directions(
    phi,
    first,
    rod,
    b_max,
    scales,
    nodes,
    richardson,
    clamp,
    angle,
    system,
    n,
    straight,
    got,
    sol,
    events,
    bar,
):
    """Solve the directions ``phi`` (numbered from ``first``) and append their states to
    ``got``, batches and single solves to ``sol`` and events to ``events``."""
    D, M = phi.size, scales.size
    tips = np.full((D, M + 1, 3), np.nan)
    theta = np.full((D, M + 1, n), np.nan)  # node angles, rad
    stable = np.ones((D, M + 1), dtype=bool)
    snaps = np.zeros((D, M), dtype=bool)
    tips[:, 0], theta[:, 0] = straight, angle
    todo = list(range(D))
    if system is None:
        todo, batch = _solve_fan(rod, b_max, phi, scales, nodes, richardson, clamp, angle)
        if batch is not None:
            idx = batch.pop("members")
            theta[idx, 1:], tips[idx, 1:], stable[idx, 1:] = (
                batch.pop("thetas"),
                batch.pop("tips"),
                batch.pop("stable"),
            )
            sol.batches.append(_Batch(members=first + idx, **batch))
    fields, currents = _direction_fields(system, b_max, phi) if todo else (None, None)
    if system is not None:
        got["currents"].append(currents)
    for d in todo:
        try:
            res = _solve_direction(rod, fields[d], scales, nodes, richardson, clamp, angle)
        except ConvergenceError as err:  # keep the states before, leave the rest out
            res = getattr(err, "result", None)
            events.append(
                {
                    "direction": first + d,
                    "kind": "unreached",
                    "scale": float(getattr(err, "reached", 0.0)),
                    "message": str(err),
                }
            )
            stable[d, 1:] = False
            if res is None:
                continue
        sol.single[first + d] = res
        k = len(res.scales)
        tips[d, 1 : k + 1] = res.tip
        theta[d, 1 : k + 1] = np.array([res.theta(i) for i in range(k)])
        stable[d, 1 : k + 1] = res.stable
        for e in res.instabilities:
            events.append({"direction": first + d, **e})
            if e["kind"] == "snap":
                snaps[d, e["index"]] = True
        if bar is not None:
            bar.update(1)
    stable &= np.isfinite(tips).all(axis=2)
    for key, v in (("tips", tips), ("theta", theta), ("stable", stable), ("snaps", snaps)):
        got[key].append(v)


def _solve_direction(rod, field, scales, nodes, richardson, clamp, angle):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StabilityWarning)
        return solve_rod(
            rod,
            field,
            scales,
            nodes=nodes,
            richardson=richardson,
            clamp_position=clamp,
            clamp_angle=angle,
        )


def _solve_fan(rod, b_max, phi, scales, nodes, richardson, clamp, angle):
    """Follow the directions together; returns the directions to re-solve one by one and the
    fan's batch (a dict; None if the fan gave up).

    The fan gives up early on a hard stretch (no snap-through handling, a coarse smallest
    sub-step): then the directions with the smallest second-variation eigenvalue at its last
    converged state (those at a fold, a bifurcation or the sharp knee of a nearly symmetric
    one) are handed to :func:`solve_rod` and the fan restarts without them.  After a fan that
    met an event, the directions near it are re-solved too."""
    D = phi.size
    mesh = make_mesh(rod, nodes)
    meshes = [mesh, mesh.refined()] if richardson else [mesh]
    probe = coils.UniformField(B=(b_max, 0.0, 0.0))
    bases = [build_problem(rod, probe, m, clamp, angle) for m in meshes]
    opts = PathOptions(
        newton=NewtonOptions(max_iter=15), min_step=1e-3, bifurcation_tol=1e-2, snap_steps=2
    )
    active = np.arange(D)
    redo: set = set()
    for _ in range(4):
        if active.size == 0:
            return sorted(redo), None
        fields = b_max * np.stack([np.cos(phi[active]), np.sin(phi[active])], 1)
        fans = [UniformFan(base, fields) for base in bases]
        try:
            run = follow_load(fans[0], fans[0].straight(), scales, opts, name="workspace")
            break
        except ConvergenceError as err:
            last = err.points[-1] if err.points else None
            u = fans[0].straight() if last is None else last.u
            # in-plane figure: the branch's folds and knees (the 3D one adds out-of-plane modes)
            mu = fans[0].base.branch_stability(
                fans[0].member_linearization(
                    fans[0].linearize(u, 0.0 if last is None else last.scale)
                ),
                precise=True,
            )
            order = np.argsort(mu)
            hard = order[: max(1, active.size // 10)]
            hard = np.union1d(hard, np.flatnonzero(mu < 0.25 * bases[0].mu0))
            redo |= set(active[hard].tolist())
            active = np.delete(active, hard)
    else:
        return sorted(redo | set(active.tolist())), None
    Dn = active.size
    coarse = np.array([p.u for p in run.points])
    states = [coarse]
    if richardson:
        res = newton(
            fans[1],
            fans[0].interpolate_to(fans[1], coarse),
            scales,
            dataclasses.replace(opts.newton, chord_start=True),
            tangent_at_end=False,
        )
        if not np.all(res.ok):
            return sorted(redo | set(active.tolist())), None
        states.append(res.u)
    k = len(scales)
    thetas = [
        f.members(u).reshape(k, Dn, f.n).transpose(1, 0, 2)
        for f, u in zip(fans, states, strict=True)
    ]
    pos = [f.base.positions(t) for f, t in zip(fans, thetas, strict=True)]  # (Dn, k, n, 2)
    if richardson:
        th = (4 * thetas[1][:, :, ::2] - thetas[0]) / 3
        tip = (4 * pos[1][:, :, -1] - pos[0][:, :, -1]) / 3
    else:
        th, tip = thetas[0], pos[0][:, :, -1]
    lin = fans[0].linearize(coarse, scales)
    signs = fans[0].member_stability(lin).reshape(k, Dn).T  # (Dn, k), 3D
    if run.events:  # directions near the event: small eigenvalue or unstable somewhere
        mu = fans[0].base.branch_stability(fans[0].member_linearization(lin), precise=True)
        mu = np.asarray(mu, float).reshape(k, Dn).T
        near = np.any(mu < 0.25 * bases[0].mu0, axis=1)
        plane = fans[0].base.branch_stability(fans[0].member_linearization(lin))
        plane = np.asarray(plane, float).reshape(k, Dn).T  # in-plane: the fan's own events
        redo |= set(active[np.flatnonzero(near | np.any(plane <= 0, axis=1))].tolist())
    batch = {
        "fans": tuple(fans),
        "states": tuple(states),
        "members": active,
        "thetas": th,
        "tips": np.concatenate(
            [clamp[:2] + rod.length * tip, np.full(tip.shape[:2] + (1,), clamp[2])], axis=2
        ),
        "stable": signs > 0,
    }
    return sorted(redo), batch


# -- derivatives ----------------------------------------------------------------------------------
class _FanMembers:
    """The members of a fan as the single-rod problem the adjoint code expects."""

    def __init__(self, fan: UniformFan):
        self.fan, self.n, self.mesh = fan, fan.n, fan.base.mesh
        self.tip_gradients = fan.base.tip_gradients
        self.load_adjoint = fan.base.load_adjoint

    def field_at_states(self, U):
        k = U.shape[0] // self.fan.D
        B = self.fan.member_fields(k)
        return B, np.zeros(B.shape + (3,))


def tip_derivatives(ws: Workspace, wrt) -> tuple[list[str], np.ndarray]:
    """d(tip x, y [m])/dp of every state of a workspace: (labels, array (D, M + 1, 2, p)).

    ``wrt``: magnetization groups ("magnitudes", "angles") and "youngs_modulus" (see
    :func:`coilrod.sensitivities`).  States at a fold or bifurcation (where the derivative
    does not exist) and the unloaded state get zeros; they bound no included cell's interior.
    """
    from .sensitivity import _groups, _mesh_derivatives, _parameters, _segments
    from .sensitivity import tip_derivatives as rod_derivatives

    sol = ws._solution
    rod = sol.rod
    have = ["youngs_modulus"]
    if _segments(rod.magnetization, rod.length) is not None:
        have = ["magnitudes", "angles", *have]
    what = f"workspace of a rod with magnetization {rod.magnetization!r}"
    groups = _groups(wrt, have, what)
    D, M1 = ws.tips.shape[:2]
    labels = _parameters(rod, groups, {})[0]
    out = np.zeros((D, M1, 2, len(labels)))
    scales = ws.magnitudes[1:] / ws.magnitudes[-1]
    k = scales.size
    for batch in sol.batches:
        per_mesh = []
        for fan, U in zip(batch.fans, batch.states, strict=True):
            lin = fan.member_linearization(fan.linearize(U, scales))
            S = np.repeat(scales, fan.D)
            with np.errstate(all="ignore"):
                try:
                    d = _mesh_derivatives(_FanMembers(fan), fan.members(U), S, rod, groups, {}, lin)
                except ValueError:  # a singular member: take them one by one below
                    d = np.full((k * fan.D, 3, len(labels)), np.nan)
            per_mesh.append(d.reshape(k, fan.D, 3, -1).transpose(1, 0, 2, 3))
        d = per_mesh[0] if len(per_mesh) == 1 else (4 * per_mesh[1] - per_mesh[0]) / 3
        out[batch.index, 1:] = rod.length * d[:, :, 0:2]
    for direction, res in sol.single.items():
        got = len(res.scales)
        try:
            _, _, _, Dd = rod_derivatives(res, np.arange(got), groups, check=False)
            out[direction, 1 : got + 1] = Dd[:, 0:2]
        except ValueError:
            out[direction, 1 : got + 1] = np.nan
    bad = ~np.isfinite(out)
    out[bad] = 0.0
    return labels, out
