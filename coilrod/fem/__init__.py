"""Finite-element model of hard-magnetic soft rods on scikit-fem (2D and 3D neo-Hookean).

Imported lazily by :func:`coilrod.solve_fem`: ``import coilrod`` never imports scikit-fem.

Modules: ``mesh`` (reference meshes), ``material`` (neo-Hookean energy, stress, tangent),
``magnetic`` (magnetic stress, body force, tangent terms), ``assembly`` (vectorised kernels,
sparse pattern), ``linalg`` (factorisations), ``problem`` (the model as a
:class:`~coilrod.path.PathProblem` of the shared engine), ``result`` (tips, export, plots),
``solve`` (the public entry point).
"""

from .mesh import DEFAULT_ELEMENTS, default_elements, length_layers
from .result import FEMResult
from .solve import DEFAULT_POISSON_RATIO, solve_fem

__all__ = [
    "solve_fem",
    "FEMResult",
    "DEFAULT_POISSON_RATIO",
    "DEFAULT_ELEMENTS",
    "default_elements",
    "length_layers",
]
