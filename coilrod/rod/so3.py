"""Rotations for the spatial rod: exponential and logarithm of SO(3), their Jacobians and the
derivative of the inverse right Jacobian, vectorised over leading axes.

Conventions: ``hat(v) w = v x w``; a rotation vector ``phi`` (rad) gives ``exp(hat(phi))``;
``exp(phi + d) = exp(J_l(phi) d) exp(phi) = exp(phi) exp(J_r(phi) d)`` to first order;
``J_r(phi) = J_l(-phi) = J_l(phi)^T``.  Every function switches to a Taylor series below a small
angle so that no quotient loses precision near the identity.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "hat",
    "cross",
    "expm",
    "logm",
    "left_jacobian",
    "about_z",
    "inv_right_jacobian_coefficients",
]

#: Angles (rad) below which the series replace the closed forms.
_SMALL = 0.05


def hat(v: np.ndarray) -> np.ndarray:
    """Skew matrices of vectors ``v`` (..., 3): shape (..., 3, 3), ``hat(v) w = v x w``."""
    out = np.zeros(v.shape + (3,))
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    out[..., 0, 1], out[..., 0, 2] = -z, y
    out[..., 1, 0], out[..., 1, 2] = z, -x
    out[..., 2, 0], out[..., 2, 1] = -y, x
    return out


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` along the last axis (broadcast), faster than :func:`numpy.cross` for small
    stacks."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _coefficients(theta: np.ndarray):
    """``sin t / t``, ``(1 - cos t) / t^2`` and ``(t - sin t) / t^3`` of angles ``theta``."""
    small = theta < _SMALL
    t = np.where(small, 1.0, theta)
    t2 = theta * theta
    a = np.where(small, 1 - t2 / 6 * (1 - t2 / 20 * (1 - t2 / 42)), np.sin(t) / t)
    b = np.where(small, 0.5 - t2 / 24 * (1 - t2 / 30 * (1 - t2 / 56)), (1 - np.cos(t)) / t**2)
    c = np.where(small, 1 / 6 - t2 / 120 * (1 - t2 / 42 * (1 - t2 / 72)), (t - np.sin(t)) / t**3)
    return a, b, c


def expm(phi: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of rotation vectors ``phi`` (..., 3) (Rodrigues)."""
    theta = np.sqrt(np.einsum("...i,...i->...", phi, phi))
    a, b, _ = _coefficients(theta)
    K = hat(phi)
    out = a[..., None, None] * K + b[..., None, None] * (K @ K)
    out[..., 0, 0] += 1.0
    out[..., 1, 1] += 1.0
    out[..., 2, 2] += 1.0
    return out


def about_z(theta: np.ndarray) -> np.ndarray:
    """Rotations by angles ``theta`` (..., rad) about z, shape (..., 3, 3): the frames
    (tangent, normal, binormal) of a planar rod with tangent angles ``theta``."""
    theta = np.asarray(theta, float)
    c, s = np.cos(theta), np.sin(theta)
    out = np.zeros(theta.shape + (3, 3))
    out[..., 0, 0], out[..., 1, 0] = c, s
    out[..., 0, 1], out[..., 1, 1] = -s, c
    out[..., 2, 2] = 1.0
    return out


def left_jacobian(phi: np.ndarray) -> np.ndarray:
    """``J_l(phi) = I + (1 - cos t)/t^2 hat(phi) + (t - sin t)/t^3 hat(phi)^2``, (..., 3, 3).

    Singular only at ``|phi| = 2 pi k``, k >= 1 (det J_l = 2 (1 - cos t) / t^2)."""
    theta = np.sqrt(np.einsum("...i,...i->...", phi, phi))
    _, b, c = _coefficients(theta)
    K = hat(phi)
    out = b[..., None, None] * K + c[..., None, None] * (K @ K)
    out[..., 0, 0] += 1.0
    out[..., 1, 1] += 1.0
    out[..., 2, 2] += 1.0
    return out


def logm(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) of rotation matrices (..., 3, 3), angle in [0, pi].

    Near pi the axis comes from the symmetric part (the skew part vanishes there)."""
    v = 0.5 * np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]],
        axis=-1,
    )
    s = np.sqrt(np.einsum("...i,...i->...", v, v))  # sin(theta)
    c = 0.5 * (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0)
    theta = np.arctan2(s, c)
    small = theta < _SMALL
    t2 = theta * theta
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(
            small,
            1 + t2 / 6 * (1 + 7 * t2 / 60 * (1 + 31 * t2 / 294)),
            theta / np.where(s > 0, s, 1),
        )
    out = factor[..., None] * v
    near_pi = theta > np.pi - 1e-3
    if np.any(near_pi):  # axis from (R + R^T) / 2 - cos(t) I = (1 - cos t) a a^T
        Rp = R[near_pi]
        S = 0.5 * (Rp + np.swapaxes(Rp, -1, -2))
        cp = c[near_pi]
        S[..., 0, 0] -= cp
        S[..., 1, 1] -= cp
        S[..., 2, 2] -= cp
        col = np.argmax(np.einsum("...ii->...i", S), axis=-1)
        axis = np.take_along_axis(S, col[..., None, None], axis=-1)[..., 0]
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        sign = np.where(np.einsum("...i,...i->...", axis, v[near_pi]) < 0, -1.0, 1.0)
        out[near_pi] = (sign * theta[near_pi])[..., None] * axis
    return out


#: Taylor coefficients of c(t) in t^2 (from cot x = sum (-1)^n 2^2n B_2n x^(2n-1) / (2n)!):
#: c(t) = sum_k a_k t^(2k), a_k = (-1)^k B_(2k+2) / (2k+2)!  (|a_k| ~ (2 pi)^-2k).
_C_SERIES = np.array(
    [
        0.08333333333333333,
        0.001388888888888889,
        3.306878306878307e-05,
        8.267195767195768e-07,
        2.08767569878681e-08,
        5.284190138687493e-10,
        1.3382536530684679e-11,
        3.3896802963225827e-13,
        8.586062056277845e-15,
        2.174868698558062e-16,
        5.5090028283602295e-18,
        1.3954464685812522e-19,
    ]
)
#: The series of c replaces the closed form below this angle (rad), where the closed form's
#: cancellation would cost digits; its truncation error there is below 1e-19.
_C_SMALL = 1.0


def inv_right_jacobian_coefficients(theta: np.ndarray):
    """``c(t) = 1/t^2 - (1 + cos t) / (2 t sin t)`` and ``c'(t) / t`` of angles ``t`` < 2 pi.

    ``J_r(psi)^-1 = I + hat(psi) / 2 + c(|psi|) hat(psi)^2`` (and ``J_l^-1`` with ``-hat``);
    ``c'(t) / t`` enters its derivative.  Below 1 rad both come from the Taylor series
    (:data:`_C_SERIES`), above from the closed forms."""
    theta = np.asarray(theta, float)
    small = theta < _C_SMALL
    t = np.where(small, 1.5, theta)
    t2 = theta * theta
    c = np.zeros_like(t2)
    dc = np.zeros_like(t2)
    for k in range(_C_SERIES.size - 1, -1, -1):  # Horner in t^2
        c = c * t2 + _C_SERIES[k]
        if k >= 1:
            dc = dc * t2 + 2 * k * _C_SERIES[k]
    cot = np.cos(t / 2) / np.sin(t / 2)
    csc2 = 1.0 / np.sin(t / 2) ** 2
    c_closed = 1 / t**2 - cot / (2 * t)
    dc_closed = (-2 / t**3 + cot / (2 * t**2) + csc2 / (4 * t)) / t
    return np.where(small, c, c_closed), np.where(small, dc, dc_closed)
