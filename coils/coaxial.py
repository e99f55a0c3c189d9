"""Coaxial groups of circular filaments (tier 2: frames, winding checks, near and far zones).

A :class:`CoaxialCoils` holds filaments sharing one axis and one centre; a single coil, a
Helmholtz pair and a Maxwell pair are all coaxial groups, so a pair is evaluated in one local
frame with one rotation, in one compiled pass over the points (:mod:`coils._compiled`): the
filaments' closed forms near the group (:mod:`coils.loop`), the group's multipole series beyond
``coils.multipole.SWITCH`` times its radius (:mod:`coils.multipole`).  numba is imported when a
group is first evaluated, not when :mod:`coils` is imported.
"""

from __future__ import annotations

import math
from collections.abc import Sized

import numpy as np
from scipy.constants import mu_0

from ._immutable import kernel_input
from ._numba_cache import Rental
from ._validate import as_array, as_axis, as_vector
from .field import Field, FieldSum, ScaledField

__all__ = ["CoaxialCoils", "frame_from_axis", "coaxial_parts", "winding_mask"]

#: A point closer than this fraction of the radius to a filament is "on the winding".
ON_WIRE_TOL = 1e-9

# flags of the compiled pass (coils._compiled)
_WANT_B, _WANT_G, _WANT_H = 1, 2, 4
_NO_B = np.empty((0, 3))
_NO_G = np.empty((0, 9))
_NO_H = np.empty((0, 27))


#: Estimated CPU seconds of numpy passes after which the compiled pass is used (ski rental:
#: about what compiling it costs in a fresh environment, README "Cold start"); 0 compiles at
#: the first evaluation, ``math.inf`` never compiles except for points the numpy pass leaves.
COMPILE_AFTER = 3.0
# measured cost of one numpy pass: per call and per point x filament (B, gradient, hessian)
_NUMPY_CALL_S, _NUMPY_POINT_S = 5e-4, 1e-6


def _kernel():
    """The compiled pass's dispatcher (imports numba and :mod:`coils._compiled`)."""
    from . import _compiled

    return _compiled.coaxial_field


#: The ski rental of the compiled pass (:class:`coils._numba_cache.Rental`).
_rental = Rental(__name__, _kernel)


def _compiled_pays(work: int) -> bool:
    """True if the compiled pass should evaluate ``work`` = points x filaments: it is compiled
    (or on disk in numba's cache at the first evaluation of the process), or the numpy passes
    so far plus this one would cost more than :data:`COMPILE_AFTER`; else the numpy pass's
    estimated cost (s of CPU) is charged."""
    return _rental.rent(_NUMPY_CALL_S + _NUMPY_POINT_S * work)


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
    axis : {"x", "y", "z"}, optionally signed ("-y"), or array-like, shape (3,)
        Common axis direction (a non-zero vector, normalised).
    center : array-like, shape (3,)
        Common centre, m.
    windings : sequence of (z0, radius, width, height), optional
        Winding cross-sections (m) inside which the field is not evaluated.

    Notes
    -----
    B, the gradient and the hessian are exact: closed forms of each filament near the group
    (elliptic integrals near the wires, their hypergeometric power series near the axis and
    farther out; :mod:`coils.loop`) and the group's multipole series beyond
    ``coils.multipole.SWITCH`` times the group radius (:mod:`coils.multipole`), to about
    ``1e-15`` relative at any distance.  One compiled pass over the points computes whichever
    of B, gradient and hessian is asked for (:mod:`coils._compiled`); its data are derived
    from the arrays of the object once, so the object is immutable (:mod:`coils._immutable`):
    its attributes cannot be assigned, its arrays (``filaments``, ``axis``, ``center``,
    ``rotation``, ``windings``) are read-only, and ``replace(**changes)`` gives a changed copy.
    """

    _immutable = True
    _caches = ("_kernel_args",)

    def __init__(self, filaments, axis="z", center=(0.0, 0.0, 0.0), windings=()):
        fil = as_array(filaments, "filaments", ("f", 3)).copy()
        if fil.shape[0] == 0:
            raise ValueError("filaments must have shape (f, 3) with f >= 1; got (0, 3)")
        if np.any(fil[:, 1] <= 0):
            raise ValueError(f"filament radii must be positive; got {fil[:, 1].tolist()}")
        self.filaments = fil
        self.axis = as_axis(axis)
        self.center = as_vector(center, "center").copy()
        self.rotation = frame_from_axis(self.axis)
        if isinstance(windings, Sized) and len(windings) == 0:
            self.windings = np.zeros((0, 4))
        else:
            self.windings = as_array(windings, "windings", ("w", 4)).copy()
            if np.any(self.windings[:, 1:] <= 0):
                raise ValueError(
                    "windings (z0, radius, width, height) must have positive radius, width and "
                    f"height; got {self.windings.tolist()}"
                )
        for arr in (self.filaments, self.axis, self.center, self.rotation, self.windings):
            arr.setflags(write=False)
        self._kernel_args = None

    @property
    def length_scale(self) -> float:
        return float(np.min(self.filaments[:, 1]))

    @property
    def radius_bound(self) -> float:
        """Largest distance (m) from the centre to a filament or a winding cross-section: the
        multipole series of the group converges beyond it."""
        z0, a = self.filaments[:, 0], self.filaments[:, 1]
        d = float(np.max(np.hypot(a, z0)))
        for wz, wa, w, h in self.windings:
            d = max(d, math.hypot(wa + 0.5 * h, abs(wz) + 0.5 * w))
        return d

    # -- tier 2: frames and singularities ------------------------------------------------------
    def to_local(self, pts: np.ndarray) -> np.ndarray:
        """Global points (n, 3) m -> coordinates in the coil frame (axis = local z)."""
        return (pts - self.center) @ self.rotation

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

    def _prepare(self):
        """Arguments of the compiled kernel (built on first use, then cached on the object)."""
        from . import _compiled
        from .multipole import SWITCH, group_moments

        d = self.radius_bound
        e = math.frexp(d)[1]  # lengths in units of L = 2^e (exact scaling)
        inv_L = math.ldexp(1.0, -e)
        z0, a, cur = (self.filaments[:, j] for j in range(3))
        a_s = a * inv_L
        fil = np.column_stack(
            [z0 * inv_L, a_s, mu_0 * cur * a_s * a_s, mu_0 * cur / (2 * math.pi), 1.0 / a_s**2]
        )
        wind = (
            np.column_stack(
                [
                    self.windings[:, 0],
                    self.windings[:, 1],
                    self.windings[:, 2] / 2,
                    self.windings[:, 3] / 2,
                ]
            )
            * inv_L
        )
        moments = group_moments(self.filaments, mu_0, d)
        with np.errstate(over="ignore"):  # 1/L^3 of an absurd radius overflows: caught per point
            scales = np.ldexp(1.0, np.array([-e, -e, -2 * e, -3 * e]))
        params = np.array([*scales, (SWITCH * d) ** 2, d, moments.kappa, ON_WIRE_TOL**2])
        # read-only inputs (kernel_input): one compiled kernel whatever the arrays' flags
        args = (
            kernel_input(self.center),
            kernel_input(self.axis),
            kernel_input(fil),
            kernel_input(wind.reshape(-1, 4)),
            kernel_input(moments.beta),
            moments.n0,
            kernel_input(params),
        )
        self._set_cache("_kernel_args", (_compiled.coaxial_field, args, 3 + len(self.windings)))
        return self._kernel_args

    def _run(self, pts, flags, factor, B, G, H):
        """One pass: add ``factor`` times the field to B (n, 3), G (n, 9), H (n, 27); raise
        ValueError naming the first point on or inside a winding.  The numpy near-zone pass
        while compiling does not pay yet (:func:`_compiled_pays`), else the compiled one."""
        kernel, args, n_err = self._kernel_args or self._prepare()
        pts = kernel_input(pts)
        if not _compiled_pays(pts.shape[0] * self.filaments.shape[0]):
            from ._vectorised import near_pass

            center, axis, fil, wind, _, _, params = args
            if near_pass(pts, center, axis, fil, wind, params, flags, factor, B, G, H):
                return
        _rental.buy()  # compiled now anyway: the numpy pass would only cost more
        err = np.empty(n_err, dtype=np.int64)
        if kernel(pts, *args, flags, factor, B, G, H, err):
            self._raise_point_error(err)

    def _raise_point_error(self, err: np.ndarray) -> None:
        if err[0] >= 0:
            raise ValueError(
                f"point {err[0]} lies on a coil winding (within {ON_WIRE_TOL:g} radius of a "
                f"filament): the field is singular there"
            )
        for (_z0, a, w, h), k in zip(self.windings, err[3:], strict=True):
            if k >= 0:
                raise ValueError(
                    f"point {k} lies inside a coil winding ({w} m x {h} m section at "
                    f"radius {a} m): the filament model does not hold there"
                )
        if err[2] >= 0:
            raise ValueError(
                f"point {err[2]} is too far from the coil centre {self.center.tolist()} m: its "
                f"coordinates relative to it overflow double precision"
            )
        raise ValueError(
            f"the field at point {err[1]} overflows double precision (coil dimensions or "
            f"currents out of range)"
        )

    def evaluator(self):
        """:meth:`coils.field.Field.evaluator`: the compiled pass called directly once it is
        compiled (no validation, no per-call dispatch; the points are made read-only), the
        ski rental's numpy pass before (:meth:`_run`); the same numbers either way."""
        kernel, args, n_err = self._kernel_args or self._prepare()
        raise_error = self._raise_point_error
        run = self._run
        both, all3 = _WANT_B | _WANT_G, _WANT_B | _WANT_G | _WANT_H

        def fields(pts, hessian):
            n = pts.shape[0]
            B = np.zeros((n, 3))
            G = np.zeros((n, 9))
            H = np.zeros((n, 27)) if hessian else _NO_H
            flags = all3 if hessian else both
            if _rental.ready:
                pts.flags.writeable = False  # (one compiled version: read-only inputs)
                err = np.empty(n_err, dtype=np.int64)
                if kernel(pts, *args, flags, 1.0, B, G, H, err):
                    raise_error(err)
            else:
                run(pts, flags, 1.0, B, G, H)
            return B, G.reshape(n, 3, 3), H.reshape(n, 3, 3, 3) if hessian else None

        return fields

    def _evaluate(self, pts, flags: int):
        """New arrays B (n, 3) T, G (n, 3, 3) T/m, H (n, 3, 3, 3) T/m^2 as asked by ``flags``
        (None for the others)."""
        n = pts.shape[0]
        B = np.zeros((n, 3)) if flags & _WANT_B else _NO_B
        G = np.zeros((n, 9)) if flags & _WANT_G else _NO_G
        H = np.zeros((n, 27)) if flags & _WANT_H else _NO_H
        self._run(pts, flags, 1.0, B, G, H)
        return (
            B if flags & _WANT_B else None,
            G.reshape(n, 3, 3) if flags & _WANT_G else None,
            H.reshape(n, 3, 3, 3) if flags & _WANT_H else None,
        )

    def _add_to(self, pts, B, G, H, factor):
        n = pts.shape[0]
        flags = 0
        if B is None:
            B = _NO_B
        else:
            flags |= _WANT_B
        if G is None:
            G = _NO_G
        else:
            flags |= _WANT_G
            G = G.reshape(n, 9)
        if H is None:
            H = _NO_H
        else:
            flags |= _WANT_H
            H = H.reshape(n, 27)
        self._run(pts, flags, factor, B, G, H)

    # -- tier 3 entry points (validated by Field) -------------------------------------------
    def _B(self, pts):
        return self._evaluate(pts, _WANT_B)[0]

    def _gradient(self, pts):
        return self._evaluate(pts, _WANT_G)[1]

    def _B_and_gradient(self, pts):
        return self._evaluate(pts, _WANT_B | _WANT_G)[:2]

    def _hessian(self, pts):
        return self._evaluate(pts, _WANT_H)[2]

    def _B_gradient_hessian(self, pts):
        return self._evaluate(pts, _WANT_B | _WANT_G | _WANT_H)

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
