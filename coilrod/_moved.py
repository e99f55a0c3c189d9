"""Old module paths of coilrod 0.1, kept importable after the move to the layered layout.

``import coilrod.elastica`` (0.1) resolves to ``coilrod.rod.elastica`` and so on; nothing is
imported until an old path is used.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys

#: old module -> new module
MOVED = {
    "coilrod.elastica": "coilrod.rod.elastica",
    "coilrod.presets": "coilrod.robot.presets",
    "coilrod.magnetization": "coilrod.robot.magnetization",
    "coilrod.sections": "coilrod.robot.sections",
    "coilrod.rod_solver": "coilrod.rod.solve",
    "coilrod.rod_result": "coilrod.rod.result",
    "coilrod.rod_mesh": "coilrod.rod.mesh",
    "coilrod.continuation": "coilrod.rod.trace",
    "coilrod.studies": "coilrod.design.studies",
    "coilrod.units": "coilrod.scene.units",
    "coilrod.planner": "coilrod.scene.planner",
    "coilrod.runner": "coilrod.scene.runner",
    "coilrod.figures": "coilrod.scene.figures",
    "coilrod.cli": "coilrod.scene.cli",
}


class _MovedFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Resolves an old module path to the module that now holds its contents."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname in MOVED:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        return importlib.import_module(MOVED[spec.name])

    def exec_module(self, module):
        """Nothing to run: ``create_module`` returned the already imported new module."""


if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
    sys.meta_path.append(_MovedFinder())
