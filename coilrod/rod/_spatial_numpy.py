"""The spatial rod's per-node pass (:func:`coilrod.rod._compiled_spatial.spatial_core`) in
vectorised numpy: nothing to compile.

The same IEEE operations in the same order as the compiled pass, over all members and nodes
at once (3x3 products summed term by term in the kernel's order; libm's ``sin``, ``cos`` and
``atan2`` called per element, as the compiled code calls them, since numpy's own may differ in
the last bit), so that the results are bitwise those of the compiled pass and a process's
numbers do not change when it compiles.  :func:`coilrod.rod._compiled_spatial.spatial_pass`
runs this until compiling pays (README, "Cold start").  The equations are those of
:mod:`coilrod.rod.spatial`; :func:`coilrod.rod.spatial.numpy_core` is an independent numpy
transcription of them (built on :mod:`coilrod.rod.so3`, rounding differently).
"""

from __future__ import annotations

import math

import numpy as np

from ._libm import libm as _libm
from .so3 import _C_SERIES, _C_SMALL, _SMALL

__all__ = ["spatial_core_numpy"]

_EYE = np.eye(3)


def _hat(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) skew matrices of v (..., 3)."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _mm(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A @ B of (..., 3, 3) stacks, summed ``0 + a0 b0 + a1 b1 + a2 b2`` as the kernel does."""
    return (
        0.0
        + A[..., :, 0, None] * B[..., None, 0, :]
        + A[..., :, 1, None] * B[..., None, 1, :]
        + A[..., :, 2, None] * B[..., None, 2, :]
    )


def _mv(A: np.ndarray, v: np.ndarray) -> np.ndarray:
    """A @ v of (..., 3, 3) and (..., 3), summed in the kernel's order."""
    return (
        0.0
        + A[..., 0] * v[..., 0, None]
        + A[..., 1] * v[..., 1, None]
        + A[..., 2] * v[..., 2, None]
    )


def _mtm(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A^T @ B of (..., 3, 3) stacks, in the kernel's order."""
    return _mm(np.swapaxes(A, -1, -2), B)


def _norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2])


def _exp_and_jl(phi: np.ndarray):
    """exp(hat(phi)) and J_l(phi), (..., 3, 3) each (``_exp_jl_at`` of the kernel)."""
    theta = _norm(phi)
    t2 = theta * theta
    sin = _libm(math.sin, theta)
    cos = _libm(math.cos, theta)
    small = theta < _SMALL
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(small, 1 - t2 / 6 * (1 - t2 / 20 * (1 - t2 / 42)), sin / theta)
        b = np.where(small, 0.5 - t2 / 24 * (1 - t2 / 30 * (1 - t2 / 56)), (1 - cos) / t2)
        c = np.where(
            small, 1 / 6 - t2 / 120 * (1 - t2 / 42 * (1 - t2 / 72)), (theta - sin) / (t2 * theta)
        )
    K = _hat(phi)
    K2 = _mm(K, K)
    Q = _EYE + a[..., None, None] * K + b[..., None, None] * K2
    J = _EYE + b[..., None, None] * K + c[..., None, None] * K2
    return Q, J


def _log_one(R: np.ndarray) -> np.ndarray:
    """The kernel's ``_log`` of one rotation near pi (its axis from the symmetric part)."""
    v0 = 0.5 * (R[2, 1] - R[1, 2])
    v1 = 0.5 * (R[0, 2] - R[2, 0])
    v2 = 0.5 * (R[1, 0] - R[0, 1])
    s = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    theta = math.atan2(s, c)
    best, col = -1.0, 0
    for i in range(3):
        d = R[i, i] - c
        if d > best:
            best, col = d, i
    out = [0.5 * (R[i, col] + R[col, i]) - (c if i == col else 0.0) for i in range(3)]
    nrm = math.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2])
    sign = 1.0 if out[0] * v0 + out[1] * v1 + out[2] * v2 >= 0 else -1.0
    return np.array([sign * theta * x / nrm for x in out])


def _log(R: np.ndarray) -> np.ndarray:
    """log of rotations (..., 3, 3) -> (..., 3) (``_log`` of the kernel)."""
    v = np.stack(
        [0.5 * (R[..., 2, 1] - R[..., 1, 2]), 0.5 * (R[..., 0, 2] - R[..., 2, 0])]
        + [0.5 * (R[..., 1, 0] - R[..., 0, 1])],
        axis=-1,
    )
    s = _norm(v)
    c = 0.5 * (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0)
    theta = np.array(
        [math.atan2(y, x) for y, x in zip(s.ravel().tolist(), c.ravel().tolist(), strict=True)]
    )
    theta = theta.reshape(s.shape)
    t2 = theta * theta
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(
            theta < _SMALL, 1 + t2 / 6 * (1 + 7 * t2 / 60 * (1 + 31 * t2 / 294)), theta / s
        )
    out = f[..., None] * v
    near_pi = theta > math.pi - 1e-3
    if near_pi.any():
        for idx in zip(*np.nonzero(near_pi), strict=True):
            out[idx] = _log_one(R[idx])
    return out


def _c_coefficients(theta: np.ndarray):
    """c and dc/dtheta / theta of J_r^-1 (``_c_coefficients`` of the kernel)."""
    t2 = theta * theta
    c = np.zeros_like(theta)
    dc = np.zeros_like(theta)
    for k in range(_C_SERIES.size - 1, -1, -1):
        c = c * t2 + _C_SERIES[k]
        if k >= 1:
            dc = dc * t2 + 2 * k * _C_SERIES[k]
    half = theta / 2
    sin = _libm(math.sin, half)
    cos = _libm(math.cos, half)
    with np.errstate(divide="ignore", invalid="ignore"):
        cot = cos / sin
        csc2 = 1.0 / (sin * sin)
        cf = 1 / (theta * theta) - cot / (2 * theta)
        dcf = (
            -2 / (theta * (theta * theta)) + cot / (2 * (theta * theta)) + csc2 / (4 * theta)
        ) / theta
    small = theta < _C_SMALL
    return np.where(small, c, cf), np.where(small, dc, dcf)


def _sym_term(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(a b^T + b a^T) / 2 - (a . b) I, (..., 3, 3)."""
    d = a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]
    out = 0.5 * (a[..., :, None] * b[..., None, :] + b[..., :, None] * a[..., None, :])
    for i in range(3):
        out[..., i, i] -= d
    return out


def _bending(frames, K, h, tangent):
    """Moments p (k, n - 1, 3) of the segments and, with ``tangent``, their Hessian blocks P
    (k, n - 1, 3, 3) (``_bending`` of the kernel)."""
    Rb = frames[:, 1:]
    psi = _log(_mtm(frames[:, :-1], Rb))
    g = psi * K / h[:, None]
    theta = _norm(psi)
    cc, dc = _c_coefficients(theta)
    tmp = _cross(psi, g)
    Jg = g - 0.5 * tmp + cc[..., None] * _cross(psi, tmp)
    p = _mv(Rb, Jg)
    if not tangent:
        return p, None
    Psi = _hat(psi)
    Psi2 = _mm(Psi, Psi)
    ccm, dcm = cc[..., None, None], dc[..., None, None]
    Minv = _EYE + 0.5 * Psi + ccm * Psi2
    Gh = _hat(g)
    M1 = _mm(Gh, Psi)
    M2 = _hat(_cross(g, psi))
    Nm = -0.5 * Gh - ccm * (M1 + M2) + dcm * psi[..., :, None] * _mv(Psi2, g)[..., None, :]
    W = Minv * K[:, None] / h[:, None, None]  # Minv[q, a] K[q] / h[i]
    acc = 0.0 + W[..., 0, :, None] * Minv[..., 0, None, :]
    acc = acc + W[..., 1, :, None] * Minv[..., 1, None, :]
    acc = acc + W[..., 2, :, None] * Minv[..., 2, None, :]
    acc2 = _mtm(Minv, Nm)  # sum_q Minv[q, a] Nm[q, b]
    inner = acc + 0.5 * (acc2 + np.swapaxes(acc2, -1, -2))
    M2 = _mm(Rb, inner)
    P = _mm(M2, np.swapaxes(Rb, -1, -2))
    return p, P


def spatial_core_numpy(
    phi, X, F, S, B, G, H, has_h, uniform, tangent, mu, K, h, w, R0, L,
    frames, R, R1, blk, diag, A_ab, m_out, ab=None, kv=0, band=False, econ=None, tol=0.0,
    floor=0.0, stats=None,
):  # fmt: skip
    """:func:`coilrod.rod._compiled_spatial.spatial_core` (same arguments, same outputs, the
    same entries written) in numpy, except the band storage and the member statistics:
    ``ab`` and ``stats`` are left alone and False returned (the caller gathers the band from
    ``blk`` and computes the statistics itself)."""
    op = 0 if uniform else 3
    with np.errstate(all="ignore"):
        Q, Jl = _exp_and_jl(phi)
        frames[:] = _mm(Q, R0)
        m_out[:] = _mv(frames, mu)
        p, P = _bending(frames, K, h, tangent)
        t = frames[..., :, 0]
        s = S[:, None, None]
        _moment_rows(phi, F, s, B, uniform, op, h, w, t, m_out, p, R, R1)
        if not uniform:
            _position_force_rows(X, F, s, G, h, w, L, frames, t, m_out, R, R1)
        if not tangent:
            return False
        _rotation_blocks(F, s, B, uniform, op, h, w, t, m_out, p, P, Jl, R, blk, diag, A_ab)
        if not uniform:
            _position_blocks(s, G, H, has_h, h, w, L, t, m_out, Jl, blk)
    return False


def _half_forces(F, h):
    """0.5 h_i F_i of the segments (k, n - 1, 3)."""
    return (0.5 * h)[:, None] * F[:, :-1]


def _moment_rows(phi, F, s, B, uniform, op, h, w, t, m, p, R, R1):
    """Moment rows (slots op:op+3) of R and R1 (``_moment_rows`` of the kernel)."""
    r1 = -w[:, None] * _cross(m, B)
    val = s * r1
    val[:, 1:] += p
    val[:, :-1] -= p
    if not uniform:
        hF = _half_forces(F, h)
        val[:, 1:] -= _cross(t[:, 1:], hF)
        val[:, :-1] -= _cross(t[:, :-1], hF)
    r1[:, 0] = 0.0
    val[:, 0] = phi[:, 0]
    R1[:, :, op : op + 3] = r1
    R[:, :, op : op + 3] = val


def _position_force_rows(X, F, s, G, h, w, L, frames, t, m, R, R1):
    """Position (0:3) and force (6:9) rows of R and R1 (a non-uniform field)."""
    R[:, 0, 0:3] = X[:, 0]
    R[:, -1, 6:9] = F[:, -1]
    R1[:, -1, 6:9] = 0.0
    R1[:, :, 0:3] = 0.0
    R[:, 1:, 0:3] = X[:, 1:] - X[:, :-1] - (0.5 * h)[:, None] * (t[:, :-1] + t[:, 1:])
    acc = 0.0 + G[:, 1:, 0, :] * m[:, 1:, 0, None] + G[:, 1:, 1, :] * m[:, 1:, 1, None]
    acc = acc + G[:, 1:, 2, :] * m[:, 1:, 2, None]
    f1 = (-w[1:] * L)[:, None] * acc
    R1[:, :-1, 6:9] = f1
    R[:, :-1, 6:9] = F[:, :-1] - F[:, 1:] + s * f1


def _rotation_blocks(F, s, B, uniform, op, h, w, t, m, p, P, Jl, R, blk, diag, A_ab):
    """diag, A_ab and the Jacobian blocks 0 m_prev, 1 m_diag, 2 m_next
    (``_rotation_blocks`` of the kernel)."""
    D = np.zeros(diag.shape)
    D[:, 1:] += P
    D[:, :-1] += P
    D += (-s * w[:, None])[..., None] * _sym_term(m, B)
    if not uniform:
        hF = _half_forces(F, h)
        D[:, 1:] += -1.0 * _sym_term(t[:, 1:], hF)
        D[:, :-1] += -1.0 * _sym_term(t[:, :-1], hF)
    D -= 0.5 * _hat(R[:, :, op : op + 3])
    diag[:] = D
    A_ab[:] = -P + 0.5 * _hat(p)
    A_ba = -P - (A_ab + P)
    blk[:, 1:, 0] = _mm(A_ba, Jl[:, :-1])
    blk[:, 1:, 1] = _mm(D[:, 1:], Jl[:, 1:])
    blk[:, 1:-1, 2] = _mm(A_ab[:, 1:], Jl[:, 2:])


def _position_blocks(s, G, H, has_h, h, w, L, t, m, Jl, blk):
    """Jacobian blocks 3 .. 9 of a non-uniform field (``_position_blocks`` of the kernel)."""
    hh = (0.5 * h)[:, None, None]
    That = _hat(t)
    blk[:, 1:, 3] = _mm(That[:, :-1] * hh, Jl[:, :-1])
    blk[:, 1:, 4] = _mm(hh * That[:, 1:], Jl[:, 1:])
    mh = _hat(m[:, 1:])
    Gi = G[:, 1:]
    cwL = (s * w[1:, None]) * L  # (k, n - 1, 1)
    cwL = cwL[..., None]
    blk[:, 1:, 5] = -cwL * _mm(mh, Gi)
    blk[:, 1:, 6] = -hh * That[:, 1:]
    blk[:, 1:-1, 7] = (-0.5 * h[1:])[:, None, None] * That[:, 1:-1]
    if has_h:
        Hi = H[:, 1:]
        acc = 0.0 + m[:, 1:, 0, None, None] * Hi[:, :, 0] + m[:, 1:, 1, None, None] * Hi[:, :, 1]
        acc = acc + m[:, 1:, 2, None, None] * Hi[:, :, 2]
    else:
        acc = 0.0
    blk[:, 1:, 8] = -cwL * L * acc
    blk[:, 1:, 9] = _mm(cwL * _mtm(Gi, mh), Jl[:, 1:])
