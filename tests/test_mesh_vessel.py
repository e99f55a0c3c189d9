"""MeshVessel: exact distances to a polyhedron, convergence to the analytic Vessel, bad input."""

import math
import warnings

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")

from coilrod.contact import MeshVessel, Vessel, VesselNetwork, phantom_path, tessellate  # noqa: E402


def _box(half=1e-3):
    m = trimesh.creation.box(extents=(2 * half,) * 3)
    return np.asarray(m.vertices), np.asarray(m.faces)


def _box_gap(p, h):
    """Closed-form signed distance (inside positive) of a cube of half-side h."""
    q = np.abs(p) - h
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    return np.where(np.max(q, axis=1) > 0, -outside, -np.max(q, axis=1))


def test_cube_gap_is_exact_signed_distance_at_faces_edges_and_corners():
    # closed form of a cube's signed distance: the sign near edges and corners needs the
    # pseudo-normals, the magnitude the exact closest point on every triangle
    h = 1e-3
    cube = MeshVessel(*_box(h), smooth=False)
    assert cube.watertight
    assert cube.volume == pytest.approx(8 * h**3)
    rng = np.random.default_rng(3)
    p = rng.uniform(-2.5 * h, 2.5 * h, (600, 3))
    np.testing.assert_allclose(cube.gap(p), _box_gap(p, h), atol=1e-15)
    # corner and edge regions outside: the gradient is the unit vector to the corner/edge
    corner = np.array([[1.5 * h, 1.2 * h, 1.1 * h]])
    u = corner - h
    np.testing.assert_allclose(cube.gap_gradient(corner), -u / np.linalg.norm(u), atol=1e-12)


def test_gradient_and_hessian_are_the_gap_derivatives():
    # central differences of the gap and of its gradient (edge, vertex and face regions)
    h = 1e-3
    cube = MeshVessel(*_box(h), smooth=False)
    p = np.array(
        [[1.4 * h, 1.3 * h, 0.2 * h], [1.4 * h, 1.3 * h, 1.2 * h], [0.3 * h, 0.1 * h, 0.2 * h]]
    )
    ev = cube.evaluate(p, 2)
    step = 1e-9
    for k in range(3):
        e = np.zeros(3)
        e[k] = step
        fd = (cube.gap(p + e) - cube.gap(p - e)) / (2 * step)
        np.testing.assert_allclose(fd, ev.gradient[:, k], atol=1e-6)
        fdg = (cube.gap_gradient(p + e) - cube.gap_gradient(p - e)) / (2 * step)
        np.testing.assert_allclose(fdg, ev.hessian[:, :, k], atol=1e-6 / h)
    assert np.abs(ev.hessian[1]).max() > 0.1 / h  # the corner region is curved


def _bend_samples(v, n=200, seed=0):
    rng = np.random.default_rng(seed)
    s = rng.uniform(0.005, v.length - 0.005, n)
    x, t = v.position(s), v.tangent(s)
    d = rng.normal(size=(n, 3))
    d -= np.einsum("ij,ij->i", d, t)[:, None] * t
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return x + d * rng.uniform(0.5e-3, 2.3e-3, n)[:, None]


def test_tessellated_bend_converges_to_the_analytic_vessel_at_second_order():
    # vertices on the exact wall: the gap error is the facets' sagitta r (1 - cos(pi/n)),
    # quartered when n doubles; the normal's error halves
    v = Vessel.bend(0.02, math.pi / 2, 2e-3, 0.01, 0.01)
    p = _bend_samples(v)
    ref = v.evaluate(p, 1)
    errs, nerrs = [], []
    for n in (8, 16):
        ev = MeshVessel(*tessellate(v, n), smooth=False).evaluate(p, 1)
        errs.append(np.abs(ev.gap - ref.gap).max())
        nerrs.append(np.abs(ev.gradient - ref.gradient).max())
        # (10% more: the quads between rings are twisted on the bend; their diagonals sag more)
        assert errs[-1] <= 2e-3 * (1 - math.cos(math.pi / n)) * 1.15
    assert math.log2(errs[0] / errs[1]) > 1.8
    assert math.log2(nerrs[0] / nerrs[1]) > 0.8


def _ring(v, s, depth, n):
    """n points on the circle at ``depth`` inside the wall of vessel v around its arc length s."""
    x, t = v.position(s)[0], v.tangent(s)[0]
    a = np.cross(t, [0.0, 0.0, 1.0])
    a /= np.linalg.norm(a)
    b = np.cross(t, a)
    th = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    r = v.radius_at(s)[0] - depth
    return x + r * (np.cos(th)[:, None] * a + np.sin(th)[:, None] * b)


def test_smoothed_gap_derivatives_are_consistent_and_continuous_across_edges():
    # central differences of the smoothed gap and its gradient, at depths from outside the wall
    # to 0.75 of the 2 mm lumen's radius (nearer the axis it blends into the polyhedral gap)
    v = Vessel.bend(0.02, math.pi / 2, 2e-3, 0.01, 0.01)
    verts, faces = tessellate(v, 12)
    mesh = MeshVessel(verts, faces)
    rng = np.random.default_rng(5)
    p = np.vstack(
        [
            _ring(v, np.array([s]), dep, 9)
            for s, dep in zip(
                rng.uniform(0.005, v.length - 0.005, 8),
                (-0.4e-3, 0.0, 0.3e-3, 0.6e-3, 0.9e-3, 1.1e-3, 1.3e-3, 1.5e-3),
                strict=True,
            )
        ]
    )
    ev = mesh.evaluate(p, 2)
    step = 1e-8
    for k in range(3):
        e = np.zeros(3)
        e[k] = step
        fd = (mesh.gap(p + e) - mesh.gap(p - e)) / (2 * step)
        np.testing.assert_allclose(fd, ev.gradient[:, k], atol=1e-5)
        fdg = (mesh.gap_gradient(p + e) - mesh.gap_gradient(p - e)) / (2 * step)
        np.testing.assert_allclose(fdg, ev.hessian[:, :, k], atol=1e-5 * np.abs(ev.hessian).max())
    # round the lumen 1 mm inside the wall (crossing every edge of a ring): the smoothed
    # normal turns by its curvature times the 6 um spacing; the polyhedron's jumps by the
    # angle between faces (30 degrees)
    ring = _ring(v, np.array([0.015]), 1e-3, 1000)
    jump = np.linalg.norm(np.diff(mesh.gap_gradient(ring), axis=0), axis=1).max()
    exact = MeshVessel(verts, faces, smooth=False)
    jump_exact = np.linalg.norm(np.diff(exact.gap_gradient(ring), axis=0), axis=1).max()
    assert jump < 2e-2 < 0.3 < jump_exact


def test_smoothed_gap_converges_to_the_analytic_bend():
    # 16 -> 32 vertices per ring: gap errors within 1 mm of the wall fall by more than 2^3
    # (curvature-corrected tangent planes), the normal's by more than 2^2
    v = Vessel.bend(0.02, math.pi / 2, 2e-3, 0.01, 0.01)
    p = _bend_samples(v, 150)
    ref = v.evaluate(p, 1)
    band = (ref.gap > -0.3e-3) & (ref.gap < 1e-3)
    assert band.sum() > 40
    errs, nerrs = [], []
    for n in (16, 32):
        ev = MeshVessel(*tessellate(v, n)).evaluate(p[band], 1)
        errs.append(np.abs(ev.gap - ref.gap[band]).max())
        nerrs.append(np.abs(ev.gradient - ref.gradient[band]).max())
    assert errs[0] < 0.02 * 2e-3
    assert math.log2(errs[0] / errs[1]) > 3.0
    assert math.log2(nerrs[0] / nerrs[1]) > 2.0


def _insert(vessel, rod, clamp_x=0.001, steps=2, b=5e-3, nodes=8):
    import coilrod
    import coils

    def schedule(k, length):
        a = np.pi / 2 * np.clip((length - 0.008) / 0.02, 0, 1)
        return coils.UniformField(B=b * np.array([np.cos(a), np.sin(a), 0.0]))

    return coilrod.insert(
        rod,
        vessel,
        np.linspace(0.006, 0.03, steps),
        schedule,
        nodes=nodes,
        clamp_position=(clamp_x, 0.0, 0.0),
        clamp_rotation=np.eye(3),
    )


def test_insertion_in_tessellated_bends_converges_to_the_analytic_one():
    # the 2 mm rod pressed round a 1.5 mm lumen's bend (contact 1 mm from the wall's axis):
    # with the polyhedral gap the contact Newton does not converge (its gradient jumps between
    # faces); with the smoothed gap the tip and the wall force tend to the analytic vessel's
    # at second order (16 -> 32 vertices per ring; benchmarks/bench_mesh_vessel.py)
    from coilrod import presets

    rod = presets.seed_rod(presets.M1())
    v = Vessel.bend(0.02, np.pi / 2, 1.5e-3, 0.005, 0.03)
    ref = _insert(v, rod)
    assert np.linalg.norm(ref.wall_force[-1]) > 1e-3  # it does touch
    tip, force = [], []
    for n in (16, 32):
        ins = _insert(MeshVessel(*tessellate(v, n)), rod)
        tip.append(np.linalg.norm(ins.tip - ref.tip, axis=1).max())
        force.append(np.abs(ins.wall_force - ref.wall_force).max())
    assert tip[0] < 2e-5  # 5e-4 of the rod's length
    assert math.log2(tip[0] / tip[1]) > 1.6
    assert math.log2(force[0] / force[1]) > 1.6


def test_branch_as_a_network_of_meshes_tends_to_the_analytic_branch():
    net = Vessel.branch(0.03, 1.5e-3, 0.012, ends="round")
    meshes = VesselNetwork([MeshVessel(*tessellate(m, 16)) for m in net.vessels])
    rng = np.random.default_rng(1)
    lo, hi = net.bounds
    p = rng.uniform(lo, hi, (400, 3))
    g = net.gap(p)
    # away from the members' ends (the tessellation caps them flat, the presets round them)
    ends = np.array([[m.position(0.0), m.position(m.length)] for m in net.vessels]).reshape(-1, 3)
    far = np.min(np.linalg.norm(p[:, None] - ends[None], axis=2), axis=1) > 3e-3
    near = (g > -1e-3) & far
    assert near.sum() > 50
    bound = 1.5e-3 * (1 - math.cos(math.pi / 16)) * 1.05
    assert np.abs(meshes.gap(p[near]) - g[near]).max() <= bound


def test_phantom_is_the_shipped_bend():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ph = MeshVessel.from_file(phantom_path("bend"))
    assert ph.watertight
    v = Vessel.bend(0.02, math.pi / 2, 2e-3, 0.01, 0.01)
    p = _bend_samples(v, 100)
    # 12 per ring: sagitta 2 mm (1 - cos 15 deg) = 68 um; rings 1 mm apart on a 20 mm bend add
    # (1 mm)^2 / (8 * 18 mm) = 7 um
    assert np.abs(ph.gap(p) - v.gap(p)).max() <= 0.08e-3
    with pytest.raises(ValueError, match="clamp at .* outside the vessel mesh"):
        ph.check_start([0.0, 0.005, 0.0], "clamp")
    assert "bend_phantom.stl" in repr(ph)


def test_mm_units(tmp_path):
    path = tmp_path / "cube.stl"
    trimesh.Trimesh(*_box(1.0)).export(path)
    cube = MeshVessel.from_file(path, units="mm")
    assert cube.gap([0.0, 0.0, 0.0])[0] == pytest.approx(1e-3)


def test_inward_normals_are_an_error_unless_fixed(tmp_path):
    # one clear error naming the file and the way out; fix_normals=True turns them round
    # (the cube of half-width 1 mm: the gap at its centre is 1 mm, as the outward mesh's)
    v, f = _box()
    path = tmp_path / "inside_out.stl"
    trimesh.Trimesh(v, f[:, ::-1], process=False).export(path)
    with pytest.raises(ValueError, match="inside_out.stl.*point into the lumen.*fix_normals=True"):
        MeshVessel.from_file(path)
    with pytest.raises(ValueError, match="fix_normals"):
        MeshVessel.from_file(path, fix_normals="yes")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cube = MeshVessel.from_file(path, fix_normals=True)
    assert cube.gap([0.0, 0.0, 0.0])[0] == pytest.approx(1e-3)
    assert MeshVessel.from_file(path, fix_normals=True).volume > 0


def test_open_mesh_is_reported(tmp_path):
    v, f = _box()
    with pytest.warns(UserWarning, match="not watertight"):
        m = MeshVessel(v, f[:-1], source="open.stl")
    assert not m.watertight
    assert "open" in repr(m)


def test_non_manifold_mesh_is_rejected():
    v, f = _box()
    # a fin: a third face on an edge of the cube
    v2 = np.vstack([v, [[5e-3, 5e-3, 5e-3]]])
    f2 = np.vstack([f, [[f[0, 0], f[0, 1], len(v)]]])
    with pytest.raises(ValueError, match="fin.stl.*not manifold"):
        MeshVessel(v2, f2, source="fin.stl")


def test_inconsistent_winding_is_rejected():
    v, f = _box()
    f = f.copy()
    f[0] = f[0, ::-1]
    with pytest.raises(ValueError, match="consistently oriented"):
        MeshVessel(v, f)


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0\n", "cannot be read|no triangle"),
        (b"\x00\x01garbage" * 3, "cannot be read|no triangle"),
        (b"", "cannot be read|no triangle"),
    ],
)
def test_corrupted_files_name_the_file(tmp_path, content, match):
    path = tmp_path / "broken.stl"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=f"broken.stl.*({match})"):
        MeshVessel.from_file(path)


def test_missing_file_and_bad_units(tmp_path):
    with pytest.raises(ValueError, match="nope.stl.*does not exist"):
        MeshVessel.from_file(tmp_path / "nope.stl")
    with pytest.raises(ValueError, match="units"):
        MeshVessel.from_file(phantom_path(), units="inch")
    with pytest.raises(ValueError, match="friction"):
        MeshVessel.from_file(phantom_path(), friction=-0.1)
    assert MeshVessel.from_file(phantom_path(), friction=0.2).friction == 0.2


# -- centrelines with radii (VMTK) --------------------------------------------------------------
from coilrod.contact import read_centerline  # noqa: E402


def _vtp(points, radii, order, fmt="ascii"):
    pts = " ".join(f"{v:.17g}" for v in np.ravel(points))
    rad = " ".join(f"{v:.17g}" for v in radii)
    con = " ".join(str(i) for i in order)
    return f"""<?xml version="1.0"?>
<VTKFile type="PolyData" version="0.1">
 <PolyData><Piece NumberOfPoints="{len(points)}" NumberOfLines="1">
  <Points><DataArray type="Float64" NumberOfComponents="3" format="{fmt}">{pts}</DataArray>
  </Points>
  <PointData><DataArray type="Float64" Name="MaximumInscribedSphereRadius" format="ascii">{rad}
  </DataArray></PointData>
  <Lines><DataArray type="Int64" Name="connectivity" format="ascii">{con}</DataArray>
  <DataArray type="Int64" Name="offsets" format="ascii">{len(order)}</DataArray></Lines>
 </Piece></PolyData>
</VTKFile>"""


def test_centerline_csv_and_vtp_give_the_tube_with_those_radii(tmp_path):
    # straight centreline on x, radius 2 mm (closed form gap r - distance from the axis)
    x = np.linspace(0.0, 40.0, 5)
    pts = np.column_stack([x, 0 * x, 0 * x])
    csv = tmp_path / "c.csv"
    csv.write_text(
        "x,y,z,MaximumInscribedSphereRadius\n" + "".join(f"{a},{b},{c},2.0\n" for a, b, c in pts)
    )
    v = read_centerline(csv, units="mm")
    p = np.array([[0.01, 0.0005, 0.0], [0.03, 0.0, -0.0025]])
    np.testing.assert_allclose(v.gap(p), [1.5e-3, -0.5e-3], atol=1e-15)
    # VTP with the points stored out of order: the polyline's connectivity orders them;
    # varying radii as Vessel(points, radii) takes them
    r = np.array([1.0, 1.5, 2.0, 1.5, 1.0])
    perm = np.array([3, 0, 4, 1, 2])
    vtp = tmp_path / "c.vtp"
    vtp.write_text(_vtp(pts[perm], r[perm], np.argsort(perm)))
    w = Vessel.from_centerline_file(vtp, units="mm")
    q = np.array([[0.015, 0.001, 0.0], [0.025, 0.0, 0.0012]])
    np.testing.assert_allclose(w.gap(q), Vessel(pts * 1e-3, r * 1e-3).gap(q), atol=1e-15)


def test_centerline_bad_input_names_the_file(tmp_path):
    bad = tmp_path / "nor.csv"
    bad.write_text("x,y,z\n0,0,0\n1,0,0\n")
    with pytest.raises(ValueError, match="nor.csv.*radius column"):
        read_centerline(bad)
    neg = tmp_path / "neg.csv"
    neg.write_text("x,y,z,radius\n0,0,0,1\n1,0,0,-1\n")
    with pytest.raises(ValueError, match=r"neg.csv.*radius of point 1"):
        read_centerline(neg)
    binary = tmp_path / "bin.vtp"
    binary.write_text(_vtp(np.eye(3), [1, 1, 1], [0, 1, 2], fmt="binary"))
    with pytest.raises(ValueError, match="bin.vtp.*only ASCII"):
        read_centerline(binary)
    broken = tmp_path / "broken.vtp"
    broken.write_text("<VTKFile><PolyData>")
    with pytest.raises(ValueError, match="broken.vtp.*not valid XML"):
        read_centerline(broken)
    with pytest.raises(ValueError, match="format must be"):
        read_centerline(phantom_path())


def test_contact_modules_import_no_circle():
    # every import between coilrod.contact's modules, at module level or inside functions:
    # the graph has no cycle (it had vessel -> presets -> vessel and network -> vessel -> presets
    # -> network)
    import ast
    from pathlib import Path

    import coilrod.contact

    folder = Path(coilrod.contact.__file__).parent
    graph = {}
    for path in folder.glob("*.py"):
        if path.stem == "__init__":
            continue
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
                deps.add(node.module.split(".")[0])
        graph[path.stem] = deps & {p.stem for p in folder.glob("*.py")}
    state = {}

    def visit(m, trail):
        if state.get(m) == "done":
            return
        assert state.get(m) != "open", f"import circle: {' -> '.join([*trail, m])}"
        state[m] = "open"
        for d in graph[m]:
            visit(d, [*trail, m])
        state[m] = "done"

    for m in graph:
        visit(m, [])
    assert "bend" in (Vessel.bend.__doc__ or "")


def test_insertion_bad_input_with_a_mesh():
    # a clamp outside the phantom's lumen, no clamp at all (a mesh has no centreline to put
    # it on), a rod thicker than a mesh tube: one named error each, before any solve
    import coilrod
    import coils
    from coilrod import presets

    rod = presets.seed_rod(presets.M1())  # 2 mm
    ph = MeshVessel.from_file(phantom_path())
    field = coils.UniformField(B=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"the clamp \(introducer\) at .* outside the vessel mesh"):
        coilrod.insert(rod, ph, [0.01], field, clamp_position=(0.002, 0.005, 0.0),
                       clamp_rotation=np.eye(3))  # fmt: skip
    with pytest.raises(ValueError, match="give clamp_position and clamp_rotation"):
        coilrod.insert(rod, ph, [0.01], field)
    thin = MeshVessel(*tessellate(Vessel.straight(0.1, 0.8e-3), 12))
    with pytest.raises(ValueError, match="thicker than the vessel"):
        coilrod.insert(rod, thin, [0.01], field, clamp_position=(0.01, 0.0, 0.0),
                       clamp_rotation=np.eye(3))  # fmt: skip
