"""What the discrete rods (planar and spatial) share as path problems: the field at the nodes
(member by member where a trial state cannot be evaluated), the conveniences of the protocol,
member slicing and the fold diagnostics."""

from __future__ import annotations

import numpy as np

from ..path.protocol import Linearization, PathProblem

#: Multiple of eps times the size of a residual's terms below which it is round-off (the
#: planar and spatial rods' error floor, and the compiled mixed corrector's).
_FLOOR = 32.0
_EPS = float(np.finfo(float).eps)

__all__ = ["DiscreteRod"]


class DiscreteRod(PathProblem):
    """Base of :class:`~coilrod.rod.planar.PlanarRod` and :class:`~coilrod.rod.spatial.SpatialRod`.

    Subclasses set ``field``, ``linear``, ``n``, ``last_failure``, ``_mu0`` and provide
    ``points`` (positions in units of L -> m), ``linearize``, ``stability`` and ``straight``.
    """

    def _field(self, x: np.ndarray, hessian: bool):
        """B (k n, 3) T, G (k n, 3, 3) T/m and H (k n, 3, 3, 3) T/m^2 (None where not needed)
        at the positions x (k, n, 2 or 3) relative to the clamp (units of L); raises ValueError
        from the field."""
        pts = self.points(x).reshape(-1, 3)
        if hessian and not self.linear:
            return self.field.B_gradient_hessian(pts)
        B, G = self.field.B_and_gradient(pts)
        return B, G, None

    def _field_by_member(self, x: np.ndarray, hessian: bool):
        """Like :meth:`_field`, but members whose field cannot be evaluated get NaN (and the
        field's message is kept in ``last_failure``)."""
        try:
            with np.errstate(all="ignore"):
                return self._field(x, hessian)
        except ValueError as exc:
            self.last_failure = f"the field could not be evaluated at the trial states ({exc})"
        k, n = x.shape[0], self.n
        B = np.full((k, n, 3), np.nan)
        G = np.full((k, n, 3, 3), np.nan)
        H = np.full((k, n, 3, 3, 3), np.nan) if hessian and not self.linear else None
        for j in range(k):
            try:
                with np.errstate(all="ignore"):
                    Bj, Gj, Hj = self._field(x[j : j + 1], hessian)
            except ValueError as exc:
                self.last_failure = f"the field could not be evaluated at the trial states ({exc})"
                continue
            B[j], G[j] = Bj, Gj
            if H is not None:
                H[j] = Hj
        return (
            B.reshape(-1, 3),
            G.reshape(-1, 3, 3),
            None if H is None else H.reshape(-1, 3, 3, 3),
        )

    @staticmethod
    def _stack(u, scale) -> tuple[np.ndarray, np.ndarray]:
        """States (k, size) and scales (k,) of one state or a stack (a scalar scale serves
        every member)."""
        U = np.asarray(u, dtype=float)
        if U.ndim == 1:
            U = U[None]
        S = np.asarray(scale, dtype=float)
        if S.shape != (U.shape[0],):
            S = np.full(U.shape[0], float(S)) if S.ndim == 0 else S.reshape(U.shape[0])
        return U, S

    def solve(self, lin: Linearization, rhs: np.ndarray) -> np.ndarray:
        return lin.tangent.solve(np.atleast_2d(rhs))

    def d_residual_d_scale(self, lin: Linearization) -> np.ndarray:
        return lin.load_rate

    def take(self, lin: Linearization, rows) -> Linearization:
        """Members ``rows`` of a stacked linearization (the factorisation is sliced, not
        recomputed: the stacked Jacobian is block diagonal)."""
        rows = np.asarray(rows, dtype=int)
        out = Linearization(
            u=lin.u[rows], scale=lin.scale[rows], residual=lin.residual[rows], ok=lin.ok[rows]
        )
        out.load_rate = lin.load_rate[rows]
        out.tangent = None if lin.tangent is None else lin.tangent.take(rows)
        return out

    def residual(self, u: np.ndarray, scale) -> np.ndarray:
        """``R(u, scale)`` with the shape of ``u`` ((size,) or (k, size))."""
        return self.linearize(u, scale, tangent=False).residual.reshape(np.shape(u))

    def near_fold(self, lin: Linearization) -> bool:
        """True if the smallest second-variation eigenvalue is below 5 % of the straight
        rod's: failing load steps there mean the branch turns back (a limit point)."""
        try:
            mu = float(self.branch_stability(lin, precise=True)[0])
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            return False
        return bool(mu < 0.05 * self.mu0)

    def fold_hint(self, lin: Linearization) -> str:
        """Say whether the state of ``lin`` is close to a limit point (fold)."""
        try:
            mu = float(self.branch_stability(lin, precise=True)[0])
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            return ""
        if not np.isfinite(mu):
            return ""
        if mu < 0.05 * self.mu0:
            return (
                f"; the smallest eigenvalue of the second variation there is {mu:.3g}: "
                "a limit point (fold), the rod snaps through beyond it -- trace it with "
                "coilrod.trace_rod"
            )
        return f"; smallest second-variation eigenvalue there {mu:.3g}"

    @property
    def mu0_stability(self) -> float:
        """Smallest eigenvalue of :meth:`stability` (the planar rod's 3D figure included) at
        the straight unloaded rod."""
        cached = getattr(self, "_mu0_stability", None)
        if cached is None:
            lin = self.linearize(self.straight(), 0.0)
            cached = self._mu0_stability = float(self.stability(lin, precise=True)[0])
        return cached

    @property
    def mu0(self) -> float:
        """Smallest second-variation eigenvalue of the straight unloaded rod (~ pi^2 / 4)."""
        if self._mu0 is None:
            lin = self.linearize(self.straight(), 0.0)
            self._mu0 = float(self.branch_stability(lin, precise=True)[0])
        return self._mu0
