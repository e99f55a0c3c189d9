"""Contact edge cases of the rod's section and start: a rectangle's face on a (nearly)
parallel wall, a vessel exactly as wide as the rod, the start check's messages."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import coils
from coilrod import Circle, Magnetization, Rod, Vessel, Wall, solve_rod

L = 0.04


def _round_rod():
    return Rod(L, 1e6, Circle(2e-3), Magnetization(128e3, 0.0))


class _Plane:
    """A plane with the gap interface alone (no check_start, no words of its own)."""

    def __init__(self, point, normal):
        self.p, self.n = np.asarray(point, float), np.asarray(normal, float)

    def gap(self, x):
        return (np.asarray(x) - self.p) @ self.n

    def gap_gradient(self, x):
        return np.broadcast_to(self.n, np.shape(x)).copy()

    def gap_hessian(self, x):
        return np.zeros(np.shape(x) + (3,))


# -- the start check ----------------------------------------------------------------------------
def test_a_vessel_exactly_as_wide_as_the_rod_is_a_start_error():
    # a 2 mm rod on the axis of a straight tube of radius r: r = 1 mm has no room (its
    # surface touches the wall all round, the contact normal at the axis is undefined:
    # this was a ConvergenceError at scale 0); so has 1 ulp more (the tube's gap rounds
    # to -1.5e-18 m there, the same failure) -- the boundary is the check's round-off,
    # 1e-12 L on both sides: half of it wider is an error, twice it a valid start, whose
    # tip then rests on the wall (tip height = clearance, by hand)
    rod, field = _round_rod(), coils.UniformField(B=(0, 1e-3, 0))
    tol = 1e-12 * L
    for wider in (0.0, np.spacing(1e-3), 0.5 * tol):
        tube = Vessel.straight(2 * L, 1e-3 + wider, start=(-0.5 * L, 0, 0))
        with pytest.raises(ValueError, match=r"obstacles\[0\] \(Vessel\) leaves no room .*"
                           r"touches it on both sides .* as wide as the rod"):  # fmt: skip
            solve_rod(rod, field, [1.0], nodes=4, obstacles=[tube], richardson=False)
    tube = Vessel.straight(2 * L, 1e-3 + 2 * tol, start=(-0.5 * L, 0, 0))
    res = solve_rod(rod, field, [1.0], nodes=4, obstacles=[tube], richardson=False,
                    stability=False)  # fmt: skip
    assert abs(res.tip[0, 1] / (2 * tol) - 1) < 1e-3
    # narrower is the error it was
    tube = Vessel.straight(2 * L, 1e-3 - 2 * tol, start=(-0.5 * L, 0, 0))
    with pytest.raises(ValueError, match=r"thicker than the vessel"):
        solve_rod(rod, field, [1.0], nodes=4, obstacles=[tube], richardson=False)
    # a rod touching a single wall at the start has room: solved as before
    res = solve_rod(rod, field, [1.0], nodes=4, obstacles=[Wall((0, -1e-3, 0), (0, 1, 0))],
                    richardson=False, stability=False)  # fmt: skip
    assert res.tip[0, 1] > 0


def test_the_start_check_names_the_node_its_arc_length_and_the_obstacle():
    # a clamp at y = 2.5 mm turned to +y inside a tube of radius 3 mm round the x axis: by
    # hand node j (5 mm segments) is at y = 2.5 + 5 j mm, node 1 at 7.5 mm lies 4.5 mm
    # outside, the deepest is the tip (node 8, y = 42.5 mm, by 39.5 mm); it named
    # "points[1]" (which points? at what arc length?)
    rod, field = _round_rod(), coils.UniformField(B=(1e-3, 0, 0))
    kw = dict(nodes=8, richardson=False, clamp_position=(0, 2.5e-3, 0), clamp_angle=np.pi / 2)
    tube = Vessel.straight(2 * L, 3e-3, start=(-0.5 * L, 0, 0))
    with pytest.raises(ValueError, match=(
        r"^obstacles\[0\] \(Vessel\) leaves no admissible straight start: the unloaded rod's "
        r"node 1 \(of 0\.\.8\) at s = 0\.005 m, \(0, 7\.5, 0\) mm, lies 4\.5 mm outside the "
        r"vessel \(8 of 9 nodes are; the deepest, node 8 at s = 0\.04 m, by 39\.5 mm\)$"
    )):  # fmt: skip
        solve_rod(rod, field, [1.0], obstacles=[tube], **kw)
    # a wall y = 20 mm facing -y: nodes 4.. (y = 22.5 mm ...) behind it; a plain object
    # with the gap interface alone: "inside it"
    for ob, words in ((Wall((0, 0.02, 0), (0, -1, 0)), r"\(Wall\) .* behind the wall"),
                      (_Plane((0, 0.02, 0), (0, -1, 0)), r"\(_Plane\) .* inside it")):  # fmt: skip
        with pytest.raises(ValueError, match=(
            words.replace(" .* ", r" leaves no admissible straight start: the unloaded "
                          r"rod's node 4 \(of 0\.\.8\) at s = 0\.02 m, \(0, 22\.5, 0\) mm, lies "
                          r"2\.5 mm ")
        )):  # fmt: skip
            solve_rod(rod, field, [1.0], obstacles=[Vessel.straight(0.1, 0.05), ob], **kw)
    # the surface check names the contact point and its arc length: the rod along +x at
    # y = 2.5 mm in that tube: its axis inside, its 1 mm surface 0.5 mm into the wall; the
    # first contact point is node 0's corner, s = h / 2 = 2.5 mm
    kw["clamp_angle"] = 0.0
    with pytest.raises(ValueError, match=(
        r"obstacles\[0\] \(Vessel\) leaves no room for the rod's surface: the straight rod's "
        r"section \(half-extents 1 x 1 mm\) at contact point 0 \(s = 0\.0025 m\) reaches 0\.5 mm"
    )):  # fmt: skip
        solve_rod(rod, field, [1.0], obstacles=[tube], **kw)


# -- centreline files ---------------------------------------------------------------------------
_VTP = """<?xml version="1.0"?><VTKFile type="PolyData"><PolyData><Piece NumberOfPoints="NPTS">
<Points><DataArray NumberOfComponents="3" format="ascii">PTS</DataArray></Points>
<PointData><DataArray Name="radius" format="ascii">RAD</DataArray></PointData>LINES
</Piece></PolyData></VTKFile>"""
_LINES = """<Lines><DataArray Name="connectivity" format="ascii">CONN</DataArray>
<DataArray Name="offsets" format="ascii">OFFS</DataArray></Lines>"""


def test_a_one_point_vtp_centreline_is_too_short(tmp_path):
    # the CSV reader's words ("has 1 point; at least 2 needed") for a VTP of fewer than two
    # points, or whose first polyline has one (it was an error about the line offsets)
    from coilrod.contact import read_centerline

    for pts, rad, conn, offs, match in [
        ("0 0 0", "1", "0", "1", "has 1 point; at least 2 needed"),  # was: "offset is 1"
        ("0 0 0", "1", None, None, "has 1 point; at least 2 needed"),
        ("", "", None, None, "has 0 points; at least 2 needed"),
        ("0 0 0 1 0 0 2 0 0", "1 1 1", "1 0 2", "1 3", "its first line has 1 point; at least 2"),
    ]:
        lines = "" if conn is None else _LINES.replace("CONN", conn).replace("OFFS", offs)
        text = _VTP.replace("PTS", pts).replace("RAD", rad).replace("LINES", lines)
        (tmp_path / "one.vtp").write_text(text.replace("NPTS", str(len(pts.split()) // 3)))
        with pytest.raises(ValueError, match=f"one.vtp.* {match}"):
            read_centerline(tmp_path / "one.vtp")
    (tmp_path / "one.csv").write_text("x,y,z,radius\n0,0,0,1\n")
    with pytest.raises(ValueError, match="one.csv.* has 1 point; at least 2 needed"):
        read_centerline(tmp_path / "one.csv")


# -- scene checks: the FEM element count ----------------------------------------------------------
def test_scene_checks_count_the_elements_the_mesh_builder_makes():
    # the scene check's element count against the meshes rod_mesh builds (their elements
    # counted): a thin rectangle's graded clamp layers (20 layers asked, 23 made) and a 2D
    # mesh with more magnetization segments than layers asked; the count was the product
    # of the numbers given (20 x 1 x 1, 2 x 2)
    from _scenes import scene_with

    from coilrod.fem.mesh import rod_mesh
    from coilrod.scene import parse_scene
    from coilrod.scene.checks import fem_cells

    seg = {"segments": [{"length": x, "magnitude": "64 kA/m"} for x in ("5 mm", "10 mm", "25 mm")]}
    thin = {"length": "40 mm", "width": "0.4 mm", "thickness": "0.8 mm",
            "youngs_modulus": "1 MPa", "magnetization": {"preset": "M1"}}  # fmt: skip
    for robot, dim, elements in ((thin, 3, (20, 1, 1)), (seg, 2, (2, 2)), (seg, 3, (4, 1, 1))):
        key = "robot" if "length" in robot else "robot__magnetization"
        scene = parse_scene(scene_with(**{key: robot}))
        made = rod_mesh(scene.rod, dim, elements, 2).t.shape[1]
        assert fem_cells(scene, dim, elements) == made
        assert made > np.prod(elements)


# -- a rectangle's face on a (nearly) parallel wall -----------------------------------------------
def _strip_on_a_floor(tilt=0.0, Q=None):
    """A strip (thickness 1 mm in the bending plane, width 3 mm across it) laid by a uniform
    body force q per length (a gradient field on M along the axis) on a floor 1e-3 L below
    its face, the floor tilted by ``tilt`` (rad) about the rod's axis; clamp, field and floor
    turned by Q together.  Returns the solve at 16 segments, q (N/m) and the touchdown
    a (m) of beam theory, a = (72 EI delta / q)^(1/4)."""
    from coilrod import Rectangle

    Q = np.eye(3) if Q is None else Q
    rod = Rod(L, 1e6, Rectangle(width=3e-3, thickness=1e-3), Magnetization(128e3, 0.0))
    EI = rod.bending_stiffness
    q = EI / L**3
    G = np.zeros((3, 3))
    G[0, 1] = -q / (rod.area * 128e3)
    delta = 1e-3 * L
    floor = Wall(Q @ [0, -delta - 0.5e-3, 0], Q @ [0, np.cos(tilt), np.sin(tilt)])
    field = coils.LinearField(B0=(0, 0, 0), gradient=Q @ G @ Q.T)
    res = solve_rod(rod, field, [1.0], nodes=16, richardson=False, obstacles=[floor],
                    stability=False, clamp_rotation=Q)  # fmt: skip
    return res, q, (72 * EI * delta / q) ** 0.25


def test_a_face_on_a_nearly_parallel_wall_is_the_flat_support():
    # The support of a rectangle along the contact normal was one corner (|n . d_a| and
    # sign(n . d_a)): under a tilt of 1e-12 rad about the axis the corner flipped from
    # side to side of the face and Newton did not converge (ConvergenceError at scale 0.008).
    # Reference: the flat support's closed form -- beyond the touchdown the strip lies flat
    # and the contact force per length is the load q (exact on the corner mesh); a tilt
    # tau changes it at order tau (tau^2 here: the wall's normal turns by tau)
    for tilt, tol in ((0.0, 1e-9), (1e-12, 1e-9), (1e-9, 1e-9), (1e-3, 1e-3)):
        res, q, a = _strip_on_a_floor(tilt)
        s = res.contact_s
        inner = (s > a + 0.1 * L) & (s < 0.95 * L)
        assert inner.sum() >= 4
        assert res.contact_set(0)[inner, 0].all()
        f = res.contact_force(0)[inner]
        n = np.array([0, np.cos(tilt), np.sin(tilt)])
        assert np.abs(f @ n / q - 1).max() < tol  # (the normal force alone: frictionless)
        assert res.gaps(0).min() >= -1e-12 * L
        if tilt == 0.0:
            flat = res
        else:
            assert np.abs(res.tip - flat.tip).max() < max(tilt, 1e-12) * L
    # the same, turned: clamp, field and floor rotated together by Q (whose face cosines are
    # rounding, not 0: the old corner flipped there too) give the rotated answer
    Q = Rotation.from_rotvec([0.3, -0.5, 0.8]).as_matrix()
    turned, q, a = _strip_on_a_floor(0.0, Q)
    np.testing.assert_allclose(turned.tip, flat.tip @ Q.T, rtol=0, atol=1e-12 * L)
    np.testing.assert_allclose(turned.contact_force(0), flat.contact_force(0) @ Q.T, rtol=0,
                               atol=1e-9 * q)  # fmt: skip


def test_the_face_rounding_in_the_contact_jacobian(monkeypatch):
    # the rounded face's curvature (the touching point moving across the face as it turns)
    # in the contact blocks, against central differences of the residual: a strip at a
    # random state against a wall nearly parallel to its faces, with the rounding widened
    # to 0.2 so that it matters at the step of the differences (without its term the
    # blocks are off by 8e-4 of the largest)
    import coilrod.rod.spatial as spatial
    from coilrod import Rectangle
    from coilrod.rod.solve import build_spatial_problem, make_mesh

    monkeypatch.setattr(spatial, "FACE_ROUNDING", 0.2)
    rod = Rod(L, 1e6, Rectangle(3e-3, 1e-3), Magnetization(128e3, 0.0))
    field = coils.LinearField(B0=(0, 0.01, 0.002), gradient=0.4 * np.diag([-0.5, 1, -0.5]))
    wall = Wall((0, 0.01, 0), (0, -1, 0.02))
    P = build_spatial_problem(rod, field, make_mesh(rod, 5), np.array([0.02, 0, 0]), np.eye(3),
                              obstacles=[wall])  # fmt: skip
    rng = np.random.default_rng(0)
    u = P.straight().reshape(P.n, P.nv)
    u[:, 0:3] += 0.01 * rng.standard_normal((P.n, 3))
    u[:, 3:6] += 0.02 * rng.standard_normal((P.n, 3))
    u[:, 6:] = rng.standard_normal((P.n, P.nv - 6))
    u = u.ravel()
    J = P.dense_jacobian(u, 0.7)

    def residual(v):
        return P.linearize(v[None], 0.7, tangent=False).residual[0]

    fd = np.array([(residual(u + 1e-6 * e) - residual(u - 1e-6 * e)) / 2e-6
                   for e in np.eye(P.size)]).T  # fmt: skip
    assert np.abs(J - fd).max() < 1e-9 * np.abs(J).max()


# -- Richardson with friction -------------------------------------------------------------------
def test_richardson_with_friction_is_an_extrapolation():
    # A Richardson solve with friction gave the same answer to ~8 digits at 8 and 16
    # segments: not a skipped extrapolation but a fourth-order one (the errors below: 5.0e-6,
    # 3.1e-7, 1.9e-8 of the force at 4, 8, 16 segments; one mesh: 1.0e-3, 2.5e-4, 6.2e-5).
    # A tip pressed on a rough wall (mu = 0.3) sticks where it touched, so its state is the
    # frictionless one: the closed-form elastica whose tip height is the wall's, loaded by
    # the wall force F = (lambda - lambda_eff) EI / L^2.  The extrapolation at 8 segments is
    # 200x closer to it than the halved mesh alone (which a skipped one would return)
    from scipy.optimize import brentq

    from coilrod.rod.elastica import elastica

    rod = _round_rod()
    lam, d = 10.0, 0.2 * L - 1e-3  # the axis' tip height: the wall minus the radius
    lam_eff = brentq(lambda x: elastica(x, np.pi / 2, length=L).tip[1] - d, 1e-9, lam,
                     xtol=1e-15, rtol=1e-14)  # fmt: skip
    F = (lam - lam_eff) * rod.bending_stiffness / L**2
    x_tip = elastica(lam_eff, np.pi / 2, length=L).tip[0]
    wall = Wall((0, 0.2 * L, 0), (0, -1, 0), friction=0.3)
    field = coils.UniformField(B=(0, rod.field_for_lambda(lam), 0))
    res = solve_rod(rod, field, [1.0], nodes=8, obstacles=[wall], stability=False)
    assert abs(res.obstacle_forces(0)[0][1] / F - 1) < 1e-6  # (3.1e-7; 16 segments: 6.2e-5)
    assert abs(res.tip[0, 0] - x_tip) < 1e-6 * L  # (1.6e-7 L; 16 segments: 3.7e-5 L)
    assert abs(res.tip[0, 1] - d) < 1e-12 * L
    assert np.abs(res.contact_force(0)[:, [0, 2]]).max() < 1e-6 * F / L  # sticks: f_t = 0
