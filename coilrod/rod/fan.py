"""A fan of planar rods: one rod in D uniform fields of different directions, one load scale.

A workspace ramps the field magnitude along many directions.  Solved one direction at a time,
each path pays the engine's per-iteration overhead; here the D independent problems are one
:class:`~coilrod.path.PathProblem` whose state stacks the D angle vectors (a block-tridiagonal
Jacobian, factorised by one LAPACK call), so the engine follows all directions together.  The
blocks do not interact: the fan's path is each direction's own path.  Its stability indicator
is the worst block's; a fold or bifurcation of any block is a fold or bifurcation of the fan,
which :func:`coilrod.workspace` detects and re-solves direction by direction.
"""

from __future__ import annotations

import numpy as np

from ..path.protocol import Linearization, PathProblem
from .planar import PlanarRod, RodTangent, _take_tangent

__all__ = ["UniformFan"]


class UniformFan(PathProblem):
    """D copies of the uniform-layout problem ``base``, copy d in the in-plane field
    ``fields[d]`` (T, at scale 1).

    Parameters
    ----------
    base : PlanarRod
        A problem in the uniform layout (its own field is not used).
    fields : ndarray, shape (D, 2)
        In-plane uniform field of each direction at scale 1, T.
    """

    batched = True
    cheap_tangent = True

    def __init__(self, base: PlanarRod, fields: np.ndarray):
        if not base.uniform:
            raise ValueError("a UniformFan needs a problem in the uniform layout")
        self.base = base
        fields = np.asarray(fields, dtype=float)
        self.D, self.n = fields.shape[0], base.n
        self.size = self.D * self.n
        self.fields = fields
        wmu = base.mesh.w[:, None] * base.mu
        bx, by = fields[:, 0:1], fields[:, 1:2]
        self._P1 = wmu[:, 0] * by - wmu[:, 1] * bx  # (D, n)
        self._Q1 = wmu[:, 0] * bx + wmu[:, 1] * by
        self.max_correction = base.max_correction
        self.max_step_change = base.max_step_change
        self.last_failure = ""

    # -- members: (k, D n) states <-> (k D, n) single-rod states --------------------------------
    def members(self, U: np.ndarray) -> np.ndarray:
        """Single-rod states of a stack of fan states (k, D n): shape (k D, n)."""
        return np.atleast_2d(U).reshape(-1, self.n)

    def member_fields(self, k: int) -> np.ndarray:
        """The field (scale 1) of each member of k stacked fan states: (k D, n, 3), T."""
        B = np.zeros((k * self.D, self.n, 3))
        B[..., :2] = np.tile(self.fields, (k, 1))[:, None, :]
        return B

    def straight(self) -> np.ndarray:
        return np.tile(self.base.straight(), self.D)

    def interpolate_to(self, fine: UniformFan, U: np.ndarray) -> np.ndarray:
        """Fan states on the refined mesh of ``fine`` (see :meth:`PlanarRod.interpolate_to`)."""
        k = np.atleast_2d(U).shape[0]
        return self.base.interpolate_to(fine.base, self.members(U)).reshape(k, fine.size)

    # -- the protocol ---------------------------------------------------------------------------
    def linearize(self, u, scale, tangent: bool = True) -> Linearization:
        U = np.atleast_2d(np.asarray(u, dtype=float))
        k = U.shape[0]
        S = np.broadcast_to(np.asarray(scale, dtype=float), (k,)).copy()
        with np.errstate(all="ignore"):
            R, R1, parts = self.base._uniform(
                self.members(U),
                np.repeat(S, self.D),
                tangent,
                np.tile(self._P1, (k, 1)),
                np.tile(self._Q1, (k, 1)),
            )
            ok_m = np.all(np.isfinite(R), axis=1)
        tan = None
        if tangent:
            tan = RodTangent(k * self.D, self.n, True, parts, R1)
            tan.bad |= ~ok_m
        lin = Linearization(
            u=U,
            scale=S,
            residual=R.reshape(k, self.size),
            ok=ok_m.reshape(k, self.D).all(axis=1),
            tangent=tan,
        )
        lin.load_rate = R1.reshape(k, self.size)
        return lin

    def member_linearization(self, lin: Linearization) -> Linearization:
        """The fan linearization as one of its k D single-rod members."""
        out = Linearization(
            u=self.members(lin.u),
            scale=np.repeat(lin.scale, self.D),
            residual=self.members(lin.residual),
            ok=np.repeat(lin.ok, self.D),
            tangent=lin.tangent,
        )
        out.load_rate = self.members(lin.load_rate)
        out.uniform_fields = self.member_fields(lin.u.shape[0])[:, 0, :]
        return out

    def solve(self, lin: Linearization, rhs: np.ndarray) -> np.ndarray:
        k = lin.u.shape[0]
        return lin.tangent.solve(self.members(rhs)).reshape(k, self.size)

    def d_residual_d_scale(self, lin: Linearization) -> np.ndarray:
        return lin.load_rate

    def take(self, lin: Linearization, rows) -> Linearization:
        rows = np.asarray(rows, dtype=int)
        out = Linearization(
            u=lin.u[rows], scale=lin.scale[rows], residual=lin.residual[rows], ok=lin.ok[rows]
        )
        out.load_rate = lin.load_rate[rows]
        if lin.tangent is not None:
            members = (rows[:, None] * self.D + np.arange(self.D)).ravel()
            out.tangent = _take_tangent(lin.tangent, members)
        return out

    def error(self, lin: Linearization, du) -> np.ndarray:
        k = lin.u.shape[0]
        return self.base.error(self.member_linearization(lin), None).reshape(k, self.D).max(1)

    def step_limit(self, u, du):
        return self.base.step_limit(u, du)

    def distance(self, du):
        return self.base.distance(du)

    def arclength_weights(self) -> np.ndarray:
        return np.full(self.size, 1.0 / self.size)

    def stability(self, lin: Linearization, precise: bool = False) -> np.ndarray:
        """The worst member's in-plane stability (det sign, or smallest eigenvalue with
        ``precise``): what the engine steps by.  The fan's path is the planar branches'; the
        3D stability of each state (out-of-plane modes) is :meth:`member_stability`, read
        once at the requested states -- locating every member's out-of-plane bifurcation
        would only cut the fan's steps."""
        return self.branch_stability(lin, precise)

    def member_stability(self, lin: Linearization, precise: bool = False) -> np.ndarray:
        """Stability of every member, shape (k D,) (see :meth:`PlanarRod.stability`)."""
        return np.asarray(self.base.stability(self.member_linearization(lin), precise), float)

    def branch_stability(self, lin: Linearization, precise: bool = False) -> np.ndarray:
        """The worst member's in-plane stability (:meth:`PlanarRod.branch_stability`)."""
        k = lin.u.shape[0]
        mu = self.base.branch_stability(self.member_linearization(lin), precise)
        return np.asarray(mu, float).reshape(k, self.D).min(axis=1)

    def near_fold(self, lin: Linearization) -> bool:
        try:
            mu = float(np.min(self.branch_stability(lin, precise=True)))
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            return False
        return bool(mu < 0.05 * self.base.mu0)
