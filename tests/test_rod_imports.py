"""Module structure of coilrod.rod: no import circle between the shared discrete base and the
planar model (issue 19)."""

import ast
from pathlib import Path

import coilrod.rod.discrete as discrete


def _imported_modules(path: Path) -> set[str]:
    """Relative module names imported anywhere in the file (function-level imports included)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            names.add(node.module or "")
    return names


def test_discrete_does_not_import_planar():
    """planar imports discrete (its base class); discrete must not import planar back."""
    assert "planar" not in _imported_modules(Path(discrete.__file__))


def test_take_slices_the_tangent_through_the_tangent():
    """DiscreteRod.take returns the members' own tangents (RodTangent.take), not refactorised."""
    import warnings

    import numpy as np

    import coils
    from coilrod import Circle, Magnetization, Rod
    from coilrod.rod.solve import build_problem, make_mesh

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rod = Rod(1.0, 1.0, Circle(1.0), Magnetization(1.0, 0.0))
    field = coils.UniformField(B=(0.0, rod.field_for_lambda(1.0), 0.0))
    P = build_problem(rod, field, make_mesh(rod, 8), np.zeros(3), 0.0)
    U = np.stack([P.straight(), P.straight() + 0.1])
    lin = P.linearize(U, np.array([1.0, 2.0]))
    one = P.take(lin, [1])
    rhs = np.ones((1, P.size))
    ref = P.linearize(U[1:], np.array([2.0])).tangent.solve(rhs)
    np.testing.assert_allclose(one.tangent.solve(rhs), ref, rtol=1e-13, atol=1e-13)
