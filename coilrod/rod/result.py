"""Result of a rod solve: equilibrium states along a load sweep."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["RodResult"]


@dataclass
class RodResult:
    """Equilibria of a rod for each requested field scale.

    Attributes
    ----------
    scales : ndarray, shape (k,)
        The field multipliers, in the order solved.
    s : ndarray, shape (n,)
        Arc length of the output nodes, m.
    tip : ndarray, shape (k, 3)
        Tip positions, m (Richardson-extrapolated when enabled).
    tip_angle : ndarray, shape (k,)
        Tangent angle at the tip, rad (spatial model: the azimuth of the tip tangent about z,
        ``atan2(t_y, t_x)``, continued from the clamp's; see :meth:`frames` for the full
        orientation).
    converged : ndarray of bool, shape (k,)
        ``error <= 1``: the state passed the solver's convergence test on every mesh used (a
        state that does not is never returned: a scale that cannot be reached raises
        :class:`~coilrod.ConvergenceError`).
    error : ndarray, shape (k,)
        The convergence measure Newton reached at each state (largest over the meshes): the
        scaled residual over the tolerance plus its round-off floor (<= 1: converged).
    stable : ndarray of bool, shape (k,)
        False where the second variation is not positive definite (unstable equilibrium).
        Always in 3D: for the planar model the out-of-plane modes (twist and bending out of the
        plane, from the spatial rod's second variation at the planar state) are counted too,
        so a planar state that would buckle out of its plane is unstable.
    stable_in_plane : ndarray of bool, shape (k,)
        Planar model only: stability against in-plane perturbations alone (the planar rod's
        own figure; computed on first access).  Equal to ``stable`` for the spatial model.
    residual : ndarray, shape (k,)
        Scaled residual max-norm of each state (largest over the meshes used), non-dimensional.
    min_eigenvalue : ndarray, shape (k,)
        Smallest eigenvalue of the second variation per unit length, in EI / L^3 units
        (non-dimensional); it crosses zero at a bifurcation or limit point.  The straight
        unloaded rod has pi^2 / 4 in the plane (bending) and, in 3D, the smaller of that, the
        out-of-plane bending EI_y / EI_z pi^2 / 4 and the torsion GJ / EI_z pi^2 / 4 (pi^2 / 6
        for a circle with nu = 1/2).  Computed on the coarse mesh (extrapolated near a loss of
        stability for uniform fields); for large meshes in non-uniform fields it is the
        eigenvalue closest to zero.  Computed on first access (the solve itself decides
        stability from the exact inertia of the second variation and does not need it).  3D
        like ``stable``; ``min_eigenvalue_in_plane`` is the planar model's in-plane figure.
    iterations : ndarray of int, shape (k,)
        Newton iterations spent on each scale (all meshes, all sub-steps).
    instabilities : list of dict
        One entry per change of stability between consecutive scales: ``index`` (first scale
        with the new stability), ``scale`` (critical scale estimated by linear interpolation of
        ``min_eigenvalue``), ``stable`` (the new stability), and for the planar model ``mode``:
        "in-plane" or "out-of-plane" (the rod would leave its plane there; the planar solver
        stays on the planar branch); and one per snap-through, with
        ``kind`` "snap", ``scale`` (last converged scale before the fold) and ``landing``
        (scale at which the path, followed around the fold, was stable again).
    segments : int
        Segments of the (coarse) mesh; the fine mesh of the extrapolation has twice as many.
    model : str
        "planar" or "spatial": the rod model that produced the states (see
        :func:`~coilrod.solve_rod`'s ``model``).
    """

    scales: np.ndarray
    s: np.ndarray
    tip: np.ndarray
    tip_angle: np.ndarray
    converged: np.ndarray
    stable: np.ndarray
    residual: np.ndarray
    _min_eigenvalue: object = field(repr=False)  # ndarray, or a callable computing it once
    iterations: np.ndarray
    segments: int
    _theta: np.ndarray = field(repr=False)
    _points: np.ndarray = field(repr=False)
    instabilities: list = field(default_factory=list)
    #: What the sensitivities need (rod, field, the discrete problems and their states).
    _solution: object = field(default=None, repr=False)
    model: str = "planar"
    _frames: np.ndarray | None = field(default=None, repr=False)
    _contact: dict | None = field(default=None, repr=False)
    error: np.ndarray = field(default=None, repr=False)
    #: planar model: the in-plane figures, arrays or callables computing them once (None:
    #: the 3D figures are the in-plane ones)
    _stable_in_plane: object = field(default=None, repr=False)
    _min_eigenvalue_in_plane: object = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.scales)

    @property
    def stable_in_plane(self) -> np.ndarray:
        """See the class docstring; shape (k,)."""
        if self._stable_in_plane is None:
            return self.stable.copy()
        if callable(self._stable_in_plane):
            self._stable_in_plane = np.asarray(self._stable_in_plane(), bool)
        return self._stable_in_plane

    @property
    def min_eigenvalue_in_plane(self) -> np.ndarray:
        """Smallest eigenvalue of the in-plane second variation (planar model; the 3D
        ``min_eigenvalue`` for the spatial one), EI / L^3 units, shape (k,)."""
        if self._min_eigenvalue_in_plane is None:
            return self.min_eigenvalue
        if callable(self._min_eigenvalue_in_plane):
            self._min_eigenvalue_in_plane = np.asarray(self._min_eigenvalue_in_plane(), float)
        return self._min_eigenvalue_in_plane

    @property
    def min_eigenvalue(self) -> np.ndarray:
        """See the class docstring; shape (k,)."""
        if callable(self._min_eigenvalue):
            self._min_eigenvalue = np.asarray(self._min_eigenvalue(), dtype=float)
        return self._min_eigenvalue

    def centerline(self, k: int) -> np.ndarray:
        """Centreline of state ``k`` at the nodes :attr:`s`, shape (n, 3), m (Richardson-
        extrapolated like the tip)."""
        return self._points[k].copy()

    def _contact_item(self, name: str, k: int):
        if self._contact is None:
            raise ValueError("this result has no obstacles (solve_rod(..., obstacles=[...]))")
        return self._contact[name][k].copy()

    @property
    def contact_s(self) -> np.ndarray:
        """Arc lengths of the contact points, shape (n,), m: contact is at the corners of
        the rod's polygon (node j's straight piece along its tangent ends half a segment
        after it, at ``s_j + h_j / 2``) and at the tip; :meth:`contact_force`,
        :meth:`gaps` and :meth:`contact_set` are given there (with the Richardson
        extrapolation: the force and the set of the refined mesh at its corner after each
        output node, ``s_j + h_j / 4``)."""
        if self._contact is None:
            raise ValueError("this result has no obstacles (solve_rod(..., obstacles=[...]))")
        return self._contact["s"].copy()

    def contact_force(self, k: int) -> np.ndarray:
        """Contact force per unit length on the rod at the contact points :attr:`contact_s`
        of state ``k``, shape (n, 3), N/m (summed over the obstacles; frictionless: along
        each wall's normal).  A contact at a single point appears as one point's force over
        its weight; :meth:`obstacle_forces` gives the mesh-independent totals."""
        return self._contact_item("force", k).sum(axis=1)

    def obstacle_forces(self, k: int) -> list[np.ndarray]:
        """Total force the rod exerts on each obstacle in state ``k``: one (3,) array per
        obstacle, N (minus the contact force on the rod, integrated along it)."""
        return list(self._contact_item("totals", k))

    def gaps(self, k: int) -> np.ndarray:
        """Gap of each contact point of the returned rod (the corners of its polygon after
        each node and the tip, :attr:`contact_s`) to each obstacle in state ``k``, shape
        (n, n_obstacles), m (>= 0 up to the Newton tolerance: no penetration; the
        Richardson extrapolation is used only where it keeps them admissible)."""
        return self._contact_item("gap", k)

    def contact_set(self, k: int) -> np.ndarray:
        """Contact points (:attr:`contact_s`) in contact with each obstacle in state ``k``,
        bool (n, n_obstacles)."""
        return self._contact_item("active", k)

    def write_vtk(self, path, states=None, *, frames: bool = True):
        """Write the centrelines (and frames) of ``states`` (default: all) as VTK polylines for
        ParaView, with a .pvd collection over the load path: see
        :func:`coilrod.rod.export.write_vtk`.  Returns the files written."""
        from .export import write_vtk

        return write_vtk(self, path, states, frames=frames)

    def frames(self, k: int) -> np.ndarray:
        """Cross-section frames of state ``k`` at the nodes :attr:`s`, shape (n, 3, 3): the
        columns of ``frames(k)[i]`` are the tangent, normal and binormal at node i in world
        coordinates (planar: rotations by the tangent angle about z)."""
        if self._frames is not None:
            return self._frames[k].copy()
        from .so3 import about_z

        return about_z(self._theta[k])

    def theta(self, k: int) -> np.ndarray:
        """Tangent angle of state ``k`` at the nodes :attr:`s`, shape (n,), rad (planar model
        only; a spatial state has :meth:`frames`)."""
        if self._theta is None:
            raise ValueError(
                "theta() is the tangent angle of a planar state; this result is spatial: use "
                "frames(k) (tangent, normal, binormal at each node)"
            )
        return self._theta[k].copy()
