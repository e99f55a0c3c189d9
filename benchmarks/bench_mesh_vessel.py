"""MeshVessel against the analytic Vessel it tessellates: gaps, normals, forces and insertion.

A bend (``Vessel.bend(0.02, pi/2, 2e-3, 0.01, 0.01)``) and a branch (as a ``VesselNetwork`` of
one mesh per member) are tessellated with ``n`` vertices per ring (rings about one ring-edge
apart, :func:`coilrod.contact.tessellate`); at 400 random points within 0.5 mm of the wall,
away from the (flat-capped) ends, the mesh's gap and normal are compared with the analytic
vessel's: the smoothed gap (the default: curvature-corrected vertex tangent planes) and the
exact polyhedral one (``smooth=False``).  Rates are log2 of successive error ratios per
doubling of n (2 = second order).  Then an insertion (the 2 mm seed rod pressed by a turning
field round the bend of a 1.5 mm lumen, 9 steps to 30 mm, 32 nodes) is run in the analytic
vessel and in the meshes: tip path and wall force (the sum of the contact forces, N).  With
the polyhedral gap the contact Newton does not converge (its gradient jumps where the closest
face changes); with the smoothed gap it does, and converges to the analytic insertion.
Results: ``benchmarks/results/mesh_vessel.md``.

Every kernel runs compiled (ski-rental thresholds 0, ``_machine.compile_at_once``): the CPU
column is a warm process's; ``bench_coldstart.py`` measures what a fresh one pays.

Run: ``python benchmarks/bench_mesh_vessel.py`` (prints markdown tables); ``--quick``: 8 and 16
vertices per ring (12 and 16 for the insertion).
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

import coilrod
import coils
from coilrod import presets
from coilrod.contact import MeshVessel, Vessel, VesselNetwork, tessellate

sys.path.insert(0, str(Path(__file__).parent))
from _machine import bench_args, compile_at_once, machine_info  # noqa: E402

RINGS = (8, 16, 32, 64)  # vertices per ring, geometry table
RINGS_INSERTION = (12, 16, 24, 32, 48, 64)


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
    print(
        "| vessel | gap | n per ring | faces | max gap error (um) | rate | max normal error "
        "| rate |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name, ref in cases.items():
        members = ref.vessels if hasattr(ref, "vessels") else [ref]
        p = _samples(members)
        if hasattr(ref, "vessels"):  # drop points in the other member's lumen (the junction)
            own = np.concatenate([np.full(len(p) // len(members), k) for k in range(len(members))])
            other = np.array([members[1 - k].gap(q[None])[0] for k, q in zip(own, p, strict=True)])
            p = p[other < -0.5e-3]
        e_ref = ref.evaluate(p, 1)
        for smooth in (True, False):
            prev = None
            for n in RINGS:
                meshes = [MeshVessel(*tessellate(m, n), smooth=smooth) for m in members]
                mv = meshes[0] if len(meshes) == 1 else VesselNetwork(meshes)
                ev = mv.evaluate(p, 1)
                eg = np.abs(ev.gap - e_ref.gap).max()
                en = np.abs(ev.gradient - e_ref.gradient).max()
                faces = sum(len(m.faces) for m in meshes)
                rg = "" if prev is None else f"{math.log2(prev[0] / eg):.2f}"
                rn = "" if prev is None else f"{math.log2(prev[1] / en):.2f}"
                kind = "smoothed" if smooth else "polyhedral"
                print(
                    f"| {name} | {kind} | {n} | {faces} | {1e6 * eg:.3g} | {rg} | {en:.3g} | {rn} |"
                )
                prev = (eg, en)


def insertion_table(r_ins=1.5e-3):
    rod = presets.seed_rod(presets.M1())
    vessel = Vessel.bend(0.02, np.pi / 2, r_ins, 0.005, 0.03)

    def schedule(k, length):
        a = np.pi / 2 * np.clip((length - 0.008) / 0.02, 0, 1)
        return coils.UniformField(B=5e-3 * np.array([np.cos(a), np.sin(a), 0.0]))

    lengths = np.linspace(0.006, 0.03, 9)
    clamp = {"clamp_position": (0.001, 0.0, 0.0), "clamp_rotation": np.eye(3)}
    t0 = time.process_time()
    ref = coilrod.insert(rod, vessel, lengths, schedule, nodes=32, **clamp)
    dt = time.process_time() - t0
    fmax = np.linalg.norm(ref.wall_force, axis=1).max()
    print(f"\nInsertion, lumen radius {1e3 * r_ins:g} mm, 2 mm rod, 9 steps to 30 mm, 32 nodes:")
    print(
        "| obstacle | faces | max tip error (um) | rate | max wall force error (uN) | rate "
        "| CPU (s) |"
    )
    print("|---|---|---|---|---|---|---|")
    print(f"| analytic (max wall force {1e3 * fmax:.4g} mN) | | 0 | | 0 | | {dt:.2f} |")
    prev = None
    for n in RINGS_INSERTION:
        mv = MeshVessel(*tessellate(vessel, n))
        t0 = time.process_time()
        try:
            ins = coilrod.insert(rod, mv, lengths, schedule, nodes=32, **clamp)
        except Exception as exc:  # report, do not hide
            print(f"| mesh n={n} | failed: {type(exc).__name__}: {str(exc)[:200]} | | | | |")
            prev = None
            continue
        dt = time.process_time() - t0
        et = np.linalg.norm(ins.tip - ref.tip, axis=1).max()
        ef = np.linalg.norm(ins.wall_force - ref.wall_force, axis=1).max()
        rt = "" if prev is None else f"{math.log(prev[1] / et) / math.log(n / prev[0]):.2f}"
        rf = "" if prev is None else f"{math.log(prev[2] / ef) / math.log(n / prev[0]):.2f}"
        print(
            f"| mesh n={n} | {len(mv.faces)} | {1e6 * et:.3g} | {rt} | {1e6 * ef:.3g} | {rf} "
            f"| {dt:.2f} |"
        )
        prev = (n, et, ef)
    exact = MeshVessel(*tessellate(vessel, 16), smooth=False)
    try:
        coilrod.insert(rod, exact, lengths, schedule, nodes=32, **clamp)
        print("| polyhedral n=16 | converged | | | | | |")
    except Exception as exc:
        print(f"| polyhedral n=16 | failed: {str(exc)[:200]} | | | | | |")


if __name__ == "__main__":
    if bench_args(__doc__).quick:
        RINGS, RINGS_INSERTION = (8, 16), (12, 16)
    compile_at_once()
    print(f"Machine: {machine_info()}; process CPU time, one run.\n")
    geometry_table()
    insertion_table(1.5e-3)
