"""Compiled Newton corrector of the planar rod in a uniform field (numba, cached on disk).

One call runs :func:`coilrod.path.corrector.newton` to the end for every member of a stack of
states of :class:`~coilrod.rod.planar.PlanarRod`'s uniform layout (node angles only): the
residual and tridiagonal Jacobian (``PlanarRod._uniform``), the factorisation and solve
(LAPACK's ``dgttrf``/``dgttrs``, partial pivoting, transcribed operation for operation), the
step limit, the backtracking line search, the error and the stagnation test, with the same
arithmetic in the same order.  The members of a stack are independent (the corrector's
batched iteration gives each its own step, backtracking and convergence; a tridiagonal
Jacobian has no chord mode), so the kernel iterates them one after the other.  The states
agree with the numpy path to round-off of the cosines and sines (libm's here, numpy's there:
they may differ in the last bit), asserted in ``tests/test_rod_planar_newton.py``.

Ski rental (README, "Cold start"): the numpy corrector runs until its estimated cost reaches
:data:`COMPILE_AFTER` (about what compiling this kernel costs on a cold cache) or numba's
cache holds it; the compiled one from then on.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from coils._numba_cache import Rental

__all__ = ["COMPILE_AFTER", "compiled_pays", "charge", "newton_uniform"]

#: Estimated CPU seconds of numpy Newton iterations after which the compiled corrector is used
#: (ski rental); 0 compiles at the first call, ``math.inf`` never.
COMPILE_AFTER = 4.0
# measured cost of the numpy corrector: per call and per iteration of one member
_NUMPY_CALL_S, _NUMPY_ITER_S = 5e-5, 1.2e-4
#: The ski rental of the compiled corrector (:class:`coils._numba_cache.Rental`).
_rental = Rental(__name__, lambda: _newton)


def compiled_pays() -> bool:
    """True if the compiled corrector should run: it is compiled (or in numba's cache), or the
    numpy corrector has cost :data:`COMPILE_AFTER` so far."""
    return _rental.pays()


def charge(iterations) -> None:
    """Charge the estimated cost (s of CPU) of a numpy corrector call of ``iterations`` (per
    member) to the ski rental."""
    _rental.charge(_NUMPY_CALL_S + _NUMPY_ITER_S * (float(np.sum(iterations)) + 1.0))


def newton_uniform(problem, U, S, opts, stability: bool = True):
    """Newton's method for the stack ``U`` (k, n) (float, C order: iterated in place) at scales
    ``S`` (k,) of a uniform-layout
    :class:`~coilrod.rod.planar.PlanarRod` with :class:`~coilrod.path.corrector.NewtonOptions`
    ``opts``; ``stability`` False skips the out-of-plane Cholesky test (``M[:, 2]`` stays 0).

    Returns
    -------
    U : ndarray, shape (k, n)
        Last iterates (the argument).
    F : ndarray, shape (4, k, n)
        At ``U``: the residual, its load derivative dR/dscale, the Jacobian's diagonal and the
        path rate ``du/dscale = -J^-1 dR/dscale`` (NaN rows where J is singular).
    M : ndarray, shape (k, 5)
        Per member: the error (inf where inadmissible), the sign of det J (0 where singular or
        inadmissible; ``RodTangent.det_signs``), 1 where a Cholesky factorisation proves the
        out-of-plane block of the 3D second variation positive definite (as
        ``out_of_plane._positive_definite``; computed with the problem's out-of-plane block
        only), 1 where the residual is finite, and the iterations.
    """
    k, n = U.shape
    arrays, par = _constants(problem)
    if not stability and par[8] != 0.0:
        par = par.copy()
        par[8] = 0.0
    ipar = np.array([opts.max_iter, opts.backtracks, opts.stagnation])
    F = np.empty((4, k, n))
    M = np.zeros((k, 5))
    _newton(U, S, *arrays, par, ipar, F, M)
    return U, F, M


def _constants(p):
    """The problem's arrays and numbers (9,) that the kernel reads (cached on it)."""
    cached = p.__dict__.get("_newton_constants")
    if cached is not None:
        return cached
    n = p.n
    seg = max(n - 1, 1)  # (segment arrays padded for a single node)
    inv_h, floor_bend = np.zeros(seg), np.zeros(seg)
    inv_h[: n - 1], floor_bend[: n - 1] = p._inv_h, p._floor_bend
    arrays = tuple(
        np.ascontiguousarray(a, dtype=float)
        for a in (p._P1, p._Q1, p._inv_w, p._k_diag, p.mu, p.mesh.w, inv_h, floor_bend)
    )
    oop = p.out_of_plane
    stab = oop is not None
    k1, k2 = (float(oop.stiffness[0]), float(oop.stiffness[1])) if stab else (1.0, 1.0)
    bx, by = (float(oop._b[0]), float(oop._b[1])) if stab else (0.0, 0.0)
    growth, rot = float(p.full_step_growth), float(p.max_rotation)
    par = np.array([p.theta0, p.tol, rot, growth, k1, k2, bx, by, 1.0 if stab else 0.0])
    p._newton_constants = (arrays, par)
    return arrays, par


@nb.njit(cache=True)
def _linearize(th, s, P1, Q1, inv_h, k_diag, theta0, R, R1, d):
    """Residual R, load derivative R1 and Jacobian diagonal d of one state (PlanarRod._uniform);
    False if the residual is not finite."""
    n = th.shape[0]
    for i in range(n):
        c = math.cos(th[i])
        si = math.sin(th[i])
        r1 = si * Q1[i] - c * P1[i]
        if i == 0:
            r1 = 0.0
        R1[i] = r1
        R[i] = s * r1
        d[i] = s * (c * Q1[i] + si * P1[i]) + k_diag[i]
    for i in range(1, n):
        R[i] += (th[i] - th[i - 1]) * inv_h[i - 1]
    for i in range(n - 1):
        R[i] -= (th[i + 1] - th[i]) * inv_h[i]
    R[0] = th[0] - theta0
    d[0] = 1.0
    ok = True
    for i in range(n):
        if not math.isfinite(R[i]):
            ok = False
    return ok


@nb.njit(cache=True)
def _error(th, R, inv_w, floor_bend, tol, ok):
    """PlanarRod.error of the uniform layout (inf where not ok or not finite)."""
    if not ok:
        return math.inf
    n = th.shape[0]
    big = 0.0
    for i in range(n):
        a = abs(th[i])
        if a > big or a != a:
            big = a
    size_th = 1.0 + big
    e = -math.inf
    for i in range(1, n):
        v = abs(R[i]) * inv_w[i] / (tol + size_th * floor_bend[i - 1])
        if v > e or v != v:
            e = v
    if not math.isfinite(e):
        return math.inf
    return e


@nb.njit(cache=True)
def _solve(d0, off_low, off_up, rhs, x, dl, d, du, du2, ipiv):
    """x = J^-1 rhs for the tridiagonal J (diagonal d0, sub-diagonal off_low, super-diagonal
    off_up), by LAPACK's dgttrf + dgttrs (no transpose, one right-hand side) step by step;
    False if a pivot is zero or a value not finite."""
    n = d0.shape[0]
    for i in range(n):
        d[i] = d0[i]
        ipiv[i] = i
        if not math.isfinite(d[i]):
            return False
    for i in range(n - 1):
        dl[i] = off_low[i]
        du[i] = off_up[i]
        du2[i] = 0.0
    for i in range(n - 1):
        if abs(d[i]) >= abs(dl[i]):
            if d[i] != 0.0:
                fact = dl[i] / d[i]
                dl[i] = fact
                d[i + 1] = d[i + 1] - fact * du[i]
        else:
            fact = d[i] / dl[i]
            d[i] = dl[i]
            dl[i] = fact
            temp = du[i]
            du[i] = d[i + 1]
            d[i + 1] = temp - fact * d[i + 1]
            if i < n - 2:
                du2[i] = du[i + 1]
                du[i + 1] = -fact * du[i + 1]
            ipiv[i] = i + 1
    for i in range(n):
        if d[i] == 0.0:
            return False
    for i in range(n):
        x[i] = rhs[i]
    for i in range(n - 1):  # L x = b
        ip = ipiv[i]
        temp = x[i + 1 - ip + i] - dl[i] * x[ip]
        x[i] = x[ip]
        x[i + 1] = temp
    x[n - 1] = x[n - 1] / d[n - 1]  # U x = b
    if n > 1:
        x[n - 2] = (x[n - 2] - du[n - 2] * x[n - 1]) / d[n - 2]
    for i in range(n - 3, -1, -1):
        x[i] = (x[i] - du[i] * x[i + 1] - du2[i] * x[i + 2]) / d[i]
    for i in range(n):
        if not math.isfinite(x[i]):
            return False
    return True


@nb.njit(cache=True)
def _odd_definite(th, s, k1, k2, bx, by, mu, inv_h, w):
    """Whether a Cholesky factorisation (LAPACK's dpbtf2, upper) proves the out-of-plane block
    of the 3D second variation at the planar state ``th`` positive definite: the symmetric
    band of ``OutOfPlane.odd_blocks(..., band=True)`` (kd = 3), assembled here."""
    n = th.shape[0]
    nf = n - 1
    m = 2 * nf
    if nf < 1:
        return True
    A = np.zeros((4, m))
    Ap = np.empty(nf)
    Am = np.empty(nf)
    q = np.empty(nf)
    pz = np.empty(nf)
    for f in range(nf):  # segment f (nodes f, f + 1), free node f + 1
        b = 0.5 * (th[f + 1] - th[f])
        sb = math.sin(b)
        a = b * math.cos(b) / sb if sb != 0.0 else 1.0
        aa = a * a
        bb = b * b
        alpha = (0.5 * (k1 + k2) * (aa + bb) + a - aa - bb) * inv_h[f]
        zr = aa - bb
        zi = -2.0 * a * b
        c = math.cos(th[f + 1])
        si = math.sin(th[f + 1])
        c2 = c * c - si * si
        s2 = 2.0 * c * si
        fac = 0.5 * (k1 - k2) * inv_h[f]
        r = fac * (zr * c2 - zi * s2)
        q[f] = fac * (zr * s2 + zi * c2)
        pz[f] = 2.0 * b * inv_h[f]
        Ap[f] = alpha + r
        Am[f] = alpha - r
        mx = c * mu[f + 1, 0] - si * mu[f + 1, 1]
        my = si * mu[f + 1, 0] + c * mu[f + 1, 1]
        sw = s * w[f + 1]
        A[3, 2 * f] = sw * (my * by) + Ap[f]
        A[3, 2 * f + 1] = sw * (mx * bx) + Am[f]
        A[2, 2 * f + 1] = q[f] - 0.5 * sw * (mx * by + my * bx)
    for f in range(nf - 1):
        A[3, 2 * f] += Ap[f + 1]
        A[3, 2 * f + 1] += Am[f + 1]
        A[2, 2 * f + 1] += q[f + 1]
        A[2, 2 * f + 2] = 0.5 * pz[f + 1] - q[f + 1]
        A[1, 2 * f + 2] = -Ap[f + 1]
        A[1, 2 * f + 3] = -Am[f + 1]
        A[0, 2 * f + 3] = -q[f + 1] - 0.5 * pz[f + 1]
    for r in range(4):
        for col in range(m):
            if not math.isfinite(A[r, col]):
                return False
    for j in range(m):  # A[3 + i - col, col] holds entry (i, col), i <= col
        ajj = A[3, j]
        if not ajj > 0.0:
            return False
        ajj = math.sqrt(ajj)
        A[3, j] = ajj
        kn = min(3, m - 1 - j)
        for p in range(1, kn + 1):
            A[3 - p, j + p] *= 1.0 / ajj
        for p in range(1, kn + 1):
            x = -A[3 - p, j + p]
            for i in range(1, p + 1):
                A[3 + i - p, j + p] += A[3 - i, j + i] * x
    return True


@nb.njit(cache=True)
def _newton(U, S, P1, Q1, inv_w, k_diag, mu, w, inv_h, floor_bend, par, ipar, F, M):
    """The compiled corrector (see :func:`newton_uniform`): U (k, n) in place, F and M out."""
    k, n = U.shape
    theta0, tol, max_rotation, growth = par[0], par[1], par[2], par[3]
    k1, k2, bx, by, stab = par[4], par[5], par[6], par[7], par[8] != 0.0
    max_iter, backtracks, stagnation = ipar[0], ipar[1], ipar[2]
    R, R1, D, rate = F[0], F[1], F[2], F[3]
    off_low = np.zeros(max(n - 1, 1))
    off_up = np.zeros(max(n - 1, 1))
    for i in range(n - 1):
        off_low[i] = -inv_h[i]
        off_up[i] = -inv_h[i]
    if n > 1:
        off_up[0] = 0.0  # row 0 is the clamp condition
    rhs = np.empty(n)
    dU = np.empty(n)
    trial = np.empty(n)
    tR = np.empty(n)
    tR1 = np.empty(n)
    td = np.empty(n)
    dl = np.empty(max(n - 1, 1))
    du = np.empty(max(n - 1, 1))
    du2 = np.empty(max(n - 1, 1))
    dd = np.empty(n)
    ipiv = np.empty(n, dtype=np.int64)
    for j in range(k):
        th = U[j]
        s = S[j]
        ok = _linearize(th, s, P1, Q1, inv_h, k_diag, theta0, R[j], R1[j], D[j])
        e = _error(th, R[j], inv_w, floor_bend, tol, ok)
        alive = ok and math.isfinite(e)
        slow = 0
        iters = 0
        for _ in range(max_iter):
            if not (alive and e > 1.0):
                break
            for i in range(n):
                rhs[i] = -R[j, i]
            if not _solve(D[j], off_low, off_up, rhs, dU, dl, dd, du, du2, ipiv):
                alive = False
                break
            rot = 0.0
            for i in range(n):
                a = abs(dU[i])
                if a > rot:
                    rot = a
            full = min(1.0, max_rotation / rot) if rot > 0 else 1.0
            alpha = full
            accepted = False
            for _r in range(backtracks + 1):
                for i in range(n):
                    trial[i] = th[i] + alpha * dU[i]
                tok = _linearize(trial, s, P1, Q1, inv_h, k_diag, theta0, tR, tR1, td)
                e_new = _error(trial, tR, inv_w, floor_bend, tol, tok)
                first = alpha == full
                accept = (e_new < e) or (e_new <= 1.0) or (first and e_new <= growth * e)
                if accept and math.isfinite(e_new):
                    slow = slow + 1 if e_new > 0.5 * e else 0
                    for i in range(n):
                        th[i] = trial[i]
                        R[j, i] = tR[i]
                        R1[j, i] = tR1[i]
                        D[j, i] = td[i]
                    e = e_new
                    accepted = True
                    break
                alpha = 0.5 * alpha
            iters += 1
            if not accepted:
                alive = False
                break
            if slow >= stagnation and e > 1.0:
                alive = False
                break
        # at the last iterate: the path rate and det J's sign from one factorisation
        ok = True
        for i in range(n):
            rhs[i] = R1[j, i]
            if not math.isfinite(R[j, i]):
                ok = False
        sign = 0.0
        if ok and _solve(D[j], off_low, off_up, rhs, dU, dl, dd, du, du2, ipiv):
            odd = 0
            for i in range(n):
                rate[j, i] = -dU[i]
                if dd[i] < 0.0:
                    odd += 1
                if ipiv[i] != i:
                    odd += 1
            sign = 1.0 if odd % 2 == 0 else -1.0
        else:
            for i in range(n):
                rate[j, i] = math.nan
        M[j, 0] = e
        M[j, 1] = sign
        if stab and _odd_definite(th, s, k1, k2, bx, by, mu, inv_h, w):
            M[j, 2] = 1.0
        M[j, 3] = 1.0 if ok else 0.0
        M[j, 4] = iters
