"""Hard-magnetic terms of the energy ``-(F M) . B(x)``, ``x = X + u`` (Zhao et al. 2019).

Per reference volume and per quadrature point (arrays over ``n`` points, spatial dimension
``d`` = 2 or 3, all SI):

* energy density ``-(F M) . B``;
* first Piola magnetic stress ``P_m = -B (x) M`` (``[i, J] = -B_i M_J``), tested with
  ``grad(du)``;
* body force ``f = G^T (F M)`` (``f_k = G_ik (F M)_i``), entering the residual as ``-f . du``;
* tangent (seed eq. 13 plus the field-curvature term): the derivative of the residual
  ``P_m : grad(du) - f . du`` in direction ``Du`` is
  ``grad(du)_iJ C_iJk Du_k + du_k C_iJk grad(Du)_iJ + du_k H_kl Du_l`` with
  ``C_iJk = -G_ik M_J`` and ``H_kl = -(F M)_i d2B_i/(dx_k dx_l)``.

For a uniform field G = 0: the magnetic term is a dead load and adds nothing to the tangent.
"""

from __future__ import annotations

import numpy as np

__all__ = ["magnetic_energy", "magnetic_stress", "body_force", "curvature_stiffness"]


def magnetic_energy(F: np.ndarray, M: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``-(F M) . B`` per point, shape (n,), J/m^3.  F (n, d, d), M (n, d) A/m, B (n, d) T."""
    return -np.sum(np.matmul(F, M[:, :, None])[:, :, 0] * B, axis=1)


def magnetic_stress(M: np.ndarray, B: np.ndarray) -> np.ndarray:
    """First Piola magnetic stress ``-B (x) M``, shape (n, d, d), Pa."""
    return -B[:, :, None] * M[:, None, :]


def body_force(F: np.ndarray, M: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Magnetic body force ``G^T (F M)``, shape (n, d), N/m^3.  G (n, d, d) T/m."""
    FM = np.matmul(F, M[:, :, None])  # (n, d, 1)
    return np.matmul(np.swapaxes(G, 1, 2), FM)[:, :, 0]


def curvature_stiffness(F: np.ndarray, M: np.ndarray, H: np.ndarray) -> np.ndarray:
    """``H_kl = -(F M)_i d2B_i/(dx_k dx_l)``, shape (n, d, d), N/m^4 (zero for linear fields)."""
    FM = np.matmul(F, M[:, :, None])[:, :, 0]
    return -np.einsum("ni,nikl->nkl", FM, H)
