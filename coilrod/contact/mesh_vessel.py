"""A vessel lumen from a triangle surface mesh (STL, OBJ, PLY): smoothed or exact gaps.

The lumen is the volume the mesh encloses (its faces' normals point out of it, away from the
lumen).  Two gaps (> 0 inside):

* **smoothed** (default, ``smooth=True``): the wall the mesh samples, recovered locally.  Each
  vertex k has a unit normal ``n_k`` (angle-weighted), a curvature tensor ``K_k`` (a least-
  squares fit of its neighbours' heights above its tangent plane) and the radius ``D_k`` of
  the largest vertex-free ball touching it from inside (shrinking balls).  A point's gap is
  ``sum_k w_k c_k / sum_k w_k`` with ``c_k`` its distance below vertex k's osculating quadric
  (the tangent plane's distance ``d_k = (v_k - p) . n_k`` less ``a^T K (I - d_k K)^-1 a / 2``,
  ``a`` the tangent offset) and C2 weights ``w_k`` of compact support: Wendland's function of
  the tangent offset over 1.5 longest incident edges, times a step from 1 to 0 as ``|d_k|``
  goes from 0.7 ``D_k`` to ``D_k`` (the opposite wall does not count).  Gradient and hessian
  are its exact derivatives (C1 across edges: the contact Newton converges against it); near
  the lumen's medial axis, where the weights fade, it blends (C2) into the exact gap.  It
  tends to the sampled surface at second order or better (about fourth on tessellated bends,
  ``benchmarks/bench_mesh_vessel.py``; near a curvature jump, such as a bend preset's joints,
  about 2.6 for the gap and 1.5 for the normal); too coarse a mesh (8 vertices round a tube)
  gives a poor curvature fit.
* **exact** (``smooth=False``): the signed distance to the polyhedron: candidate triangles from
  KD-trees over the vertices and the triangle centroids, exact closest points on them
  (vectorised over points and candidates; trimesh reads and checks the mesh), the sign from
  the angle-weighted pseudo-normal of the closest feature (face, edge or vertex; Baerentzen &
  Aanaes 2005), exact for a closed, consistently oriented mesh.  Gradient and hessian are
  those of the distance to the closest feature: a face (a plane: hessian 0), an edge (a line:
  ``(I - t t^T - u u^T) / d``) or a vertex (a point: ``(I - u u^T) / d``); the gradient jumps
  where the closest face changes, which the semi-smooth contact Newton does not survive.

:func:`tessellate` turns an analytic :class:`~coilrod.contact.Vessel` into such a mesh (rings
of vertices on its wall, capped ends): the phantoms shipped in ``coilrod/contact/data/`` were
made by the project this way from its own presets (no patient data).
"""

from __future__ import annotations

import os
import warnings
from importlib import resources

import numpy as np

from coils._files import input_path
from coils._validate import as_bool, as_choice, as_count, as_points

from .obstacle import Obstacle, _mm, _point_mm, as_friction
from .vessel import Vessel

__all__ = ["MeshVessel", "tessellate", "phantom_path"]

_UNITS = {"m": 1.0, "mm": 1e-3}
#: Sizes (m, the largest extent) outside which a mesh file's units are doubted
#: (coilrod.UnitsWarning): a lumen larger than a body's 3 m, smaller than 0.1 mm.
MAX_SIZE, MIN_SIZE = 3.0, 1e-4
#: A closed lumen's mean radius (2 x volume / area: a tube's radius, less at its caps) over
#: which its file's units are doubted too: the centreline files' widest vessel
#: (``centerline_file.MAX_RADIUS``, an aorta's 15 mm with a margin).
MAX_RADIUS = 0.05


def phantom_path(name: str = "bend") -> str:
    """Path of a phantom shipped with coilrod.

    ``"bend"``: ``tessellate(Vessel.bend(0.02, pi/2, 2e-3, 0.01, 0.01), 12, 1e-3,
    caps="fan")`` (12 vertices per ring, rings 0.99 mm apart, the ends capped flat by fans of
    triangles from their centres), a binary STL in metres: its triangles are that call's,
    rounded to single precision, bit for bit.  Made by the project from its own preset (no
    patient or third-party data); distributed under coilrod's licence (MIT).
    ``coilrod/contact/data/README.md`` says the same."""
    name = as_choice(name, "name", ("bend",))
    return str(resources.files("coilrod.contact") / "data" / f"{name}_phantom.stl")


class MeshVessel(Obstacle):
    """Rigid lumen enclosed by a triangle surface mesh.

    Parameters
    ----------
    vertices : array-like, shape (n, 3)
        Vertex positions, m.
    faces : array-like of int, shape (m, 3)
        Vertex indices of the triangles, normals (right-hand rule) pointing out of the lumen.
        A closed mesh whose normals all point into the lumen is a ValueError unless
        ``fix_normals``.
    source : str, optional
        Where the mesh came from (a file name), used in messages.
    friction : float
        Coulomb friction coefficient mu >= 0 of the wall (for the contact models).
    smooth : bool
        True (default): the smoothed gap (see the module: C1 across edges, exact derivatives,
        what contact and insertion need); False: the exact distance to the polyhedron.
        :meth:`closest` is the polyhedron's either way.
    fix_normals : bool
        Turn a closed mesh whose normals point into the lumen around (default False: a
        ValueError naming ``source``; the orientation of an open mesh cannot be checked).

    Attributes
    ----------
    vertices : ndarray, shape (n, 3)
        m, read-only (after any reorientation).
    faces : ndarray, shape (m, 3)
    watertight : bool
        Whether the mesh is closed (every edge shared by exactly two faces).  An open mesh
        (a tube without end caps) is accepted with a warning: the gap is still the signed
        distance to its surface, but beyond its open ends it is not a lumen.
    volume : float
        Enclosed volume, m^3 (closed meshes; nan for open ones).

    Raises
    ------
    ValueError
        Fewer than 4 vertices or 4 faces, non-finite vertices, bad indices, degenerate
        faces, non-manifold edges (shared by more than two faces) or vertices (two sheets
        meeting at a point), inconsistent winding, inward-facing normals (of any closed
        component) without ``fix_normals``, or a closed surface with outward normals nested
        inside the lumen; each message names ``source``.

    Examples
    --------
    >>> from coilrod.contact import Vessel
    >>> tube = MeshVessel(*tessellate(Vessel.straight(0.04, 1e-3), 32, 1e-3))
    >>> float(tube.gap([0.02, 0.0, 0.0])[0]) > 0.99e-3
    True
    """

    _outside = "outside the vessel mesh"
    _immutable = True

    def __init__(
        self,
        vertices,
        faces,
        *,
        source: str | None = None,
        friction=0.0,
        smooth: bool = True,
        fix_normals: bool = False,
    ):
        label = "mesh" if source is None else f"mesh {source!r}"
        self.source = source
        self.friction = as_friction(friction)
        self.smooth = as_bool(smooth, "smooth")
        fix_normals = as_bool(fix_normals, "fix_normals")
        mesh = self._checked(vertices, faces, label)
        mesh = self._oriented(mesh, label, fix_normals)
        self._index(mesh)

    @staticmethod
    def _checked(vertices, faces, label: str):
        """The trimesh of ``vertices`` and ``faces`` (duplicate vertices merged), checked: at
        least 4 of each, valid indices, no degenerate face, manifold (no edge of more than two
        faces, no vertex pinching two sheets), consistently wound; else ValueError naming the
        problem (``label``: the mesh's name in it)."""
        import trimesh

        v = as_points(vertices, "vertices")
        f = np.asarray(faces)
        if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
            raise ValueError(f"{label}: faces must be an integer array of shape (m, 3)")
        if len(v) < 4 or len(f) < 4:
            raise ValueError(f"{label} has {len(v)} vertices and {len(f)} faces; a lumen needs 4+")
        if f.min() < 0 or f.max() >= len(v):
            raise ValueError(f"{label}: face indices must lie in [0, {len(v)})")
        mesh = trimesh.Trimesh(v, f, process=True, validate=False)
        area = mesh.area_faces
        if np.any(area <= 1e-14 * mesh.scale**2):
            k = int(np.argmin(area))
            raise ValueError(f"{label}: face {k} is degenerate (zero area)")
        counts = np.bincount(mesh.edges_unique_inverse, minlength=len(mesh.edges_unique))
        if np.any(counts > 2):
            k = int(np.argmax(counts))
            raise ValueError(
                f"{label} is not manifold: edge {mesh.edges_unique[k].tolist()} is shared by "
                f"{counts[k]} faces"
            )
        if not mesh.is_winding_consistent:
            raise ValueError(
                f"{label}: the faces are not consistently oriented (neighbouring normals "
                "point to opposite sides); repair it (e.g. trimesh.repair.fix_winding)"
            )
        pinch = _pinched_vertex(mesh.faces, mesh.face_adjacency, mesh.face_adjacency_edges)
        if pinch is not None:
            raise ValueError(
                f"{label} is not manifold: vertex {pinch} at {_point_mm(mesh.vertices[pinch])} "
                "joins two sheets of faces that share no edge there (two surfaces touching "
                "at a point); separate them"
            )
        return mesh

    def _oriented(self, mesh, label: str, fix_normals: bool):
        """``mesh`` with its normals pointing out of the lumen (closed: every component's
        orientation checked, inverted ones turned around with ``fix_normals``, else
        ValueError); sets :attr:`watertight` and :attr:`volume` (NaN if open: warned)."""
        import trimesh

        self.watertight = bool(mesh.is_watertight)
        if self.watertight:
            # every closed component by itself: the winding number just outside each one's
            # faces must be 0 (a component turned inside out gives -1 there, one nested in
            # another lumen +1); the total volume alone misses an inverted component beside
            # a larger right one
            inverted, nested = _component_orientation(mesh)
            if nested is not None:
                raise ValueError(
                    f"{label}: the closed surface of face {nested} lies inside the lumen "
                    "with its normals pointing out of it (a lumen inside the lumen); a cavity "
                    "in the lumen (a solid inside it) must have normals pointing into it"
                )
            if inverted.any():
                if not fix_normals:
                    part = (
                        ""
                        if inverted.all()
                        else f" (faces {_ranges(np.flatnonzero(inverted))} of {len(inverted)})"
                    )
                    raise ValueError(
                        f"{label}: the face normals point into the lumen{part} (the lumen is "
                        "the enclosed volume, its normals must point out of it); reverse the "
                        "faces' winding, or pass fix_normals=True to turn them around"
                    )
                faces = np.array(mesh.faces)
                faces[inverted] = faces[inverted][:, ::-1]
                mesh = trimesh.Trimesh(mesh.vertices, faces, process=False, validate=False)
            self.volume = float(mesh.volume)
        else:
            warnings.warn(
                f"{label} is not watertight (open boundary edges): its orientation cannot be "
                "checked and beyond its open ends the gap is not a lumen's",
                stacklevel=3,
            )
            self.volume = float("nan")
        return mesh

    def _index(self, mesh) -> None:
        """The oriented ``mesh``'s arrays, normals, search trees and the smoothed gap's vertex
        supports, depths and reach."""
        from scipy.spatial import cKDTree

        self._mesh = mesh
        self.vertices = np.array(mesh.vertices, dtype=float)
        self.faces = np.array(mesh.faces, dtype=np.int64)
        self._normals(mesh)
        tris = self.vertices[self.faces]
        cen = tris.mean(axis=1)
        self._ctree = cKDTree(cen)
        self._vtree = cKDTree(self.vertices)
        self._rmax = float(np.max(np.linalg.norm(tris - cen[:, None], axis=2)))
        # the smoothed gap's vertex supports: tangential (longest incident edge) and normal
        # (the inscribed ball's radius, at most 50 supports)
        edges = mesh.edges_unique
        elen = np.linalg.norm(np.diff(self.vertices[edges], axis=1)[:, 0], axis=1)
        longest = np.zeros(len(self.vertices))
        np.maximum.at(longest, edges[:, 0], elen)
        np.maximum.at(longest, edges[:, 1], elen)
        self._support = SUPPORT * longest
        diag = float(np.linalg.norm(np.ptp(self.vertices, axis=0)))
        ball = _ball_radii(self.vertices, self._vertex_normals, self._vtree, diag, edges)
        self._bases = _tangent_bases(self._vertex_normals)
        self._curv = _curvatures(self.vertices, self._vertex_normals, self._bases, edges)
        kmax = np.max(np.linalg.eigvalsh(self._curv), axis=1)
        with np.errstate(divide="ignore"):
            radius = np.where(kmax > 0, 0.9 / kmax, np.inf)
        self._depth = np.minimum(np.minimum(ball, radius), 50.0 * self._support)
        self._reach = float(np.max(np.hypot(self._support, self._depth)))

    def _normals(self, mesh) -> None:
        """Angle-weighted pseudo-normals of faces, edges (by face and local index) and vertices."""
        nf = np.asarray(mesh.face_normals, dtype=float)
        self._face_normals = nf
        # edge k of a face joins its vertices k and k+1 (trimesh's faces_unique_edges)
        fue = np.asarray(mesh.faces_unique_edges)
        ne = np.zeros((len(mesh.edges_unique), 3))
        np.add.at(ne, fue.ravel(), np.repeat(nf, 3, axis=0))
        ne /= np.maximum(np.linalg.norm(ne, axis=1, keepdims=True), 1e-300)
        self._edge_of_face = fue
        self._edge_normals = ne
        self._edge_dirs = np.diff(self.vertices[mesh.edges_unique], axis=1)[:, 0]
        self._edge_dirs /= np.linalg.norm(self._edge_dirs, axis=1, keepdims=True)
        nv = np.zeros((len(self.vertices), 3))
        np.add.at(
            nv,
            self.faces.ravel(),
            (np.asarray(mesh.face_angles)[:, :, None] * nf[:, None, :]).reshape(-1, 3),
        )
        nv /= np.maximum(np.linalg.norm(nv, axis=1, keepdims=True), 1e-300)
        self._vertex_normals = nv

    # -- files ----------------------------------------------------------------------------------
    @classmethod
    def from_file(
        cls, path, units: str = "m", friction=0.0, smooth: bool = True, fix_normals: bool = False
    ) -> MeshVessel:
        """Read a lumen from a surface mesh file (STL, OBJ, PLY, ... as trimesh reads them).

        Parameters
        ----------
        path : str or os.PathLike
            The file.
        units : {"m", "mm"}
            Length unit of the file's coordinates (converted to m).
        friction : float
            Friction coefficient mu >= 0 (see :class:`MeshVessel`).
        smooth : bool
            The smoothed gap (default) or the exact one (see :class:`MeshVessel`).
        fix_normals : bool
            Turn a closed mesh whose normals point into the lumen around (default False:
            such a file is a ValueError naming it).

        Raises
        ------
        ValueError
            Unreadable or corrupted files, an extension that is not a mesh format, files
            without one triangle surface, and the mesh errors of :class:`MeshVessel`; every
            message names the file.  A missing file is
            :class:`~coils._files.MissingFileError` (a ValueError and a FileNotFoundError), a
            folder :class:`~coils._files.NotAFileError` (a ValueError and an
            IsADirectoryError).

        Warns
        -----
        coilrod.UnitsWarning
            A mesh over :data:`MAX_SIZE` (3 m) or under :data:`MIN_SIZE` (0.1 mm) across, or
            a closed one whose mean radius (2 x volume / area) is over :data:`MAX_RADIUS`
            (50 mm) -- most likely a file in mm read as m, or the reverse.
        """
        import trimesh

        units = as_choice(units, "units", tuple(_UNITS))
        path = input_path(path, "mesh file")
        ext = os.path.splitext(path)[1].lower().lstrip(".")
        if not ext:
            raise ValueError(
                f"mesh file {path!r} has no extension; the format is read from it (.stl, "
                ".obj, .ply, ...)"
            )
        if ext not in trimesh.available_formats():
            raise ValueError(
                f"mesh file {path!r}: the format .{ext} is not a mesh format trimesh reads "
                "(e.g. .stl, .obj, .ply)"
            )
        try:
            loaded = trimesh.load(path, force="mesh", process=False)
        except Exception as exc:  # trimesh raises many types for bad files
            # (a damaged binary file ends in trimesh's text fallback: a decode or import error)
            why = (
                "not a valid file of that format (damaged, truncated, or of another format)"
                if isinstance(exc, ImportError | UnicodeError)
                else f"{type(exc).__name__}: {exc}"
            )
            raise ValueError(f"mesh file {path!r} cannot be read as .{ext}: {why}") from None
        if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
            raise ValueError(
                f"mesh file {path!r} holds no triangle surface (empty, damaged, or of another "
                "format than its extension says?)"
            )
        vertices = np.asarray(loaded.vertices, dtype=float)
        if not np.all(np.isfinite(vertices)):
            raise ValueError(f"mesh file {path!r} has non-finite vertex coordinates")
        if ext in ("stl", "ply"):  # (formats that store single precision)
            _check_precision(vertices, np.asarray(loaded.faces), path)
        from ..errors import UnitsWarning

        size = _UNITS[units] * float(np.max(np.ptp(vertices, axis=0)))
        other = "mm" if units == "m" else "m"
        if not MIN_SIZE <= size <= MAX_SIZE:
            warnings.warn(
                f"mesh file {path!r} is {size:.3g} m across with units={units!r}: no vessel "
                f"lumen is that {'large' if size > MAX_SIZE else 'small'}; is the file in "
                f"{other} (units={other!r})?",
                UnitsWarning,
                stacklevel=2,
            )
        mesh = cls(
            vertices * _UNITS[units],
            np.asarray(loaded.faces),
            source=path,
            friction=friction,
            smooth=smooth,
            fix_normals=fix_normals,
        )
        # a short piece in mm read as m (a 2.5 mm tube: 2.5 m across) is not too large, but
        # its lumen is 1 m wide
        radius = 2.0 * mesh.volume / float(mesh._mesh.area) if mesh.watertight else 0.0
        if size <= MAX_SIZE and radius > MAX_RADIUS:
            warnings.warn(
                f"mesh file {path!r} encloses a lumen {radius:.3g} m in mean radius (2 x volume "
                f"/ area) with units={units!r}: no blood vessel is that wide; is the file in "
                f"{other} (units={other!r})?",
                UnitsWarning,
                stacklevel=2,
            )
        return mesh

    # -- gap ------------------------------------------------------------------------------------
    def closest(self, points) -> np.ndarray:
        """Closest points on the wall, shape (n, 3), m."""
        return self._nearest(as_points(points))[0]

    def _nearest(self, points: np.ndarray):
        """Exact closest points (n, 3), distances (n,) and triangles (n,).

        The distance ``D`` to the nearest vertex (a KD-tree over the vertices) bounds the
        distance to the surface; every triangle within ``D`` has its centroid within
        ``D + rmax`` (its largest centroid-to-corner distance), so a KD-tree over the centroids
        gives all candidates, measured exactly (:func:`_closest_on_triangles`) and vectorised.
        (trimesh's ``nearest.on_surface`` is not used: with trimesh 5.2 it misses the closest
        triangle of some points by 1e-4 of the radius and more.)
        """
        bound = self._vtree.query(points)[0]
        radius = bound * (1 + 1e-9) + self._rmax
        if len(points) * len(self.faces) <= BLOCK:  # (every triangle a candidate: one block)
            return self._nearest_block(points, radius)
        blocks = _blocks(self._ctree.query_ball_point(points, radius, return_length=True))
        if len(blocks) == 1:
            return self._nearest_block(points, radius)
        parts = [self._nearest_block(points[b], radius[b]) for b in blocks]
        return tuple(np.concatenate([part[i] for part in parts]) for i in range(3))

    def _nearest_block(self, points: np.ndarray, radius: np.ndarray):
        """:meth:`_nearest` of points whose candidates (triangles with centroids within
        ``radius`` (n,)) fit one vectorised block."""
        cand = self._ctree.query_ball_point(points, radius)
        lens = np.fromiter((len(c) for c in cand), dtype=np.int64, count=len(points))
        idx = np.concatenate([np.asarray(c, dtype=np.int64) for c in cand])
        owner = np.repeat(np.arange(len(points)), lens)
        cp = _closest_on_triangles(self.vertices[self.faces[idx]], points[owner])
        dist = np.linalg.norm(cp - points[owner], axis=1)
        order = np.lexsort((dist, owner))
        first = order[np.r_[0, np.cumsum(lens)[:-1]]]
        return cp[first], dist[first], idx[first]

    def _evaluate(self, points: np.ndarray, order: int):
        if not self.smooth:
            return self._evaluate_exact(points, order)
        # (points deep in a finely meshed lumen have thousands of vertices within reach, and
        # every candidate pair costs ~1 kB of temporaries at order 2: blocks of points)
        if len(points) * len(self.vertices) <= BLOCK:
            return self._evaluate_smooth(points, order)
        blocks = _blocks(self._vtree.query_ball_point(points, self._reach, return_length=True))
        if len(blocks) == 1:
            return self._evaluate_smooth(points, order)
        parts = [self._evaluate_smooth(points[b], order) for b in blocks]
        return tuple(
            None if parts[0][i] is None else np.concatenate([part[i] for part in parts])
            for i in range(3)
        )

    def _evaluate_smooth(self, points: np.ndarray, order: int):
        """The smoothed gap and its derivatives up to ``order`` (see the module)."""
        W, A, gW, gA, hW, hA = _smooth_sums(
            points,
            self.vertices,
            self._vertex_normals,
            self._support,
            self._depth,
            self._bases,
            self._curv,
            self._vtree,
            self._reach,
            order,
        )
        full = W >= WEIGHT_FULL
        Ws = np.where(W > 0, W, 1.0)
        gap = A / Ws
        grad = hess = None
        if order >= 1:
            grad = (gA - gap[:, None] * gW) / Ws[:, None]
        if order >= 2:
            hess = (
                hA
                - gap[:, None, None] * hW
                - grad[:, :, None] * gW[:, None, :]
                - gW[:, :, None] * grad[:, None, :]
            ) / Ws[:, None, None]
        if np.all(full):
            return gap, grad, hess
        # near the medial axis: blend into the exact polyhedral gap as W falls to half
        part = np.flatnonzero(~full)
        fg, fgrad, fhess = self._evaluate_exact(points[part], order)
        s, ds, d2s = _smoothstep((WEIGHT_FULL - W[part]) / (0.5 * WEIGHT_FULL))
        ds, d2s = ds * (-2.0 / WEIGHT_FULL), d2s * (2.0 / WEIGHT_FULL) ** 2
        sg = gap[part]
        diff = sg - fg
        gap = gap.copy()
        gap[part] = s * sg + (1 - s) * fg
        if order >= 1:
            gw = gW[part]
            sgrad = grad[part]
            grad = grad.copy()
            grad[part] = s[:, None] * sgrad + (1 - s)[:, None] * fgrad + (ds * diff)[:, None] * gw
        if order >= 2:
            dgrad = sgrad - fgrad
            hess = hess.copy()
            hess[part] = (
                s[:, None, None] * hess[part]
                + (1 - s)[:, None, None] * fhess
                + ds[:, None, None]
                * (dgrad[:, :, None] * gw[:, None, :] + gw[:, :, None] * dgrad[:, None, :])
                + (d2s * diff)[:, None, None] * gw[:, :, None] * gw[:, None, :]
                + (ds * diff)[:, None, None] * hW[part]
            )
        return gap, grad, hess

    def _evaluate_exact(self, points: np.ndarray, order: int):
        c, d, tri = self._nearest(points)
        diff = points - c
        # closest feature from the barycentric coordinates of c
        corners = self.vertices[self.faces[tri]]
        bary = _barycentric(c, corners)
        small = bary <= 1e-9
        nzero = small.sum(axis=1)
        normal = self._face_normals[tri].copy()
        on_edge = nzero == 1
        if np.any(on_edge):
            j = np.argmax(small[on_edge], axis=1)  # vertex opposite the edge
            e = self._edge_of_face[tri[on_edge], (j + 1) % 3]
            normal[on_edge] = self._edge_normals[e]
        on_vertex = nzero >= 2
        if np.any(on_vertex):
            j = np.argmax(~small[on_vertex], axis=1)
            normal[on_vertex] = self._vertex_normals[self.faces[tri[on_vertex], j]]
        sign = np.where(np.einsum("ij,ij->i", diff, normal) > 0.0, -1.0, 1.0)  # + inside
        gap = sign * d
        grad = hess = None
        if order >= 1:
            tiny = d <= 1e-12 * self._mesh.scale
            u = np.where(tiny[:, None], -normal, diff / np.where(tiny, 1.0, d)[:, None])
            grad = np.where(tiny[:, None], -normal, sign[:, None] * u)
            if order >= 2:
                hess = np.zeros((len(points), 3, 3))
                curved = (nzero >= 1) & ~tiny
                if np.any(curved):
                    uu = u[curved]
                    h = np.eye(3) - uu[:, :, None] * uu[:, None, :]
                    edge = on_edge[curved]
                    if np.any(edge):
                        rows = np.flatnonzero(curved)[edge]
                        j = np.argmax(small[rows], axis=1)
                        t = self._edge_dirs[self._edge_of_face[tri[rows], (j + 1) % 3]]
                        h[edge] -= t[:, :, None] * t[:, None, :]
                    hess[curved] = (sign[curved] / d[curved])[:, None, None] * h
        return gap, grad, hess

    @property
    def bounds(self) -> np.ndarray:
        """Box (2, 3) of the mesh, m."""
        return np.array(self._mesh.bounds, dtype=float)

    def __repr__(self) -> str:
        src = "" if self.source is None else f"{self.source!r}, "
        closed = "watertight" if self.watertight else "open"
        size = _mm(float(np.max(np.ptp(self.vertices, axis=0))))
        return f"MeshVessel({src}{len(self.faces)} faces, {closed}, size {size})"

    def _draw(self, ax, **kwargs):
        kwargs.setdefault("color", "0.5")
        kwargs.setdefault("linewidth", 0.3)
        # the silhouette in x-y: the boundary edges of the faces seen from +z and -z
        edges = self._mesh.edges_unique
        adj = self._mesh.face_adjacency_edges
        up = self._face_normals[:, 2] >= 0
        a, b = self._mesh.face_adjacency.T
        sil = adj[up[a] != up[b]]
        sel = sil if len(sil) else edges
        xy = self.vertices[sel][:, :, :2]
        segs = np.full((len(sel), 3, 2), np.nan)
        segs[:, :2] = xy
        ax.plot(segs[:, :, 0].ravel(), segs[:, :, 1].ravel(), **kwargs)


# -- the smoothed gap -------------------------------------------------------------------------
#: Support of a vertex's weight along its tangent plane, in its longest incident edge.
SUPPORT = 1.5
#: The normal cut-off keeps a vertex's full weight up to this fraction of its ball radius.
PLATEAU = 0.7
#: The smoothed gap is used alone where the weights sum to more than this (the exact
#: polyhedral gap alone below half of it: near the lumen's medial axis).
WEIGHT_FULL = 0.3


#: Most vertices :func:`tessellate` makes (a MeshVessel of 2e6 triangles takes a minute and
#: several GB to build).
MAX_VERTICES = 1_000_000
#: Candidate pairs (point, vertex or triangle) evaluated in one vectorised block: the
#: temporaries of a block stay near 100 MB however many points are asked at once.
BLOCK = 100_000


def _blocks(counts: np.ndarray, budget: int | None = None) -> list[slice]:
    """Slices of consecutive points whose candidate ``counts`` (n,) sum to at most
    ``budget`` (default :data:`BLOCK`; a point with more candidates is a block alone)."""
    budget = BLOCK if budget is None else budget
    ends = np.cumsum(counts)
    if len(ends) == 0 or ends[-1] <= budget:
        return [slice(0, len(counts))]
    out, start = [], 0
    while start < len(ends):
        base = ends[start - 1] if start else 0
        stop = max(int(np.searchsorted(ends, base + budget, side="right")), start + 1)
        out.append(slice(start, stop))
        start = stop
    return out


#: Largest rounding of single-precision coordinates, as a fraction of the shortest edge,
#: that a mesh file's vertices may have without a warning.
PRECISION = 1e-3


def _check_precision(vertices: np.ndarray, faces: np.ndarray, path: str) -> None:
    """Warn if the file's coordinates are single precision (STL always, PLY often) and far
    enough from the origin for their rounding to reach :data:`PRECISION` of the shortest
    edge: the mesh is then distorted in the file (the gaps are exact for the distorted mesh;
    at a million times its size from the origin its faces collapse, a "degenerate" error)."""
    if not np.array_equal(vertices.astype(np.float32).astype(float), vertices):
        return  # (not single precision)
    far = float(np.max(np.abs(vertices)))
    rounding = 0.5 * float(np.spacing(np.float32(far)))
    tri = vertices[faces]
    edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).ravel()
    edges = edges[edges > 0]
    if edges.size == 0:
        return  # (every face collapsed: the mesh's own "degenerate" error follows)
    short = float(edges.min())
    if rounding > PRECISION * short:
        warnings.warn(
            f"mesh file {path!r} stores single-precision coordinates up to {far:.3g} from "
            f"the origin: they are rounded by up to {rounding:.2g} (file units), "
            f"{rounding / short:.2g} of its shortest edge ({short:.3g}); "
            "the mesh is distorted in the file -- move it near the origin before saving, or "
            "save it in double precision (OBJ, double PLY)",
            stacklevel=3,
        )


def _pinched_vertex(faces, adjacency, adjacency_edges):
    """A vertex whose faces form more than one fan (sheets meeting only at the vertex), or
    None: the corners (face, vertex) joined across every shared edge, counted per vertex."""
    faces = np.asarray(faces)
    adjacency, edges = np.asarray(adjacency), np.asarray(adjacency_edges)
    if len(faces) == 0:
        return None

    def corner(f, v):
        return 3 * f + np.argmax(faces[f] == v[:, None], axis=1)

    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rows = np.concatenate([corner(adjacency[:, 0], edges[:, k]) for k in (0, 1)])
    cols = np.concatenate([corner(adjacency[:, 1], edges[:, k]) for k in (0, 1)])
    n = 3 * len(faces)
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    count, label = connected_components(graph, directed=False)
    # each fan (component of corners) belongs to one vertex: as many fans as vertices used
    # unless a vertex has two
    if count == np.count_nonzero(np.bincount(faces.ravel())):
        return None
    owner = np.empty(count, dtype=np.int64)
    owner[label] = faces.ravel()
    return int(np.argmax(np.bincount(owner)))


def _winding(tris: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Winding numbers of points ``p`` (k, 3) about the closed triangles ``tris`` (m, 3, 3):
    the solid angles (Van Oosterom & Strackee 1983) summed over 4 pi; +1 inside a surface
    whose normals point out of it, 0 outside."""
    a, b, c = (tris[None, :, i] - p[:, None] for i in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
    num = np.einsum("kmi,kmi->km", a, np.cross(b, c))
    den = (
        la * lb * lc
        + np.einsum("kmi,kmi->km", a, b) * lc
        + np.einsum("kmi,kmi->km", a, c) * lb
        + np.einsum("kmi,kmi->km", b, c) * la
    )
    return np.arctan2(num, den).sum(axis=1) / (2 * np.pi)


def _component_orientation(mesh):
    """Per face: whether its closed component is turned inside out (the winding number of
    the whole mesh just outside one of its faces is -1), and a face of a component nested
    in the lumen with outward normals (+1 there), or None."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    m = len(mesh.faces)
    adj = np.asarray(mesh.face_adjacency)
    graph = coo_matrix((np.ones(len(adj)), (adj[:, 0], adj[:, 1])), shape=(m, m))
    count, label = connected_components(graph, directed=False)
    area = np.asarray(mesh.area_faces)
    # each component's largest face: a point a little outside its centroid
    first = np.full(count, -1)
    order = np.argsort(area)
    first[label[order]] = order  # (the last write per component is its largest face)
    tris = np.asarray(mesh.triangles)
    normal = np.asarray(mesh.face_normals)[first]
    step = 1e-3 * np.sqrt(area[first])
    probe = tris[first].mean(axis=1) + step[:, None] * normal
    chunk = max(1, 2_000_000 // m)  # (k, m) arrays of at most a few million entries
    w = np.concatenate([_winding(tris, probe[i : i + chunk]) for i in range(0, count, chunk)])
    w = np.rint(w).astype(int)
    nested = np.flatnonzero(w > 0)
    return w[label] < 0, (int(first[nested[0]]) if nested.size else None)


def _ranges(idx: np.ndarray) -> str:
    """``[0, 1, 2, 7]`` as ``"0-2, 7"`` (at most four ranges shown)."""
    cuts = np.flatnonzero(np.diff(idx) != 1) + 1
    parts = [f"{r[0]}-{r[-1]}" if len(r) > 1 else f"{r[0]}" for r in np.split(idx, cuts)]
    return ", ".join(parts[:4]) + (", ..." if len(parts) > 4 else "")


def _smoothstep(t):
    """C2 step 1 -> 0 on t in [0, 1] and its first two derivatives (quintic)."""
    t = np.clip(t, 0.0, 1.0)
    s = 1.0 - t**3 * (10.0 - 15.0 * t + 6.0 * t**2)
    ds = -30.0 * t**2 * (1.0 - t) ** 2
    d2s = -60.0 * t * (1.0 - t) * (1.0 - 2.0 * t)
    return s, ds, d2s


def _tangent_bases(normals):
    """Two unit tangents (n, 3, 2) completing each unit normal (n, 3) to an orthonormal frame."""
    axis = np.zeros_like(normals)
    axis[np.arange(len(normals)), np.argmin(np.abs(normals), axis=1)] = 1.0
    t1 = np.cross(normals, axis)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normals, t1)
    return np.stack([t1, t2], axis=2)


def _curvatures(vertices, normals, bases, edges):
    """Curvature tensors (n, 2, 2) in the tangent bases, 1/m, > 0 where the wall curves
    around the lumen (a tube's circumference: 1/r): least-squares fit of the heights of each
    vertex's neighbours above its tangent plane, ``z = -a^T K a / 2`` (``a`` their tangent
    coordinates)."""
    nv = len(vertices)
    both = np.concatenate([edges, edges[:, ::-1]])
    k, j = both[:, 0], both[:, 1]
    e = vertices[j] - vertices[k]
    z = np.einsum("ij,ij->i", e, normals[k])
    a = np.einsum("ij,ijl->il", e, bases[k])
    rows = np.stack([-0.5 * a[:, 0] ** 2, -a[:, 0] * a[:, 1], -0.5 * a[:, 1] ** 2], axis=1)
    N = np.zeros((nv, 3, 3))
    b = np.zeros((nv, 3))
    np.add.at(N, k, rows[:, :, None] * rows[:, None, :])
    np.add.at(b, k, rows * z[:, None])
    ridge = 1e-9 * np.trace(N, axis1=1, axis2=2)[:, None, None] * np.eye(3)
    c = np.linalg.solve(N + ridge + 1e-300 * np.eye(3), b[:, :, None])[:, :, 0]
    K = np.empty((nv, 2, 2))
    K[:, 0, 0], K[:, 0, 1], K[:, 1, 0], K[:, 1, 1] = c[:, 0], c[:, 1], c[:, 1], c[:, 2]
    return K


def _ball_radii(vertices, normals, tree, start, edges):
    """Radius (n,) of the largest vertex-free ball touching each vertex from inside (centre
    on the inward normal): the shrinking-ball medial axis estimate (Ma, Bai & Huang 2012),
    started from the smallest ball through a neighbour (or ``start``)."""
    t = np.full(len(vertices), start)
    both = np.concatenate([edges, edges[:, ::-1]])
    e = vertices[both[:, 0]] - vertices[both[:, 1]]
    den = 2.0 * np.einsum("ij,ij->i", e, normals[both[:, 0]])
    up = den > 0
    np.minimum.at(t, both[up, 0], np.einsum("ij,ij->i", e[up], e[up]) / den[up])
    todo = np.arange(len(vertices))
    for _ in range(60):
        c = vertices[todo] - t[todo, None] * normals[todo]
        dist, near = tree.query(c, k=2)
        # the nearest vertex that is not the vertex itself
        own = near[:, 0] == todo
        j = np.where(own, near[:, 1], near[:, 0])
        dj = np.where(own, dist[:, 1], dist[:, 0])
        inside = dj < t[todo] * (1.0 - 1e-9)
        todo, j = todo[inside], j[inside]
        if todo.size == 0:
            break
        e = vertices[todo] - vertices[j]
        # the ball through the vertex and j (j inside the old ball: e . n > 0)
        t[todo] = np.einsum("ij,ij->i", e, e) / (2.0 * np.einsum("ij,ij->i", e, normals[todo]))
    return t


def _smooth_sums(points, v, n, h, depth, bases, curv, tree, reach, order):
    """Weighted plane distances of the points (n_p, 3) to the vertices' tangent planes.

    Returns W (n_p,), A = sum w d (n_p,) and, with order >= 1, their gradients (n_p, 3) and
    with order 2 their hessians (n_p, 3, 3).  Vertex k (position v_k, unit normal n_k, out of
    the lumen) weighs ``w_k = phi(|P_k (p - v_k)| / h_k) psi(d_k / D_k)`` with ``d_k =
    (v_k - p) . n_k`` its plane's distance (> 0 inside), ``P_k`` the projection on its tangent
    plane, ``phi`` Wendland's C2 function of compact support and ``psi`` a C2 step from 1 (at
    ``|d_k| <= PLATEAU D_k``) to 0 (at ``|d_k| >= D_k``, ``D_k`` the vertex's inscribed ball
    radius: the opposite wall's vertices do not count).  The plane distance is corrected for
    the wall's curvature ``K_k`` at the vertex (its distance from the offset of the osculating
    quadric): ``c_k = d_k - a^T M a / 2``, ``a`` the tangent coordinates of ``p - v_k``,
    ``M = K_k (I - d_k K_k)^-1``; on a circle of radius r this is exact to O(r theta^4).
    The gap is ``sum w_k c_k / sum w_k``.
    """
    npt = len(points)
    cand = tree.query_ball_point(points, reach)
    lens = np.fromiter((len(c) for c in cand), dtype=np.int64, count=npt)
    k = np.concatenate([np.asarray(c, dtype=np.int64) for c in cand]) if lens.sum() else None
    out_W, out_A = np.zeros(npt), np.zeros(npt)
    gW = gA = hW = hA = None
    if order >= 1:
        gW, gA = np.zeros((npt, 3)), np.zeros((npt, 3))
    if order >= 2:
        hW, hA = np.zeros((npt, 3, 3)), np.zeros((npt, 3, 3))
    if k is None:
        return out_W, out_A, gW, gA, hW, hA
    i = np.repeat(np.arange(npt), lens)
    e = points[i] - v[k]
    nk = n[k]
    d = -np.einsum("ij,ij->i", e, nk)
    et = e + d[:, None] * nk
    hk = h[k]
    rho = np.linalg.norm(et, axis=1) / hk
    x = np.abs(d) / depth[k]
    keep = (rho < 1.0) & (x < 1.0)
    i, k, e, nk, d, et, hk, rho, x = (a[keep] for a in (i, k, e, nk, d, et, hk, rho, x))
    phi = (1.0 - rho) ** 4 * (4.0 * rho + 1.0)
    psi, dpsi, d2psi = _smoothstep((x - PLATEAU) / (1.0 - PLATEAU))
    w = phi * psi
    # curvature correction f = a^T M a / 2 (M = K (I - d K)^-1, 2 x 2 in the tangent basis)
    T = bases[k]
    Kk = curv[k]
    a = np.einsum("ij,ijl->il", e, T)
    A = np.eye(2) - d[:, None, None] * Kk
    det = A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
    Ainv = np.empty_like(A)
    Ainv[:, 0, 0], Ainv[:, 1, 1] = A[:, 1, 1] / det, A[:, 0, 0] / det
    Ainv[:, 0, 1], Ainv[:, 1, 0] = -A[:, 0, 1] / det, -A[:, 1, 0] / det
    M = Kk @ Ainv
    Ma = np.einsum("ilm,im->il", M, a)
    c = d - 0.5 * np.einsum("il,il->i", a, Ma)
    np.add.at(out_W, i, w)
    np.add.at(out_A, i, w * c)
    if order == 0:
        return out_W, out_A, gW, gA, hW, hA
    # phi's gradient -20 (1 - rho)^3 e_t / h^2; psi's along -sign(d) n / D (x = |d| / D)
    gphi = (-20.0 * (1.0 - rho) ** 3 / hk**2)[:, None] * et
    sx = np.sign(d) / (depth[k] * (1.0 - PLATEAU))
    gpsi = (-dpsi * sx)[:, None] * nk
    gw = psi[:, None] * gphi + phi[:, None] * gpsi
    M2a = np.einsum("ilm,im->il", M, Ma)
    aM2a = np.einsum("il,il->i", a, M2a)
    gc = -nk - np.einsum("ijl,il->ij", T, Ma) + (0.5 * aM2a)[:, None] * nk
    np.add.at(gW, i, gw)
    np.add.at(gA, i, gw * c[:, None] + w[:, None] * gc)
    if order == 1:
        return out_W, out_A, gW, gA, hW, hA
    eye = np.eye(3)
    P = eye - nk[:, :, None] * nk[:, None, :]
    et_len = rho * hk
    with np.errstate(divide="ignore", invalid="ignore"):
        eu = np.where((et_len > 0)[:, None], et / et_len[:, None], 0.0)
    hphi = (-20.0 / hk**2)[:, None, None] * (
        ((1.0 - rho) ** 3)[:, None, None] * P
        - (3.0 * (1.0 - rho) ** 2 * rho)[:, None, None] * eu[:, :, None] * eu[:, None, :]
    )
    hpsi = (d2psi * sx**2)[:, None, None] * nk[:, :, None] * nk[:, None, :]
    hw = (
        psi[:, None, None] * hphi
        + gphi[:, :, None] * gpsi[:, None, :]
        + gpsi[:, :, None] * gphi[:, None, :]
        + phi[:, None, None] * hpsi
    )
    TM2a = np.einsum("ijl,il->ij", T, M2a)
    aM3a = np.einsum("il,il->i", M2a, Ma)  # a^T M^3 a (M symmetric up to the fit's rounding)
    hf = (
        np.einsum("ijl,ilm,ikm->ijk", T, M, T)
        - TM2a[:, :, None] * nk[:, None, :]
        - nk[:, :, None] * TM2a[:, None, :]
        + aM3a[:, None, None] * nk[:, :, None] * nk[:, None, :]
    )
    np.add.at(hW, i, hw)
    np.add.at(
        hA,
        i,
        hw * c[:, None, None]
        + gw[:, :, None] * gc[:, None, :]
        + gc[:, :, None] * gw[:, None, :]
        - w[:, None, None] * hf,
    )
    return out_W, out_A, gW, gA, hW, hA


def _closest_on_triangles(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Closest points (n, 3) of triangles tri (n, 3, 3) to points p (n, 3) (Ericson 2005,
    5.1.5, vectorised over the Voronoi regions of the corners, edges and face)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac, ap = b - a, c - a, p - a

    def dot(u, v):
        return np.einsum("ij,ij->i", u, v)

    d1, d2 = dot(ab, ap), dot(ac, ap)
    bp = p - b
    d3, d4 = dot(ab, bp), dot(ac, bp)
    cp = p - c
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    den = va + vb + vc
    with np.errstate(divide="ignore", invalid="ignore"):
        v = vb / den
        w = vc / den
        out = a + v[:, None] * ab + w[:, None] * ac  # face region
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    e_bc = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
    out = np.where(e_bc[:, None], b + np.nan_to_num(t_bc)[:, None] * (c - b), out)
    e_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    out = np.where(e_ac[:, None], a + np.nan_to_num(t_ac)[:, None] * ac, out)
    e_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    out = np.where(e_ab[:, None], a + np.nan_to_num(t_ab)[:, None] * ab, out)
    out = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, out)
    out = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, out)
    out = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, out)
    return out


def _ring_strip(n_rings: int, n_around: int) -> np.ndarray:
    """Faces (2 n_around (n_rings - 1), 3) joining consecutive rings of ``n_around`` vertices
    (ring j's vertices at ``j n_around + k``), each quad cut along a diagonal."""
    i = np.arange(n_rings - 1)[:, None] * n_around
    k = np.arange(n_around)[None, :]
    a0, a1 = i + k, i + (k + 1) % n_around
    b0, b1 = a0 + n_around, a1 + n_around
    return np.concatenate(
        [np.stack([a0, a1, b1], -1).reshape(-1, 3), np.stack([a0, b1, b0], -1).reshape(-1, 3)]
    )


def _barycentric(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (n, 3) of points p (n, 3) in triangles tri (n, 3, 3)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    v0, v1, v2 = b - a, c - a, p - a
    d00 = np.einsum("ij,ij->i", v0, v0)
    d01 = np.einsum("ij,ij->i", v0, v1)
    d11 = np.einsum("ij,ij->i", v1, v1)
    d20 = np.einsum("ij,ij->i", v2, v0)
    d21 = np.einsum("ij,ij->i", v2, v1)
    den = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    return np.stack([1.0 - v - w, v, w], axis=1)


def tessellate(vessel, n_around: int = 16, spacing=None, caps: str = "rings"):
    """Triangle mesh of an analytic vessel's wall between its end cross-sections, capped.

    Rings of ``n_around`` vertices on the exact wall at arc-length steps of about
    ``spacing`` (the ring's edge length by default), joined by triangles; each end is closed
    by a flat cap.  Vertices lie on the analytic wall, so the mesh's gap tends to the
    vessel's at second order in the edge length.

    Parameters
    ----------
    vessel : Vessel
        A single tube (a :class:`~coilrod.contact.VesselNetwork` is tessellated per member).
    n_around : int
        Vertices per ring (>= 3).
    spacing : float, optional
        Ring spacing along the centreline, m.
    caps : {"rings", "fan"}
        How the end discs are triangulated: concentric rings about one ring edge apart
        (default), or a fan of triangles from the centre (the shipped phantom's; its edges
        are a lumen radius long at any ``n_around``, so the smoothed gap's supports of the
        rim's vertices reach a radius from the cap's sharp edge, and its error near the caps
        grows as ``n_around`` grows: 0.65 mm outside a branch's junction at 128 per ring).

    Returns
    -------
    vertices : ndarray, shape (n, 3)
        m.
    faces : ndarray, shape (m, 3)
        Outward normals.

    Raises
    ------
    ValueError
        More than :data:`MAX_VERTICES` vertices, or a ``spacing`` so coarse that the chord
        between two rings (the mesh's axis there) is more than half the narrowest lumen
        radius from the centreline (the mesh would be another vessel: a 90 deg bend of bend
        radius 20 mm in two rings is its chord, 12.9 mm from its centreline at mid-bend).
    """
    if not isinstance(vessel, Vessel):
        raise ValueError(f"vessel must be a Vessel; got {type(vessel).__name__}")
    n_around = as_count(n_around, "n_around", minimum=3)
    caps = as_choice(caps, "caps", ("rings", "fan"))
    r_min = float(np.min(vessel.radius_at(np.linspace(0.0, vessel.length, 65))))
    if spacing is None:
        spacing = 2 * np.pi * r_min / n_around
    from coils._validate import positive

    spacing = positive(spacing, "spacing")
    n_rings = max(2, int(np.ceil(min(vessel.length / spacing, 1e12))) + 1)
    if n_rings * n_around > MAX_VERTICES:  # (was a MemoryError, or minutes of swapping)
        raise ValueError(
            f"tessellate: {n_rings} rings of {n_around} vertices ({n_rings * n_around:.3g}) "
            f"exceed {MAX_VERTICES:.0e} vertices; give a larger spacing (m; {spacing:.3g} "
            "now) or a smaller n_around"
        )
    s = np.linspace(0.0, vessel.length, n_rings)
    x = vessel.position(s)
    # the mesh's axis is the chords between rings: far from the centreline, another vessel
    mid = vessel.position(0.5 * (s[:-1] + s[1:]))
    off = np.linalg.norm(mid - 0.5 * (x[:-1] + x[1:]), axis=1)
    if off.max() > 0.5 * r_min:
        k = int(np.argmax(off))
        raise ValueError(
            f"tessellate: spacing = {spacing:.3g} m is too coarse for this vessel: between its "
            f"rings at {_mm(s[k])} and {_mm(s[k + 1])} the mesh's axis (their chord) is "
            f"{_mm(off[k])} from the centreline, over half the narrowest radius "
            f"({_mm(r_min)}); give a smaller spacing (m)"
        )
    t = vessel.tangent(s)
    r = vessel.radius_at(s)
    # rotation-minimising frame along the centreline (double reflection, Wang et al. 2008)
    ref = np.array([0.0, 0.0, 1.0]) if abs(t[0, 2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    n = np.empty_like(t)
    n[0] = np.cross(ref, t[0])
    n[0] /= np.linalg.norm(n[0])
    for i in range(n_rings - 1):  # n_rings steps, not triangles
        v1 = x[i + 1] - x[i]
        c1 = v1 @ v1
        rl = n[i] - (2 / c1) * (v1 @ n[i]) * v1
        tl = t[i] - (2 / c1) * (v1 @ t[i]) * v1
        v2 = t[i + 1] - tl
        c2 = v2 @ v2
        n[i + 1] = rl - (2 / c2) * (v2 @ rl) * v2 if c2 > 0 else rl
    b = np.cross(t, n)
    th = 2 * np.pi * np.arange(n_around) / n_around
    ring = (
        x[:, None, :]
        + r[:, None, None]
        * (np.cos(th)[None, :, None] * n[:, None, :] + np.sin(th)[None, :, None] * b[:, None, :])
    ).reshape(-1, 3)
    if caps == "fan":
        vertices = np.vstack([ring, x[0], x[-1]])
        side = _ring_strip(n_rings, n_around)
        c0, c1 = len(ring), len(ring) + 1
        k = np.arange(n_around)
        last = (n_rings - 1) * n_around
        cap0 = np.stack([np.full(n_around, c0), (k + 1) % n_around, k], -1)
        cap1 = np.stack([np.full(n_around, c1), last + k, last + (k + 1) % n_around], -1)
        faces = np.concatenate([side, cap0, cap1]).astype(np.int64)
    else:  # the end rings shrunk towards the centres in steps of about one ring edge
        stack = ring.reshape(n_rings, n_around, 3)
        m = max(1, int(np.ceil(n_around / (2 * np.pi))))
        q = (np.arange(1, m) / m)[:, None, None]  # from the centre out
        rings = np.concatenate(
            [x[0] + (stack[0] - x[0]) * q, stack, x[-1] + (stack[-1] - x[-1]) * q[::-1]]
        )
        vertices = np.vstack([x[0], rings.reshape(-1, 3), x[-1]])
        k = np.arange(n_around)
        c1, last = len(vertices) - 1, 1 + (len(rings) - 1) * n_around
        cap0 = np.stack([np.zeros(n_around, np.int64), 1 + (k + 1) % n_around, 1 + k], -1)
        cap1 = np.stack([np.full(n_around, c1), last + k, last + (k + 1) % n_around], -1)
        side = 1 + _ring_strip(len(rings), n_around)
        faces = np.concatenate([side, cap0, cap1]).astype(np.int64)
    # outward: the enclosed volume is positive
    import trimesh

    if trimesh.Trimesh(vertices, faces, process=False).volume < 0:
        faces = faces[:, ::-1].copy()
    return vertices, faces
