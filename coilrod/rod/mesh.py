"""Arc-length meshes of the discrete rod (piecewise uniform, nodes at the breakpoints) and the
node magnetization integrated exactly across jumps."""

from __future__ import annotations

import numpy as np

from coils._memo import remember

__all__ = ["RodMesh", "node_magnetization", "segment_weights", "MERGE_BREAKS"]

#: Breakpoints closer than this (fraction of L) to each other or to an end are merged: a
#: segment shorter than that carries a negligible part of the load and would only make the
#: discrete equations ill-conditioned.
MERGE_BREAKS = 1e-10

#: Node magnetizations of constant profiles already computed, keyed on everything the result
#: depends on (the profile's constants, the rod length, dim and the mesh's node arrays by
#: value), so a changed input is a new key, never a stale hit; at most :data:`_CACHE_SIZE`
#: entries (oldest dropped first).
_CONSTANT_CACHE: dict = {}
_CACHE_SIZE = 16
#: Meshes already built: (edges, counts) keyed on ``(segments, breaks)`` and the node arrays
#: (s, h, w) keyed on (edges, counts), all by value (a mesh is a pure function of them;
#: every mesh gets its own copies); at most :data:`_CACHE_SIZE` entries.
_NODE_CACHE: dict = {}


class RodMesh:
    """Piecewise-uniform nodes on [0, 1] with a node at every breakpoint.

    Parameters
    ----------
    segments : int
        Approximate number of segments N (each piece between breakpoints gets at least 2).
    breaks : ndarray, shape (k,)
        Interior breakpoints (fractions of L); those within :data:`MERGE_BREAKS` of an end or
        of each other are merged.

    Attributes
    ----------
    s : ndarray, shape (n,)
        Node arc lengths, fractions of L (``s[0] = 0``, ``s[-1] = 1``).
    h : ndarray, shape (n - 1,)
        Segment lengths.
    w : ndarray, shape (n,)
        Trapezoid weights (half the adjacent segments).
    """

    def __init__(self, segments: int, breaks=()):
        breaks = np.asarray(breaks, float)
        key = (float(segments), breaks.tobytes())  # (an int count multiplies as its float)
        cached = _NODE_CACHE.get(key)
        if cached is None:
            br = np.sort(breaks.ravel())
            br = br[(br > MERGE_BREAKS) & (br < 1.0 - MERGE_BREAKS)]
            if br.size:
                br = br[np.concatenate([[True], np.diff(br) > MERGE_BREAKS])]
            edges = np.concatenate([[0.0], br, [1.0]])
            counts = _piece_counts(segments, np.diff(edges))
            cached = _remember(_NODE_CACHE, key, (edges, counts))
        self._build(*(a.copy() for a in cached))

    def _build(self, edges: np.ndarray, counts: np.ndarray) -> None:
        self.edges = edges
        self.counts = counts
        key = (edges.tobytes(), counts.astype(np.int64).tobytes())  # (bytes: not __init__'s)
        cached = _NODE_CACHE.get(key)
        if cached is None:
            pieces = [
                np.linspace(a, b, c + 1)[:-1]
                for a, b, c in zip(edges[:-1], edges[1:], counts, strict=True)
            ]
            s = np.concatenate([*pieces, [1.0]])
            h = np.diff(s)
            w = np.zeros(s.size)
            w[:-1] += h / 2
            w[1:] += h / 2
            cached = _remember(_NODE_CACHE, key, (s, h, w))
        # each mesh owns its arrays (a caller may change them: the cache keeps its own)
        self.s, self.h, self.w = (a.copy() for a in cached)

    def refined(self) -> RodMesh:
        """The mesh with every segment halved (its nodes contain this mesh's nodes)."""
        out = RodMesh.__new__(RodMesh)
        out._build(self.edges, 2 * self.counts)
        return out

    @property
    def n(self) -> int:
        """Number of nodes N + 1."""
        return self.s.size


#: Segments per piece from which a mesh of twice the segments halves every segment (nested
#: meshes): below it each piece's count is rounded on its own.
NESTED_FROM = 8


def _piece_counts(segments, lengths: np.ndarray) -> np.ndarray:
    """Segments of each piece (lengths: fractions of L, shape (p,)), at least 2 each.

    ``round(segments * length)`` per piece, except that when half the segments already give
    every piece :data:`NESTED_FROM` or more, the counts are twice those of half the segments:
    doubling ``segments`` then halves every segment, so the pieces' spacings keep their ratio
    and the discretisation error falls like ``h^2`` monotonically (rounding each piece afresh
    changed the ratio from one mesh to the next, and errors of opposite sign in the pieces
    made the tip's convergence non-monotone with a breakpoint off the uniform grid).  Where
    ``segments * length`` are integers, the counts are the plain rounding's.
    """
    exact = segments * lengths
    half = 0.5 * float(segments)
    if (
        np.any(exact != np.round(exact))
        and half == int(half)
        and np.all(half * lengths >= NESTED_FROM)
    ):
        return 2 * _piece_counts(half, lengths)
    return np.maximum(2, np.round(exact).astype(int))


def _one_sided(mesh: RodMesh, length: float):
    """Arc lengths (m) where the one-sided limits of a profile are read at each node (left,
    right; shape (n,) each) and their weights (n,) (see :func:`node_magnetization`)."""
    L = float(length)
    s = mesh.s * L
    h = mesh.h * L
    ulp = np.spacing(np.maximum(np.abs(s), L))
    left_len = np.concatenate([[h[0]], h])  # the node's left segment (node 0: unused)
    right_len = np.concatenate([h, [h[-1]]])
    d_left = np.maximum(2.0**-26 * left_len, 1e3 * ulp)
    d_right = np.maximum(2.0**-26 * right_len, 1e3 * ulp)
    hl = np.concatenate([[0.0], mesh.h]) / 2 / mesh.w
    hr = np.concatenate([mesh.h, [0.0]]) / 2 / mesh.w
    return np.clip(s - d_left, 0.0, L), np.clip(s + d_right, 0.0, L), hl, hr


def node_magnetization(magnetization, mesh: RodMesh, length: float, dim: int = 2) -> np.ndarray:
    """Trapezoid node magnetization in the body frame, shape (n, dim), A/m.

    Parameters
    ----------
    magnetization : coilrod.Magnetization
        The profile along the rod.
    mesh : RodMesh
        Nodes as fractions of the rod length.
    length : float
        Rod length L, m.
    dim : {2, 3}
        2: the (tangent, normal) components of :meth:`Magnetization.vector`, the projection of
        M on the bending plane (the planar rod); 3: the (tangent, normal, binormal)
        components of :meth:`Magnetization.vector3`.

    Returns
    -------
    ndarray, shape (n, dim)
        A/m.

    Notes
    -----
    At a node the one-sided limits of the profile are weighted by the adjacent half-segments,
    so a jump at a node (every breakpoint is one) is integrated exactly by the trapezoid rule.
    The one-sided limits are read a small distance inside each adjacent segment
    (``2^-26`` of the segment, at least ``10^3`` ulp of the node), never at the node itself: a
    node that lands a few ulp beside a breakpoint still reads each side's own value, so the
    result is continuous in the breakpoint position.
    """
    if isinstance(dim, bool) or dim not in (2, 3):
        raise ValueError(f"dim must be 2 or 3; got {dim!r}")
    key = _constant_key(magnetization, mesh, length, dim)
    cached = _CONSTANT_CACHE.get(key) if key is not None else None
    if cached is not None:
        return cached.copy()
    vector = magnetization.vector if dim == 2 else magnetization.vector3
    left, right, hl, hr = _one_sided(mesh, length)
    both = vector(np.concatenate([left, right]))  # one evaluation of the profile
    out = hl[:, None] * both[: left.size] + hr[:, None] * both[left.size :]
    if key is not None:
        _remember(_CONSTANT_CACHE, key, out.copy())
    return out


def _remember(cache: dict, key, value, size: int = _CACHE_SIZE):
    """:func:`coils._memo.remember` (the package's one bounded-cache rule: ``value`` stored
    under ``key`` as the most recent entry, the oldest dropped beyond ``size``, default
    :data:`_CACHE_SIZE`); returns ``value``."""
    return remember(cache, key, value, size)


def _constant_key(magnetization, mesh: RodMesh, length: float, dim: int):
    """Cache key of :func:`node_magnetization` for a constant profile of the plain
    :class:`~coilrod.Magnetization` class (its constants as exact float bit patterns, the
    length, dim and the mesh's ``s``, ``h``, ``w`` by value), or None: callable profiles
    (which may read mutable state) and subclasses are evaluated every time."""
    from ..robot.magnetization import Magnetization

    if type(magnetization) is not Magnetization or not magnetization.is_constant:
        return None
    consts = (magnetization._magnitude, magnetization._angle, magnetization._elevation)
    try:
        bits = tuple(float(c).hex() for c in (*consts, length))
    except (TypeError, ValueError):
        return None
    return (bits, dim, mesh.s.tobytes(), mesh.h.tobytes(), mesh.w.tobytes())


def segment_weights(edges: np.ndarray, mesh: RodMesh, length: float) -> np.ndarray:
    """Share of each node's trapezoid weight in each segment of a piecewise-constant profile
    with segment ``edges`` (m, shape (p + 1,)): shape (n, p), rows summing to 1.  The node
    magnetization of the profile is ``weights @ (M_j (cos a_j, sin a_j))``, exactly as
    :func:`node_magnetization` computes it."""
    left, right, hl, hr = _one_sided(mesh, length)
    edges = np.asarray(edges, float)
    p = edges.size - 1
    out = np.zeros((mesh.n, p))
    rows = np.arange(mesh.n)
    for side, weight in ((left, hl), (right, hr)):
        index = np.clip(np.searchsorted(edges, side, side="right") - 1, 0, p - 1)
        np.add.at(out, (rows, index), weight)
    return out
