"""Results of a finite-element solve: tips, displacement fields, export and plotting."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["FEMResult"]


class FEMResult:
    """Equilibria of :func:`coilrod.solve_fem` at each requested load scale.

    Attributes
    ----------
    scales : ndarray, shape (n,)
        The requested field multipliers.
    tip : ndarray, shape (n, 3)
        Centroid of the deformed free end face (x = L) at each scale, m (z = 0 in 2D).
    tip_angle : ndarray, shape (n,)
        Angle (rad, from +x, unwrapped along the path) of the deformed tip tangent: the normal
        of the free end face, taken as the image of the section's y direction (least squares
        over the face nodes) turned by -pi/2 -- the rod model's tip angle.
    converged : ndarray, shape (n,)
        ``error <= 1``: the state passed Newton's convergence test (a state that does not is
        never returned: unreachable loads raise ``ConvergenceError``).
    error : ndarray, shape (n,)
        The convergence measure Newton reached at each state (<= 1: converged).
    stable : ndarray, shape (n,)
        False where the (condensed) tangent has negative eigenvalues (none at the unloaded
        state): counted from the factorisation's inertia where it reveals it, else from the
        sign of the determinant (an odd number of eigenvalues crossed zero; two crossing
        together would then cancel).
    iterations : ndarray, shape (n,)
        Newton iterations spent reaching each scale from the previous one.
    mesh : skfem.Mesh
        The reference mesh.
    nodes : ndarray, shape (dim, n_nodes)
        Reference positions of the displacement nodes (mesh vertices first, then the edge,
        face and interior nodes of quadratic elements), m.
    stats : SolveStats
        Counters (evaluations, factorisations, step cuts).
    """

    def __init__(self, assembler, scales, states, stats, stable, error):
        self._asm = assembler
        self.scales = np.asarray(scales, dtype=float)
        self._states = list(states)
        self.stats = stats
        self.mesh = assembler.mesh
        self.nodes = assembler.nodes
        self.dim = assembler.dim
        self.order = assembler.order
        self.tip = np.array([assembler.tip(u) for u in self._states]).reshape(-1, 3)
        self.tip_angle = self._tip_angles()
        self.error = np.asarray(error, dtype=float)
        self.converged = self.error <= 1.0
        if not self.converged.all():
            from ..errors import ConvergenceError

            k = int(np.argmin(self.converged))
            raise ConvergenceError(
                f"solve_fem: the state at scale {self.scales[k]:g} (index {k}) does not meet "
                f"the convergence test (error {self.error[k]:.3g} of the tolerance)",
                reached=float(self.scales[k - 1]) if k else 0.0,
                target=float(self.scales[k]),
                residual=float(self.error[k]),
            )
        self.stable = np.asarray(stable, dtype=bool)
        self.iterations = np.asarray(stats.iterations, dtype=int)
        #: Changes of stability and snap-throughs along the path (see coilrod.path.events).
        self.instabilities: list = []

    def _tip_angles(self) -> np.ndarray:
        X = self.nodes
        length = X[0].max()
        face = np.abs(X[0] - length) <= 1e-9 * max(length, 1e-300)
        # deformed face positions ~ c + Y a + Z b: a is the image of the section's y axis
        cols = [np.ones(face.sum()), X[1, face]] + ([X[2, face]] if self.dim == 3 else [])
        design = np.column_stack(cols)
        angles = np.empty(len(self._states))
        for k in range(len(self._states)):
            x = self.deformed_nodes(k)[:2, face].T
            coef = np.linalg.lstsq(design, x, rcond=None)[0]
            a = coef[1]
            angles[k] = np.arctan2(a[1], a[0]) - np.pi / 2
        return np.unwrap(np.concatenate([[0.0], angles]))[1:]

    def __len__(self) -> int:
        return len(self._states)

    def _index(self, k) -> int:
        """``k`` as a state index (negative from the end), or a ValueError naming it."""
        n = len(self)
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or not -n <= k < n:
            raise ValueError(f"k must be a state index from {-n} to {n - 1}; got {k!r}")
        return int(k)

    def displacement(self, k: int) -> np.ndarray:
        """Nodal displacement of state ``k``, shape (dim, n_nodes), m (see :attr:`nodes`)."""
        return self._asm.nodal(self._states[self._index(k)])

    def deformed_nodes(self, k: int) -> np.ndarray:
        """Deformed node positions of state ``k``, shape (dim, n_nodes), m."""
        return self.nodes + self.displacement(k)

    # -- export -----------------------------------------------------------------------------
    def _meshio(self, k: int):
        from skfem.io.meshio import to_meshio

        u = self.displacement(k)
        npts = self.mesh.p.shape[1]
        mesh = self.mesh
        disp = np.zeros((npts, 3))
        disp[:, : self.dim] = u[:, :npts].T
        out = to_meshio(mesh, point_data={"displacement": disp})
        if out.points.shape[1] == 2:  # VTU needs 3D points (meshio pads them, printing so)
            out.points = np.column_stack([out.points, np.zeros(len(out.points))])
        return out

    def export(self, path, k: int | None = None) -> Path:
        """Write displacement fields for ParaView (apply "Warp By Vector" to see the shape).

        Parameters
        ----------
        path : str or Path
            ``.xdmf`` writes all states as a time series (time = load scale) unless ``k``
            is given; any other meshio extension (``.vtu``, ``.vtk``) writes state ``k``
            (default: the last).

        Returns
        -------
        Path

        Raises
        ------
        ValueError
            An extension meshio does not write, or ``k`` not a state index.
        OSError
            The file cannot be written (the message names it).  The file is written whole or
            not at all (a temporary file, renamed): an existing file is replaced at once.
        """
        import meshio

        from coils._files import replacing

        path = Path(path)
        if path.suffix.lower() not in meshio.extension_to_filetypes:
            raise ValueError(
                f"path {str(path)!r}: meshio writes no {path.suffix or 'extensionless'!r} "
                "files; use .vtu, .vtk or .xdmf"
            )
        if k is not None:
            k = self._index(k)
        if path.suffix == ".xdmf" and k is None:
            first = self._meshio(0)
            # XML (inline) data: no HDF5 dependency
            with (
                replacing(path) as tmp,
                meshio.xdmf.TimeSeriesWriter(tmp, data_format="XML") as writer,
            ):
                writer.write_points_cells(first.points, first.cells)
                for j, s in enumerate(self.scales):
                    writer.write_data(float(s), point_data=self._meshio(j).point_data)
            return path
        k = len(self) - 1 if k is None else k
        if path.suffix.lower() in (".xdmf", ".xmf"):  # its HDF5 side file is named after it
            self._meshio(k).write(path)
            return path
        with replacing(path) as tmp:
            self._meshio(k).write(tmp)
        return path

    def plot(self, k: int = -1, ax=None, **kwargs):
        """Draw the edges of the deformed mesh of state ``k`` in the x-y (bending) plane.

        Returns
        -------
        matplotlib.axes.Axes
        """
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots()
        x = self.deformed_nodes(k)
        edges = self.mesh.facets if self.dim == 2 else self.mesh.edges
        segs = np.stack([x[:2, edges[0]], x[:2, edges[1]]]).transpose(2, 0, 1)
        from matplotlib.collections import LineCollection

        kwargs.setdefault("linewidths", 0.6)
        kwargs.setdefault("colors", "C0")
        ax.add_collection(LineCollection(segs, **kwargs))
        ax.autoscale()
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"scale {self.scales[self._index(k)]:g}")
        return ax
