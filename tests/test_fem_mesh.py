"""FEM meshes: element layers end at the magnetization's breakpoints; default element counts.

* every breakpoint is a facet plane of the 2D strip, the 3D box and the 3D O-grid, no element
  straddles one, each piece between breakpoints has at least one element layer, and the
  layers number ``elements[0]``; breakpoints are merged and trimmed by the rod mesh's rule;
* a breakpoint a few ulp off a round number gives that number's layers (no sliver, no count
  flipping between two pieces at a tie), and the solution is continuous in its position;
* convergence: a two-segment profile (a jump of |M| and of its angle) converges at the rate of
  a smooth problem (about 4 for the quadratic strip's tip) when the jump is an element
  boundary, and only at first order when it falls inside elements (the uniform layers of
  before): the quadrature smears the jump over one element.
"""

from __future__ import annotations

import numpy as np
import pytest
from skfem import MeshQuad1

import coilrod
import coils
from coilrod import presets
from coilrod.fem import DEFAULT_ELEMENTS, default_elements, length_layers
from coilrod.fem.mesh import clamp_layer, clamp_layers, rod_mesh
from coilrod.rod.mesh import MERGE_BREAKS

L = 0.04
D = L / 20
ULP = np.spacing(L)


def _segmented(lengths, section=None):
    n = len(lengths)
    M = coilrod.Magnetization.segments(
        lengths, np.linspace(128e3, 64e3, n), np.linspace(0.0, 0.9, n)
    )
    return coilrod.Rod(L, 1e6, section or coilrod.Rectangle(D, D), M)


def _layers(mesh) -> np.ndarray:
    """x of the element corners (a MeshHex2 lists its quadratic nodes in ``p`` too)."""
    return np.unique(mesh.p[0, mesh.t])


@pytest.mark.parametrize(
    ("dim", "section", "elements"),
    [
        (2, coilrod.Rectangle(D, D), (20, 1)),
        (3, coilrod.Rectangle(D, 1.5 * D), (20, 1, 2)),
        (3, coilrod.Circle(D), (20, 2, 1)),
    ],
)
def test_every_breakpoint_is_a_facet_plane(dim, section, elements):
    # a segment (0.5 mm) shorter than the L/20 = 2 mm elements, breakpoints off the grid
    lengths = [0.0031, 0.0107, 0.0005, 0.0094]
    rod = _segmented([*lengths, L - sum(lengths)], section)
    breaks = np.array(rod.magnetization.breakpoints)
    mesh = rod_mesh(rod, dim, elements)
    xs = _layers(mesh)
    # elements[0] layers in all, and in 3D the first (3.1 mm) halved once at the clamp (to
    # no longer than the section's smallest extent, 2 mm)
    graded = 0 if dim == 2 else clamp_layers(lengths[0], clamp_layer(section))
    assert graded == (dim - 2)
    assert xs.size == elements[0] + 1 + graded
    assert xs[0] == 0.0
    assert xs[-1] == L
    for b in breaks:
        assert np.min(np.abs(xs - b)) <= 2 * ULP  # a layer boundary at b
    # no element straddles a breakpoint
    xe = mesh.p[0, mesh.t]
    lo, hi = xe.min(axis=0), xe.max(axis=0)
    inside = (lo[:, None] < breaks - 2 * ULP) & (hi[:, None] > breaks + 2 * ULP)
    assert not inside.any()
    # at least one layer per piece, uniform within each piece (the clamp's graded layers
    # merged back)
    xs = np.delete(xs, np.arange(1, 1 + graded))
    edges = np.concatenate([[0.0], breaks, [L]])
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        piece = xs[(xs >= a - 2 * ULP) & (xs <= b + 2 * ULP)]
        assert piece.size >= 2
        np.testing.assert_allclose(np.diff(piece), (b - a) / (piece.size - 1), rtol=1e-12)


def test_breakpoints_merged_and_trimmed_like_the_rod_mesh():
    b = 0.37 * L
    close = b + 0.5 * MERGE_BREAKS * L  # merged into b
    near_ends = [0.0, 0.3 * MERGE_BREAKS * L, L - 0.3 * MERGE_BREAKS * L, L]  # dropped
    xs = length_layers(L, 10, [close, b, *near_ends])
    assert xs.size == 11
    assert b in xs
    assert close not in xs
    assert np.min(np.diff(xs)) > 0.5 * L / 10  # no sliver near an end or near b
    # more pieces than elements: one element each
    many = length_layers(L, 3, [0.1 * L, 0.2 * L, 0.3 * L, 0.4 * L])
    np.testing.assert_allclose(many, L * np.array([0.0, 0.1, 0.2, 0.3, 0.4, 1.0]), atol=ULP)
    # short pieces raised to one element are paid for by the long one: still n in all
    xs = length_layers(L, 6, [0.01 * L, 0.02 * L, 0.03 * L])
    assert xs.size == 7
    np.testing.assert_allclose(np.diff(xs)[3:], 0.97 * L / 3, rtol=1e-12)


@pytest.mark.parametrize("n", [10, 20])
def test_breakpoints_a_few_ulp_off_give_the_round_numbers_layers(n):
    """b = L/4 +- a few ulp: identical layers (with n = 10 the shares 2.5 + 7.5 tie), the
    boundary exactly at b, no sliver beside it."""
    reference = length_layers(L, n, [L / 4])
    for k in (-3, -1, 1, 3):
        b = L / 4 + k * np.spacing(L / 4)
        xs = length_layers(L, n, [b])
        assert b in xs  # the breakpoint itself, not a rounded copy of it
        np.testing.assert_allclose(xs, reference, rtol=0, atol=4 * ULP)
    if n == 20:  # L/4 is a node of the uniform mesh: the layers are the uniform ones
        np.testing.assert_allclose(reference, np.linspace(0, L, n + 1), rtol=0, atol=2 * ULP)


def test_breakpoint_whose_fraction_does_not_round_trip():
    """b / L * L != b for this b: the layer boundary is b itself, the layers on each side
    uniform (5 and 15 of them), none thinner than 0.9 L/20."""
    b = 0.010139330887976007
    assert b / L * L != b
    xs = length_layers(L, 20, [b])
    assert xs[5] == b
    np.testing.assert_allclose(np.diff(xs[:6]), b / 5, rtol=1e-12)
    np.testing.assert_allclose(np.diff(xs[5:]), (L - b) / 15, rtol=1e-12)
    assert np.diff(xs).min() > 0.9 * L / 20
    for k in (-2, 2):  # its neighbours give the same layers
        np.testing.assert_allclose(length_layers(L, 20, [b + k * np.spacing(b)]), xs, atol=4 * ULP)


def _two_segment_rod(b):
    M = coilrod.Magnetization.segments([b, L - b], [128e3, 64e3], [0.0, 0.6])
    return coilrod.Rod(L, 1e6, coilrod.Rectangle(D, D), M)


def _tip_y(rod, lam, mesh=None, elements=None):
    field = coils.UniformField((0.0, rod.field_for_lambda(1.0), 0.0))
    res = coilrod.solve_fem(
        rod, field, [lam], dim=2, elements=elements, mesh=mesh, poisson_ratio=0.0
    )
    return res.tip[0, 1] / L


def _order(t) -> float:
    """Observed order from three meshes, each twice as fine as the last."""
    return float(np.log2(abs(t[0] - t[1]) / abs(t[1] - t[2])))


def test_jump_at_element_boundaries_converges_at_the_smooth_rate():
    """Two segments (|M| halves and the angle turns by 0.6 rad at b = L/3), lambda = 2 (tip
    at about 0.26 L), 2D plane stress with nu = 0 (no clamp-corner singularity, so the
    smooth rate shows): the tip converges at about h^4 with the jump on a layer boundary
    and at h^1 with the jump inside elements, where it stays 30x less accurate even on a
    finer mesh."""
    b = L / 3
    rod = _two_segment_rod(b)
    aligned = [_tip_y(rod, 2.0, elements=(n, 1)) for n in (12, 24, 48)]
    p_aligned = _order(aligned)
    assert 3.4 < p_aligned < 4.6, p_aligned
    limit = aligned[2] + (aligned[2] - aligned[1]) / (2**p_aligned - 1)

    def uniform(n):  # the layers of before: b = L/3 at 2/3 or 1/3 of an element
        return MeshQuad1.init_tensor(np.linspace(0.0, L, n + 1), np.linspace(-D / 2, D / 2, 2))

    off = [_tip_y(rod, 2.0, mesh=uniform(n)) for n in (20, 40, 80)]
    p_off = _order(off)
    assert 0.7 < p_off < 1.3, p_off
    assert abs(off[2] - limit) > 30 * abs(aligned[2] - limit)
    assert abs(off[2] - limit) < 1e-3  # the same limit, reached slowly


@pytest.mark.parametrize("b", [L / 4, 0.010139330887976007])
def test_solution_is_continuous_in_the_breakpoint(b):
    """Moving the breakpoint by a few ulp moves the tip by rounding only (10 elements: at
    b = L/4 the shares tie at 2.5 + 7.5)."""
    tips = [
        _tip_y(_two_segment_rod(b + k * np.spacing(b)), 2.0, elements=(10, 1)) for k in (-2, 0, 2)
    ]
    assert max(tips) - min(tips) < 1e-11, tips
    assert tips[1] > 0.2


def test_default_elements_are_the_solvers_and_the_scene_checks():
    from coilrod.scene import checks

    box = coilrod.Rod(L, 1e6, coilrod.Rectangle(D, D), presets.M1())
    circle = presets.seed_rod()
    assert default_elements(box, 2) == default_elements(circle, 2) == (20, 1)
    assert default_elements(box, 3) == (20, 1, 1)
    assert default_elements(circle, 3) == (20, 2, 1)
    assert checks.FEM_DEFAULT_ELEMENTS is DEFAULT_ELEMENTS
    with pytest.raises(ValueError, match="dim"):
        default_elements(box, 1)
    field = coils.UniformField((0.0, 0.0, 0.0))
    res = coilrod.solve_fem(box, field, [0.0], dim=3)
    assert res.mesh.t.shape[1] == 20 * 1 * 1
    res = coilrod.solve_fem(box, field, [0.0], dim=2)
    assert res.mesh.t.shape[1] == 20 * 1


def test_3d_layers_are_graded_at_the_clamp_and_a_given_ungraded_mesh_warns():
    """Every 3D mesh rod_mesh makes has no layer longer than the section's smallest extent at
    the clamp, nor than twice its distance from the clamp (also after a short first piece);
    2D and the rod-of-L/20 defaults are unchanged; a given uniform mesh long against the
    section at the clamp gets the StabilityWarning (its stability count is a mesh property:
    tests/test_fem_stability.py::test_pure_tension_is_stable_on_coarse_meshes)."""
    from coilrod.fem.mesh import box_mesh, ungraded_clamp

    thin = coilrod.Rod(L, 1e6, coilrod.Rectangle(4e-4, 8e-4), presets.M1())
    segmented = _segmented([3e-4, 0.01, L - 0.0103], coilrod.Circle(4e-4))
    for rod, elements in ((thin, (1, 1, 1)), (thin, (8, 1, 2)), (segmented, (4, 2, 1))):
        mesh = rod_mesh(rod, 3, elements)
        xs = _layers(mesh)
        h, x0 = np.diff(xs), xs[:-1]
        assert np.all(h <= np.maximum(4e-4, 2 * x0) * (1 + 1e-9))
        assert ungraded_clamp(mesh, rod.section) == ""
        assert xs.size - 1 <= elements[0] + np.log2(L / elements[0] / 4e-4) + 3
    np.testing.assert_array_equal(_layers(rod_mesh(thin, 2, (8, 1))), np.linspace(0, L, 9))
    np.testing.assert_array_equal(
        _layers(rod_mesh(_segmented([L]), 3, DEFAULT_ELEMENTS[3])), np.linspace(0, L, 21)
    )
    field = coils.UniformField((0.01, 0.0, 0.0))
    with pytest.warns(coilrod.StabilityWarning, match=r"element 0.005 m long starts 0 m from"):
        coilrod.solve_fem(thin, field, [0.0], dim=3, mesh=box_mesh(L, 8e-4, 4e-4, 8, 1, 1))
    graded = box_mesh(L, 8e-4, 4e-4, 8, 1, 1, clamp=4e-4)
    assert ungraded_clamp(graded, thin.section) == ""
    assert "unreliable" in ungraded_clamp(box_mesh(L, 8e-4, 4e-4, 8, 1, 1), thin.section)
