"""Reference meshes of the rod body: 2D strip, 3D box and 3D circular (O-grid) section.

The rod is clamped at ``x = 0`` and its free end is ``x = L``; the section is centred on the
x axis with the bending-plane extent along y (DESIGN.md).  Along x the element layers are
piecewise uniform with a layer boundary at every breakpoint of the magnetization
(:func:`length_layers`), so that no element straddles a jump of |M| or of its angle.
"""

from __future__ import annotations

import math
import os
from types import MappingProxyType

import numpy as np

from coilrod.robot.sections import Circle, Rectangle
from coilrod.rod.mesh import RodMesh

__all__ = [
    "DEFAULT_ELEMENTS",
    "default_elements",
    "length_layers",
    "rectangle_mesh",
    "box_mesh",
    "circle_mesh",
    "rod_mesh",
    "check_elements",
    "check_mesh",
    "check_memory",
    "linear_circle_problem",
    "clamp_layer",
    "ungraded_clamp",
    "equivalent_height",
]

#: Half-width of the O-grid's central square as a fraction of the radius.
CORE_FRACTION = 0.5

#: Tolerance (relative to L) of a given mesh's ends on x = 0 and x = L (as the clamp's).
MESH_END_TOL = 1e-9
#: Tolerance (relative to the section's size) of a given mesh's nodes on the section's bounds
#: and of a Rectangle's (or the 2D strip's) mesh area.
MESH_SECTION_TOL = 1e-6
#: Smallest area of a given mesh of a Circle section over the circle's: the inscribed octagon
#: (8 sin(pi/4) / (2 pi) = 0.9003), the coarsest section of coilrod's own O-grids (the linear
#: one with ``core = 2``); a curved O-grid is 1.2 % short at most.
MIN_CIRCLE_AREA_RATIO = 8 * math.sin(math.pi / 4) / (2 * math.pi) * (1 - 1e-9)

#: ``solve_fem``'s default ``elements``: (length, thickness) in 2D (key 2), (length,
#: thickness, width) for a 3D Rectangle (key 3) and (length, core, ring) for a 3D Circle (key
#: ``"3circle"``).  Use :func:`default_elements` to pick the entry for a rod.
DEFAULT_ELEMENTS = MappingProxyType({2: (20, 1), 3: (20, 1, 1), "3circle": (20, 2, 1)})

#: The 3D meshes of :func:`rod_mesh` grade the layers at the clamp (halving the first layer
#: until it is no longer than this many times the section's smallest extent; see
#: :func:`length_layers`).  A layer long against the section at the clamp makes the stability
#: count a property of the mesh: the discrete stresses of the clamp's boundary layer twist the
#: section there, resisted only by the element's torsional stiffness ~ G J / h, and a rod in
#: pure tension (it cannot buckle) lost stability at 0.39 of a field of 0.5 T on (8, 1, 1)
#: elements of a 0.4 mm square section 40 mm long (h = 12.5 times the side); uniform
#: (16, 1, 1) and (32, 1, 1) at 1.27 and 3.38.  Graded from one side, none up to 8.
CLAMP_LAYER = 1.0
#: A given 3D mesh whose layers near the clamp exceed this many times the grading's limit gets
#: a StabilityWarning from ``solve_fem`` (:func:`ungraded_clamp`).
UNGRADED_FACTOR = 2.0

#: Piece lengths times the element count are rounded to this many decimals before the count
#: is shared out, so that breakpoints a few ulp off a round number give the round number's
#: mesh (no count flips between two pieces at a tie).
_COUNT_DECIMALS = 9


def default_elements(rod, dim: int) -> tuple[int, ...]:
    """``solve_fem``'s default element counts for ``rod`` in ``dim`` dimensions.

    Parameters
    ----------
    rod : coilrod.Rod
        Its section picks the 3D layout (box for a Rectangle, O-grid for a Circle).
    dim : {2, 3}

    Returns
    -------
    tuple of int, length ``dim``
        Elements along (length, thickness) in 2D, (length, thickness, width) for a 3D
        Rectangle and (length, core, ring) for a 3D Circle (see :func:`rod_mesh`).

    Examples
    --------
    >>> import coilrod
    >>> rod = coilrod.Rod(0.04, 1e6, coilrod.Circle(2e-3), coilrod.presets.M1())
    >>> default_elements(rod, 2), default_elements(rod, 3)
    ((20, 1), (20, 2, 1))
    """
    if dim == 2:
        return DEFAULT_ELEMENTS[2]
    if dim == 3:
        return DEFAULT_ELEMENTS["3circle" if isinstance(rod.section, Circle) else 3]
    raise ValueError(f"dim must be 2 or 3; got {dim!r}")


def _layer_counts(n: int, fractions: np.ndarray) -> np.ndarray:
    """Elements per piece, ``max(n, pieces)`` in all: ``n`` shared out in proportion to
    ``fractions`` (summing to 1) by largest remainders, at least one per piece; ties go to the
    piece nearer the clamp."""
    share = np.round(n * fractions, _COUNT_DECIMALS)
    counts = np.maximum(1, np.floor(share).astype(int))
    spare = n - int(counts.sum())
    if spare > 0:
        order = np.argsort(-(share - counts), kind="stable")
        counts[order[:spare]] += 1
    while spare < 0 and np.any(counts > 1):  # short pieces raised to one element: give back
        over = np.where(counts > 1, counts - share, -np.inf)
        counts[int(np.argmax(over))] -= 1
        spare += 1
    return counts


def length_layers(
    length: float, n_length: int, breakpoints=(), clamp: float | None = None
) -> np.ndarray:
    """x-coordinates of the element layer boundaries: piecewise uniform, one at each breakpoint.

    The breakpoints are merged and trimmed exactly as for the rod model
    (:class:`coilrod.rod.mesh.RodMesh`): those within ``MERGE_BREAKS * L`` (1e-10 L) of an end
    are dropped and of a cluster closer than that only the first is kept.  The ``n_length``
    elements are shared out among the pieces in proportion to their lengths (largest
    remainders), at least one per piece, so that there are ``max(n_length, pieces)`` in all,
    and every piece is divided uniformly.  A kept breakpoint is a layer boundary exactly (its
    own floating-point value), and a breakpoint a few ulp off a round number gives that
    number's layers: the shares are rounded to 1e-9 of an element before they are compared.

    With ``clamp`` the layers near the clamp are graded: a layer from x to x + h longer than
    ``max(clamp, 2 x)`` is halved towards x until its first part is not (h/2^m, h/2^m,
    h/2^(m-1), ..., h/2 for the first layer), which adds about ``log2(h / clamp)`` layers; the
    3D meshes of :func:`rod_mesh` take ``clamp`` = the section's smallest extent
    (:func:`clamp_layer`, :data:`CLAMP_LAYER`).

    Parameters
    ----------
    length : float
        Rod length L, m.
    n_length : int
        Elements along the length (more if there are more pieces; see above).
    breakpoints : array-like, shape (k,)
        Arc lengths (m) of the magnetization's jumps (``Magnetization.breakpoints``).
    clamp : float, optional
        Longest layer at the clamp, m (None: no grading).

    Returns
    -------
    ndarray, shape (n + 1,)
        Increasing layer boundaries, m, from exactly 0 to exactly ``length``.

    Examples
    --------
    >>> length_layers(0.04, 4).tolist()
    [0.0, 0.01, 0.02, 0.03, 0.04]
    >>> length_layers(0.04, 4, [0.015]).tolist()  # 1.5 + 2.5 elements: the tie goes to the clamp
    [0.0, 0.0075, 0.015, 0.0275, 0.04]
    >>> (length_layers(0.04, 4, clamp=0.003) * 1e3).round(6).tolist()  # graded at the clamp
    [0.0, 2.5, 5.0, 10.0, 20.0, 30.0, 40.0]
    """
    L = float(length)
    br = np.sort(np.asarray(breakpoints, dtype=float).ravel())
    inner = np.empty(0)
    if br.size:
        kept = RodMesh(1, br / L).edges[1:-1]  # the rod's merging rule, on fractions of L
        inner = br[np.searchsorted(br / L, kept)]  # the breakpoints themselves, in metres
    edges = np.concatenate([[0.0], inner, [L]])
    counts = _layer_counts(int(n_length), np.diff(edges) / L)
    pieces = [
        np.linspace(a, b, c + 1)[:-1] for a, b, c in zip(edges[:-1], edges[1:], counts, strict=True)
    ]
    xs = np.concatenate([*pieces, [L]])
    if clamp is None:
        return xs
    out = [xs[:1]]
    for a, b in zip(xs[:-1], xs[1:], strict=True):
        m = clamp_layers(b - a, max(clamp, 2.0 * a))
        if m:  # halve the layer m times towards a: a + h/2^m, ..., a + h/2
            out.append(a + (b - a) * 0.5 ** np.arange(m, 0, -1))
        out.append([b])
    return np.concatenate(out)


def clamp_layer(section) -> float:
    """Longest layer (m) a 3D mesh of :func:`rod_mesh` has at the clamp: :data:`CLAMP_LAYER`
    times the section's smallest extent (a Rectangle's smaller side, a Circle's diameter)."""
    if isinstance(section, Rectangle):
        return CLAMP_LAYER * min(section.thickness, section.width)
    return CLAMP_LAYER * section.diameter


def clamp_layers(length: float, limit: float | None) -> int:
    """Halvings of a layer ``length`` (m) long until it is no longer than ``limit`` (m; 0 for
    None): the layers :func:`length_layers` adds to it."""
    if limit is None or not length > limit * (1 + 1e-9):
        return 0
    return math.ceil(math.log2(length / limit) - 1e-9)


def ungraded_clamp(mesh, section) -> str:
    """A 3D ``mesh`` whose layers near the clamp are long against ``section``: the message
    (empty if none).  An element from x to x + h along the rod must have ``h <= 2 max(c, 2 x)``
    with ``c`` the :func:`clamp_layer` of the section (twice the limit of the meshes of
    :func:`length_layers` with ``clamp = c``: graded from 2 c, a rod in pure tension was stable
    to a stretch of about 2); else the stability count at the clamp is a property of the mesh
    (see :data:`CLAMP_LAYER`)."""
    xe = mesh.p[0, mesh.t]
    lo, hi = xe.min(axis=0), xe.max(axis=0)
    limit = UNGRADED_FACTOR * np.maximum(clamp_layer(section), 2.0 * lo)
    bad = (hi - lo) > limit * (1 + 1e-6)
    if not bad.any():
        return ""
    k = int(np.argmax(np.where(bad, (hi - lo) / limit, 0.0)))
    return (
        f"mesh: an element {hi[k] - lo[k]:.3g} m long starts {lo[k]:.3g} m from the clamp, "
        f"longer than {UNGRADED_FACTOR * clamp_layer(section):.3g} m (twice the section's "
        "smallest extent) and than four times its distance from the clamp: the stability "
        "count is unreliable on such a mesh (the discrete stresses of the clamp's boundary "
        "layer twist the section there; a rod in pure tension, which cannot buckle, was "
        "reported unstable at small loads); grade the layers at the clamp as "
        "coilrod.fem.length_layers(..., clamp=...) does"
    )


def check_elements(elements, dim: int) -> tuple[int, ...]:
    """Validate ``elements`` as ``dim`` positive integers (a ValueError names ``elements``)."""
    try:
        vals = tuple(elements)
    except TypeError:
        raise ValueError(
            f"elements must be a tuple of {dim} positive integers; got {elements!r}"
        ) from None
    if len(vals) != dim:
        raise ValueError(f"elements must have {dim} entries for dim={dim}; got {vals!r}")
    out = []
    for v in vals:
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v <= 0:
            raise ValueError(f"elements must be positive integers; got {vals!r}")
        out.append(int(v))
    return tuple(out)


#: Memory of one element while solving, bytes, by (dim, order): measured peak resident memory
#: of ``solve_fem`` on rods of one element across (~19 kB, ~63 kB, ~110 kB, ~960 kB), rounded up.
ELEMENT_BYTES = MappingProxyType({(2, 1): 2e4, (2, 2): 7e4, (3, 1): 1.2e5, (3, 2): 1e6})


def physical_memory() -> float | None:
    """This machine's physical memory, bytes (None where the platform does not say)."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE")) * float(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def element_count(section, dim: int, elements: tuple[int, ...], length=None) -> int:
    """Elements of the mesh :func:`rod_mesh` makes from ``elements`` (at least; more layers
    along the length where the magnetization has more pieces): in 2D and for a 3D Rectangle
    their product, for a 3D Circle ``length (core^2 + 4 core ring)``; in 3D with the rod's
    ``length`` (m) given, with the layers graded at the clamp (:func:`length_layers`)."""
    n, *rest = elements
    if dim == 3 and length is not None:
        n = length_layers(length, n, (), clamp_layer(section)).size - 1
    if dim == 3 and isinstance(section, Circle):
        core, ring = rest
        return n * (core * core + 4 * core * ring)
    return n * math.prod(rest)


def check_memory(section, dim: int, order: int, elements: tuple[int, ...], length=None) -> None:
    """Raise ValueError (naming ``elements``) if the mesh of ``elements`` would need more
    memory than the machine has (:data:`ELEMENT_BYTES` per element), instead of building it
    until the operating system stops the process (``length``: see :func:`element_count`)."""
    count = element_count(section, dim, elements, length)
    need = count * ELEMENT_BYTES[dim, order]
    have = physical_memory()
    if have is not None and need > have:
        raise ValueError(
            f"elements {tuple(elements)}: {count:,} elements "
            f"would need about {need / 1e9:.3g} GB of memory ({ELEMENT_BYTES[dim, order] / 1e3:g} "
            f"kB each in {dim}D of order {order}); this machine has {have / 1e9:.3g} GB"
        )


def equivalent_height(section) -> float:
    """Height (m) of the 2D strip that represents ``section`` in the bending plane.

    A Rectangle keeps its thickness.  A Circle is represented by the rectangle with the same
    ratio I/A (so the same magneto-elastic number lambda): h = sqrt(12 I / A) = sqrt(3) D / 2.
    """
    if isinstance(section, Rectangle):
        return section.thickness
    return math.sqrt(12.0 * section.second_moment / section.area)


def rectangle_mesh(length: float, height: float, n_length: int, n_thickness: int, breakpoints=()):
    """Quadrilateral mesh of ``[0, length] x [-height/2, height/2]``.

    Parameters
    ----------
    length, height : float
        Extent along x and y, metres.
    n_length, n_thickness : int
        Elements along x (about, see :func:`length_layers`) and y.
    breakpoints : array-like, shape (k,)
        Arc lengths (m) where element layers must end (magnetization jumps).

    Returns
    -------
    skfem.MeshQuad1
    """
    from skfem import MeshQuad1

    return MeshQuad1.init_tensor(
        length_layers(length, n_length, breakpoints),
        np.linspace(-height / 2, height / 2, n_thickness + 1),
    )


def box_mesh(
    length: float,
    thickness: float,
    width: float,
    n_length: int,
    n_thickness: int,
    n_width: int,
    breakpoints=(),
    clamp: float | None = None,
):
    """Hexahedral mesh of ``[0, L] x [-t/2, t/2] x [-w/2, w/2]`` (thickness along y).

    Parameters
    ----------
    length, thickness, width : float
        Extent along x, y and z, metres.
    n_length, n_thickness, n_width : int
        Elements along x (about, see :func:`length_layers`), y and z.
    breakpoints : array-like, shape (k,)
        Arc lengths (m) where element layers must end (magnetization jumps).
    clamp : float, optional
        Longest layer at the clamp, m: the layers are graded there (:func:`length_layers`).

    Returns
    -------
    skfem.MeshHex1
    """
    from skfem import MeshHex1

    return MeshHex1.init_tensor(
        length_layers(length, n_length, breakpoints, clamp),
        np.linspace(-thickness / 2, thickness / 2, n_thickness + 1),
        np.linspace(-width / 2, width / 2, n_width + 1),
    )


def _disc_quads(radius: float, n_core: int, n_ring: int) -> tuple[np.ndarray, np.ndarray]:
    """O-grid quadrilaterals of a disc: vertices (2, n) in the (y, z) plane and quads (4, m).

    A central square of ``n_core x n_core`` quads (half-width ``CORE_FRACTION * radius``) and
    four ring blocks of ``n_core`` (around) x ``n_ring`` (radial) quads each; the ring's nodes
    blend linearly from the square's side to the circle at equal angles.  Quads are listed
    counter-clockwise (v00, v10, v11, v01).
    """
    s = CORE_FRACTION * radius
    tau = np.linspace(-1.0, 1.0, n_core + 1)
    blocks = []
    # core block: grid (i along y, j along z)
    cy, cz = np.meshgrid(s * tau, s * tau, indexing="ij")
    blocks.append(np.stack([cy, cz]))
    rho = np.linspace(0.0, 1.0, n_ring + 1)
    for k in range(4):
        c, si = math.cos(k * math.pi / 2), math.sin(k * math.pi / 2)
        rot = np.array([[c, -si], [si, c]])
        T, P = np.meshgrid(tau, rho, indexing="ij")  # i around, j radial
        inner = np.stack([np.full_like(T, s), s * T])
        phi = T * math.pi / 4
        outer = np.stack([radius * np.cos(phi), radius * np.sin(phi)])
        pts = (1 - P) * inner + P * outer
        blocks.append(np.einsum("ab,bij->aij", rot, pts))
    # merge coincident vertices
    allpts = np.concatenate([b.reshape(2, -1) for b in blocks], axis=1)
    key = np.round(allpts / radius * 1e9).astype(np.int64)
    _, first, inverse = np.unique(key, axis=1, return_index=True, return_inverse=True)
    verts = allpts[:, first]
    inverse = inverse.ravel()
    quads = []
    offset = 0
    for b in blocks:
        ni, nj = b.shape[1], b.shape[2]
        idx = inverse[offset : offset + ni * nj].reshape(ni, nj)
        offset += ni * nj
        q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]]).reshape(4, -1)
        # orient counter-clockwise in the (y, z) plane
        a, bq, d = verts[:, q[0]], verts[:, q[1]], verts[:, q[3]]
        cross = (bq[0] - a[0]) * (d[1] - a[1]) - (bq[1] - a[1]) * (d[0] - a[0])
        flip = cross < 0
        q[:, flip] = q[[0, 3, 2, 1]][:, flip]
        quads.append(q)
    return verts, np.concatenate(quads, axis=1)


def circle_mesh(
    length: float,
    diameter: float,
    n_length: int,
    n_core: int = 1,
    n_ring: int = 1,
    breakpoints=(),
    quadratic: bool = True,
    clamp: float | None = None,
):
    """Mapped hexahedral mesh of a circular cylinder along x (O-grid section).

    The section is an O-grid (see ``_disc_quads``): ``n_core**2 + 4 n_core n_ring`` elements
    per section, extruded in about ``n_length`` layers that end at every breakpoint (arc
    lengths, m; see :func:`length_layers`; graded at the clamp to layers no longer than
    ``clamp``, m, if given).  With ``quadratic`` (for quadratic elements) the
    mesh is a 27-node ``MeshHex2`` whose lateral-surface nodes lie on the exact cylinder
    (isoparametric quadratic boundary): the circumference has ``4 n_core`` parabolic arcs and
    the section area is 1.2 % short with ``n_core = 1`` (90-degree arcs), 0.08 % with 2 and
    0.016 % with 3.  Without (for linear elements) it is the ``MeshHex1`` of the same vertices:
    the section is the inscribed ``4 n_core``-gon (area 36 % short with ``n_core = 1``, 10 %
    with 2, 4.5 % with 3).  Linear elements need the linear mesh: on the quadratic geometry
    they come out ~10 times too stiff (coilrod issue 23).

    Returns
    -------
    skfem.MeshHex2 or skfem.MeshHex1
    """
    from skfem import Basis, ElementHex2, MeshHex1, MeshHex2

    R = diameter / 2
    verts, quads = _disc_quads(R, n_core, n_ring)
    nv = verts.shape[1]
    xs = length_layers(length, n_length, breakpoints, clamp)
    n_length = xs.size - 1
    p = np.concatenate([np.vstack([np.full(nv, x), verts]) for x in xs], axis=1)
    lo = quads[:, None, :] + nv * np.arange(n_length)[None, :, None]  # (4, nl, nq)
    hi = lo + nv
    lo, hi = lo.reshape(4, -1), hi.reshape(4, -1)
    q00, q10, q11, q01 = lo
    Q00, Q10, Q11, Q01 = hi
    # skfem hex vertex order (r0, r1, r2): 000, 001, 010, 100, 011, 101, 110, 111 with
    # r0 along x, r1 = the quad's second direction, r2 = its first (positive Jacobian)
    t = np.stack([q00, q10, q01, Q00, q11, Q10, Q01, Q11])
    m1 = MeshHex1(p, t)
    if not quadratic:
        return m1
    m2 = MeshHex2.from_mesh(m1)
    # move lateral-surface nodes (edge, facet midpoints) radially onto the cylinder
    tol = 1e-9 * length
    facets = m1.facets_satisfying(
        lambda x: (x[0] > tol) & (x[0] < length - tol) & (x[1] ** 2 + x[2] ** 2 > (0.5 * R) ** 2),
        boundaries_only=True,
    )
    dofs = Basis(m1, ElementHex2(), intorder=1).get_dofs(facets=facets).all()
    doflocs = m2.doflocs.copy()
    yz = doflocs[1:, dofs]
    doflocs[1:, dofs] = yz * (R / np.linalg.norm(yz, axis=0))
    return MeshHex2(doflocs, m2.t)


def linear_circle_problem(section, dim: int, order: int, elements) -> str:
    """Why ``elements`` cannot mesh ``section`` for linear elements ("" if they can): a 3D
    Circle of order 1 with ``core = 1`` is meshed by its inscribed square (the linear O-grid's
    section, 36 % short of the circle's area); ``core >= 2`` gives at least the octagon."""
    if dim == 3 and order == 1 and isinstance(section, Circle) and elements[1] < 2:
        return (
            f"elements {tuple(elements)}: a linear (order 1) O-grid with core = {elements[1]} "
            "has a square section, 36 % short of the circle's area; give core >= 2 (an "
            "octagon or finer) or order 2"
        )
    return ""


def check_mesh(mesh, rod, dim: int, order: int) -> None:
    """Raise ValueError unless ``mesh`` is a reference mesh of ``rod`` for ``solve_fem``.

    The mesh must be a scikit-fem quadrilateral (2D) or hexahedral (3D) mesh, of linear
    geometry for linear elements (linear elements on a quadratic-geometry mesh are ~10 times
    too stiff), span x in [0, L] (to ``MESH_END_TOL`` L), keep its nodes within the section's
    bounds centred on the x axis (|y| <= h / 2 with the strip's height h in 2D, the
    Rectangle's |y| <= thickness / 2 and |z| <= width / 2, the Circle's radius; to
    ``MESH_SECTION_TOL``), and have the section's area (volume / L; the 2D strip's height):
    to ``MESH_SECTION_TOL`` for a Rectangle and the strip, between the inscribed octagon's
    (:data:`MIN_CIRCLE_AREA_RATIO`) and the circle's for a Circle.

    Parameters
    ----------
    mesh : skfem.Mesh
    rod : coilrod.Rod
    dim : {2, 3}
    order : {1, 2}
    """
    import skfem

    kinds = {2: (skfem.MeshQuad1, skfem.MeshQuad2), 3: (skfem.MeshHex1, skfem.MeshHex2)}[dim]
    if not isinstance(mesh, kinds):
        raise ValueError(
            f"mesh must be a scikit-fem {' or '.join(k.__name__ for k in kinds)} for dim={dim}; "
            f"got {type(mesh).__name__}"
        )
    if order == 1 and isinstance(mesh, kinds[1]):
        raise ValueError(
            f"mesh: linear elements (order=1) on a quadratic-geometry {type(mesh).__name__} are "
            f"about 10 times too stiff; give its linear mesh ({kinds[0].__name__}(mesh.p, "
            "mesh.t)) or order=2"
        )
    L = float(rod.length)
    x = mesh.doflocs
    if not np.all(np.isfinite(x)):
        bad = int(np.nonzero(~np.all(np.isfinite(x), axis=0))[0][0])
        raise ValueError(f"mesh nodes must be finite; node {bad} is {x[:, bad].tolist()}")
    lo, hi = float(x[0].min()), float(x[0].max())
    if abs(lo) > MESH_END_TOL * L or abs(hi - L) > MESH_END_TOL * L:
        raise ValueError(
            f"mesh must span x in [0, L] = [0, {L:.6g}] m (the rod clamped at x = 0, its tip at "
            f"x = L); it spans [{lo:.6g}, {hi:.6g}] m"
        )
    sec = rod.section
    if dim == 2:
        half = {"y": 0.5 * equivalent_height(sec)}
    elif isinstance(sec, Rectangle):
        half = {"y": 0.5 * sec.thickness, "z": 0.5 * sec.width}
    else:
        half = {"r": 0.5 * sec.diameter}
    size = max(half.values())
    for name, h in half.items():
        coord = np.hypot(x[1], x[2]) if name == "r" else x[1 if name == "y" else 2]
        far = float(np.max(np.abs(coord)))
        if far > h + MESH_SECTION_TOL * size:
            what = "radius sqrt(y^2 + z^2)" if name == "r" else f"|{name}|"
            raise ValueError(
                f"mesh nodes reach {what} = {far:.6g} m, beyond the section's {h:.6g} m (the "
                f"section {sec!r}{' as the 2D strip' if dim == 2 else ''} is centred on the x "
                "axis)"
            )
    try:
        area = float(skfem.Basis(mesh, mesh.elem(), intorder=5).dx.sum()) / L
    except Exception as exc:  # scikit-fem raises a bare Exception("Zero Jacobian determinant")
        raise ValueError(
            f"mesh has a degenerate element (of zero area or volume; scikit-fem: {exc})"
        ) from None
    nominal = equivalent_height(sec) if dim == 2 else sec.area
    ratio = area / nominal
    if isinstance(sec, Circle) and dim == 3:
        ok, want = MIN_CIRCLE_AREA_RATIO <= ratio <= 1 + MESH_SECTION_TOL, "90 to 100 %"
    else:
        ok, want = abs(ratio - 1) <= MESH_SECTION_TOL, "100 %"
    if not ok:
        what = "height (area / L)" if dim == 2 else "section area (volume / L)"
        raise ValueError(
            f"mesh {what} is {area:.6g}, {100 * ratio:.4g} % of the section's {nominal:.6g} "
            f"(must be {want}): the mesh does not fill the section {sec!r}"
        )


def rod_mesh(rod, dim: int, elements: tuple[int, ...], order: int = 2):
    """The reference mesh of ``rod`` for a ``dim``-dimensional model of element ``order``.

    ``elements`` counts elements along (length, thickness) in 2D, (length, thickness, width)
    for a 3D Rectangle, and (length, core, ring) for a 3D Circle: ``core`` elements along each
    side of the O-grid's central square and ``ring`` radial layers around it.  The layers
    along the length end at the magnetization's breakpoints (:func:`length_layers`): there
    are ``elements[0]`` of them, or one per piece between breakpoints if that is more; in 3D
    more at the clamp, where they are graded to no longer than the section's smallest extent
    (:func:`clamp_layer`; a layer long against the section there makes the stability count a
    property of the mesh, see :data:`CLAMP_LAYER`).  A 3D Circle has quadratic geometry
    (``MeshHex2``) for ``order`` 2 and the linear mesh of the same vertices (``MeshHex1``, a
    polygonal section) for ``order`` 1 (:func:`circle_mesh`).
    """
    L = rod.length
    sec = rod.section
    br = rod.magnetization.breakpoints
    if dim == 2:
        return rectangle_mesh(L, equivalent_height(sec), *elements, breakpoints=br)
    clamp = clamp_layer(sec)
    if isinstance(sec, Rectangle):
        return box_mesh(L, sec.thickness, sec.width, *elements, breakpoints=br, clamp=clamp)
    if isinstance(sec, Circle):
        problem = linear_circle_problem(sec, dim, order, elements)
        if problem:
            raise ValueError(problem)
        return circle_mesh(
            L, sec.diameter, *elements, breakpoints=br, quadratic=order == 2, clamp=clamp
        )
    raise ValueError(f"unsupported section {sec!r}")
