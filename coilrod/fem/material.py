"""Compressible neo-Hookean solid (Zhao et al. 2019 form), vectorised over quadrature points.

All functions take deformation gradients ``F`` of shape ``(n, 3, 3)`` (dimensionless) and
return energy densities (J/m^3 = Pa), first Piola stresses ``P[n, i, J]`` (Pa) and tangents
``A[n, i, J, k, L] = dP_iJ / dF_kL`` (Pa).  Callers guarantee ``det F > 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "DyadicTangent",
    "inverse_and_determinant",
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


def inverse_and_determinant(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``F^-1`` and ``det F`` of a stack of 3x3 matrices by cofactors.

    Parameters
    ----------
    F : ndarray, shape (n, 3, 3)

    Returns
    -------
    Fi : ndarray, shape (n, 3, 3)
        The inverses (callers guarantee ``det F != 0``).
    J : ndarray, shape (n,)
        The determinants.

    Examples
    --------
    >>> import numpy as np
    >>> F = np.array([[[2.0, 1, 0], [0, 1, 0], [0, 0, 4]]])
    >>> Fi, J = inverse_and_determinant(F)
    >>> float(J[0]), bool(np.allclose(Fi[0] @ F[0], np.eye(3)))
    (8.0, True)
    """
    a = np.moveaxis(F, (-2, -1), (0, 1))  # a[i, j] is the (n,) array F[:, i, j]
    cof = np.empty((3, 3) + F.shape[:-2])
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            cof[i, j] = a[i1, j1] * a[i2, j2] - a[i1, j2] * a[i2, j1]
    J = a[0, 0] * cof[0, 0] + a[0, 1] * cof[0, 1] + a[0, 2] * cof[0, 2]
    Fi = np.moveaxis(cof, (0, 1), (-1, -2)) / J[..., None, None]  # Fi = cof^T / J
    return np.ascontiguousarray(Fi), J


def _dyad(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a_iJ b_kL`` for stacks of matrices: (n, 3, 3) x (n, 3, 3) -> (n, 3, 3, 3, 3)."""
    return a[:, :, :, None, None] * b[:, None, None, :, :]


def _cross_dyad(Fi: np.ndarray) -> np.ndarray:
    """``Fi_Jk Fi_Li`` arranged as ``[n, i, J, k, L]``."""
    return Fi[:, None, :, :, None] * np.swapaxes(Fi, 1, 2)[:, :, None, None, :]


@dataclass
class DyadicTangent:
    """An isotropic hyperelastic tangent ``A = dP/dF`` kept as the coefficients of its dyads.

    ``A_iJkL = identity d_ik d_JL + mixed (F_iJ G_kL + G_iJ F_kL) + inverse G_iJ G_kL
    + cross G_iL G_kJ`` with ``G = F^-T`` (so ``G_iL G_kJ = Fi_Jk Fi_Li``): the neo-Hookean
    tangent and the second derivative of ``J`` have this form.  The element kernel contracts it
    with shape-function gradients without forming the ``(n, 3, 3, 3, 3)`` array.

    Attributes
    ----------
    F, FiT : ndarray, shape (n, 3, 3)
        Deformation gradient and ``F^-T``.
    identity, mixed, inverse, cross : ndarray, shape (n,)
        Coefficients, Pa.
    """

    F: np.ndarray
    FiT: np.ndarray
    identity: np.ndarray
    mixed: np.ndarray
    inverse: np.ndarray
    cross: np.ndarray

    def __add__(self, other: DyadicTangent) -> DyadicTangent:
        """Sum of two tangents at the same ``F``."""
        return DyadicTangent(
            self.F,
            self.FiT,
            self.identity + other.identity,
            self.mixed + other.mixed,
            self.inverse + other.inverse,
            self.cross + other.cross,
        )

    def scaled(self, s: np.ndarray) -> DyadicTangent:
        """The tangent multiplied point by point by ``s``, shape (n,)."""
        return DyadicTangent(
            self.F,
            self.FiT,
            s * self.identity,
            s * self.mixed,
            s * self.inverse,
            s * self.cross,
        )

    def dense(self) -> np.ndarray:
        """``A[n, i, J, k, L]``, shape (n, 3, 3, 3, 3), Pa."""
        F, G = self.F, self.FiT
        co = lambda c: c[:, None, None, None, None]  # noqa: E731
        A = co(self.mixed) * (_dyad(F, G) + _dyad(G, F))
        A += co(self.inverse) * _dyad(G, G)
        A += co(self.cross) * _cross_dyad(np.swapaxes(G, 1, 2))
        A += co(self.identity) * np.einsum("ik,JL->iJkL", np.eye(3), np.eye(3))[None]
        return A


def isochoric(F: np.ndarray, shear: float, tangent: bool = True, dyadic: bool = False, inv=None):
    """Isochoric part ``W = G/2 (J^(-2/3) tr(F^T F) - 3)``.

    Parameters
    ----------
    F : ndarray, shape (n, 3, 3)
    shear : float
        G, Pa.
    tangent : bool
        Also return the tangent.
    dyadic : bool
        Return the tangent as a :class:`DyadicTangent` instead of an array.
    inv : tuple of ndarray, optional
        ``(F^-1, det F)`` if already computed (see :func:`inverse_and_determinant`).

    Returns
    -------
    W : ndarray, shape (n,)
    P : ndarray, shape (n, 3, 3)
        ``G J^(-2/3) (F - I1/3 F^-T)``.
    A : ndarray, shape (n, 3, 3, 3, 3), DyadicTangent or None
        ``G J^(-2/3) [d_ik d_JL - 2/3 (F_iJ Fi_Lk + Fi_Ji F_kL) + 2/9 I1 Fi_Ji Fi_Lk
        + 1/3 I1 Fi_Jk Fi_Li]`` with ``Fi = F^-1``.
    """
    Fi, J = inverse_and_determinant(F) if inv is None else inv
    FiT = np.swapaxes(Fi, 1, 2)
    I1 = np.einsum("nij,nij->n", F, F)
    c = shear * J ** (-2.0 / 3.0)
    W = 0.5 * (c * I1 - 3.0 * shear)
    P = c[:, None, None] * (F - (I1 / 3.0)[:, None, None] * FiT)
    if not tangent:
        return W, P, None
    T = DyadicTangent(F, FiT, c, (-2.0 / 3.0) * c, (2.0 / 9.0) * c * I1, (1.0 / 3.0) * c * I1)
    return W, P, T if dyadic else T.dense()


def jacobian_derivatives(F: np.ndarray, second: bool = True, dyadic: bool = False, inv=None):
    """``J = det F``, ``dJ/dF = J F^-T`` and ``d2J/dF2 = J (Fi_Ji Fi_Lk - Fi_Jk Fi_Li)``.

    Parameters
    ----------
    F : ndarray, shape (n, 3, 3)
    second : bool
        Also return the second derivative.
    dyadic, inv
        As in :func:`isochoric`.

    Returns
    -------
    J : ndarray, shape (n,)
    dJ : ndarray, shape (n, 3, 3)
    d2J : ndarray, shape (n, 3, 3, 3, 3), DyadicTangent or None
    """
    Fi, J = inverse_and_determinant(F) if inv is None else inv
    FiT = np.swapaxes(Fi, 1, 2)
    dJ = J[:, None, None] * FiT
    if not second:
        return J, dJ, None
    zero = np.zeros_like(J)
    T = DyadicTangent(F, FiT, zero, zero, J, -J)
    return J, dJ, T if dyadic else T.dense()


def volumetric(F: np.ndarray, bulk: float, tangent: bool = True, dyadic: bool = False, inv=None):
    """Volumetric part ``U = K/2 (J - 1)^2``: returns ``(U, P, A)`` like :func:`isochoric`."""
    J, dJ, d2J = jacobian_derivatives(F, tangent, True, inv)
    p = bulk * (J - 1.0)
    U = 0.5 * bulk * (J - 1.0) ** 2
    P = p[:, None, None] * dJ
    if not tangent:
        return U, P, None
    # p d2J + K dJ (x) dJ, dJ = J F^-T
    T = d2J.scaled(p)
    T.inverse = T.inverse + bulk * J * J
    return U, P, T if dyadic else T.dense()


def neo_hookean(
    F: np.ndarray, shear: float, bulk: float, tangent: bool = True, dyadic: bool = False, inv=None
):
    """Full compressible neo-Hookean ``W = G/2 (J^(-2/3) I1 - 3) + K/2 (J - 1)^2``.

    Parameters
    ----------
    F : ndarray, shape (n, 3, 3)
    shear, bulk : float
        G and K in Pa.
    tangent : bool
        Also return ``A = dP/dF``.
    dyadic, inv
        As in :func:`isochoric`.

    Returns
    -------
    W : ndarray, shape (n,), Pa;  P : ndarray, shape (n, 3, 3), Pa;
    A : ndarray, shape (n, 3, 3, 3, 3), Pa, DyadicTangent, or None.

    Examples
    --------
    >>> import numpy as np
    >>> F = np.diag([1.1, 1.0, 1.0])[None]
    >>> W, P, A = neo_hookean(F, 1.0, 100.0)
    >>> bool(P[0, 0, 0] > 0)
    True
    """
    inv = inverse_and_determinant(F) if inv is None else inv
    W, P, A = isochoric(F, shear, tangent, True, inv)
    U, Pv, Av = volumetric(F, bulk, tangent, True, inv)
    if not tangent:
        return W + U, P + Pv, None
    T = A + Av
    return W + U, P + Pv, T if dyadic else T.dense()


def _a3333(T: DyadicTangent) -> np.ndarray:
    """``A[:, 2, 2, 2, 2]`` of ``T.dense()``, shape (n,), Pa, without forming the (n, 3, 3, 3, 3)
    array: the same products summed in the same order as :meth:`DyadicTangent.dense`, so the
    same numbers to the last bit."""
    f, g = T.F[:, 2, 2], T.FiT[:, 2, 2]
    a = T.mixed * (f * g + g * f)
    a += T.inverse * (g * g)
    a += T.cross * (g * g)
    a += T.identity * 1.0
    return a


def _dense_block(T: DyadicTangent, i: slice, j: slice, k: slice, l: slice) -> np.ndarray:
    """``T.dense()[:, i, j, k, l]`` (Pa) without forming the whole (n, 3, 3, 3, 3) array: the
    same products summed in the same order as :meth:`DyadicTangent.dense`, entry by entry."""
    F, G = T.F, T.FiT
    co = lambda c: c[:, None, None, None, None]  # noqa: E731
    A = co(T.mixed) * (_dyad(F[:, i, j], G[:, k, l]) + _dyad(G[:, i, j], F[:, k, l]))
    A += co(T.inverse) * _dyad(G[:, i, j], G[:, k, l])
    # cross: Fi_Jk Fi_Li with Fi = G^T, i.e. G_kJ G_iL, arranged [n, i, J, k, L]
    A += co(T.cross) * (
        np.swapaxes(G[:, k, j], 1, 2)[:, None, :, :, None] * G[:, i, l][:, :, None, None, :]
    )
    eye = np.eye(3)
    A += co(T.identity) * np.einsum("ik,JL->iJkL", eye[i, k], eye[j, l])[None]
    return A


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
        _, P, T = neo_hookean(F, shear, bulk, True, dyadic=True)
        step = P[:, 2, 2] / _a3333(T)
        lam_new = lam - step
        # keep the stretch positive (halve toward zero instead of crossing it)
        lam = np.where(lam_new > 0, lam_new, 0.5 * lam)
        if np.max(np.abs(step) / lam) < tol:
            break
    F[:, 2, 2] = lam
    W, P, T = neo_hookean(F, shear, bulk, tangent, dyadic=True)
    P2 = P[:, :2, :2].copy()
    if not tangent:
        return W, P2, None, lam
    ab, t = slice(0, 2), slice(2, 3)
    A2 = (
        _dense_block(T, ab, ab, ab, ab)
        - _dyad(_dense_block(T, ab, ab, t, t)[..., 0, 0], _dense_block(T, t, t, ab, ab)[:, 0, 0])
        / _a3333(T)[:, None, None, None, None]
    )
    return W, P2, A2, lam
