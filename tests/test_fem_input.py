"""FEM input validation (ValueError naming the argument), lazy import, result API and I/O."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from _scenes import scene_with

import coilrod
import coils
from coilrod import presets
from coilrod.fem.mesh import clamp_layers

L = 0.04


@pytest.fixture
def rod():
    return coilrod.Rod(L, 1e6, coilrod.Rectangle(L / 20, L / 20), presets.M1())


@pytest.fixture
def field(rod):
    return coils.UniformField((0.0, rod.field_for_lambda(1.0), 0.0))


class NaNField(coils.Field):
    def _B(self, p):
        out = np.zeros_like(p)
        out[:, 1] = np.nan
        return out

    def _gradient(self, p):
        return np.zeros((p.shape[0], 3, 3))


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        (dict(elements=(0, 1, 1)), "elements"),
        (dict(elements=(20, -1, 1)), "elements"),
        (dict(elements=(20, 1)), "elements"),
        (dict(elements=(20, 1.5, 1)), "elements"),
        (dict(elements=5), "elements"),
        (dict(dim=4), "dim"),
        (dict(dim=1), "dim"),
        (dict(order=3), "order"),
        (dict(order=0), "order"),
        (dict(poisson_ratio=0.5), "poisson_ratio"),
        (dict(poisson_ratio=float("nan")), "poisson_ratio"),
        (dict(plane="membrane", dim=2, elements=(4, 1)), "plane"),
        (dict(formulation="fbar"), "formulation"),
        (dict(utol=0.0), "utol"),
        (dict(max_iterations=0), "max_iterations"),
        (dict(max_cuts=500), "max_cuts"),
        (dict(rtol=-1.0), "rtol"),
        (dict(max_cuts=0), "max_cuts"),
    ],
)
def test_bad_arguments_raise_value_error_naming_them(rod, field, kwargs, name):
    with pytest.raises(ValueError, match=name):
        coilrod.solve_fem(rod, field, [1.0], **kwargs)


def test_bad_scales_rod_field(rod, field):
    with pytest.raises(ValueError, match="scales"):
        coilrod.solve_fem(rod, field, [1.0, np.nan])
    with pytest.raises(ValueError, match="scales"):
        coilrod.solve_fem(rod, field, [])
    with pytest.raises(ValueError, match="rod"):
        coilrod.solve_fem("rod", field, [1.0])
    with pytest.raises(ValueError, match="field"):
        coilrod.solve_fem(rod, (0, 1, 0), [1.0])


def test_nan_field_is_rejected(rod):
    with pytest.raises(ValueError, match="field"):
        coilrod.solve_fem(rod, NaNField(), [1.0], dim=2, elements=(4, 1))


def test_mesh_of_wrong_dimension(rod, field):
    from skfem import MeshQuad1

    with pytest.raises(ValueError, match="mesh"):
        coilrod.solve_fem(rod, field, [1.0], dim=3, mesh=MeshQuad1())


def test_import_coilrod_does_not_import_scikit_fem():
    code = "import sys, coilrod; assert 'skfem' not in sys.modules, 'skfem imported'"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_result_api_export_and_plot(rod, field, tmp_path):
    import meshio

    res = coilrod.solve_fem(rod, field, [0.0, 1.0], dim=3, elements=(4, 1, 1))
    assert res.tip.shape == (2, 3)
    np.testing.assert_allclose(res.tip[0], [L, 0.0, 0.0], atol=1e-12 * L)
    u = res.displacement(1)
    assert u.shape == (3, res.nodes.shape[1])
    # the free-end centroid is the mean of the end-face nodes' positions for this box
    # (quadratic nodes: the centroid of a bilinear face is its Simpson average)
    xk = res.deformed_nodes(1)
    assert np.allclose(
        xk[:, np.abs(res.nodes[0]) < 1e-12], res.nodes[:, np.abs(res.nodes[0]) < 1e-12]
    )
    vtu = res.export(tmp_path / "state.vtu")
    back = meshio.read(vtu)
    nv = res.mesh.p.shape[1]
    np.testing.assert_allclose(back.point_data["displacement"], u[:, :nv].T)
    xdmf = res.export(tmp_path / "path.xdmf")
    with meshio.xdmf.TimeSeriesReader(xdmf) as reader:
        reader.read_points_cells()
        assert reader.num_steps == 2
    # bad paths and states: one ValueError or OSError naming them (were meshio's WriteError,
    # an IndexError, a half-written file), and no temporary file left
    with pytest.raises(ValueError, match="state.txt.*meshio writes no '.txt'"):
        res.export(tmp_path / "state.txt")
    with pytest.raises(ValueError, match="k must be a state index from -2 to 1; got 2"):
        res.export(tmp_path / "state.vtu", k=2)
    with pytest.raises(FileNotFoundError, match="cannot write '.*none/state.vtu'"):
        res.export(tmp_path / "none" / "state.vtu")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["path.xdmf", "state.vtu"]
    ax = res.plot(1)
    assert ax.get_xlabel() == "x (m)"


def test_circle_mesh_and_2d_circle(field):
    """Seed rod: the 2D strip has the circle's I/A; the 3D mesh is a quadratic O-grid."""
    rod = presets.seed_rod()
    res2 = coilrod.solve_fem(rod, field, [0.0], dim=2, elements=(4, 1))
    h = res2.nodes[1].max() - res2.nodes[1].min()
    D = rod.section.diameter
    assert h == pytest.approx(np.sqrt(3) / 2 * D, rel=1e-12)
    res3 = coilrod.solve_fem(rod, field, [0.0], dim=3, elements=(2, 2, 1))
    # 2 layers and the clamp's graded ones (the first halved to no longer than D)
    layers = 2 + clamp_layers(rod.length / 2, D)
    assert layers > 2
    assert res3.mesh.t.shape[1] == layers * (2 * 2 + 4 * 2 * 1)
    r = np.hypot(res3.nodes[1], res3.nodes[2])
    assert r.max() == pytest.approx(D / 2, rel=1e-12)


# -- what the 2D FEM cannot represent (issue 23) ------------------------------------------------
def _square_rod():
    return coilrod.Rod(L, 1e6, coilrod.Rectangle(2e-3, 2e-3), presets.M1())


def test_2d_refuses_an_out_of_plane_field_and_3d_is_the_rotated_elastica():
    """B = (0, 2b, 3b): the 2D FEM kept (B_x, B_y) and put the tip 22.9 mm off.  It must refuse
    (as the planar rod does), and the 3D FEM -- the square section bends alike about every
    axis -- is the planar rod (an independent discretisation) in the plane of x and B,
    lambda = sqrt(13), rotated back, within the continuum's known offset (clamp layer, shear:
    about 1 % of L; tests/test_fem_accuracy.py)."""
    rod = _square_rod()
    b = rod.field_for_lambda(1.0)
    field = coils.UniformField((0.0, 2 * b, 3 * b))
    with pytest.raises(ValueError, match=r"dim=2 would drop.*B_z.*use dim=3"):
        coilrod.solve_fem(rod, field, [1.0], dim=2, elements=(10, 1))
    with pytest.raises(ValueError, match="B_z"):  # the same criterion
        coilrod.solve_rod(rod, field, [1.0], model="planar")
    fem = coilrod.solve_fem(rod, field, [1.0], dim=3, elements=(10, 1, 1))
    planar = coilrod.solve_rod(rod, coils.UniformField((0.0, np.sqrt(13) * b, 0.0)), [1.0])
    x, w = planar.tip[0, 0], planar.tip[0, 1]  # w along the field's unit (0, 2, 3) / sqrt(13)
    expected = np.array([x, 2 * w / np.sqrt(13), 3 * w / np.sqrt(13)])
    assert np.linalg.norm(fem.tip[0] - expected) < 0.005 * L, (fem.tip[0], expected)
    assert expected[2] > 0.4 * L  # a large out-of-plane deflection, not a small one


class _TwistField(coils.Field):
    """B = g (z, 0, x) (curl- and divergence-free): B_z = 0 on the x axis but dB_z/dx = g, an
    out-of-plane force on the rod's plane z = 0."""

    def _B(self, p):
        return 0.05 * np.stack([p[:, 2], 0.0 * p[:, 0], p[:, 0]], axis=1) + [0, 0.01, 0]

    def _gradient(self, p):
        G = np.zeros((p.shape[0], 3, 3))
        G[:, 0, 2] = G[:, 2, 0] = 0.05
        return G


@pytest.mark.parametrize(
    ("field", "refused"),
    [
        (coils.UniformField((0.0, 0.01, 1e-4)), True),
        (_TwistField(), True),
        (coils.UniformField((0.003, 0.01, 0.0)), False),
        (coils.LinearField((0.0, 0.01, 0.0), coils.maxwell_gradient(0.5), (0.01, 0, 0)), False),
    ],
)
def test_2d_fem_refuses_what_the_planar_rod_refuses(field, refused):
    rod = _square_rod()
    if refused:
        with pytest.raises(ValueError, match="use dim=3"):
            coilrod.solve_fem(rod, field, [0.0], dim=2, elements=(4, 1))
        with pytest.raises(ValueError, match="model='planar' would drop"):
            coilrod.solve_rod(rod, field, [0.0], model="planar")
    else:
        coilrod.solve_fem(rod, field, [0.0], dim=2, elements=(4, 1))
        coilrod.solve_rod(rod, field, [0.0], model="planar")


# -- a given mesh must be the rod's (issue 23) --------------------------------------------------
def _box(x1, y0, y1, z0=-1e-3, z1=1e-3, x0=0.0):
    from skfem import MeshHex1

    return MeshHex1.init_tensor(
        np.linspace(x0, x1, 5), np.linspace(y0, y1, 2), np.linspace(z0, z1, 2)
    )


@pytest.mark.parametrize(
    ("mesh", "match"),
    [
        (_box(2 * L, -1e-3, 1e-3), r"span x in \[0, L\]"),  # tip taken inside the mesh
        (_box(L, -1e-3, 1e-3, x0=-1e-3), r"span x in \[0, L\]"),
        (_box(L, -0.8e-3, 1.2e-3), r"\|y\| = 0.0012"),  # off the axis
        (_box(L, -1.5e-3, 1.5e-3), r"\|y\| = 0.0015"),  # too thick
        (_box(L, -1e-3, 1e-3, -2e-3, 2e-3), r"\|z\| = 0.002"),  # too wide
        (_box(L, -0.5e-3, 0.5e-3), r"area .* 50 %"),  # too thin
    ],
)
# uniform given meshes of 4 layers, 5 sections long: valid, with the ungraded clamp's warning
@pytest.mark.filterwarnings("ignore:mesh. an element:coilrod.StabilityWarning")
def test_a_given_mesh_must_be_the_rods(mesh, match):
    rod = _square_rod()
    field = coils.UniformField((0.0, rod.field_for_lambda(1.0), 0.0))
    with pytest.raises(ValueError, match="mesh") as err:
        coilrod.solve_fem(rod, field, [0.0], dim=3, mesh=mesh)
    assert err.match(match)
    coilrod.solve_fem(rod, field, [0.0], dim=3, mesh=_box(L, -1e-3, 1e-3))  # the right one


# uniform given meshes of 4 layers, 5 sections long: valid, with the ungraded clamp's warning
@pytest.mark.filterwarnings("ignore:mesh. an element:coilrod.StabilityWarning")
def test_given_mesh_kind_and_the_generated_meshes_pass():
    from skfem import MeshHex1, MeshQuad1, MeshTri

    from coilrod.fem.mesh import check_mesh, circle_mesh, rod_mesh

    rod = _square_rod()
    field = coils.UniformField((0.0, rod.field_for_lambda(1.0), 0.0))
    with pytest.raises(ValueError, match="MeshQuad1 or MeshQuad2"):
        coilrod.solve_fem(rod, field, [0.0], dim=2, mesh=MeshTri())
    strip = MeshQuad1.init_tensor(np.linspace(0, L, 5), np.linspace(-1e-3, 1e-3, 2))
    coilrod.solve_fem(rod, field, [0.0], dim=2, mesh=strip)
    seed = presets.seed_rod()
    quadratic = circle_mesh(seed.length, seed.section.diameter, 4, 2, 1)
    with pytest.raises(ValueError, match="linear elements .* quadratic-geometry MeshHex2"):
        coilrod.solve_fem(seed, field, [0.0], dim=3, order=1, mesh=quadratic)
    coilrod.solve_fem(seed, field, [0.0], dim=3, order=1, mesh=MeshHex1(quadratic.p, quadratic.t))
    with pytest.raises(ValueError, match="core = 1 has a square section"):
        coilrod.solve_fem(seed, field, [0.0], dim=3, order=1, elements=(4, 1, 1))
    for r in (rod, seed):
        for dim, order, el in [
            (2, 1, (4, 2)),
            (2, 2, (4, 1)),
            (3, 1, (4, 2, 2)),
            (3, 2, (4, 1, 1)),
        ]:
            check_mesh(rod_mesh(r, dim, el, order), r, dim, order)


def test_scene_check_refuses_the_linear_square_ogrid():
    """check and run stop at the same problem: order 1 with core = 1 on a Circle."""
    from coilrod.scene import SceneError, parse_scene

    data = scene_with(models={"run": ["fem3d"]}, fem={"order": 1, "elements3d": [20, 1, 1]})
    with pytest.raises(SceneError, match=r"fem.elements3d: elements \(20, 1, 1\).*core = 1"):
        parse_scene(data)
    parse_scene(scene_with(models={"run": ["fem3d"]}, fem={"order": 1, "elements3d": [20, 2, 1]}))
