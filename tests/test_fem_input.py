"""FEM input validation (ValueError naming the argument), lazy import, result API and I/O."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import coilrod
import coils
from coilrod import presets

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
    assert res3.mesh.t.shape[1] == 2 * (2 * 2 + 4 * 2 * 1)
    r = np.hypot(res3.nodes[1], res3.nodes[2])
    assert r.max() == pytest.approx(D / 2, rel=1e-12)
