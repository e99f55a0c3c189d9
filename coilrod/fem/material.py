"""Compressible neo-Hookean solid (Zhao et al. 2019 form), vectorised over quadrature points.

All functions take deformation gradients ``F`` of shape ``(n, 3, 3)`` (dimensionless) and
return energy densities (J/m^3 = Pa), first Piola stresses ``P[n, i, J]`` (Pa) and tangents
``A[n, i, J, k, L] = dP_iJ / dF_kL`` (Pa).  Callers guarantee ``det F > 0``.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "moduli",
    "isochoric",
    "jacobian_derivatives",
    "volumetric",
    "neo_hookean",
    "plane_stress",
]


def moduli(youngs_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """Shear and bulk moduli ``(G, K)`` in Pa from E (Pa) and Poisson's ratio.

    Examples
    --------
    >>> G, K = moduli(3.0, 0.25)
    >>> round(G, 12), round(K, 12)
    (1.2, 2.0)
    """
    G = youngs_modulus / (2.0 * (1.0 + poisson_ratio))
    K = youngs_modulus / (3.0 * (1.0 - 2.0 * poisson_ratio))
    return G, K


def _inv_det(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.linalg.inv(F), np.linalg.det(F)


def _dyad(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a_iJ b_kL`` for stacks of matrices: (n, 3, 3) x (n, 3, 3) -> (n, 3, 3, 3, 3)."""
    return a[:, :, :, None, None] * b[:, None, None, :, :]


def _cross_dyad(Fi: np.ndarray) -> np.ndarray:
    """``Fi_Jk Fi_Li`` arranged as ``[n, i, J, k, L]``."""
    return Fi[:, None, :, :, None] * np.swapaxes(Fi, 1, 2)[:, :, None, None, :]


def isochoric(F: np.ndarray, shear: float, tangent: bool = True):
    """Isochoric part ``W = G/2 (J^(-2/3) tr(F^T F) - 3)``.

    Returns
    -------
    W : ndarray, shape (n,)
    P : ndarray, shape (n, 3, 3)
        ``G J^(-2/3) (F - I1/3 F^-T)``.
    A : ndarray, shape (n, 3, 3, 3, 3) or None
        ``G J^(-2/3) [d_ik d_JL - 2/3 (F_iJ Fi_Lk + Fi_Ji F_kL) + 2/9 I1 Fi_Ji Fi_Lk
        + 1/3 I1 Fi_Jk Fi_Li]`` with ``Fi = F^-1``.
    """
    Fi, J = _inv_det(F)
    FiT = np.swapaxes(Fi, 1, 2)
    I1 = np.einsum("nij,nij->n", F, F)
    c = shear * J ** (-2.0 / 3.0)
    W = 0.5 * (c * I1 - 3.0 * shear)
    P = c[:, None, None] * (F - (I1 / 3.0)[:, None, None] * FiT)
    if not tangent:
        return W, P, None
    eye = np.eye(3)
    I1e = I1[:, None, None, None, None]
    A = (-2.0 / 3.0) * (_dyad(F, FiT) + _dyad(FiT, F))
    A += (2.0 / 9.0) * I1e * _dyad(FiT, FiT)
    A += (1.0 / 3.0) * I1e * _cross_dyad(Fi)
    A += np.einsum("ik,JL->iJkL", eye, eye)
    A *= c[:, None, None, None, None]
    return W, P, A


def jacobian_derivatives(F: np.ndarray, second: bool = True):
    """``J = det F``, ``dJ/dF = J F^-T`` and ``d2J/dF2 = J (Fi_Ji Fi_Lk - Fi_Jk Fi_Li)``.

    Returns
    -------
    J : ndarray, shape (n,)
    dJ : ndarray, shape (n, 3, 3)
    d2J : ndarray, shape (n, 3, 3, 3, 3) or None
    """
    Fi, J = _inv_det(F)
    FiT = np.swapaxes(Fi, 1, 2)
    dJ = J[:, None, None] * FiT
    if not second:
        return J, dJ, None
    d2J = _dyad(FiT, FiT) - _cross_dyad(Fi)
    d2J *= J[:, None, None, None, None]
    return J, dJ, d2J


def volumetric(F: np.ndarray, bulk: float, tangent: bool = True):
    """Volumetric part ``U = K/2 (J - 1)^2``: returns ``(U, P, A)`` like :func:`isochoric`."""
    J, dJ, d2J = jacobian_derivatives(F, tangent)
    p = bulk * (J - 1.0)
    U = 0.5 * bulk * (J - 1.0) ** 2
    P = p[:, None, None] * dJ
    if not tangent:
        return U, P, None
    A = p[:, None, None, None, None] * d2J + bulk * _dyad(dJ, dJ)
    return U, P, A


def neo_hookean(F: np.ndarray, shear: float, bulk: float, tangent: bool = True):
    """Full compressible neo-Hookean ``W = G/2 (J^(-2/3) I1 - 3) + K/2 (J - 1)^2``.

    Parameters
    ----------
    F : ndarray, shape (n, 3, 3)
    shear, bulk : float
        G and K in Pa.
    tangent : bool
        Also return ``A = dP/dF``.

    Returns
    -------
    W : ndarray, shape (n,), Pa;  P : ndarray, shape (n, 3, 3), Pa;
    A : ndarray, shape (n, 3, 3, 3, 3), Pa, or None.

    Examples
    --------
    >>> import numpy as np
    >>> F = np.diag([1.1, 1.0, 1.0])[None]
    >>> W, P, A = neo_hookean(F, 1.0, 100.0)
    >>> bool(P[0, 0, 0] > 0)
    True
    """
    W, P, A = isochoric(F, shear, tangent)
    U, Pv, Av = volumetric(F, bulk, tangent)
    return W + U, P + Pv, (A + Av) if tangent else None


def plane_stress(
    F2: np.ndarray,
    shear: float,
    bulk: float,
    lam3: np.ndarray | None = None,
    tangent: bool = True,
    tol: float = 1e-13,
    maxiter: int = 50,
):
    """Plane stress: the thickness stretch ``lam3`` makes ``P_33 = 0`` at every point.

    Solved by a vectorised local Newton; the tangent is condensed,
    ``A2 = A_ab - A_a33 A_33b / A_3333``.

    Parameters
    ----------
    F2 : ndarray, shape (n, 2, 2)
        In-plane deformation gradient.
    lam3 : ndarray, shape (n,), optional
        Starting thickness stretches (default ``J2^(-1/2)``).

    Returns
    -------
    W : ndarray, shape (n,);  P2 : ndarray, shape (n, 2, 2);
    A2 : ndarray, shape (n, 2, 2, 2, 2) or None;  lam3 : ndarray, shape (n,).
    """
    n = F2.shape[0]
    J2 = F2[:, 0, 0] * F2[:, 1, 1] - F2[:, 0, 1] * F2[:, 1, 0]
    lam = J2**-0.5 if lam3 is None else np.array(lam3, dtype=float)
    F = np.zeros((n, 3, 3))
    F[:, :2, :2] = F2
    for _ in range(maxiter):
        F[:, 2, 2] = lam
        _, P, A = neo_hookean(F, shear, bulk, True)
        step = P[:, 2, 2] / A[:, 2, 2, 2, 2]
        lam_new = lam - step
        # keep the stretch positive (halve toward zero instead of crossing it)
        lam = np.where(lam_new > 0, lam_new, 0.5 * lam)
        if np.max(np.abs(step) / lam) < tol:
            break
    F[:, 2, 2] = lam
    W, P, A = neo_hookean(F, shear, bulk, tangent)
    P2 = P[:, :2, :2].copy()
    if not tangent:
        return W, P2, None, lam
    A2 = (
        A[:, :2, :2, :2, :2]
        - _dyad(A[:, :2, :2, 2, 2], A[:, 2, 2, :2, :2])
        / A[:, 2, 2, 2, 2][:, None, None, None, None]
    )
    return W, P2, A2, lam
