"""What a scene may ask for: ranges of the physical quantities and caps on the work.

The ranges are wide enough for any real robot and coil (micro-robots to metre-long rods, gels to
steel, bench coils to MRI magnets) and narrow enough that every derived number (currents,
stiffness, the magneto-elastic number) stays finite and meaningful.  The caps keep one scene
below roughly half an hour and a few GB on a laptop: measured on a 2-core Xeon, a quadratic FEM
element costs about 0.1 MB (2D) and 1 MB (3D) of memory and 6 ms (2D) and 70 ms (3D) per load
step; a 4096-node rod in a coil field about 0.6 s per load step.

A value outside these limits is a :class:`~coilrod.scene.SceneError` naming the key, the range
and the reason.
"""

from __future__ import annotations

import math
from typing import NamedTuple

__all__ = [
    "Range",
    "RANGES",
    "MAX_STEPS",
    "MAX_NODES",
    "MIN_NODES",
    "MAX_SEGMENTS",
    "MAX_COILS",
    "MAX_FILAMENTS",
    "MAX_FEM_ELEMENTS",
    "MAX_FEM_ELEMENT_STEPS",
    "MAX_SCALE",
    "MAX_MAGNETOELASTIC",
    "MAX_SWEEP_POINTS",
]


class Range(NamedTuple):
    """Allowed magnitudes of one kind of quantity (SI), with the bounds as the user writes them.

    ``low`` is the smallest allowed non-zero magnitude (0: any), ``high`` the largest; ``why``
    says what the range covers, for the error message.
    """

    low: float
    high: float
    text: str
    why: str


#: Allowed ranges of the physical quantities (SI), by kind.
RANGES: dict[str, Range] = {
    "robot length": Range(1e-6, 10.0, "between 1 um and 10 m", "micro-robots to metre-long rods"),
    "section": Range(1e-7, 1.0, "between 0.1 um and 1 m", "and below the robot length"),
    "youngs_modulus": Range(1.0, 1e12, "between 1 Pa and 1000 GPa", "soft gels to diamond"),
    "magnetization": Range(0.0, 1e7, "at most 10 MA/m in size", "NdFeB magnets reach about 1 MA/m"),
    "flux density": Range(0.0, 100.0, "at most 100 T in size", "the strongest magnets reach 45 T"),
    "gradient": Range(
        0.0, 1e4, "at most 10000 T/m in size", "magnetic tweezers reach about 1000 T/m"
    ),
    "coil size": Range(1e-4, 100.0, "between 0.1 mm and 100 m", "micro-coils to MRI magnets"),
    "position": Range(0.0, 100.0, "within 100 m of the clamp", "the size of the largest coils"),
    "current": Range(0.0, 1e6, "at most 1 MA per turn in size", "superconducting coils carry kA"),
    "angle": Range(0.0, 2 * math.pi, "between -360 deg and 360 deg", "one turn either way"),
}

#: Load steps (``load.steps`` or the length of ``load.scales``).
MAX_STEPS = 1000
#: Largest load scale (``load.max_scale``, ``load.scales``): a multiple of the scene's field.
MAX_SCALE = 1000.0
#: Segments of the coarse rod mesh (``rod.nodes``); solve_rod needs at least 4.
MIN_NODES, MAX_NODES = 4, 4096
#: Magnetization segments (``robot.magnetization.segments``).
MAX_SEGMENTS = 1000
#: Coils in ``field.coil``.
MAX_COILS = 64
#: Gauss filaments per direction of a finite winding (``field.coil[i].filaments``).
MAX_FILAMENTS = 16
#: FEM elements in all (2D: quadrilaterals, 3D: hexahedra), by dimension: about 2 GB.
MAX_FEM_ELEMENTS = {2: 20_000, 3: 2_000}
#: FEM elements times load steps, by dimension: about 20 minutes per field.
MAX_FEM_ELEMENT_STEPS = {2: 200_000, 3: 20_000}
#: Largest magneto-elastic number lambda = |M| |B| A L^2 / (E I) (or gamma for a gradient) at
#: the top load: beyond it the rod simply lines up with the field within a boundary layer of
#: width L / sqrt(lambda) at the clamp, which no default mesh resolves.
MAX_MAGNETOELASTIC = 1e4
#: Points of a sweep (the product of the value counts): a day of 0.1 s rod points on one core,
#: and the rows of a CSV file a spreadsheet or pandas still reads at once.
MAX_SWEEP_POINTS = 1_000_000
