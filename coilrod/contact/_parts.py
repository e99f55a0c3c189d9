"""The free part of a device and an insertion step's discrete problem (from the rod's
constants, taken once per insertion).

:func:`~coilrod.contact.insert` solves one spatial rod per step: the free part of the device
(:func:`free_part`, public as ``coilrod.contact.insertion.free_part``), its mesh and its
problem.  Built through the
public constructors, each step checks a rod that was checked already (``Rod``,
``Magnetization.segments``: the segment lengths, a maximum of the magnitude over 2001 samples
for the units warning) and evaluates the magnetization profile through its validating
callables.  :class:`StepProblems` takes the device's constants once and forms each step's
mesh and node moments from the segment arrays directly, with the same floating-point
operations in the same order: the problems are those of the public path, bitwise
(``tests/test_rod_contact.py``).  A magnetization that is not piecewise constant (callable
profiles) goes the public way.
"""

from __future__ import annotations

import numpy as np

from ..robot.magnetization import Magnetization
from ..robot.rod import Rod
from ..rod.mesh import RodMesh, _one_sided
from ..rod.solve import build_spatial_problem, make_mesh, rod_stiffnesses

__all__ = ["StepProblems", "free_part"]


def free_part(rod: Rod, length: float) -> Rod:
    """The distal ``length`` (m) of ``rod`` as a rod clamped at its proximal end: the part
    out of the introducer.  Its magnetization is the rod's, shifted so that the tips coincide
    (segment profiles stay segments)."""
    off = rod.length - length
    if not 0 < length <= rod.length * (1 + 1e-12):
        raise ValueError(f"free length must lie in (0, {rod.length:g}] m; got {length!r}")
    off = max(off, 0.0)
    mag = rod.magnetization
    edges = getattr(mag, "segment_edges", None)
    if edges is not None:
        cut = np.clip(edges - off, 0.0, None)
        keep = np.flatnonzero(np.diff(cut) > 0)
        kw = {}
        if hasattr(mag, "segment_elevations"):
            kw["elevations"] = np.asarray(mag.segment_elevations)[keep]
        new = Magnetization.segments(
            np.diff(cut)[keep],
            np.asarray(mag.segment_magnitudes)[keep],
            np.asarray(mag.segment_angles)[keep],
            **kw,
        )
    else:
        kw = {}
        if hasattr(mag, "elevation") and not getattr(mag, "is_planar", True):
            kw["elevation"] = lambda s: mag.elevation(np.asarray(s) + off)
        new = Magnetization(
            lambda s: mag.magnitude(np.asarray(s) + off),
            lambda s: mag.angle(np.asarray(s) + off),
            breakpoints=[b - off for b in mag.breakpoints if off < b < rod.length],
            **kw,
        )
    extra = {}
    if hasattr(rod, "poisson_ratio"):
        extra["poisson_ratio"] = rod.poisson_ratio
    return Rod(length, rod.youngs_modulus, rod.section, new, **extra)


class StepProblems:
    """The spatial problem of the free part of ``rod`` at a free length, in a field.

    Parameters
    ----------
    rod : Rod
        The whole device (checked at its construction).
    nodes : int
        Segments of each step's mesh (:func:`~coilrod.rod.solve.make_mesh`).
    clamp : ndarray, shape (3,)
        The introducer's position, m.
    R0 : ndarray, shape (3, 3)
        The introducer's frame.
    tol : float
        Newton tolerance.
    obstacles : sequence
        The obstacles of every step.

    Calling it with ``(length, field)`` (m, coils.Field) returns the problem that
    ``build_spatial_problem(free_part(rod, length), field, make_mesh(free, nodes), clamp, R0,
    tol, obstacles=obstacles)`` builds, with the same arrays bit for bit.
    """

    def __init__(self, rod: Rod, nodes: int, clamp, R0, tol: float, obstacles):
        self.rod, self.nodes = rod, nodes
        self.clamp, self.R0, self.tol = clamp, R0, tol
        self.obstacles = list(obstacles)
        mag = rod.magnetization
        self.fast = type(mag) is Magnetization and getattr(mag, "segment_edges", None) is not None
        if not self.fast:
            return
        self.edges = np.asarray(mag.segment_edges, float)
        mags = np.asarray(mag.segment_magnitudes, float)
        angs = np.asarray(mag.segment_angles, float)
        elevs = np.asarray(mag.segment_elevations, float)
        # per segment, the factors Magnetization.vector3 forms per sample (the same
        # functions of the same values: the products below are its products)
        self.mags, self.elevs = mags, elevs
        self.cos_a, self.sin_a = np.cos(angs), np.sin(angs)
        self.cos_e, self.sin_e = np.cos(elevs), np.sin(elevs)
        self.stiffness = rod_stiffnesses(rod)
        self.scale = (rod.area, rod.bending_stiffness)  # (_node_moments: A L^2 / EI)

    def __call__(self, length: float, field):
        if not self.fast:  # the public path (free_part checks the length)
            free = free_part(self.rod, length)
            return build_spatial_problem(
                free, field, make_mesh(free, self.nodes), self.clamp, self.R0, self.tol,
                obstacles=self.obstacles,
            )  # fmt: skip
        from ..rod.spatial import SpatialRod

        L = float(length)
        if not 0 < L <= self.rod.length * (1 + 1e-12):  # (free_part's check)
            raise ValueError(f"free length must lie in (0, {self.rod.length:g}] m; got {length!r}")
        # the free part's segments, as free_part and Magnetization.segments form them
        off = max(self.rod.length - L, 0.0)
        cut = np.clip(self.edges - off, 0.0, None)
        lengths = np.diff(cut)
        keep = np.flatnonzero(lengths > 0)
        edges = np.concatenate([[0.0], np.cumsum(lengths[keep])])
        # the mesh: make_mesh on the profile's breakpoints (increasing: Magnetization's sort
        # leaves them as they are)
        mesh = RodMesh(self.nodes, edges[1:-1] / L)
        # node magnetization (mesh.node_magnetization, dim 3) of the segment profile: the
        # one-sided limits at each node, read in the segments Magnetization.segments picks
        left, right, hl, hr = _one_sided(mesh, L)
        s = np.concatenate([left, right])
        index = np.searchsorted(edges, s, side="right")
        index -= 1
        np.clip(index, 0, keep.size - 1, out=index)
        index = keep[index]  # (the rod's own segments)
        mag = self.mags[index]
        both = np.empty((s.size, 3))
        if self.elevs[keep].any():  # (Magnetization.vector and vector3 off the plane)
            in_plane = mag * self.cos_e[index]
            both[:, 2] = mag * self.sin_e[index]
        else:
            in_plane = mag
            both[:, 2] = 0.0
        both[:, 0] = in_plane * self.cos_a[index]
        both[:, 1] = in_plane * self.sin_a[index]
        n = left.size
        mu = hl[:, None] * both[:n] + hr[:, None] * both[n:]
        area, EI = self.scale
        mu *= area * L**2 / EI
        return SpatialRod(
            mesh, mu, self.stiffness.copy(), field, L, self.clamp, self.R0, self.tol, False,
            self.obstacles, section=self.rod.section if self.obstacles else None,
        )  # fmt: skip
