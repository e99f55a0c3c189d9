"""A genuinely 3D magnetic cantilever relaxed to static equilibrium with PyElastica 1.0
(PositionVerlet + AnalyticalLinearDamper), for bench_rod3d.py's comparison.

Runs in its own environment (no coilrod import):
    python3.11 -m venv V && V/bin/pip install pyelastica==1.0.0 numba
    V/bin/python benchmarks/peers/pyelastica_spatial.py --n 25 50 100 --json out.json

Problem (L = 1, circular r = 0.025, E = 1e6, nu = 0.5: G = E/3, rho = 1e3): clamp at the
origin, tangent +x; PyElastica's directors d3 = +x (tangent), d1 = +y, d2 = +z map to
coilrod's body frame (tangent, normal, binormal) = (d3, d1, d2).  Body magnetization
M_body = (cos a cos e, sin a cos e, sin e) (coilrod's (t, n, b) components) with a = 0.3,
e = 0.4, uniform field B along (0.3, 1, 0.5)/|.|, |M||B| A L^2 / (E I) = lambda = 3.  The
couple per element k is A l_k m x B (world), applied in the material frame (d_i . (m x B)).
Stop when the tip moves < tol L over one period of the first bending mode.
"""

import argparse
import json
import time

import elastica as ea
import numpy as np
from numba import njit

ANGLE, ELEVATION, LAM = 0.3, 0.4, 3.0
FIELD = np.array([0.3, 1.0, 0.5]) / np.linalg.norm([0.3, 1.0, 0.5])


@njit(cache=True)
def _add_couple(external_torques, directors, moment, mb, B):
    n = moment.shape[0]
    for k in range(n):
        # world magnetization: M_t d3 + M_n d1 + M_b d2
        m0 = mb[0] * directors[2, 0, k] + mb[1] * directors[0, 0, k] + mb[2] * directors[1, 0, k]
        m1 = mb[0] * directors[2, 1, k] + mb[1] * directors[0, 1, k] + mb[2] * directors[1, 1, k]
        m2 = mb[0] * directors[2, 2, k] + mb[1] * directors[0, 2, k] + mb[2] * directors[1, 2, k]
        c0 = m1 * B[2] - m2 * B[1]
        c1 = m2 * B[0] - m0 * B[2]
        c2 = m0 * B[1] - m1 * B[0]
        for i in range(3):
            external_torques[i, k] += moment[k] * (
                directors[i, 0, k] * c0 + directors[i, 1, k] * c1 + directors[i, 2, k] * c2
            )


class MagneticCouple(ea.NoForces):
    def __init__(self, magnetization_times_area, body, field, rest_lengths):
        super().__init__()
        self.moment = magnetization_times_area * np.array(rest_lengths, dtype=np.float64)
        self.body = np.asarray(body, dtype=np.float64)
        self.field = np.asarray(field, dtype=np.float64)

    def apply_torques(self, system, time=0.0):  # noqa: ARG002  (PyElastica's signature)
        _add_couple(
            system.external_torques, system.director_collection, self.moment, self.body, self.field
        )


class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
    pass


def run(n_elem, dt_fac=0.8, gamma_fac=3.0, shear_scale=1.0, tol=1e-6, max_steps=50_000_000):
    L, r, E, rho = 1.0, 0.025, 1e6, 1e3
    G = E / 3.0
    A, I = np.pi * r**2, np.pi * r**4 / 4.0
    MA = LAM * E * I / L**2
    body = np.array(
        [np.cos(ANGLE) * np.cos(ELEVATION), np.sin(ANGLE) * np.cos(ELEVATION), np.sin(ELEVATION)]
    )
    c = np.sqrt(E / rho)
    dl = L / n_elem
    dt = dt_fac * dl / c
    omega1 = 1.875104**2 * np.sqrt(E * I / (rho * A * L**4))
    sim = Sim()
    rod = ea.CosseratRod.straight_rod(
        n_elem,
        np.zeros(3),
        np.array([1.0, 0, 0]),
        np.array([0, 1.0, 0]),
        L,
        r,
        rho,
        youngs_modulus=E,
        shear_modulus=G,
    )
    if shear_scale != 1.0:
        rod.shear_matrix *= shear_scale
    sim.append(rod)
    sim.constrain(rod).using(
        ea.OneEndFixedBC, constrained_position_idx=(0,), constrained_director_idx=(0,)
    )
    sim.add_forcing_to(rod).using(
        MagneticCouple,
        magnetization_times_area=MA,
        body=body,
        field=FIELD,
        rest_lengths=rod.rest_lengths,
    )
    sim.dampen(rod).using(
        ea.AnalyticalLinearDamper, uniform_damping_constant=gamma_fac * omega1, time_step=dt
    )
    sim.finalize()
    stepper = ea.PositionVerlet()
    window = 1.0 / omega1
    sub = max(1, int(round(window / 10 / dt)))
    hist, t, step, converged = [], np.float64(0.0), 0, False
    t0 = time.perf_counter()
    while step < max_steps:
        for _ in range(sub):
            t = stepper.step(sim, t, dt)
        step += sub
        tip = rod.position_collection[:, -1].copy()
        if not np.all(np.isfinite(tip)):
            break
        hist.append(tip)
        if len(hist) > 10:
            h = np.array(hist[-11:])
            if np.max(np.linalg.norm(h - h[-1], axis=1)) < tol * L:
                converged = True
                break
    wall = time.perf_counter() - t0
    tip = rod.position_collection[:, -1].copy()
    return dict(
        n_elem=n_elem,
        lam=LAM,
        dt=dt,
        steps=step,
        wall_s=wall,
        converged=converged,
        tip=(tip / L).tolist(),
        shear_scale=shear_scale,
    )


#: ~90 % of the measured stability limit of the time step (as the planar peer script)
DT_FAC = {25: 0.65, 50: 0.8, 100: 0.85, 200: 0.85}

if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--n", type=int, nargs="+", default=[25, 50, 100])
    p.add_argument("--json", default=None)
    a = p.parse_args()
    run(10, max_steps=2000)  # JIT warm-up
    outs = []
    for n in a.n:
        out = run(n, dt_fac=DT_FAC.get(n, 0.8))
        print(json.dumps(out), flush=True)
        outs.append(out)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(outs, fh, indent=1)
