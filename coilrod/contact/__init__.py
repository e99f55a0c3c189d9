"""Rigid obstacles for contact: walls, vessels (tubes around a centreline) and vessel networks.

Every obstacle has the same small interface (:class:`Obstacle`): the signed gap ``gap(p)``
(> 0 admissible, < 0 penetration, m), its gradient (the unit normal into the admissible side)
and hessian, ``evaluate(p, order)`` for all three from one nearest-point search,
``contains``, ``check_start``, ``bounds`` and ``plot``.  The contact terms of the models use
only this interface.

====================  =========================================================================
``Wall``              a plane (``geometry`` exact)
``Vessel``            a tube around a polyline, a C2 spline or exact line/arc pieces; constant,
                      piecewise-linear or smooth radius; ends extended or rounded
``VesselNetwork``     the union of several vessels' lumens (gap = max)
``MeshVessel``        the lumen inside a triangle surface mesh (STL, OBJ, PLY; exact distances)
``read_centerline``   a Vessel from VMTK's centreline + inscribed-sphere radii (CSV, ASCII VTP)
``presets``           ``straight``, ``bend``, ``aneurysm``, ``branch`` (also ``Vessel.<name>``)
``insert``            quasi-static insertion of a rod into a vessel (:mod:`.insertion`)
====================  =========================================================================
"""

from . import presets
from .insertion import Insertion, insert
from .mesh_vessel import MeshVessel, phantom_path, tessellate
from .network import VesselNetwork
from .obstacle import GapEvaluation, Obstacle
from .vessel import Vessel, read_centerline
from .wall import Wall

__all__ = [
    "Obstacle",
    "GapEvaluation",
    "Wall",
    "Vessel",
    "VesselNetwork",
    "MeshVessel",
    "tessellate",
    "phantom_path",
    "read_centerline",
    "presets",
    "insert",
    "Insertion",
]
