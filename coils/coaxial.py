"""Coaxial groups of circular filaments (tier 2: frames, winding checks, chunking).

A :class:`CoaxialCoils` holds filaments sharing one axis and one centre; a single coil, a
Helmholtz pair and a Maxwell pair are all coaxial groups, so a pair is evaluated in one local
frame with one rotation.
"""

from __future__ import annotations

import numpy as np
from scipy.constants import mu_0

from ._validate import as_axis, as_vector
from .field import CHUNK, Field, FieldSum, ScaledField
from .loop import SYMMETRIC_EXPANSION, loop_B_and_gradient_local, loop_hessian_local

__all__ = ["CoaxialCoils", "frame_from_axis", "coaxial_parts", "winding_mask"]

#: CODATA mu0 over the 4e-7 pi used inside the kernel.
_MU0_SCALE = mu_0 / (4e-7 * np.pi)
#: A point closer than this fraction of the radius to a filament is "on the winding".
ON_WIRE_TOL = 1e-9


def frame_from_axis(axis: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) whose columns are (u, v, axis): local -> global coordinates."""
    n = np.asarray(axis, dtype=float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(helper, n)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return np.column_stack([u, v, n])


class CoaxialCoils(Field):
    """Circular filaments sharing an axis and a centre.

    Parameters
    ----------
    filaments : array-like, shape (f, 3)
        Rows ``(z_offset, radius, current)``: loop plane at ``center + z_offset * axis`` (m),
        radius (m), ampere-turns (A, counter-clockwise about ``axis``).
    axis : {"x", "y", "z"} or array-like, shape (3,)
        Common axis direction.
    center : array-like, shape (3,)
        Common centre, m.
    windings : sequence of (z0, radius, width, height), optional
        Winding cross-sections (m) inside which the field is not evaluated.

    Notes
    -----
    B, the gradient and the hessian are all exact closed forms (elliptic integrals, with power
    series near the axis; :mod:`coils.loop`), evaluated in the coils' frame and rotated to the
    global one with one matrix product per chunk of points.
    """

    def __init__(self, filaments, axis="z", center=(0.0, 0.0, 0.0), windings=()):
        fil = np.asarray(filaments, dtype=float)
        if fil.ndim != 2 or fil.shape[1] != 3 or fil.shape[0] == 0:
            raise ValueError(f"filaments must have shape (f, 3); got {fil.shape}")
        if not np.all(np.isfinite(fil)):
            raise ValueError("filaments must be finite")
        if np.any(fil[:, 1] <= 0):
            raise ValueError("filament radii must be positive")
        self.filaments = fil
        self.axis = as_axis(axis)
        self.center = as_vector(center, "center")
        self.rotation = frame_from_axis(self.axis)
        self.windings = np.asarray(windings, dtype=float).reshape(-1, 4)

    @property
    def length_scale(self) -> float:
        return float(np.min(self.filaments[:, 1]))

    # -- tier 2: frames and singularities ------------------------------------------------------
    def to_local(self, pts: np.ndarray) -> np.ndarray:
        """Global points (n, 3) m -> coordinates in the coil frame (axis = local z)."""
        return (pts - self.center) @ self.rotation

    def _check_not_on_winding(self, local: np.ndarray, nearest: np.ndarray) -> None:
        """Raise if a point is on a filament (``nearest``: min (distance / radius)^2 from the
        kernel) or inside a finite winding's cross-section."""
        bad = ~(nearest >= ON_WIRE_TOL**2)  # also catches NaN/inf from a singular evaluation
        if np.any(bad):
            k = int(np.argmax(bad))
            raise ValueError(
                f"point {k} lies on a coil winding (within {ON_WIRE_TOL:g} radius of a "
                f"filament): the field is singular there"
            )
        for (_z0, a, w, h), inside in zip(self.windings, self._inside_windings(local), strict=True):
            if np.any(inside):
                k = int(np.argmax(inside))
                raise ValueError(
                    f"point {k} lies inside a coil winding ({w} m x {h} m section at "
                    f"radius {a} m): the filament model does not hold there"
                )

    def _inside_windings(self, local: np.ndarray, closed: bool = False):
        """Yield, per winding cross-section, a bool mask of the local points (n, 3) inside it
        (``closed``: boundary included)."""
        if not len(self.windings):
            return
        rho = np.hypot(local[:, 0], local[:, 1])
        z = local[:, 2]
        less = np.less_equal if closed else np.less
        for z0, a, w, h in self.windings:
            yield less(np.abs(z - z0), 0.5 * w) & less(np.abs(rho - a), 0.5 * h)

    def _local_kernel(self, pts: np.ndarray, kernel, *args):
        """Run ``kernel(local, filaments, *args, nearest)`` on one chunk of global points and
        check that no point is on a winding; returns the kernel's result (local frame)."""
        local = self.to_local(pts)
        nearest = np.empty(local.shape[0])
        with np.errstate(divide="ignore", invalid="ignore"):
            out = kernel(local, self.filaments, *args, nearest)
        self._check_not_on_winding(local, nearest)
        return out

    def _evaluate(self, pts: np.ndarray, with_gradient: bool):
        n = pts.shape[0]
        B = np.empty((n, 3))
        G = np.empty((n, 3, 3)) if with_gradient else None
        R = self.rotation
        RR = np.kron(R, R)  # G_global = R g R^T as one (n x 9) @ (9 x 9) product
        for start in range(0, n, CHUNK):
            sl = slice(start, min(start + CHUNK, n))
            b, g = self._local_kernel(pts[sl], loop_B_and_gradient_local, with_gradient)
            B[sl] = (_MU0_SCALE * b) @ R.T
            if with_gradient:
                G[sl] = (g.reshape(-1, 9) @ (_MU0_SCALE * RR.T)).reshape(-1, 3, 3)
        return B, G

    def _hessian(self, pts: np.ndarray) -> np.ndarray:
        """Closed-form hessian (n, 3, 3, 3), T/m^2: see :func:`coils.loop.loop_hessian_local`."""
        n = pts.shape[0]
        H = np.empty((n, 3, 3, 3))
        R = self.rotation
        # H_IJL = R_Ii R_Jj R_Ll h_ijl, from the 10 distinct local entries: one (n x 10) @ (10 x 27)
        RRR = _MU0_SCALE * np.einsum("ai,bj,cl->ijlabc", R, R, R).reshape(27, 27)
        to_global = SYMMETRIC_EXPANSION @ RRR
        step = max(1, CHUNK // len(self.filaments))  # the kernel's temporaries are (chunk, f)
        for start in range(0, n, step):
            sl = slice(start, min(start + step, n))
            h = self._local_kernel(pts[sl], _hessian_unique)
            H[sl] = (h @ to_global).reshape(-1, 3, 3, 3)
        return H

    # -- tier 3 entry points (validated by Field) -------------------------------------------
    def _B(self, pts):
        return self._evaluate(pts, False)[0]

    def _gradient(self, pts):
        return self._evaluate(pts, True)[1]

    def _B_and_gradient(self, pts):
        return self._evaluate(pts, True)

    def to_magpylib(self):
        """The filaments as a ``magpylib.Collection`` of ``magpylib.current.Circle`` sources.

        Use it to inspect or plot the coils with magpylib (``collection.show()``) or to
        cross-check fields (``collection.getB(points)``, T).
        """
        import magpylib as magpy
        from scipy.spatial.transform import Rotation

        rot = Rotation.from_matrix(self.rotation)
        loops = []
        for z0, a, cur in self.filaments:
            loop = magpy.current.Circle(current=float(cur), diameter=2.0 * a)
            loop.rotate(rot, anchor=(0.0, 0.0, 0.0))
            loop.move(self.center + z0 * self.axis)
            loops.append(loop)
        return magpy.Collection(*loops)

    def ideal(self, zero_tol: float = 1e-12):
        """The ideal field the published models assume: B and gradient at the centre.

        See :func:`coils.ideal.linearize`; a Helmholtz pair's ideal field is uniform
        (``ideal().uniform`` is True, so solvers skip the force path).
        """
        from .ideal import linearize

        return linearize(self, self.center, zero_tol)


def _hessian_unique(local, filaments, nearest):
    """The 10 distinct hessian entries in the local frame (see :func:`loop_hessian_local`)."""
    return loop_hessian_local(local, filaments, nearest, unique_only=True)


def coaxial_parts(field: Field):
    """Yield the coaxial filament groups (coils, pairs) inside ``field`` (sums, scalings)."""
    if isinstance(field, FieldSum):
        for p in field.parts:
            yield from coaxial_parts(p)
    elif isinstance(field, ScaledField):
        yield from coaxial_parts(field.field)
    elif hasattr(field, "filaments"):
        yield field


def winding_mask(field: Field, pts: np.ndarray, margin: float) -> np.ndarray:
    """True where a point is within ``margin`` x radius of a filament or inside a winding."""
    mask = np.zeros(len(pts), dtype=bool)
    for part in coaxial_parts(field):
        local = part.to_local(pts)
        rho = np.hypot(local[:, 0], local[:, 1])
        for z0, a, _ in part.filaments:
            mask |= np.hypot(rho - a, local[:, 2] - z0) < margin * a
        for inside in part._inside_windings(local, closed=True):
            mask |= inside
    return mask
