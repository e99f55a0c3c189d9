"""Closed-form magnetic elastica: M(1) (uniform axial magnetization) in a uniform field.

For |M| uniform along the tangent and B uniform at angle phi_B, seed eq. (5) loses its force
terms and becomes the elastica ``EI theta'' + A |M| |B| sin(phi_B - theta) = 0`` with
``theta(0) = theta_0`` and ``theta'(L) = 0``.  With ``v = theta - phi_B + pi`` it is the pendulum
``v'' = -(lambda / L^2) sin v``, ``lambda = |M| |B| A L^2 / (E I)``, whose first integral
``v'^2 = 2 (lambda / L^2) (cos v - cos v_L)`` is integrated by the substitution
``sin(v / 2) = p sin(phi)``, ``p = sin(v_L / 2)``:

* arc length ``sqrt(lambda) = K(p^2) - F(phi_0 | p^2)``, ``sin(phi_0) = sin(v_0 / 2) / p``;
* along the field ``L - (2 L / sqrt(lambda)) (E(p^2) - E(phi_0 | p^2))``;
* across the field ``-(2 L p / sqrt(lambda)) cos(phi_0)``.

This module is the independent reference the rod solver is tested against; it shares no code
with it.  The rod bends counter-clockwise toward the field when the field lies counter-clockwise
of the clamp tangent by ``beta = phi_B - theta_0`` in (0, pi); clockwise cases are mirrored.
For ``beta`` in (pi, 2 pi) and counter-clockwise bending the same formulas give the
*complementary* branch (bent the long way round), which exists only above a fold
(:func:`elastica_fold`); an antiparallel field (``beta = pi``) buckles at ``lambda = pi^2 / 4``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq, minimize_scalar
from scipy.special import ellipe, ellipeinc, ellipkinc, ellipkm1

from coils._validate import finite_scalar, positive

__all__ = [
    "ElasticaState",
    "elastica",
    "elastica_branch",
    "elastica_fold",
    "small_deflection_tip",
    "BUCKLING_LAMBDA",
]

#: Critical magneto-elastic number of a clamped rod in an antiparallel field, pi^2 / 4.
BUCKLING_LAMBDA = math.pi**2 / 4


@dataclass(frozen=True)
class ElasticaState:
    """One closed-form equilibrium.

    Attributes
    ----------
    lam : float
        Magneto-elastic number lambda = |M||B| A L^2 / (E I).
    tip : ndarray, shape (2,)
        Tip position (x, y) relative to the clamp, m.
    tip_angle : float
        Tangent angle at the tip, rad.
    p : float
        Elliptic modulus sin(v_L / 2) (0 for the straight state).
    """

    lam: float
    tip: np.ndarray
    tip_angle: float
    p: float


def _wrap(angle: float) -> float:
    """Angle in [0, 2 pi)."""
    return float(np.mod(angle, 2 * math.pi))


def _ccw_state(m1: float, beta: float, length: float, clamp_angle: float) -> ElasticaState:
    """Counter-clockwise equilibrium of complementary parameter ``m1 = 1 - p^2`` for a field
    ``beta`` ccw of the clamp.  ``m1`` (not p) is the variable so that states close to
    alignment (m1 -> 0, large lambda) keep full precision: K = ellipkm1(m1)."""
    v0 = math.pi - beta  # in (-pi, pi)
    m = 1.0 - m1
    p = math.sqrt(m)
    sin_phi0 = float(np.clip(math.sin(v0 / 2) / p, -1.0, 1.0)) if p > 0 else 0.0
    phi0 = math.asin(sin_phi0)
    root_lam = ellipkm1(m1) - ellipkinc(phi0, m)
    lam = float(root_lam**2)
    along = length - 2 * length / root_lam * (ellipe(m) - ellipeinc(phi0, m))
    across = -2 * length * p / root_lam * math.cos(phi0)
    phi_b = clamp_angle + beta
    e_b = np.array([math.cos(phi_b), math.sin(phi_b)])
    e_perp = np.array([-math.sin(phi_b), math.cos(phi_b)])
    tip = along * e_b + across * e_perp
    tip_angle = 2 * math.atan2(p, math.sqrt(m1)) - math.pi + phi_b
    return ElasticaState(lam, tip, float(tip_angle), float(p))


def _straight(lam: float, length: float, clamp_angle: float) -> ElasticaState:
    tip = length * np.array([math.cos(clamp_angle), math.sin(clamp_angle)])
    return ElasticaState(float(lam), tip, float(clamp_angle), 0.0)


def _mirror(state: ElasticaState, clamp_angle: float) -> ElasticaState:
    """Reflect a state about the clamp tangent line."""
    c, s = math.cos(2 * clamp_angle), math.sin(2 * clamp_angle)
    refl = np.array([[c, s], [s, -c]])
    return ElasticaState(state.lam, refl @ state.tip, 2 * clamp_angle - state.tip_angle, state.p)


def elastica(
    lam: float,
    field_angle: float,
    *,
    length: float = 1.0,
    clamp_angle: float = 0.0,
    rtol: float = 1e-15,
) -> ElasticaState:
    """Equilibrium of M(1) in a uniform field, bending toward the field the short way.

    Parameters
    ----------
    lam : float
        lambda = |M||B| A L^2 / (E I) >= 0.
    field_angle : float
        Direction phi_B of B in the bending plane, rad from +x.
    length : float
        Rod length L, m (the tip scales with it).
    clamp_angle : float
        Tangent angle theta_0 at the clamp, rad.
    rtol : float
        Relative tolerance of the root in the elliptic modulus.

    Returns
    -------
    ElasticaState
        Tip (x, y) relative to the clamp in m, tip angle in rad.  For an antiparallel field the
        straight state below pi^2/4 and the counter-clockwise buckled state above it.

    Examples
    --------
    >>> st = elastica(1e-4, math.pi / 2)        # small deflection: y_tip = lambda L / 3
    >>> round(float(st.tip[1]) / 1e-4, 6)
    0.333333
    >>> round(elastica(3.0, math.pi).tip_angle, 6) > 0   # buckled above pi^2/4
    True
    """
    lam = finite_scalar(lam, "lam")
    if lam < 0:
        raise ValueError(f"lam must be >= 0; got {lam}")
    length = positive(length, "length")
    field_angle = finite_scalar(field_angle, "field_angle")
    clamp_angle = finite_scalar(clamp_angle, "clamp_angle")
    beta = _wrap(field_angle - clamp_angle)
    if lam == 0 or beta == 0.0:
        return _straight(lam, length, clamp_angle)
    if beta > math.pi:  # the field is clockwise of the clamp: mirror the ccw solution
        return _mirror(
            elastica(
                lam,
                clamp_angle - (field_angle - clamp_angle),
                length=length,
                clamp_angle=clamp_angle,
                rtol=rtol,
            ),
            clamp_angle,
        )
    if beta == math.pi and lam <= BUCKLING_LAMBDA:
        return _straight(lam, length, clamp_angle)
    half = (math.pi - beta) / 2  # p ranges over (sin(half), 1), m1 over (0, cos(half)^2)
    target = math.sqrt(lam)

    def gap(log_m1: float) -> float:
        return _ccw_state(math.exp(log_m1), beta, 1.0, 0.0).lam ** 0.5 - target

    hi = 2 * math.log(math.cos(half)) - 1e-15 if half > 0 else 0.0
    lo = -700.0
    if gap(lo) < 0:
        raise ValueError(f"lam = {lam} is beyond the range of the elliptic solution")
    log_m1 = brentq(gap, lo, hi, xtol=1e-14, rtol=max(rtol, 4e-16), maxiter=500)
    return _ccw_state(math.exp(log_m1), beta, length, clamp_angle)


def elastica_branch(
    p, field_angle: float, *, length: float = 1.0, clamp_angle: float = 0.0
) -> list[ElasticaState]:
    """Counter-clockwise equilibria parametrised by the elliptic modulus ``p``.

    For a field counter-clockwise of the clamp (beta in (0, pi]) this is the natural branch;
    for beta in (pi, 2 pi) it is the complementary branch (bent the long way round), which has
    a fold at the minimum of lambda(p) (see :func:`elastica_fold`).

    Parameters
    ----------
    p : float or array-like, shape (k,)
        Moduli in (sin((pi - beta) / 2), 1) (beta in (0, pi]) or (sin((beta - pi) / 2), 1).
    field_angle, length, clamp_angle : float
        As in :func:`elastica`.

    Returns
    -------
    list of ElasticaState
    """
    beta = _wrap(finite_scalar(field_angle, "field_angle") - clamp_angle)
    low = abs(math.sin((math.pi - beta) / 2))
    out = []
    for value in np.atleast_1d(np.asarray(p, dtype=float)):
        if not low < value < 1:
            raise ValueError(f"p must lie in ({low}, 1) for this field angle; got {value}")
        out.append(
            _ccw_state(1.0 - float(value) ** 2, beta, positive(length, "length"), clamp_angle)
        )
    return out


def elastica_fold(field_angle: float, *, clamp_angle: float = 0.0) -> ElasticaState:
    """The fold (limit point) of the complementary branch: the smallest lambda at which a rod
    bent the long way round toward a field ``beta`` in (pi, 2 pi) ccw of the clamp exists.

    Below this lambda the long-way state cannot exist: a rod held there snaps through to the
    natural branch.

    Examples
    --------
    >>> fold = elastica_fold(math.pi + 0.05)
    >>> BUCKLING_LAMBDA < fold.lam < 1.2 * BUCKLING_LAMBDA
    True
    """
    beta = _wrap(finite_scalar(field_angle, "field_angle") - clamp_angle)
    if not math.pi < beta < 2 * math.pi:
        raise ValueError(
            "field_angle must lie in (pi, 2 pi) counter-clockwise of the clamp "
            f"for a fold; got {beta} rad"
        )
    low = math.sin((beta - math.pi) / 2)

    def lam_of(t: float) -> float:
        p = low + (1 - low) * t
        return _ccw_state(1.0 - p * p, beta, 1.0, clamp_angle).lam

    res = minimize_scalar(
        lam_of, bounds=(1e-9, 1 - 1e-9), method="bounded", options={"xatol": 1e-13}
    )
    p = low + (1 - low) * res.x
    return _ccw_state(1.0 - p * p, beta, 1.0, clamp_angle)


def small_deflection_tip(lam: float, length: float = 1.0) -> float:
    """Linear-theory tip deflection of M(1) with B perpendicular: ``lambda L / 3`` (m)."""
    return finite_scalar(lam, "lam") * positive(length, "length") / 3.0
