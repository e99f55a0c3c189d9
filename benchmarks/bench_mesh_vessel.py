"""MeshVessel against the analytic Vessel it tessellates: gaps, normals and an insertion.

A bend (``Vessel.bend(0.02, pi/2, 2e-3, 0.01, 0.01)``) and a branch (as a ``VesselNetwork`` of
one mesh per member) are tessellated with ``n`` vertices per ring (rings about one ring-edge
apart, :func:`coilrod.contact.tessellate`); the mesh's exact polyhedral gap and normal at 400
random points within 0.5 mm of the wall, away from the (flat-capped) ends, are compared with
the analytic vessel's.  Rates are log2 of successive error ratios (2 = second order).  Then
the README's insertion (the bend of radius ``r_ins``) is run in the analytic vessel and in the
meshes: tip path and largest wall force.  (With the README's 3 mm lumen the rod never touches
the wall on these 9 steps, so the lumen is 1.5 mm here.)  Known result: the contact Newton
does not converge against the faceted wall (the polyhedron's gap is only Lipschitz inside:
its gradient jumps where the closest face changes), see results/mesh_vessel.md.

Run: ``python benchmarks/bench_mesh_vessel.py`` (prints markdown tables).
"""

from __future__ import annotations

import math
import time

import numpy as np

import coilrod
import coils
from coilrod import presets
from coilrod.contact import MeshVessel, Vessel, VesselNetwork, tessellate


def _samples(vessels, n=400, seed=0):
    rng = np.random.default_rng(seed)
    pts = []
    for v in vessels:
        s = rng.uniform(0.004, v.length - 0.004, n // len(vessels))
        x, t = v.position(s), v.tangent(s)
        d = rng.normal(size=(len(s), 3))
        d -= np.einsum("ij,ij->i", d, t)[:, None] * t
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        r = v.radius_at(s)
        pts.append(x + d * (r + rng.uniform(-0.5e-3, 0.5e-3, len(s)))[:, None])
    return np.vstack(pts)


def geometry_table():
    cases = {
        "bend": Vessel.bend(0.02, math.pi / 2, 2e-3, 0.01, 0.01),
        "branch": Vessel.branch(0.03, 1.5e-3, 0.012),
    }
    print("| vessel | n per ring | faces | max gap error (um) | rate | max normal error | rate |")
    print("|---|---|---|---|---|---|---|")
    for name, ref in cases.items():
        members = ref.vessels if hasattr(ref, "vessels") else [ref]
        p = _samples(members)
        if hasattr(ref, "vessels"):  # drop points in the other member's lumen (the junction)
            own = np.concatenate([np.full(len(p) // len(members), k) for k in range(len(members))])
            other = np.array([members[1 - k].gap(q[None])[0] for k, q in zip(own, p, strict=True)])
            p = p[other < -0.5e-3]
        e_ref = ref.evaluate(p, 1)
        prev = None
        for n in (8, 16, 32, 64):
            meshes = [MeshVessel(*tessellate(m, n)) for m in members]
            mv = meshes[0] if len(meshes) == 1 else VesselNetwork(meshes)
            ev = mv.evaluate(p, 1)
            eg = np.abs(ev.gap - e_ref.gap).max()
            en = np.abs(ev.gradient - e_ref.gradient).max()
            faces = sum(len(m.faces) for m in meshes)
            rg = "" if prev is None else f"{math.log2(prev[0] / eg):.2f}"
            rn = "" if prev is None else f"{math.log2(prev[1] / en):.2f}"
            print(f"| {name} | {n} | {faces} | {1e6 * eg:.3g} | {rg} | {en:.3g} | {rn} |")
            prev = (eg, en)


def insertion_table(r_ins=1.5e-3):
    rod = presets.seed_rod(presets.M1())
    vessel = Vessel.bend(0.02, np.pi / 2, r_ins, 0.005, 0.03)

    def schedule(k, length):
        a = np.pi / 2 * np.clip((length - 0.008) / 0.02, 0, 1)
        return coils.UniformField(B=5e-3 * np.array([np.cos(a), np.sin(a), 0.0]))

    lengths = np.linspace(0.006, 0.03, 9)
    clamp = {"clamp_position": (0.001, 0.0, 0.0), "clamp_rotation": np.eye(3)}
    ref = coilrod.insert(rod, vessel, lengths, schedule, nodes=32, **clamp)
    print(f"\nInsertion, bend radius of the lumen {1e3 * r_ins:g} mm, 9 steps to 30 mm:")
    print("| obstacle | max tip distance to analytic (um) | max wall force (N) | CPU (s) |")
    print("|---|---|---|---|")
    print(f"| analytic | 0 | {ref.wall_force.max():.3g} | |")
    for n in (8, 16, 32):
        mv = MeshVessel(*tessellate(vessel, n))
        t0 = time.process_time()
        try:
            ins = coilrod.insert(rod, mv, lengths, schedule, nodes=32, **clamp)
            dt = time.process_time() - t0
            err = np.linalg.norm(ins.tip - ref.tip, axis=1).max()
            print(f"| mesh n={n} | {1e6 * err:.3g} | {ins.wall_force.max():.3g} | {dt:.2f} |")
        except Exception as exc:  # report, do not hide
            print(f"| mesh n={n} | failed: {type(exc).__name__}: {str(exc)[:80]} | | |")


if __name__ == "__main__":
    geometry_table()
    insertion_table(1.5e-3)
