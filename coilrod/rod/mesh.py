"""Arc-length meshes of the discrete rod: piecewise uniform, with nodes at the breakpoints."""

from __future__ import annotations

import numpy as np

__all__ = ["RodMesh"]


class RodMesh:
    """Piecewise-uniform nodes on [0, 1] with a node at every breakpoint.

    Parameters
    ----------
    segments : int
        Approximate number of segments N (each piece between breakpoints gets at least 2).
    breaks : ndarray, shape (k,)
        Interior breakpoints in (0, 1) (fractions of L).
    """

    def __init__(self, segments: int, breaks=()):
        edges = np.unique(np.concatenate([[0.0], np.asarray(breaks, float), [1.0]]))
        lengths = np.diff(edges)
        counts = np.maximum(2, np.round(segments * lengths).astype(int))
        self._build(edges, counts)

    def _build(self, edges: np.ndarray, counts: np.ndarray) -> None:
        self.edges = edges
        self.counts = counts
        pieces = [
            np.linspace(a, b, c + 1)[:-1]
            for a, b, c in zip(edges[:-1], edges[1:], counts, strict=True)
        ]
        self.s = np.concatenate([*pieces, [1.0]])
        self.h = np.diff(self.s)
        self.w = np.zeros(self.s.size)
        self.w[:-1] += self.h / 2
        self.w[1:] += self.h / 2

    def refined(self) -> RodMesh:
        """The mesh with every segment halved (its nodes contain this mesh's nodes)."""
        out = RodMesh.__new__(RodMesh)
        out._build(self.edges, 2 * self.counts)
        return out

    @property
    def n(self) -> int:
        """Number of nodes N + 1."""
        return self.s.size
