"""Superposition of coils and ideal fields (three orthogonal pairs, uniform + gradient, ...)."""

from __future__ import annotations

import numpy as np

from ._validate import as_vector
from .field import FieldSum

__all__ = ["CoilSystem"]


class CoilSystem(FieldSum):
    """A superposition of field sources; B, gradient and hessian add.

    Parameters
    ----------
    parts : sequence of Field
        Coils, pairs, ideal fields or other systems.
    center : array-like, shape (3,), optional
        Working point for :meth:`ideal` (m); default: the mean of the parts' centres.

    Examples
    --------
    >>> from coils import CoilSystem, HelmholtzPair, MaxwellPair
    >>> system = CoilSystem([HelmholtzPair(0.1, 100, 1.0), MaxwellPair(0.1, 100, 1.0)])
    >>> len(system.parts)
    2
    """

    def __init__(self, parts, center=None):
        super().__init__(parts)
        if center is None:
            centres = [p.center for p in self.parts if hasattr(p, "center")]
            center = np.mean(centres, axis=0) if centres else np.zeros(3)
        self.center = as_vector(center, "center")

    def ideal(self, zero_tol: float = 1e-12):
        """The LinearField of B and gradient at ``center`` (see :func:`coils.ideal.linearize`)."""
        from .ideal import linearize

        return linearize(self, self.center, zero_tol)

    def to_magpylib(self):
        """All coil filaments as one ``magpylib.Collection`` (ideal parts are skipped)."""
        import magpylib as magpy

        children = [p.to_magpylib() for p in self.parts if hasattr(p, "to_magpylib")]
        return magpy.Collection(*children)
