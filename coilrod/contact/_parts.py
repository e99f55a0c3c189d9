"""An insertion step's discrete problem from the rod's constants, taken once per insertion.

:func:`~coilrod.contact.insert` solves one spatial rod per step: the free part of the device
(:func:`~coilrod.contact.insertion.free_part`), its mesh and its problem.  Built through the
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

__all__ = ["StepProblems"]


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
        self.mags = np.asarray(mag.segment_magnitudes, float)
        self.angs = np.asarray(mag.segment_angles, float)
        self.elevs = np.asarray(mag.segment_elevations, float)
        self.stiffness = rod_stiffnesses(rod)

    def __call__(self, length: float, field):
        if not self.fast:  # the public path (free_part checks the length)
            from .insertion import free_part

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
        keep = np.flatnonzero(np.diff(cut) > 0)
        edges = np.concatenate([[0.0], np.cumsum(np.diff(cut)[keep])])
        mags, angs, elevs = self.mags[keep], self.angs[keep], self.elevs[keep]
        # the mesh: make_mesh on the profile's breakpoints (Magnetization sorts them)
        breaks = np.array(sorted(edges[1:-1].tolist()), dtype=float)
        mesh = RodMesh(self.nodes, breaks / L)
        # node magnetization (mesh.node_magnetization, dim 3) of the segment profile: the
        # one-sided limits at each node, read in the segments Magnetization.segments picks
        left, right, hl, hr = _one_sided(mesh, L)
        s = np.concatenate([left, right])
        index = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, len(mags) - 1)
        mag, ang = mags[index], angs[index]
        if np.any(elevs):  # (Magnetization.vector and vector3 off the plane)
            elev = elevs[index]
            in_plane = mag * np.cos(elev)
            normal = mag * np.sin(elev)
        else:
            in_plane, normal = mag, np.zeros(s.shape)
        both = np.concatenate(
            [np.stack([in_plane * np.cos(ang), in_plane * np.sin(ang)], axis=-1),
             normal[..., None]], axis=-1,
        )  # fmt: skip
        mu = hl[:, None] * both[: left.size] + hr[:, None] * both[left.size :]
        mu = mu * (self.rod.area * L**2 / self.rod.bending_stiffness)
        return SpatialRod(
            mesh, mu, self.stiffness.copy(), field, L, self.clamp, self.R0, self.tol, False,
            self.obstacles, section=self.rod.section if self.obstacles else None,
        )  # fmt: skip
