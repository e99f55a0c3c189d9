"""Independent reference for the rod tests: seed eq. (5) as a first-order BVP for solve_bvp.

Unknowns y = (theta, kappa, x, y, Fx, Fy) with F(s) = A int_s^L f ds' (so F' = -A f, F(L) = 0):

    theta' = kappa,   EI kappa' = -A t_z - (-sin(theta) Fx + cos(theta) Fy),
    x' = cos(theta),  y' = sin(theta),  F' = -A f,

t_z = m_x B_y - m_y B_x, f = (grad B)^T m, m = |M| (cos(theta + theta_m), sin(...)), B and grad B
at the deformed point.  A magnetization with breakpoints is solved as a multipoint problem:
each piece is mapped to [0, 1] and the pieces are joined by continuity conditions, so the
jumps are exact.  Shares no code with coilrod's solver (only the field and rod objects).
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_bvp


class BVPSolution:
    """solve_bvp result of a multipoint problem: ``sol(s)`` gives y (6, ...) at arc length s."""

    def __init__(self, raw, edges):
        self.raw = raw
        self.edges = edges
        self.status = raw.status
        self.x = raw.x

    def sol(self, s):
        s = np.atleast_1d(np.asarray(s, dtype=float))
        j = np.clip(np.searchsorted(self.edges, s, side="right") - 1, 0, len(self.edges) - 2)
        tau = (s - self.edges[j]) / np.diff(self.edges)[j]
        out = np.empty((6, s.size))
        for k in range(s.size):
            out[:, k] = self.raw.sol(tau[k])[6 * j[k] : 6 * j[k] + 6]
        return out[:, 0] if out.shape[1] == 1 else out


def solve_bvp_rod(
    rod,
    field,
    scale=1.0,
    *,
    clamp_position=(0.0, 0.0, 0.0),
    clamp_angle=0.0,
    tol=1e-10,
    guess=None,
    nodes=101,
    max_nodes=200000,
):
    """Solve eq. (5) with scipy's solve_bvp; ``sol(L)[2:4]`` is the tip.

    ``guess`` is an optional callable s -> theta(s) (rad) for the initial mesh.
    """
    L = rod.length
    EI = rod.bending_stiffness
    A = rod.area
    mag = rod.magnetization
    clamp = np.asarray(clamp_position, dtype=float)
    edges = np.unique(np.concatenate([[0.0], [b for b in mag.breakpoints if 0 < b < L], [L]]))
    lengths = np.diff(edges)
    k = lengths.size

    def piece(s, y, inside):
        theta, kappa, x, yy, Fx, Fy = y
        pts = np.stack([x, yy, np.full_like(x, clamp[2])], axis=1)
        B, G = field.B_and_gradient(pts)
        B, G = scale * B, scale * G
        phase = theta + mag.angle(inside)
        M = mag.magnitude(inside)
        mx, my = M * np.cos(phase), M * np.sin(phase)
        tz = mx * B[:, 1] - my * B[:, 0]
        fx = G[:, 0, 0] * mx + G[:, 1, 0] * my
        fy = G[:, 0, 1] * mx + G[:, 1, 1] * my
        dkappa = (-A * tz - (-np.sin(theta) * Fx + np.cos(theta) * Fy)) / EI
        return np.vstack([kappa, dkappa, np.cos(theta), np.sin(theta), -A * fx, -A * fy])

    def rhs(tau, Y):
        out = np.empty_like(Y)
        t_in = np.clip(tau, 1e-12, 1 - 1e-12)  # magnetization of the piece itself at its ends
        for j in range(k):
            s = edges[j] + tau * lengths[j]
            inside = edges[j] + t_in * lengths[j]
            out[6 * j : 6 * j + 6] = lengths[j] * piece(s, Y[6 * j : 6 * j + 6], inside)
        return out

    def bc(Ya, Yb):
        res = [Ya[0] - clamp_angle, Ya[2] - clamp[0], Ya[3] - clamp[1]]
        for j in range(k - 1):
            res.extend(Yb[6 * j : 6 * j + 6] - Ya[6 * j + 6 : 6 * j + 12])
        last = 6 * (k - 1)
        res.extend([Yb[last + 1], Yb[last + 4], Yb[last + 5]])
        return np.array(res)

    tau = np.linspace(0.0, 1.0, nodes)
    s_all = np.linspace(0.0, L, 20 * nodes)
    th_all = (
        np.full_like(s_all, clamp_angle) if guess is None else np.asarray(guess(s_all), dtype=float)
    )
    ds = np.diff(s_all, prepend=0.0)
    x_all = clamp[0] + np.cumsum(np.cos(th_all) * ds)
    y_all = clamp[1] + np.cumsum(np.sin(th_all) * ds)
    Y0 = np.zeros((6 * k, nodes))
    for j in range(k):
        s = edges[j] + tau * lengths[j]
        th = np.interp(s, s_all, th_all)
        Y0[6 * j] = th
        Y0[6 * j + 1] = np.interp(s, s_all, np.gradient(th_all, s_all))
        Y0[6 * j + 2] = np.interp(s, s_all, x_all)
        Y0[6 * j + 3] = np.interp(s, s_all, y_all)
    raw = solve_bvp(rhs, bc, tau, Y0, tol=tol, max_nodes=max_nodes)
    return BVPSolution(raw, edges)


def bvp_tip_continued(rod, field, scales, tol=1e-9):
    """Tip (x, y) in m of solve_bvp continued along ``scales`` (each solve starts from the
    previous one's theta), for references at loads too large for a cold start."""
    guess = None
    for s in scales:
        sol = solve_bvp_rod(rod, field, s, tol=tol, guess=guess)
        if sol.status != 0:
            raise RuntimeError(f"solve_bvp failed at scale {s} (status {sol.status})")

        def guess(arc, sol=sol):
            return sol.sol(arc)[0]

    y = sol.sol(np.array([rod.length]))
    return np.ravel([y[2], y[3]])
