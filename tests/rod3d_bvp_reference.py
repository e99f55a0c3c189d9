"""An independent reference for the spatial rod: the static 3D Kirchhoff equations with
magnetic loads as a first-order boundary value problem, solved by scipy ``solve_bvp``.

State along the arc length s (non-dimensional, s in [0, 1], lengths in L, moments in EI_z/L,
forces in EI_z/L^2): position x (3), unit quaternion q (4, scalar first; the frame R(q) has
columns tangent, normal, binormal), internal force n (3) and moment m (3) in world axes:

    x' = R e1,   q' = q (x) (0, kappa) / 2,   kappa = K^-1 R^T m,
    n' = -f,     m' = -x' x n - tau,
    tau = c mu_w x b(x),  f = c L G(x)^T mu_w,  mu_w = R mu(s),

with K = diag(GJ, EI_y, EI_z) / EI_z, mu the body magnetization times A L^2 / EI_z (1/T), b and
G the field (T) and its gradient (T/m) at scale 1, c the scale; boundary conditions x(0) = 0,
q(0) = q_clamp, n(1) = 0, m(1) = 0.  The quaternion ODE keeps |q| = 1 exactly.  Nothing here
uses coilrod's rod solvers (only coils fields); loads are reached by continuation in the scale.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_bvp
from scipy.spatial.transform import Rotation


def _rot(q):
    """Rotation matrices (3, 3, m) of quaternions q (4, m), scalar first."""
    w, x, y, z = q / np.linalg.norm(q, axis=0)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def spatial_reference(
    length, stiffnesses, area, magnetization, field, scales, *,
    clamp_position=(0.0, 0.0, 0.0), clamp_rotation=None, tol=1e-10, nodes=41,
):  # fmt: skip
    """Equilibria of the spatial rod at each scale (continued from the straight rod).

    Parameters
    ----------
    length : float
        m.
    stiffnesses : (GJ, EI_y, EI_z)
        N m^2.
    area : float
        m^2.
    magnetization : callable
        s (m, (m,)) -> (m, 3) body-frame magnetization, A/m (smooth).
    field : coils field
    scales : sequence of float
    tol : float
        solve_bvp tolerance (collocation residual and boundary conditions).

    Returns
    -------
    list of dict
        Per scale: ``tip`` (3,) m, ``x`` (m, 3) m, ``R`` (m, 3, 3), ``s`` (m,) m, ``sol``.
    """
    L = float(length)
    EIz = float(stiffnesses[2])
    K = np.asarray(stiffnesses, float) / EIz
    clamp = np.asarray(clamp_position, float)
    R0 = np.eye(3) if clamp_rotation is None else np.asarray(clamp_rotation, float)
    q0 = Rotation.from_matrix(R0).as_quat()  # scalar last
    q0 = np.r_[q0[3], q0[:3]]
    factor = area * L**2 / EIz

    def mu(s):
        return (np.asarray(magnetization(s * L), float) * factor).T  # (3, m)

    def make(c):
        def rhs(s, y):
            x, q, n, m = y[0:3], y[3:7], y[7:10], y[10:13]
            R = _rot(q)
            t = R[:, 0]
            kappa = np.einsum("jim,jm->im", R, m) / K[:, None]  # K^-1 R^T m
            w, a, b, d = q
            k1, k2, k3 = kappa
            dq = 0.5 * np.array(
                [
                    -a * k1 - b * k2 - d * k3,
                    w * k1 + b * k3 - d * k2,
                    w * k2 + d * k1 - a * k3,
                    w * k3 + a * k2 - b * k1,
                ]
            )
            pts = (clamp[:, None] + L * x).T
            B, G = field.B_and_gradient(pts)
            mw = np.einsum("ijm,jm->im", R, mu(s))
            tau = c * np.cross(mw.T, B).T
            f = c * L * np.einsum("mij,im->jm", G, mw)
            dn = -f
            dm = -np.cross(t.T, n.T).T - tau
            return np.vstack([t, dq, dn, dm])

        def bc(ya, yb):
            return np.r_[ya[0:3], ya[3:7] - q0, yb[7:10], yb[10:13]]

        return rhs, bc

    s = np.linspace(0.0, 1.0, nodes)
    y = np.zeros((13, s.size))
    y[0:3] = np.outer(R0[:, 0], s)
    y[3:7] = q0[:, None]
    out, c_prev = [], 0.0
    for target in np.atleast_1d(np.asarray(scales, float)):
        step = target - c_prev
        c = c_prev
        while c < target - 1e-15 * max(1.0, abs(target)):
            trial = min(target, c + step)
            rhs, bc = make(trial)
            sol = solve_bvp(rhs, bc, s, y, tol=tol, bc_tol=tol, max_nodes=200000)
            if sol.status != 0:
                step /= 2
                if step < 1e-6 * abs(target):
                    raise RuntimeError(f"solve_bvp failed at scale {trial}: {sol.message}")
                continue
            c, s, y = trial, sol.x, sol.y
            step = min(2 * step, target - c) if c < target else step
        c_prev = c
        x = clamp + L * y[0:3].T
        R = np.moveaxis(_rot(y[3:7]), -1, 0)
        out.append({"scale": c, "tip": x[-1].copy(), "x": x, "R": R, "s": s * L, "sol": sol})
    return out
