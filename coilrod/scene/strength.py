"""The reference strength of a scene's field and its magneto-elastic number.

Shared by the scene checks, the runner's tables and the figures (kept apart from all three so
that none of them imports another for it).
"""

from __future__ import annotations

import numpy as np

import coils

__all__ = ["field_strength"]


def field_strength(scene) -> tuple[float, str, float]:
    """Reference strength of the scene's field at scale 1 and the magneto-elastic number.

    Parameters
    ----------
    scene : Scene
        A validated scene (its rod and fields are used).

    Returns
    -------
    value : float
        |B| at the field's centre in T (``label == "B"``); for a pure-gradient field the
        largest principal gradient in T/m (``label == "gradient"``).
    label : str
        "B" or "gradient".
    number : float
        lambda = |M| |B| A L^2 / (E I), or gamma = |M| g A L^3 / (E I) for a pure gradient;
        dimensionless, |M| the largest magnetization along the rod.

    Examples
    --------
    >>> from coilrod.scene import parse_scene
    >>> scene = parse_scene({
    ...     "robot": {"length": "40 mm", "diameter": "2 mm", "youngs_modulus": "1 MPa",
    ...               "magnetization": {"magnitude": "128 kA/m"}},
    ...     "field": {"type": "uniform", "B": "10 mT"}})
    >>> value, label, number = field_strength(scene)
    >>> label, round(value, 6), round(number, 3)   # lambda = 128e3 * 0.01 * 16 L^2 / (E D^2)
    ('B', 0.01, 8.192)
    """
    rod = scene.rod
    ideal = scene.fields.get("ideal")
    if ideal is None:
        ideal = coils.linearize(scene.fields["coils"], scene.fields["coils"].center)
    b = float(np.linalg.norm(ideal.B0))
    M = rod.magnetization.max_magnitude(rod.length)
    if b > 0:
        return b, "B", rod.magnetoelastic_number(b)
    g = float(np.abs(np.linalg.eigvalsh(0.5 * (ideal.G + ideal.G.T))).max())
    return g, "gradient", M * g * rod.area * rod.length**3 / rod.bending_stiffness
