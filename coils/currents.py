"""Minimum-power currents for a target that is linear in them (tier 1: plain linear algebra).

The field and gradient a coil system makes at a point are linear in its channel currents,
``A I = b`` (rows: field and gradient components, columns: channels).  Among the currents that
make the target, the ones that dissipate least copper power ``sum_j w_j I_j^2`` (``w_j`` the
channel resistances) are wanted, within the channel limits ``|I_j| <= u_j``.  With
``J = sqrt(w) I`` and ``A_w = A diag(1 / sqrt(w))`` this is the least-distance problem

    min |J|^2   subject to   A_w J = b,   |J_j| <= sqrt(w_j) u_j,

solved here in three steps:

1. without the limits, the minimum-norm solution ``J0 = pinv(A_w) b`` (truncated SVD); if
   ``A_w J0 != b`` the target lies outside what the channels can make;
2. if ``J0`` respects the limits it is the answer; otherwise a linear program finds the largest
   fraction ``s`` of the target the limits allow (``scipy.optimize.linprog``, HiGHS);
3. if ``s >= 1``, the solutions are ``J = J0 + N z`` (``N`` an orthonormal basis of the null
   space of ``A_w``, orthogonal to ``J0``), so ``|J|^2 = |J0|^2 + |z|^2``: the smallest ``z``
   inside the limits, a least-distance program, is solved exactly by non-negative least squares
   (Lawson & Hanson, *Solving Least Squares Problems*, 1974, ch. 23; ``scipy.optimize.nnls``).

Nothing here validates input or knows about coils; :meth:`coils.CoilSystem.currents_for` does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Solution", "minimum_norm", "largest_fraction", "least_distance", "minimum_power"]

#: Singular values below this fraction of the largest are treated as zero (rank of A_w).
RCOND = 1e-10
#: A target is made if the residual is below this fraction of it.
RESIDUAL_TOL = 1e-9


@dataclass(frozen=True)
class Solution:
    """Outcome of :func:`minimum_power`.

    Attributes
    ----------
    currents : ndarray, shape (m,) or None
        The minimum-power currents (A) within the limits; None if the target cannot be made.
    residual : ndarray, shape (k,)
        ``A I - b`` of the minimum-power currents without limits (zero if the target is made).
    rank : int
        Number of independent target components the channels can make.
    fraction : float or None
        Largest fraction of the target the limits allow (``>= 1`` when it can be made within
        them), or None when the unlimited minimum-power currents already respect the limits.
    unlimited : ndarray, shape (m,)
        The minimum-power currents without limits, A.
    """

    currents: np.ndarray | None
    residual: np.ndarray
    rank: int
    fraction: float | None
    unlimited: np.ndarray

    @property
    def reachable(self) -> bool:
        """True if the channels can make the target (limits aside)."""
        return self.currents is not None or self.fraction is not None


def minimum_norm(A: np.ndarray, b: np.ndarray):
    """Minimum-norm least-squares solution of ``A x = b`` by truncated SVD.

    Returns
    -------
    x : ndarray, shape (m,)
    rank : int
        Singular values above ``RCOND`` times the largest.
    null : ndarray, shape (m, m - rank)
        Orthonormal basis of the null space of ``A``.
    """
    m = A.shape[1]
    if A.size == 0 or not np.any(A):
        return np.zeros(m), 0, np.eye(m)
    U, s, Vt = np.linalg.svd(A, full_matrices=True)
    rank = int(np.sum(s > RCOND * s[0]))
    x = Vt[:rank].T @ ((U[:, :rank].T @ b) / s[:rank])
    return x, rank, Vt[rank:].T


def largest_fraction(A: np.ndarray, b: np.ndarray, bounds: np.ndarray) -> tuple[float, np.ndarray]:
    """Largest ``s`` in [0, 1] such that ``A x = s b`` for some ``|x| <= bounds`` (a linear
    program); returns ``(s, x)``.  ``bounds`` may hold ``inf``."""
    from scipy.optimize import linprog

    k, m = A.shape
    cost = np.zeros(m + 1)
    cost[-1] = -1.0  # maximise s
    # in units of the limits (x = u y, |y| <= 1) and of |b|: HiGHS's feasibility tolerances
    # are absolute (~1e-7), so limits of 1e-12 A and a target of 1e-12 T were "met"
    finite = np.isfinite(bounds)
    unit = np.where(finite, bounds, 1.0)
    size = float(np.linalg.norm(b)) or 1.0
    A_eq = np.hstack([A * unit, -b[:, None]]) / size
    var_bounds = [(-1.0, 1.0) if f else (None, None) for f in finite]
    res = linprog(
        cost,
        A_eq=A_eq,
        b_eq=np.zeros(k),
        bounds=[*var_bounds, (0.0, 1.0)],
        method="highs",
    )
    if res.status != 0:  # cannot happen: x = 0, s = 0 is feasible
        raise RuntimeError(f"the linear program for the current limits failed: {res.message}")
    return float(res.x[-1]) + 0.0, unit * res.x[:-1]  # (+ 0.0: no "-0 %")


def least_distance(G: np.ndarray, h: np.ndarray) -> np.ndarray | None:
    """Shortest ``x`` with ``G x >= h`` (least-distance programming), or None if none exists.

    Lawson & Hanson's reduction to non-negative least squares: with ``E = [G^T; h^T]`` and
    ``f = (0, ..., 0, 1)``, the NNLS residual ``r = E u - f`` is zero if the constraints are
    incompatible, else ``x = -r[:-1] / r[-1]``.  Rows of ``G`` are normalised first.
    """
    from scipy.optimize import nnls

    norms = np.linalg.norm(G, axis=1)
    keep = norms > 0
    if not np.all(h[~keep] <= 0):  # 0 >= h fails: incompatible
        return None
    G, h = G[keep] / norms[keep, None], h[keep] / norms[keep]
    n = G.shape[1]
    if G.shape[0] == 0 or not np.any(h > 0):
        return np.zeros(n)  # x = 0 is feasible
    scale = float(np.abs(h).max())
    E = np.vstack([G.T, (h / scale)[None, :]])
    f = np.zeros(n + 1)
    f[-1] = 1.0
    u, _ = nnls(E, f, maxiter=50 * E.shape[1])
    r = E @ u - f
    if not -r[-1] > 1e-14:  # -r[-1] = |r|^2: zero when incompatible
        return None
    return -scale * r[:-1] / r[-1]


def minimum_power(
    A: np.ndarray, b: np.ndarray, weights: np.ndarray, limits: np.ndarray
) -> Solution:
    """Currents ``I`` (m,) minimising ``sum w I^2`` with ``A I = b`` and ``|I| <= limits``.

    Parameters
    ----------
    A : ndarray, shape (k, m)
        Target components per unit current of each channel.
    b : ndarray, shape (k,)
        Target.
    weights : ndarray, shape (m,)
        Positive weights (channel resistances, ohm).
    limits : ndarray, shape (m,)
        Positive bounds on ``|I|`` (A; inf: none).

    Returns
    -------
    Solution
        See :class:`Solution`; the caller raises with the context it knows.
    """
    root = np.sqrt(weights)
    Aw = A / root
    J0, rank, null = minimum_norm(Aw, b)
    unlimited = J0 / root
    residual = A @ unlimited - b
    norm_b = np.linalg.norm(b)
    if np.linalg.norm(residual) > RESIDUAL_TOL * norm_b:
        return Solution(None, residual, rank, None, unlimited)
    if np.all(np.abs(unlimited) <= limits):
        return Solution(unlimited, residual, rank, None, unlimited)
    fraction, _ = largest_fraction(A, b, limits)
    if fraction < 1.0 - RESIDUAL_TOL:
        return Solution(None, residual, rank, fraction, unlimited)
    u = limits * root
    J = _least_distance_currents(J0, null, u)
    if J is None:
        # the linear program found currents within the limits, but the least-distance
        # program in the exact null space failed: near-singular A (singular values just above
        # RCOND, e.g. a rod that feels only the field at its tip) leaves the exact null space
        # a sliver the limits miss, or the NNLS solver fails.  Directions that make less than
        # RESIDUAL_TOL of the target are dropped from A (a truncated SVD) and tried again.
        J = _truncated_currents(Aw, b, u, norm_b)
    if J is None:
        raise RuntimeError("the least-distance program failed on a feasible current target")
    return Solution(J / root, residual, rank, fraction, unlimited)


def _least_distance_currents(J0, null, u):
    """The scaled currents ``J0 + null z`` closest to ``J0`` within ``|J| <= u``, or None if
    the least-distance program fails."""
    finite = np.isfinite(u)
    if not np.any(finite):
        return J0
    G = np.vstack([null[finite], -null[finite]])
    h = np.concatenate([-u[finite] - J0[finite], -u[finite] + J0[finite]])
    z = least_distance(G, h)
    scale = float(np.abs(u[finite]).max())
    if z is None or np.any(G @ z < h - 1e-9 * scale):
        return None
    return np.clip(J0 + null @ z, -u, u)  # the last ulp at an active limit


def _truncated_currents(Aw, b, u, norm_b):
    """:func:`_least_distance_currents` with the SVD of ``Aw`` truncated at growing relative
    cut-offs (1e-9 ... 1e-6 of the largest singular value), the first whose currents make
    ``b`` to RESIDUAL_TOL; None if none does."""
    U, sv, Vt = np.linalg.svd(Aw, full_matrices=True)
    c = U.T @ b
    for rcond in (1e-9, 1e-8, 1e-7, 1e-6):
        rank = int(np.sum(sv > rcond * sv[0]))
        J0 = Vt[:rank].T @ (c[:rank] / sv[:rank])
        J = _least_distance_currents(J0, Vt[rank:].T, u)
        if J is not None and np.linalg.norm(Aw @ J - b) <= RESIDUAL_TOL * norm_b:
            return J
    return None


def _fmt_mm(point) -> str:
    return "(" + ", ".join(f"{1e3 * v:.4g}" for v in point) + ") mm"


def _show_vec(v) -> str:
    return "(" + ", ".join(f"{x:.3g}" for x in v) + ")"


def currents_for_target(source, point, B, gradient, weights, default_weights, names, words):
    """The minimum-power currents (A, shape (m,)) with which the multi-channel ``source``
    (:class:`coils.CoilSystem`, :class:`coils.MPEM`: ``unit_fields``, ``fixed_field``,
    ``length_scale``, ``_max_current``) makes ``B`` (3,) T and/or ``gradient`` (3, 3) T/m
    at ``point`` (3,) m; a ValueError that tells an unreachable target from one beyond the
    current limits otherwise.  ``weights`` (m,) as given (None: ``default_weights``);
    ``names`` (m,) the channels' names; ``words`` the source's wording of the errors (keys
    ``who``, ``channels``, ``channel``, ``limits``, ``fixed``, ``currents``)."""
    from ._validate import as_array, as_vector

    if B is None and gradient is None:
        raise ValueError("give a target: B (3,) in T and/or gradient (3, 3) in T/m")
    m = len(names)
    if weights is None:
        w = default_weights
    else:
        w = as_vector(weights, "weights", m)
        if not np.all(w > 0):
            raise ValueError(f"weights must be positive; got {w.tolist()}")
    Bu, Gu = source.unit_fields(point)
    Bf, Gf = source.fixed_field(point)
    ell = source.length_scale  # gradient rows in T: comparable with the field rows
    rows, rhs = [], []
    if B is not None:
        rows.append(Bu[0])
        rhs.append(as_vector(B, "B") - Bf[0])
    if gradient is not None:
        target_G = as_array(gradient, "gradient", (3, 3))
        size = float(np.abs(target_G).max())
        asym = float(np.abs(target_G - target_G.T).max())
        trace = float(np.trace(target_G))
        if asym > 1e-9 * size or abs(trace) > 1e-9 * size:
            raise ValueError(
                f"gradient must be symmetric and traceless (curl B = div B = 0 in free "
                f"space); got asymmetry {asym:.3g} T/m and trace {trace:.3g} T/m"
            )
        rows.append(ell * Gu[0].reshape(9, m))
        rhs.append(ell * (target_G - Gf[0]).reshape(9))
    limits = source._max_current
    sol = minimum_power(np.vstack(rows), np.concatenate(rhs), w, limits)
    if sol.currents is not None:
        return sol.currents
    where = _fmt_mm(point)
    if not sol.reachable:
        miss, k = [], 0
        if B is not None:
            miss.append(f"B by {_show_vec(1e3 * sol.residual[:3])} mT")
            k = 3
        if gradient is not None:
            miss.append(f"the gradient by {_show_vec(sol.residual[k:] / ell)} T/m")
        total = (3 if B is not None else 0) + (5 if gradient is not None else 0)
        raise ValueError(
            f"{words['who']} cannot make this target at {where}: its {m} {words['channels']} "
            f"make {sol.rank} of the {total} independent components asked for; the nearest it "
            f"makes misses {' and '.join(miss)}"
        )
    j = int(np.argmax(np.abs(sol.unlimited) / limits))
    raise ValueError(
        f"the target at {where} exceeds the current limits{words['limits']}: at most "
        f"{100 * sol.fraction:.4g} % of the field the {words['channels']} must make (the target "
        f"less {words['fixed']}) can be made within max_current (the {words['currents']} "
        f"currents need {sol.unlimited[j]:.4g} A in {words['channel']} {j} ({names[j]}), "
        f"limit {limits[j]:g} A)"
    )
