"""Toy :class:`~coilrod.path.PathProblem` models with closed-form equilibrium paths.

Each toy is ``R(u, s) = Q f(Q^T u, s)``: a scalar function ``f(v, s)`` applied to every
component of ``v = Q^T u`` (per-component parameters broadcast over the components), seen
through a fixed orthogonal ``Q`` (identity by default; a rotation couples the components while
keeping the closed form, ``u = Q v*``).  The tangent ``J = Q diag(f_v) Q^T`` is symmetric with
eigenvalues ``f_v``: the equilibrium is stable iff every ``f_v > 0`` (the potential
``sum F(v_i, s)`` with ``F' = f`` has a minimum there).

The same toy exists batched (``batched=True``: stacks of states, like the planar rod) and one
state at a time (like the FEM model).  Every evaluation is logged (``toy.log``), so tests can
count tangents, chord evaluations and stacked corrections, and read Newton's residual history.

The families (``f``, ``f_v``, ``f_s``) and their closed forms:

* :func:`smooth_cubic` ``a v^3 + b v - c s`` (a >= 0, b > 0): one stable branch, Cardano;
* :func:`pitchfork` ``v^3 - (s - s_c) v - eps``: symmetric (eps = 0) or imperfect bifurcation
  (optionally about a curved trivial branch ``v = amp sin s``);
* :func:`fold` ``v^3 - v + s``: limit points at ``s = +-2/(3 sqrt 3)``, ``v = +-1/sqrt 3``;
* :func:`arctan_problem` ``atan(v) - s``: ``v = tan(s)``; full Newton steps diverge from
  ``|v0| > 1.3917``;
* :func:`linear` ``v - s`` with a tangent scaled by ``tangent_factor`` (an inexact tangent:
  Newton contracts the error by exactly ``1 - 1/tangent_factor`` per iteration).
"""

from __future__ import annotations

import math

import numpy as np

from coilrod.path import Linearization, PathProblem

#: Fold of ``v^3 - v + s``: the scale and the state at the upper limit point.
FOLD_SCALE = 2.0 / (3.0 * math.sqrt(3.0))
FOLD_STATE = 1.0 / math.sqrt(3.0)


class Runaway(RuntimeError):
    """A toy was evaluated more often than its ``budget`` allows."""


class Toy(PathProblem):
    """``R(u, s) = Q f(Q^T u, s)`` (module docstring).

    Parameters
    ----------
    f, f_v, f_s : callable
        ``(v, s) -> ndarray`` on arrays ``v`` of shape (k, n) and ``s`` of shape (k, 1).
    size : int
    batched : bool
    tol : float
        Converged iff ``max |R| <= tol``.
    Q : ndarray, shape (size, size), optional
        Orthogonal coupling (identity if None).
    admissible : callable, optional
        ``(v, s) -> bool ndarray (k,)``; False members are inadmissible (``ok`` False, NaN
        residual), as a coil winding or an inverted element is for a real model.
    stability : {"eigenvalue", "sign"}
        The cheap indicator: the smallest eigenvalue ``min f_v``, or the sign of ``det J``
        (+-1, 0 if singular), as the rod's cheap indicator is.  ``precise`` always gives the
        eigenvalue.
    tangent_factor : float
        :meth:`solve` uses ``tangent_factor * J`` (an inexact tangent).
    max_correction, max_step_change, full_step_growth : float
        The protocol's attributes (defaults of :class:`~coilrod.path.PathProblem`).
    budget : int, optional
        Raise :class:`Runaway` after this many evaluations (a test of a loop that might not
        end fails instead of hanging).
    """

    def __init__(
        self,
        f,
        f_v,
        f_s,
        size=1,
        *,
        batched=True,
        tol=1e-10,
        Q=None,
        admissible=None,
        stability="eigenvalue",
        tangent_factor=1.0,
        max_correction=np.inf,
        max_step_change=np.inf,
        full_step_growth=1.0,
        budget=None,
    ):
        self.f, self.f_v, self.f_s = f, f_v, f_s
        self.size = int(size)
        self.batched = bool(batched)
        self.tol = float(tol)
        self.Q = None if Q is None else np.asarray(Q, float)
        self.admissible = admissible
        self.stability_mode = stability
        self.tangent_factor = float(tangent_factor)
        self.max_correction = max_correction
        self.max_step_change = max_step_change
        self.full_step_growth = full_step_growth
        self.budget = budget
        self.log: list[tuple[np.ndarray, np.ndarray, bool]] = []

    # -- closed-form helpers ------------------------------------------------------------------
    def to_v(self, u):
        u = np.asarray(u, float)
        return u if self.Q is None else u @ self.Q

    def to_u(self, v):
        v = np.asarray(v, float)
        return v if self.Q is None else v @ self.Q.T

    def residual_of(self, u, s):
        """``R(u, s)`` for a state (size,) or stack (k, size), without logging."""
        u2 = np.atleast_2d(np.asarray(u, float))
        s2 = np.broadcast_to(np.asarray(s, float), (len(u2),))[:, None]
        with np.errstate(all="ignore"):
            r = self.to_u(self.f(self.to_v(u2), s2))
        return r.reshape(np.shape(u))

    def eigenvalues(self, u, s):
        u2 = np.atleast_2d(np.asarray(u, float))
        s2 = np.broadcast_to(np.asarray(s, float), (len(u2),))[:, None]
        with np.errstate(all="ignore"):
            return self.f_v(self.to_v(u2), s2)

    # -- the protocol -------------------------------------------------------------------------
    def linearize(self, u, scale, tangent=True):
        single = not self.batched
        U = np.atleast_2d(np.asarray(u, float))
        S = np.broadcast_to(np.asarray(scale, float), (len(U),)).astype(float)
        self.log.append((U.copy(), S.copy(), bool(tangent)))
        if self.budget is not None and len(self.log) > self.budget:
            raise Runaway(f"more than {self.budget} evaluations")
        V = self.to_v(U)
        with np.errstate(all="ignore"):
            fv = self.f(V, S[:, None])
            ok = np.all(np.isfinite(V), axis=1) & np.all(np.isfinite(fv), axis=1)
            if self.admissible is not None:
                ok &= np.asarray(self.admissible(V, S[:, None]), bool)
            R = np.where(ok[:, None], self.to_u(fv), np.nan)
            J = None
            if tangent:
                d = self.f_v(V, S[:, None])
                J = d[:, :, None] * np.eye(self.size)
                if self.Q is not None:
                    J = self.Q @ J @ self.Q.T
        if single:
            return Linearization(U[0], float(S[0]), R[0], bool(ok[0]), None if J is None else J[0])
        return Linearization(U, S, R, ok, J)

    def solve(self, lin, rhs):
        if lin.tangent is None:
            raise ValueError("this linearization carries no tangent")
        J = self.tangent_factor * np.asarray(lin.tangent)
        if not self.batched:
            out = np.linalg.solve(J, rhs)  # raises LinAlgError if singular
            if not np.all(np.isfinite(out)):
                raise np.linalg.LinAlgError("singular toy tangent")
            return out
        rhs = np.atleast_2d(rhs)
        out = np.full(rhs.shape, np.nan)
        for j in range(len(rhs)):
            try:
                out[j] = np.linalg.solve(J[j], rhs[j])
            except np.linalg.LinAlgError:
                pass
        return out

    def d_residual_d_scale(self, lin):
        U = np.atleast_2d(lin.u)
        S = np.atleast_1d(np.asarray(lin.scale, float))
        with np.errstate(all="ignore"):
            out = self.to_u(self.f_s(self.to_v(U), S[:, None]))
        return out[0] if not self.batched else out

    def error(self, lin, du):
        with np.errstate(all="ignore"):
            R = np.atleast_2d(lin.residual)
            e = np.max(np.abs(R), axis=1) / self.tol
            e = np.where(np.atleast_1d(lin.ok), e, np.inf)
        return float(e[0]) if not self.batched else e

    def stability(self, lin, precise=False):
        eig = self.eigenvalues(lin.u, lin.scale)
        if precise or self.stability_mode == "eigenvalue":
            out = eig.min(axis=1)
        else:
            out = np.prod(np.sign(eig), axis=1)
        return float(out[0]) if not self.batched else out

    # -- bookkeeping for tests ----------------------------------------------------------------
    def clear(self):
        self.log.clear()

    def evaluations(self, tangent=None):
        """Number of logged evaluations (with, without or regardless of a tangent)."""
        return sum(1 for _, _, t in self.log if tangent is None or t == tangent)


# -- families -----------------------------------------------------------------------------------
def smooth_cubic(a=1.0, b=1.0, c=1.0, **kw) -> Toy:
    """``a v^3 + b v - c s`` (per component; a >= 0, b > 0): one stable branch."""
    a, b, c = (np.asarray(x, float) for x in (a, b, c))
    size = kw.pop("size", max(a.size, b.size, c.size))
    toy = Toy(
        lambda v, s: a * v**3 + b * v - c * s,
        lambda v, s: 3 * a * v**2 + b + 0 * s,
        lambda v, s: -c + 0 * v,
        size,
        **kw,
    )
    toy.params = (a, b, c)
    toy.exact = lambda s: toy.to_u(cubic_root(a, b, c * np.asarray(s, float)[..., None]))
    return toy


def cubic_root(a, b, q):
    """The real root of ``a v^3 + b v = q`` (a >= 0, b > 0), elementwise, without the
    cancellation of Cardano's formula: ``v = 2 sqrt(p/3) sinh(asinh(3 q' sqrt(3/p) / (2 p)) / 3)``
    with ``p = b/a``, ``q' = q/a`` (``q/b`` where a = 0)."""
    a, b, q = np.broadcast_arrays(*(np.asarray(x, float) for x in (a, b, q)))
    out = np.empty(a.shape)
    lin = a == 0
    out[lin] = q[lin] / b[lin]
    p = b[~lin] / a[~lin]
    qq = q[~lin] / a[~lin]
    r = np.sqrt(p / 3.0)
    out[~lin] = 2 * r * np.sinh(np.arcsinh(qq / (2 * r**3)) / 3.0)
    return out


def pitchfork(s_c=1.0, eps=0.0, amp=0.0, **kw) -> Toy:
    """``w^3 - (s - s_c) w - eps`` with ``w = v - amp sin(s)``: stability ``3 w^2 - (s - s_c)``.

    With ``amp = 0`` the trivial branch of the symmetric pitchfork (eps = 0) is ``v = 0``
    exactly; with ``amp != 0`` it is the curved ``v = amp sin(s)`` (as the symmetric branch
    of a structure deforms before it buckles), and the closed forms hold for ``w``.
    """

    def g(s):
        return amp * np.sin(s)

    def w_s(v, s):
        return v - g(s)

    toy = Toy(
        lambda v, s: w_s(v, s) ** 3 - (s - s_c) * w_s(v, s) - eps,
        lambda v, s: 3 * w_s(v, s) ** 2 - (s - s_c),
        lambda v, s: -amp * np.cos(s) * (3 * w_s(v, s) ** 2 - (s - s_c)) - w_s(v, s),
        **kw,
    )
    toy.s_c, toy.eps, toy.trivial = s_c, eps, g
    return toy


def fold(**kw) -> Toy:
    """``v^3 - v + s``: folds at ``s = +-FOLD_SCALE``."""
    return Toy(
        lambda v, s: v**3 - v + s,
        lambda v, s: 3 * v**2 - 1 + 0 * s,
        lambda v, s: 1 + 0 * v,
        **kw,
    )


def arctan_problem(**kw) -> Toy:
    """``atan(v) - s``: ``v = tan(s)``, always stable."""
    return Toy(
        lambda v, s: np.arctan(v) - s,
        lambda v, s: 1.0 / (1.0 + v**2) + 0 * s,
        lambda v, s: -1.0 + 0 * v,
        **kw,
    )


def linear(**kw) -> Toy:
    """``v - s`` (use ``tangent_factor`` for an inexact tangent)."""
    return Toy(
        lambda v, s: v - s,
        lambda v, s: 1.0 + 0 * v + 0 * s,
        lambda v, s: -1.0 + 0 * v,
        **kw,
    )


def real_roots(coeffs) -> np.ndarray:
    """Sorted real roots of the polynomial ``coeffs`` (highest power first), polished by
    two Newton steps (the companion eigenvalues are accurate to ~1e-15 relative)."""
    p = np.asarray(coeffs, float)
    r = np.roots(p)
    r = np.sort(r[np.abs(r.imag) <= 1e-7 * (1 + np.abs(r.real))].real)
    dp = np.polyder(p)
    for _ in range(2):
        d = np.polyval(dp, r)
        with np.errstate(all="ignore"):
            step = np.where(d != 0, np.polyval(p, r) / d, 0.0)
        r = r - step
    return r


def pitchfork_roots(s, s_c=1.0, eps=0.0) -> np.ndarray:
    """Real roots of ``v^3 - (s - s_c) v - eps``, sorted."""
    return real_roots([1.0, 0.0, -(s - s_c), -eps])


def fold_roots(s) -> np.ndarray:
    """Real roots of ``v^3 - v + s``, sorted (three for |s| < FOLD_SCALE)."""
    return real_roots([1.0, 0.0, -1.0, s])


def rotation(n, seed=0) -> np.ndarray:
    """A fixed orthogonal (n, n) matrix."""
    rng = np.random.default_rng(seed)
    q, r = np.linalg.qr(rng.normal(size=(n, n)))
    return q * np.sign(np.diag(r))


def branch_tolerance(toy: Toy, u_exact, s) -> float:
    """How far a converged state (``max |R| <= tol``) may lie from the exact equilibrium
    ``u_exact``: ``|u - u*| <= |J^-1| |R| <= sqrt(n) tol / min |f_v|`` (max-norm), doubled,
    plus round-off."""
    eig = np.abs(toy.eigenvalues(u_exact, s)).min()
    return 2.0 * math.sqrt(toy.size) * toy.tol / eig + 1e-12 * (1.0 + np.abs(u_exact).max())
